# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The equivalent calibration: the camera_info distortion model that best stands for the trace.

Pure numpy, no ROS. ``camera_info``'s D is one of the models ROS consumers read, fitted to the
traced field (docs/design.md section 2.8), with ``r_u = tan(theta)`` and ``r_d = rho_real / v``:

- plumb_bob ``r_d = r_u (1 + k1 r_u^2 + k2 r_u^4 + k3 r_u^6)``;
- rational_polynomial ``r_d (1 + k4 r_u^2 + k5 r_u^4 + k6 r_u^6) = r_u (1 + k1 r_u^2 + k2 r_u^4
  + k3 r_u^6)``;
- equidistant (Kannala-Brandt, cv2.fisheye) ``r_d = theta (1 + k1 theta^2 + k2 theta^4 +
  k3 theta^6 + k4 theta^8)``.

Each is fitted by least squares refined towards the minimax (Lawson's reweighting), then
measured by its LARGEST displacement over the raw image (where a consumer's rectification map
puts each raw pixel against the trace); the first in that order within 0.05 px is published,
else the one with the smallest error (and a warning says so: ``info``, ``/diagnostics``).
Pinhole models cannot describe a field of 90 deg or more.

The domain is what a consumer can undistort: every field angle a raw pixel sees, up to the
farthest corner, the end of the traced field or 90 deg. Past 90 deg no consumer of
camera_info has a direction (OpenCV and image_geometry work in ``x/z, y/z``; the
equidistant model's ``cv2.fisheye.undistortPoints`` returns the mirrored direction there):
the share of the raw image that lies there is reported (``beyond_fraction``); image_rect in
the equidistant projection shows it. With the axis on the sensor the raw image holds every
radius up to its farthest corner, so the largest error over the raw image is the largest
``|r_model(theta) - r_traced(theta)| max(f_x, f_y)`` over that range of angles: measured on
MEASURE_SAMPLES of them against the trace's cubic Hermite interpolant (the projection's), it
is what OpenCV on K, D is off by (``test/test_camera_info_consumers.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
import functools
import math

from mechdeconv_ros.lenses.lens_errors import FloatArray
from mechdeconv_ros.model.radial_map import hermite, RadialMap
import numpy as np


#: The equivalent calibration is the simplest model whose largest displacement error over
#: the raw image is at most this (px); when none reaches it, the one with the smallest.
EQUIVALENT_MAX_ERROR_PX = 0.05
#: Consumer models in order of preference: the most widely read first (plumb_bob and
#: rational_polynomial are read by every ROS consumer, equidistant by cv2.fisheye-based
#: ones: image_geometry C++, Isaac ROS; ROS's Python image_geometry has no fisheye support).
EQUIVALENT_MODELS = ('plumb_bob', 'rational_polynomial', 'equidistant')
#: Samples of the fit and reweighting passes of the minimax (Lawson) refinement.
FIT_SAMPLES = 256
LAWSON_PASSES = 40
#: Field angles the largest error is measured on (uniform over the domain).
MEASURE_SAMPLES = 2048
#: No consumer of camera_info has a direction at or past this field angle (deg): OpenCV's
#: models, cv2.fisheye included, and image_geometry take and give x/z, y/z, which cannot
#: tell 90 + a deg from 90 - a deg (cv2.fisheye.undistortPoints returns the mirrored
#: direction there).
CONSUMER_LIMIT_DEG = 90.0


@dataclass(frozen=True)
class EquivalentFit:
    """One fitted consumer model: coefficients and its errors over the raw image (px)."""

    distortion_model: str
    D: tuple[float, ...]
    max_error_px: float
    rms_error_px: float
    #: The field angle (deg) up to which it is fitted and measured (:func:`consumer_reach_rad`).
    reach_deg: float = math.nan
    #: The share of the raw image's traced pixels past :data:`CONSUMER_LIMIT_DEG`, where no
    #: consumer of camera_info has a direction (a corner of a wide angle; image_rect in the
    #: equidistant projection shows them).
    beyond_fraction: float = 0.0


def equivalent_radius(distortion_model: str, D: tuple[float, ...] | FloatArray,
                      theta: FloatArray) -> FloatArray:
    """
    Return the distorted normalised radius a consumer model gives a field angle.

    plumb_bob: r = t (1 + k1 t^2 + k2 t^4 + k3 t^6), t = tan(theta); rational_polynomial:
    r = t (1 + k1 t^2 + k2 t^4 + k3 t^6) / (1 + k4 t^2 + k5 t^4 + k6 t^6); equidistant
    (Kannala-Brandt, as cv2.fisheye): r = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 +
    k4 theta^8). The pinhole models are NaN from 90 deg.

    :param distortion_model: one of :data:`EQUIVALENT_MODELS`.
    :param D: the coefficients in camera_info order.
    :param theta: field angles, rad.
    :return: radii in normalised (x/f) units.
    """
    theta = np.asarray(theta, dtype=np.float64)
    d = [float(x) for x in D]
    if distortion_model == 'equidistant':
        t2 = theta * theta
        return theta * (1.0 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3]))))
    with np.errstate(invalid='ignore', over='ignore'):
        t = np.where(theta < 0.5 * math.pi, np.tan(theta), np.nan)
        r2 = t * t
        num = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]))
        if distortion_model == 'rational_polynomial':
            num = num / (1.0 + r2 * (d[5] + r2 * (d[6] + r2 * d[7])))
        return t * num


def boundary_points(w: int, h: int, per_side: int = 64) -> FloatArray:
    """Return points on the outer edges of a w x h pixel image (pixel-edge coordinates)."""
    xs = np.linspace(-0.5, w - 0.5, per_side)
    ys = np.linspace(-0.5, h - 0.5, per_side)
    return np.concatenate([
        np.stack([xs, np.full_like(xs, -0.5)], axis=1),
        np.stack([xs, np.full_like(xs, h - 0.5)], axis=1),
        np.stack([np.full_like(ys, -0.5), ys], axis=1),
        np.stack([np.full_like(ys, w - 0.5), ys], axis=1),
    ])


@functools.lru_cache(maxsize=8)
def raw_probe_points(width: int, height: int) -> FloatArray:
    """Return the raw pixels the consumer error is measured on: edges, corners and a grid."""
    xs = np.linspace(-0.5, width - 0.5, 41)
    ys = np.linspace(-0.5, height - 0.5, 31)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    return np.concatenate([boundary_points(width, height), grid])


def consumer_reach_rad(field: RadialMap, v: float, K: FloatArray, width: int,
                       height: int) -> float:
    """
    Return the largest field angle a camera_info consumer undistorts on this raw image (rad).

    That is the raw image's farthest corner from the principal point (the traced axis, on the
    sensor), the end of the traced field, or :data:`CONSUMER_LIMIT_DEG`, whichever is least:
    every field angle from 0 to it is seen by some raw pixel.

    :param field: the field traced by angle.
    :param v: image distance, mm.
    :param K: raw camera matrix.
    :param width: raw width, px.
    :param height: raw height, px.
    :return: the reach, rad.
    """
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [-0.5, height - 0.5],
                        [width - 0.5, height - 0.5]])
    rn = float(np.max(np.hypot((corners[:, 0] - cx) / fx, (corners[:, 1] - cy) / fy)))
    corner = float(field.angle_from_real(np.array(rn * v)))
    end = field.max_field_angle_rad
    return min(corner if math.isfinite(corner) else end, end, math.radians(CONSUMER_LIMIT_DEG))


def fit_equivalent(field: RadialMap, v: float, K: FloatArray, width: int, height: int,
                   every: bool = False) -> list[EquivalentFit]:
    """
    Fit every consumer model to the traced field and measure it over the raw image.

    The domain is every field angle a raw pixel sees that a consumer can undistort: 0 to
    :func:`consumer_reach_rad` (with the axis on the sensor the raw image holds every radius
    up to its farthest corner). The fit is least squares in pixels on FIT_SAMPLES field angles
    of it, refined towards the minimax by Lawson's reweighting. The error of a model is
    ``|r_model(theta) - r_traced(theta)|`` times the larger focal length (px), its largest over
    MEASURE_SAMPLES angles of the domain: where a consumer's rectification map
    (cv2.initUndistortRectifyMap, cv2.fisheye.initUndistortRectifyMap) puts a raw pixel against
    the trace (the traced height is the cubic Hermite interpolant the projection uses). The RMS
    is over the raw probe pixels. Raw pixels outside the image circle carry no direction; those
    past 90 deg none a consumer can use (``beyond_fraction``).

    :param field: the field traced by angle (``LensModel.field_curve``).
    :param v: image distance, mm (normalised radius = real / v).
    :param K: raw camera matrix.
    :param width: raw width, px.
    :param height: raw height, px.
    :param every: fit every model; by default the fits stop at the first model within
        EQUIVALENT_MAX_ERROR_PX (the one published: the rest would cost rebuild time).
    :return: one :class:`EquivalentFit` per model fitted, in :data:`EQUIVALENT_MODELS` order.
    """
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    points = raw_probe_points(width, height)
    xn, yn = (points[:, 0] - cx) / fx, (points[:, 1] - cy) / fy
    rn = np.hypot(xn, yn)
    theta_p = field.angle_from_real(rn * v)
    seen = np.isfinite(theta_p)
    beyond = float(np.mean(theta_p[seen] >= math.radians(CONSUMER_LIMIT_DEG))) if seen.any() \
        else 0.0
    inside = seen & (theta_p < math.radians(CONSUMER_LIMIT_DEG))
    xn, yn, rn, theta_p = xn[inside], yn[inside], rn[inside], theta_p[inside]
    # Pixels per unit of normalised radius along each probe's direction.
    with np.errstate(invalid='ignore', divide='ignore'):
        gain = np.where(rn > 0, np.hypot(xn * fx, yn * fy) / rn, max(fx, fy))
    reach = consumer_reach_rad(field, v, K, width, height)
    theta = np.linspace(0.0, reach, FIT_SAMPLES + 1)[1:]
    target = _traced(field, theta) / v
    measure = np.linspace(0.0, reach, MEASURE_SAMPLES + 1)[1:]
    measure_target = _traced(field, measure) / v
    scale = max(fx, fy)
    fits: list[EquivalentFit] = []
    for name in EQUIVALENT_MODELS:
        if fits and fits[-1].max_error_px <= EQUIVALENT_MAX_ERROR_PX and not every:
            break       # the simpler model is chosen: the others are not needed
        coefficients = _fit_model(name, theta, target, scale)
        if coefficients is None and name == 'rational_polynomial' and fits[0].D != _zero_d(
                'plumb_bob') and math.isfinite(fits[0].max_error_px):
            # A degenerate rational fit (small fields): plumb_bob is its special case.
            coefficients = fits[0].D + (0.0, 0.0, 0.0)
        if coefficients is None:
            fits.append(EquivalentFit(name, _zero_d(name), math.inf, math.inf,
                                      math.degrees(reach), beyond))
            continue
        curve = np.abs(equivalent_radius(name, coefficients, measure) - measure_target) * scale
        worst = float(np.max(curve)) if curve.size else 0.0
        # The RMS over the probe pixels: the error curve at their angles, along their azimuth.
        error = np.interp(theta_p, measure, curve) * gain / scale
        rms = float(np.sqrt(np.mean(error * error))) if error.size else 0.0
        fits.append(EquivalentFit(name, coefficients, worst if math.isfinite(worst) else math.inf,
                                  rms, math.degrees(reach), beyond))
    return fits


def _traced(field: RadialMap, theta: FloatArray) -> FloatArray:
    """Return the traced real height (mm) at field angles within the field (cubic Hermite)."""
    if field.field_angle_rad.size < 5:
        return np.interp(theta, field.field_angle_rad, field.real_mm)
    return hermite(field.field_angle_rad, field.real_mm, theta)


def _zero_d(name: str) -> tuple[float, ...]:
    return (0.0,) * {'plumb_bob': 5, 'rational_polynomial': 8, 'equidistant': 4}[name]


def _fit_model(name: str, theta: FloatArray, target: FloatArray,
               scale: float) -> tuple[float, ...] | None:
    """Fit one model to r(theta) = target (normalised); None where it cannot represent it."""
    if theta.size < 8:
        return _zero_d(name)
    if name == 'equidistant':
        t2 = theta * theta
        basis = theta[:, None] * np.stack([t2, t2 ** 2, t2 ** 3, t2 ** 4], axis=1)
        rhs = target - theta
    else:
        if not theta[-1] < math.radians(89.0):
            return None     # a pinhole model cannot reach 90 deg (tan is infinite)
        t = np.tan(theta)
        r2 = t * t
        powers = np.stack([r2, r2 * r2, r2 * r2 * r2], axis=1)
        basis = t[:, None] * powers
        rhs = target - t
        if name == 'rational_polynomial':
            # r (1 + den) = t (1 + num): linear in (num, den) (equation error, reweighted by
            # the denominator below so the residual is the radius error).
            basis = np.hstack([basis, -target[:, None] * powers])
    # Columns scaled to unit norm (the powers of small radii are tiny and nearly collinear).
    norms = np.linalg.norm(basis, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    basis = basis / norms
    weights = np.ones(theta.size)
    row_scale = np.ones(theta.size)
    best, best_error = None, math.inf
    ridge = 0.0
    for _ in range(LAWSON_PASSES):
        w = np.sqrt(weights) * row_scale * scale
        matrix = basis * w[:, None]
        while True:
            coef = _ridge_lstsq(matrix, rhs * w, ridge * float(np.sum(w * w)))
            if name != 'rational_polynomial':
                break
            den = 1.0 + powers @ (coef[3:] / norms[3:])
            if np.all(den > 0) or ridge >= 1e-2:
                break
            # A pole inside the field: the equation-error fit is ill-conditioned here;
            # damp it (ridge regression) until the denominator stays positive.
            ridge = max(100.0 * ridge, 1e-12)
        if not np.all(np.isfinite(coef)):
            break
        if name == 'rational_polynomial':
            if not np.all(den > 0):
                break
            row_scale = 1.0 / den
            # Reweighted by 1/den the fit is better conditioned: relax the damping again.
            ridge = ridge / 100.0 if ridge > 1e-12 else 0.0
        residual = np.abs(basis @ coef - rhs) * row_scale
        worst = float(np.max(residual))
        if worst * scale <= 0.1 * EQUIVALENT_MAX_ERROR_PX:
            best = coef / norms
            break       # well within the bound: the minimax refinement is not needed
        if worst < best_error:
            if worst > 0.98 * best_error and best is not None:
                best = coef / norms
                break   # Lawson has converged (under 2 % gained)
            best, best_error = coef / norms, worst
        total = float(np.sum(weights * residual))
        if not total > 0:
            break
        # Lawson: weight each sample by its share of the error (towards the minimax fit).
        weights = np.maximum(weights * residual / total * theta.size, 1e-12)
    if best is None:
        return None
    coef = best
    c = [float(x) for x in coef]
    if name == 'plumb_bob':
        return (c[0], c[1], 0.0, 0.0, c[2])
    if name == 'rational_polynomial':
        return (c[0], c[1], 0.0, 0.0, c[2], c[3], c[4], c[5])
    return tuple(c)


def _ridge_lstsq(matrix: FloatArray, rhs: FloatArray, damping: float) -> FloatArray:
    """Solve min |A x - b|^2 + damping |x|^2 (plain least squares for damping 0)."""
    if damping > 0.0:
        size = matrix.shape[1]
        matrix = np.vstack([matrix, math.sqrt(damping) * np.eye(size)])
        rhs = np.concatenate([rhs, np.zeros(size)])
    return np.linalg.lstsq(matrix, rhs, rcond=None)[0]


def choose_equivalent(fits: list[EquivalentFit]) -> EquivalentFit:
    """
    Return the first model (in preference order) within EQUIVALENT_MAX_ERROR_PX, else the best.

    :param fits: from :func:`fit_equivalent`.
    :return: the chosen fit.
    """
    for fit in fits:
        if fit.max_error_px <= EQUIVALENT_MAX_ERROR_PX:
            return fit
    return min(fits, key=lambda fit: fit.max_error_px)


def bound_warning(chosen: EquivalentFit, parameter: str, what: str) -> list[str]:
    """
    Return the warning for a published fit over EQUIVALENT_MAX_ERROR_PX (none within it).

    :param chosen: the published fit.
    :param parameter: the parameters the warning names (the lens, or the sensor's tilt).
    :param what: what no model represents ("this lens", "this tilt").
    :return: ``[]`` or one warning (``info``, ``/diagnostics`` WARN).
    """
    if chosen.max_error_px <= EQUIVALENT_MAX_ERROR_PX:
        return []
    return [f'{parameter}: no ROS distortion model represents {what} within '
            f'{EQUIVALENT_MAX_ERROR_PX:g} px over the raw image (to {chosen.reach_deg:.1f} deg): '
            f'camera_info carries the best fit, {chosen.distortion_model}, off by up to '
            f'{chosen.max_error_px:.3g} px (image_rect is exact)']
