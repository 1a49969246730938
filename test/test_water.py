# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The index of water (Quan & Fry 1995) and the port plastics (Sultanova et al. 2009).

- published values: pure water at 20 degC, 589.3 nm, relative to air, 1.33299 (CRC Handbook
  of Chemistry and Physics; Daimon & Masumura, Applied Optics 46:3811, 2007, measured
  1.333 0 relative to air); the magnitudes Quan & Fry's equation gives at 550 nm, 25 degC:
  1.3339 fresh, 1.3402 at 35 PSU; the salinity, temperature and wavelength effects;
- an independent formula (IAPWS R9-97 with the density of pure water) agrees within 4e-5
  over 400-700 nm, 0-30 degC for fresh water;
- outside the range the formula is refused, naming the parameter;
- PMMA and polycarbonate: nd 1.4906 / 1.5848 as Sultanova et al. tabulate (nd 1.4914 and
  1.5855 are the usual datasheet values, within 1e-3).
"""

from __future__ import annotations

from mechdeconv_ros.optics.glass import GlassError, lookup, refractive_index
from mechdeconv_ros.optics.water import iapws_water_index, water_index, WaterError
import numpy as np
import pytest


def test_published_values() -> None:
    assert water_index(589.3, 20.0, 0.0) == pytest.approx(1.33299, abs=3e-5)
    assert water_index(550.0, 25.0, 0.0) == pytest.approx(1.3339, abs=1e-4)
    assert water_index(550.0, 25.0, 35.0) == pytest.approx(1.3402, abs=1e-4)
    # Salinity raises the index by about 0.0064 (0.5 % in scale), heat lowers it, blue is
    # higher than red (the water's own lateral colour).
    assert water_index(550.0, 25.0, 35.0) - water_index(550.0, 25.0, 0.0) == pytest.approx(
        0.0064, abs=3e-4)
    heat = water_index(550.0, 25.0) - water_index(550.0, 5.0)
    assert heat == pytest.approx(-0.0014, abs=3e-4)
    assert water_index(650.0, 25.0, 35.0) - water_index(450.0, 25.0, 35.0) == pytest.approx(
        -0.0079, abs=4e-4)


def test_independent_formula_agrees() -> None:
    worst = max(abs(water_index(lam, t) - iapws_water_index(lam, t))
                for lam in np.linspace(400.0, 700.0, 31) for t in np.linspace(0.0, 30.0, 31))
    assert worst < 4e-5
    assert worst > 1e-6      # two formulas, not one copied


@pytest.mark.parametrize('args,name', [
    ((399.0, 20.0, 0.0), 'lens.wavelength_nm'), ((701.0, 20.0, 0.0), 'lens.wavelength_nm'),
    ((550.0, -1.0, 0.0), 'scene.temperature_c'), ((550.0, 31.0, 0.0), 'scene.temperature_c'),
    ((550.0, 20.0, -0.1), 'scene.salinity_psu'), ((550.0, 20.0, 36.0), 'scene.salinity_psu')])
def test_outside_the_range_is_refused(args: tuple, name: str) -> None:
    with pytest.raises(WaterError, match=name) as err:
        water_index(*args)
    assert err.value.parameter == name


def test_plastics() -> None:
    assert refractive_index('PMMA', 587.56) == pytest.approx(1.4906, abs=1e-4)
    assert refractive_index('acrylic', 587.56) == pytest.approx(1.4914, abs=1e-3)
    assert refractive_index('POLYCARBONATE', 587.56) == pytest.approx(1.5848, abs=1e-4)
    assert lookup('PC').label == 'PLASTIC:POLYCARBONATE'
    assert lookup('PLASTIC:PMMA').vd == pytest.approx(53, abs=3)
    # Dispersion: blue above red; measured range enforced.
    assert refractive_index('PMMA', 450.0) > refractive_index('PMMA', 650.0)
    with pytest.raises(GlassError, match='436.8'):
        refractive_index('PMMA', 400.0)
