# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The refractive index of water and seawater, relative to air, from published formulas.

Pure Python, no ROS.

Quan & Fry (1995)
-----------------
X. Quan and E. S. Fry, "Empirical equation for the index of refraction of seawater", Applied
Optics 34(18):3477-3480, 1995, fitted to the measurements of Austin & Halikas (1976), gives
the index of seawater relative to air (wavelengths in air) as

    n(S, T, lambda) = n0 + (n1 + n2 T + n3 T^2) S + n4 T^2
                      + (n5 + n6 S + n7 T) / lambda + n8 / lambda^2 + n9 / lambda^3

with S the salinity (PSU, numerically parts per thousand), T the temperature (degC), lambda
the wavelength (nm) and n0 = 1.31405, n1 = 1.779e-4, n2 = -1.05e-6, n3 = 1.6e-8,
n4 = -2.02e-6, n5 = 15.868, n6 = 0.01155, n7 = -0.00423, n8 = -4382, n9 = 1.1455e6. Its range
is that of the data: 400-700 nm, 0-30 degC, 0-35 PSU, at atmospheric pressure; the paper
states an accuracy of about 3e-5 against the data. Outside the range :func:`water_index`
refuses (:class:`WaterError`) rather than extrapolate.

An independent check (fresh water)
----------------------------------
The IAPWS formulation (Harvey, Gallagher & Levelt Sengers, J. Phys. Chem. Ref. Data 27(4):761,
1998; IAPWS R9-97) gives the index of pure water relative to vacuum from its density:

    (n^2 - 1) / (n^2 + 2) / rho' = a0 + a1 rho' + a2 T' + a3 lambda'^2 T' + a4 / lambda'^2
                                   + a5 / (lambda'^2 - lUV^2) + a6 / (lambda'^2 - lIR^2)
                                   + a7 rho'^2

with rho' = rho / (1000 kg/m^3), T' = T / 273.15 K, lambda' = lambda_vac / 589 nm, the
density of air-free water at 1 atm from Tanaka et al., Metrologia 38:301, 2001, and the index
of air from Edlen (1966) at 20 degC, 101325 Pa (used both to turn the wavelength in air into
the vacuum one and to divide the vacuum index by it). :func:`iapws_water_index` is used by
test/test_water.py to check Quan & Fry within 4e-5 over its range.
"""

from __future__ import annotations

import math

#: Quan & Fry (1995) coefficients n0 ... n9 (module docstring).
QUAN_FRY = (1.31405, 1.779e-4, -1.05e-6, 1.6e-8, -2.02e-6, 15.868, 0.01155, -0.00423,
            -4382.0, 1.1455e6)
#: The range of Quan & Fry's fit: wavelength (nm), temperature (degC), salinity (PSU).
WAVELENGTH_RANGE_NM = (400.0, 700.0)
TEMPERATURE_RANGE_C = (0.0, 30.0)
SALINITY_RANGE_PSU = (0.0, 35.0)
#: The salinity of ``scene.medium: seawater`` when none is given (open ocean), PSU.
SEAWATER_SALINITY_PSU = 35.0

#: IAPWS R9-97 coefficients a0 ... a7 and the UV and IR resonance wavelengths (reduced).
_IAPWS = (0.244257733, 9.74634476e-3, -3.73234996e-3, 2.68678472e-4, 1.58920570e-3,
          2.45934259e-3, 0.900704920, -1.66626219e-2)
_IAPWS_UV = 0.2292020
_IAPWS_IR = 5.432937


class WaterError(ValueError):
    """A temperature, salinity or wavelength outside the range of the water index formula."""

    def __init__(self, parameter: str, message: str) -> None:
        """Keep the name of the parameter at fault (``scene.temperature_c``, ...)."""
        super().__init__(f'{parameter}: {message}')
        self.parameter = parameter
        self.detail = message


def _check(parameter: str, value: float, bounds: tuple[float, float], unit: str,
           what: str) -> None:
    if not (math.isfinite(value) and bounds[0] <= value <= bounds[1]):
        raise WaterError(parameter, f'{value:g} {unit} is outside {bounds[0]:g}-{bounds[1]:g} '
                                    f'{unit}, the {what} range of the water index formula (Quan '
                                    '& Fry 1995, fitted to Austin & Halikas 1976): it is not '
                                    'extrapolated; give scene.medium_index instead')


def water_index(wavelength_nm: float, temperature_c: float = 20.0,
                salinity_psu: float = 0.0, *,
                wavelength_parameter: str = 'lens.wavelength_nm') -> float:
    """
    Return the index of (sea)water relative to air (Quan & Fry 1995, module docstring).

    :param wavelength_nm: wavelength in air, nm (400-700).
    :param temperature_c: temperature, degC (0-30).
    :param salinity_psu: salinity, PSU (0-35; 0 = fresh water).
    :param wavelength_parameter: the parameter named when the wavelength is out of range.
    :return: the index.
    :raises WaterError: naming the parameter outside the formula's range.
    """
    lam, t, s = float(wavelength_nm), float(temperature_c), float(salinity_psu)
    _check(wavelength_parameter, lam, WAVELENGTH_RANGE_NM, 'nm', 'wavelength')
    _check('scene.temperature_c', t, TEMPERATURE_RANGE_C, 'degC', 'temperature')
    _check('scene.salinity_psu', s, SALINITY_RANGE_PSU, 'PSU', 'salinity')
    n0, n1, n2, n3, n4, n5, n6, n7, n8, n9 = QUAN_FRY
    return (n0 + (n1 + n2 * t + n3 * t * t) * s + n4 * t * t
            + (n5 + n6 * s + n7 * t) / lam + n8 / lam ** 2 + n9 / lam ** 3)


def air_index(wavelength_nm: float) -> float:
    """
    Return the index of dry air at 20 degC and 101325 Pa (Edlen 1966).

    :param wavelength_nm: wavelength, nm (vacuum or air: the difference is below 1e-9 here).
    :return: the index.
    """
    sigma2 = (1000.0 / float(wavelength_nm)) ** 2
    n15 = 1e-8 * (8342.54 + 2406147.0 / (130.0 - sigma2) + 15998.0 / (38.9 - sigma2))
    # From 15 degC to 20 degC at constant pressure (ideal gas: n - 1 scales with density).
    return 1.0 + n15 * (288.15 / 293.15)


def water_density_kg_m3(temperature_c: float) -> float:
    """
    Return the density of air-free pure water at 1 atm (Tanaka et al. 2001), kg/m^3.

    :param temperature_c: degC, 0-40.
    :return: the density.
    """
    t = float(temperature_c)
    a1, a2, a3, a4, a5 = -3.983035, 301.797, 522528.9, 69.34881, 999.974950
    return a5 * (1.0 - (t + a1) ** 2 * (t + a2) / (a3 * (t + a4)))


def iapws_water_index(wavelength_nm: float, temperature_c: float) -> float:
    """
    Return the index of pure water relative to air from IAPWS R9-97 (module docstring).

    :param wavelength_nm: wavelength in air, nm.
    :param temperature_c: degC.
    :return: the index relative to air.
    """
    n_air = air_index(wavelength_nm)
    lam = float(wavelength_nm) * n_air / 589.0
    rho = water_density_kg_m3(temperature_c) / 1000.0
    t = (float(temperature_c) + 273.15) / 273.15
    a0, a1, a2, a3, a4, a5, a6, a7 = _IAPWS
    lam2 = lam * lam
    lorentz = rho * (a0 + a1 * rho + a2 * t + a3 * lam2 * t + a4 / lam2
                     + a5 / (lam2 - _IAPWS_UV ** 2) + a6 / (lam2 - _IAPWS_IR ** 2)
                     + a7 * rho * rho)
    n_vacuum = math.sqrt((1.0 + 2.0 * lorentz) / (1.0 - lorentz))
    return n_vacuum / n_air
