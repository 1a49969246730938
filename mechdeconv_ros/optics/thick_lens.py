# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The paper's thick lens (Lim & Furukawa 2008, eq. 7-9) and first-order tolerance propagation.

Pure numpy, no ROS. Lengths in mm; z is the optical axis, light travels +z, the front vertex
is at z = 0 and the rear vertex at z = t. Radii are signed: r > 0 when the centre of curvature
lies on the image side (a biconvex lens has r1 > 0, r2 < 0); r = 0 is a flat surface. The
lens has index n in air.

Focal length (eq. 7-8), written with the curvatures c = 1/r (c = 0 for flat) so that flat
surfaces need no special case::

    1/f = (n - 1) (c1 - c2 + (n - 1) t c1 c2 / n)
    f   = n r1 r2 / ((n - 1) (n r2 - n r1 + (n - 1) t))      (both surfaces curved)

Principal planes, z from the front vertex::

    z_H  = -f (n - 1) t c2 / n        (= -f (n-1) t / (n r2))
    z_H' = t - f (n - 1) t c1 / n     (= t - f (n-1) t / (n r1))

Aperture stop: a plane at z_s = z_H - m_a, the stop offset m_a > 0 towards the object.

Symmetric biconvex lens of focal length f (r1 = R, r2 = -R): (n - 1)(2/R - (n - 1) t/(n R^2))
= 1/f, i.e. R^2 - 2 (n - 1) f R + (n - 1)^2 t f / n = 0, whose weaker-curvature root is
R = (n - 1) (f + sqrt(f^2 - t f / n)); it exists for t <= n f and tends to the thin-lens
R = 2 (n - 1) f as t -> 0.

Tolerances (eq. 9): f_d = f + w_f with w_f Gaussian; sigma_f from independent Gaussian
input errors by first-order propagation, sigma_f^2 = sum_i (df/dx_i sigma_i)^2, with
central-difference partials.
"""

from __future__ import annotations

import math
from typing import Callable, Mapping

from mechdeconv_ros.optics.prescription import (
    AFOCAL_POWER_PER_MM, finite_number, Prescription, Surface)


def _lens(n: float, r1_mm: float, r2_mm: float,
          t_mm: float) -> tuple[float, float, float, float]:
    """Return the checked n, t, c1, c2 of a thick lens."""
    n = finite_number('refractive index', n)
    if n < 1:
        raise ValueError(f'refractive index {n:g} < 1')
    t = finite_number('thickness', t_mm)
    if t < 0:
        raise ValueError(f'thickness {t:g} mm < 0')
    r1 = finite_number('r1', r1_mm)
    r2 = finite_number('r2', r2_mm)
    return n, t, 0.0 if r1 == 0 else 1.0 / r1, 0.0 if r2 == 0 else 1.0 / r2


def _power(n: float, t: float, c1: float, c2: float) -> float:
    power = (n - 1.0) * (c1 - c2 + (n - 1.0) * t * c1 * c2 / n)
    if not abs(power) >= AFOCAL_POWER_PER_MM:
        raise ValueError(f'r1 and r2 give an afocal lens (power {power:.3g} /mm ~ 0): it has '
                         'no focal length')
    return power


def thick_lens_focal_length(n: float, r1_mm: float, r2_mm: float, t_mm: float) -> float:
    """
    Return the focal length of a thick lens in air (paper eq. 7-8).

    :param n: refractive index of the glass (>= 1).
    :param r1_mm: signed radius of the front surface (0 = flat).
    :param r2_mm: signed radius of the rear surface (0 = flat).
    :param t_mm: centre thickness (>= 0).
    :return: f in mm (negative for a diverging lens).
    :raises ValueError: for an afocal lens (|1/f| < 1e-9 /mm) or invalid numbers.
    """
    return 1.0 / _power(*_lens(n, r1_mm, r2_mm, t_mm))


def thick_lens_principal_planes(n: float, r1_mm: float, r2_mm: float,
                                t_mm: float) -> tuple[float, float]:
    """
    Return the principal planes of a thick lens in air.

    :param n: refractive index of the glass.
    :param r1_mm: signed radius of the front surface (0 = flat).
    :param r2_mm: signed radius of the rear surface (0 = flat).
    :param t_mm: centre thickness.
    :return: (z_H, z_H') in mm from the front vertex.
    :raises ValueError: for an afocal lens or invalid numbers.
    """
    n, t, c1, c2 = _lens(n, r1_mm, r2_mm, t_mm)
    f = 1.0 / _power(n, t, c1, c2)
    return -f * (n - 1.0) * t * c2 / n, t - f * (n - 1.0) * t * c1 / n


def thick_lens(n: float, r1_mm: float, r2_mm: float, t_mm: float, stop_offset_mm: float,
               aperture_diameter_mm: float = 0.0) -> Prescription:
    """
    Return the two-surface prescription of the paper's thick lens.

    The surfaces have unlimited semi-diameters. The stop plane is at z_H - m_a. The aperture
    diameter is recorded as the stop semi-diameter but clips nothing: the stop only defines
    the chief ray, which crosses it at its centre.

    :param n: refractive index of the glass.
    :param r1_mm: signed radius of the front surface (0 = flat).
    :param r2_mm: signed radius of the rear surface (0 = flat).
    :param t_mm: centre thickness.
    :param stop_offset_mm: m_a, stop offset from the front principal plane, > 0 towards the
        object.
    :param aperture_diameter_mm: d_a (0 = not given).
    :return: the prescription.
    :raises ValueError: for an afocal lens or invalid numbers.
    """
    n, t, _, _ = _lens(n, r1_mm, r2_mm, t_mm)
    z_h, _ = thick_lens_principal_planes(n, r1_mm, r2_mm, t)
    offset = finite_number('stop offset', stop_offset_mm)
    diameter = finite_number('aperture diameter', aperture_diameter_mm)
    if diameter < 0:
        raise ValueError(f'aperture diameter {diameter:g} mm < 0')
    return Prescription(surfaces=(Surface(float(r1_mm), t, n), Surface(float(r2_mm), 0.0, 1.0)),
                        stop_z_mm=z_h - offset, stop_semi_diameter_mm=diameter / 2.0)


def biconvex_for_focal_length(f_mm: float, n: float, t_mm: float) -> float:
    """
    Return the radius R of the symmetric biconvex lens (r1 = R, r2 = -R) of focal length f.

    :param f_mm: focal length (> 0).
    :param n: refractive index of the glass (> 1).
    :param t_mm: centre thickness (>= 0).
    :return: R in mm, the weaker-curvature root (module docstring).
    :raises ValueError: when no such lens exists (t > n f, f <= 0 or n <= 1).
    """
    f = finite_number('focal length', f_mm)
    n = finite_number('refractive index', n)
    t = finite_number('thickness', t_mm)
    if f <= 0:
        raise ValueError(f'focal length {f:g} mm must be > 0 for a biconvex lens')
    if n <= 1:
        raise ValueError(f'refractive index {n:g} must be > 1 for a lens')
    if t < 0:
        raise ValueError(f'thickness {t:g} mm < 0')
    discriminant = f * f - t * f / n
    if discriminant < 0:
        raise ValueError(f'no biconvex lens of index {n:g} and thickness {t:g} mm has focal '
                         f'length {f:g} mm (needs t <= n f = {n * f:g} mm)')
    return (n - 1.0) * (f + math.sqrt(discriminant))


def propagate_sigma(fn: Callable[[dict[str, float]], float], nominal: Mapping[str, float],
                    sigmas: Mapping[str, float]) -> float:
    """
    Return the first-order standard deviation of fn for independent Gaussian inputs.

    sigma_fn = sqrt(sum_i (dfn/dx_i sigma_i)^2), each partial by a central difference with the
    step 1e-3 max(sigma_i, 1e-6 |x_i|). Zero sigmas are skipped.

    :param fn: function of a dict of the parameters (it gets a fresh copy of ``nominal``).
    :param nominal: nominal parameter values.
    :param sigmas: 1-sigma of each varied parameter (keys must be in ``nominal``).
    :return: sigma of fn, in fn's unit.
    :raises ValueError: for an unknown key, a negative or non-finite sigma.
    """
    total = 0.0
    for name, sigma in sigmas.items():
        if name not in nominal:
            raise ValueError(f'sigma given for unknown parameter {name!r}')
        sigma = finite_number(f'sigma of {name}', sigma)
        if sigma < 0:
            raise ValueError(f'sigma of {name} is {sigma:g} < 0')
        if sigma == 0:
            continue
        x = float(nominal[name])
        step = 1e-3 * max(sigma, 1e-6 * abs(x))
        plus = dict(nominal)
        plus[name] = x + step
        minus = dict(nominal)
        minus[name] = x - step
        derivative = (fn(plus) - fn(minus)) / (2.0 * step)
        total += (derivative * sigma) ** 2
    return math.sqrt(total)
