# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Glass by name in the lens parameters: lens.glass, lens.surfaces.glass, lens.wavelength_nm.

Closed forms: the thick lens's focal length (paper eq. 8) at the glass's index at the
wavelength, v = f l / (l - f) in K; the refusals name the parameter and the surface.
"""

from __future__ import annotations

import math

from mechdeconv_ros.model.model import build_model, ModelError
from mechdeconv_ros.optics import glass
from mechdeconv_ros.optics import thick_lens
from mechdeconv_ros.tools.cli import format_report
import numpy as np
from numpy.testing import assert_allclose
import pytest

pytestmark = pytest.mark.filterwarnings('error')

SIZE = {'sensor.width_px': 640, 'sensor.height_px': 480}
PRESCRIPTION = {**SIZE, 'lens.surfaces.radius_mm': [10.0, -10.0, 0.0],
                'lens.surfaces.thickness_mm': [2.0, 1.0, 0.0],
                'lens.surfaces.refractive_index': [1.5, 1.0, 1.0], 'lens.stop_surface': 2,
                'lens.aperture_diameter_mm': 1.0}


def expected_fx(n: float, r1: float = 4.0, r2: float = -4.0, t: float = 3.0,
                l_mm: float = 1000.0, pixel_um: float = 4.0625) -> float:
    f = thick_lens.thick_lens_focal_length(n, r1, r2, t)
    return f * l_mm / (l_mm - f) / (pixel_um * 1e-3)


@pytest.mark.parametrize('wave', [435.8343, 486.1327, 587.5618, 656.2725, 850.0, 1013.98],
                         ids=['g', 'F', 'd', 'C', '850', 't'])
def test_thick_lens_glass_sets_the_index_at_the_wavelength(wave: float) -> None:
    model = build_model({**SIZE, 'lens.glass': 'N-BK7', 'lens.wavelength_nm': wave})
    n = glass.refractive_index('N-BK7', wave)
    assert model.prescription.surfaces[0].refractive_index == n
    assert_allclose(model.K[0, 0], expected_fx(n), rtol=1e-10)
    # The same lens given by its index.
    plain = build_model({**SIZE, 'lens.refractive_index': n})
    assert_allclose(model.K, plain.K, rtol=1e-12)
    assert model.D == plain.D


def test_lateral_colour_orders_the_channels() -> None:
    """A positive singlet: blue bends more, so its focal length is the shortest."""
    fx = [build_model({**SIZE, 'lens.glass': 'SCHOTT:F2', 'lens.wavelength_nm': w}).K[0, 0]
          for w in (460.0, 540.0, 620.0)]
    assert fx[0] < fx[1] < fx[2]


def test_no_glass_keeps_the_wavelength_out_of_it() -> None:
    base = build_model(SIZE)
    other = build_model({**SIZE, 'lens.wavelength_nm': 900.0})
    assert_allclose(base.K, other.K, rtol=0)


def test_focal_length_with_glass_is_designed_at_the_d_line() -> None:
    values = {**SIZE, 'lens.glass': 'N-BK7', 'lens.focal_length_mm': 6.0,
              'scene.distance_mm': 0.0}
    at_d = build_model({**values, 'lens.wavelength_nm': glass.LINES_NM['d']})
    assert_allclose(at_d.focal_length_mm, 6.0, rtol=1e-12)
    at_850 = build_model({**values, 'lens.wavelength_nm': 850.0})
    r1 = at_d.prescription.surfaces[0].radius_mm
    assert_allclose(at_850.prescription.surfaces[0].radius_mm, r1, rtol=1e-14)
    n = glass.refractive_index('N-BK7', 850.0)
    assert_allclose(at_850.focal_length_mm, thick_lens.thick_lens_focal_length(n, r1, -r1, 3.0),
                    rtol=1e-12)
    assert at_850.focal_length_mm > 6.0    # lower index in the infrared


def test_prescription_glasses_per_surface() -> None:
    named = build_model({**PRESCRIPTION, 'lens.surfaces.glass': ['S-LAH66', 'AIR', ''],
                         'lens.wavelength_nm': 656.2725})
    n = glass.refractive_index('OHARA:S-LAH66', 656.2725)
    assert [s.refractive_index for s in named.prescription.surfaces] == [n, 1.0, 1.0]
    same = build_model({**PRESCRIPTION, 'lens.surfaces.refractive_index': [n, 1.0, 1.0]})
    assert_allclose(named.K, same.K, rtol=1e-14)
    # '' keeps the surface's refractive_index; the index array may be empty with names.
    kept = build_model({**PRESCRIPTION, 'lens.surfaces.glass': ['', '', '']})
    assert kept.prescription.surfaces[0].refractive_index == 1.5
    empty = build_model({**PRESCRIPTION, 'lens.surfaces.refractive_index': [],
                         'lens.surfaces.glass': ['MODEL:1.6:40', '', '']})
    assert_allclose(empty.prescription.surfaces[0].refractive_index,
                    glass.model_glass_index(1.6, 40.0, 587.56), rtol=1e-14)
    assert [s.refractive_index for s in empty.prescription.surfaces[1:]] == [1.0, 1.0]


def test_report_gives_the_wavelength_and_every_surface_index() -> None:
    model = build_model({**PRESCRIPTION, 'lens.surfaces.glass': ['N-SF11', '', ''],
                         'lens.wavelength_nm': 850.0})
    report = model.report()
    assert report['wavelength_nm'] == 850.0
    assert [s['glass'] for s in report['surfaces']] == ['N-SF11', None, None]
    assert report['surfaces'][0]['refractive_index'] == glass.refractive_index('N-SF11', 850.0)
    assert report['surfaces'][1]['refractive_index'] == 1.0
    assert 'glass at 850 nm: surface 0 N-SF11 n = 1.761926' in format_report(report)
    thick = build_model({**SIZE, 'lens.glass': 'H-ZF52'}).report()
    assert thick['surfaces'][0]['glass'] == 'H-ZF52'
    assert build_model(SIZE).report()['surfaces'][0]['glass'] is None


def test_tolerances_perturb_the_glass_index() -> None:
    named = build_model({**SIZE, 'lens.glass': 'N-BK7', 'lens.wavelength_nm': 587.5618})
    plain = build_model({**SIZE, 'lens.refractive_index': named.prescription.surfaces[0]
                         .refractive_index})
    assert math.isfinite(named.summary['focal_length_sigma_mm'])
    assert_allclose(named.summary['focal_length_sigma_mm'],
                    plain.summary['focal_length_sigma_mm'], rtol=1e-9)


@pytest.mark.parametrize(('values', 'parameter', 'needles'), [
    ({**SIZE, 'lens.glass': 'N-BK8'}, 'lens.glass', ['N-BK8', 'SCHOTT:N-BK7']),
    ({**SIZE, 'lens.glass': 'SF11'}, 'lens.glass', ['ambiguous', 'SCHOTT', 'HIKARI']),
    ({**SIZE, 'lens.glass': 'TAFD25', 'lens.wavelength_nm': 1200.0}, 'lens.wavelength_nm',
     ['HOYA:TAFD25', '365.01-1013.98 nm']),
    ({**PRESCRIPTION, 'lens.surfaces.glass': ['N-BK7', 'NOPE', '']}, 'lens.surfaces.glass',
     ['surface 1', 'NOPE']),
    ({**PRESCRIPTION, 'lens.surfaces.glass': ['J-BK7A', '', ''], 'lens.wavelength_nm': 2400.0},
     'lens.wavelength_nm', ['surface 0', 'HIKARI:J-BK7A']),
    ({**PRESCRIPTION, 'lens.surfaces.glass': ['N-BK7']}, 'lens.surfaces.glass',
     ['1 names', '3']),
    ({**PRESCRIPTION, 'lens.glass': 'N-BK7'}, 'lens.glass', ['lens.surfaces.glass']),
    ({**SIZE, 'lens.surfaces.glass': ['N-BK7', '']}, 'lens.surfaces.glass', ['lens.glass']),
    ({**PRESCRIPTION, 'lens.surfaces.glass': ['MODEL:1.5:5', '', '']}, 'lens.surfaces.glass',
     ['surface 0', 'vd']),
], ids=['unknown', 'ambiguous', 'wavelength', 'surface-unknown', 'surface-wavelength',
        'length', 'thick-name-in-prescription', 'surface-names-in-thick', 'model-vd'])
def test_refusals_name_the_parameter_and_surface(values: dict, parameter: str,
                                                 needles: list[str]) -> None:
    with pytest.raises(ModelError) as err:
        build_model(values)
    assert err.value.parameter == parameter, str(err.value)
    for needle in needles:
        assert needle in str(err.value), (needle, str(err.value))


def test_wavelength_parameter_range() -> None:
    with pytest.raises(ModelError) as err:
        build_model({**SIZE, 'lens.wavelength_nm': 100.0})
    assert err.value.parameter == 'lens.wavelength_nm'


def test_model_values_keep_the_names() -> None:
    """The model's values are the parameters as given; the source's carry the indices."""
    model = build_model({**SIZE, 'lens.glass': 'N-BK7'})
    assert model.values['lens.glass'] == 'N-BK7'
    assert model.source.values['lens.glass'] == ''
    assert model.source.values['lens.refractive_index'] == pytest.approx(1.5168, abs=1e-6)
    assert np.isfinite(model.K).all()
