# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The equivalent calibration of a tilted sensor: the consumer models fitted in two dimensions.

Pure numpy, no ROS. A tilted sensor breaks the rotational symmetry, so the consumer models
(:mod:`mechdeconv_ros.model.camera_info_fit`) are fitted to the traced raw pixels of the
probe points themselves (K fixed: principal point at the traced axis), in pixels:

- plumb_bob: ``x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)``,
  ``y_d = y (...) + p1 (r^2 + 2 y^2) + 2 p2 x y``, ``(x, y) = tan(theta) (cos phi, sin phi)``,
  ``u = f_x x_d + c_x`` (OpenCV's order ``k1, k2, p1, p2, k3``): linear in the coefficients;
- rational_polynomial: the radial factor ``(1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 +
  k5 r^4 + k6 r^6)`` and the same tangential terms: solved as the linear equation error
  ``x_d D = x N + T D_prev`` (``D_prev`` the previous iteration's denominator), iterated;
- equidistant (cv2.fisheye): radial only (``x_d = theta_d x / r``), no tangential terms:
  fitted only where the pinhole models cannot be (a field of 89 deg or more).

Each is refined towards the minimax by Lawson's reweighting and measured by its largest
displacement (px) over the probe points under 90 deg (past it no consumer has a direction).
A tilt's keystone (a projective term) is in none of them: a tilt they miss by more than
0.05 px is published with the best fit and its error (the model's warnings, ``info`` and
``/diagnostics``).
"""

from __future__ import annotations

import math

from mechdeconv_ros.lenses.lens_errors import FloatArray
from mechdeconv_ros.model.camera_info_fit import (
    CONSUMER_LIMIT_DEG, EQUIVALENT_MAX_ERROR_PX, EQUIVALENT_MODELS, EquivalentFit)
import numpy as np

#: Reweighting passes of the minimax refinement (a tilt's keystone stays: the fit's error
#: settles within a few).
LAWSON_PASSES = 6
#: Probe points a fit is solved on (the error is measured on all of them).
FIT_POINTS = 400
#: Iterations of the rational model's equation-error linearisation.
RATIONAL_ITERATIONS = 3


def fit_tilted(theta: FloatArray, phi: FloatArray, u: FloatArray, v: FloatArray,
               K: FloatArray, every: bool = False) -> list[EquivalentFit]:
    """
    Fit every consumer model to traced directions and their raw pixels.

    :param theta: field angles of the probe points (rad).
    :param phi: their azimuths.
    :param u: their raw columns.
    :param v: their raw rows.
    :param K: raw camera matrix (principal point at the traced axis).
    :param every: fit every model (default: stop at the first within 0.05 px).
    :return: fits in :data:`EQUIVALENT_MODELS` order.
    """
    seen = np.isfinite(theta) & np.isfinite(phi)
    # Past 90 deg no consumer has a direction (camera_info_fit.CONSUMER_LIMIT_DEG).
    keep = seen & (theta < math.radians(CONSUMER_LIMIT_DEG))
    beyond = 1.0 - float(np.mean(keep[seen])) if seen.any() else 0.0
    theta, phi, u, v = theta[keep], phi[keep], u[keep], v[keep]
    reach = math.degrees(float(np.max(theta))) if theta.size else 0.0
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    fits: list[EquivalentFit] = []
    for name in EQUIVALENT_MODELS:
        if fits and fits[-1].max_error_px <= EQUIVALENT_MAX_ERROR_PX and not every:
            break
        if (name == 'equidistant' and not every
                and any(math.isfinite(f.max_error_px) for f in fits)):
            break       # radial only: it cannot beat a pinhole model's tangential terms
        if name != 'equidistant' and not (theta.size and theta.max() < math.radians(89.0)):
            fits.append(EquivalentFit(name, _zero(name), math.inf, math.inf, reach, beyond))
            continue
        # Fitted on at most FIT_POINTS of the probes (spread evenly), measured on all.
        pick = np.unique(np.linspace(0, theta.size - 1, min(theta.size, FIT_POINTS))
                         .round().astype(int))
        coefficients = _fit(name, theta[pick], phi[pick], (u[pick] - cx) / fx,
                            (v[pick] - cy) / fy, fx, fy)
        pu, pv = project_model(name, coefficients, theta, phi, K)
        error = np.hypot(pu - u, pv - v)
        error = np.where(np.isfinite(error), error, np.inf)
        fits.append(EquivalentFit(name, coefficients, float(np.max(error)),
                                  float(np.sqrt(np.mean(error * error))), reach, beyond))
    return fits


def _zero(name: str) -> tuple[float, ...]:
    return (0.0,) * {'plumb_bob': 5, 'rational_polynomial': 8, 'equidistant': 4}[name]


def project_model(name: str, D: tuple[float, ...], theta: FloatArray, phi: FloatArray,
                  K: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Project directions with a consumer model (OpenCV's equations).

    :param name: the distortion model.
    :param D: its coefficients in camera_info order.
    :param theta: field angles, rad.
    :param phi: azimuths, rad.
    :param K: camera matrix.
    :return: ``(u, v)``.
    """
    d = [float(c) for c in D]
    if name == 'equidistant':
        t2 = theta * theta
        theta_d = theta * (1.0 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3]))))
        xd, yd = theta_d * np.cos(phi), theta_d * np.sin(phi)
    else:
        with np.errstate(invalid='ignore', over='ignore'):
            t = np.where(theta < 0.5 * math.pi, np.tan(theta), np.nan)
        x, y = t * np.cos(phi), t * np.sin(phi)
        r2 = x * x + y * y
        radial = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]))
        if name == 'rational_polynomial':
            radial = radial / (1.0 + r2 * (d[5] + r2 * (d[6] + r2 * d[7])))
        p1, p2 = d[2], d[3]
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]


def _fit(name: str, theta: FloatArray, phi: FloatArray, xd: FloatArray, yd: FloatArray,
         fx: float, fy: float) -> tuple[float, ...]:
    """Least squares in pixels, refined towards the minimax (Lawson)."""
    n = theta.size
    if name == 'equidistant':
        c, s = np.cos(phi), np.sin(phi)
        t2 = theta * theta
        powers = theta[:, None] * np.stack([t2, t2 ** 2, t2 ** 3, t2 ** 4], axis=1)
        basis = np.vstack([fx * c[:, None] * powers, fy * s[:, None] * powers])
        rhs = np.concatenate([fx * (xd - theta * c), fy * (yd - theta * s)])
        coefficients = _lawson(basis, rhs, n)
        return tuple(float(k) for k in coefficients)
    t = np.tan(theta)
    x, y = t * np.cos(phi), t * np.sin(phi)
    r2 = x * x + y * y
    radial = np.stack([r2, r2 * r2, r2 ** 3], axis=1)
    tangential_x = np.stack([2.0 * x * y, r2 + 2.0 * x * x], axis=1)
    tangential_y = np.stack([r2 + 2.0 * y * y, 2.0 * x * y], axis=1)
    if name == 'plumb_bob':
        basis = np.vstack([fx * np.hstack([x[:, None] * radial, tangential_x]),
                           fy * np.hstack([y[:, None] * radial, tangential_y])])
        rhs = np.concatenate([fx * (xd - x), fy * (yd - y)])
        k1, k2, k3, p1, p2 = _lawson(basis, rhs, n)
        return (float(k1), float(k2), float(p1), float(p2), float(k3))
    den = np.ones(n)
    best: tuple[float, ...] = _zero(name)
    for _ in range(RATIONAL_ITERATIONS):
        # x_d (1 + k4 r^2 + ...) = x (1 + k1 r^2 + ...) + T D_prev, scaled by 1 / D_prev so
        # the residual is the pixel error.
        scale = 1.0 / den
        basis = np.vstack([
            fx * scale[:, None] * np.hstack([x[:, None] * radial, -xd[:, None] * radial,
                                             den[:, None] * tangential_x]),
            fy * scale[:, None] * np.hstack([y[:, None] * radial, -yd[:, None] * radial,
                                             den[:, None] * tangential_y])])
        rhs = np.concatenate([fx * scale * (xd - x), fy * scale * (yd - y)])
        coefficients = _lawson(basis, rhs, n)
        if not np.all(np.isfinite(coefficients)):
            break
        k1, k2, k3, k4, k5, k6, p1, p2 = (float(c) for c in coefficients)
        den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
        if not np.all(den > 0.0):
            break       # a pole inside the field: keep the last good fit
        best = (k1, k2, p1, p2, k3, k4, k5, k6)
    return best


def _lawson(basis: FloatArray, rhs: FloatArray, points: int) -> FloatArray:
    """Least squares reweighted towards the minimax of the per-point pixel distance."""
    norms = np.linalg.norm(basis, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    scaled = basis / norms
    weights = np.ones(points)
    best, best_error = None, math.inf
    for _ in range(LAWSON_PASSES):
        w = np.sqrt(np.concatenate([weights, weights]))
        coefficients = np.linalg.lstsq(scaled * w[:, None], rhs * w, rcond=None)[0]
        residual = scaled @ coefficients - rhs
        distance = np.hypot(residual[:points], residual[points:])
        worst = float(np.max(distance)) if distance.size else 0.0
        if worst < best_error:
            best, best_error = coefficients, worst
        if worst <= 0.1 * EQUIVALENT_MAX_ERROR_PX:
            break
        total = float(np.sum(weights * distance))
        if not total > 0:
            break
        weights = np.maximum(weights * distance / total * points, 1e-12)
    assert best is not None
    return best / norms
