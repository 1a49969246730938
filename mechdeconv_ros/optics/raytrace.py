# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Chief rays: ray aiming over the whole field, and the real image heights it gives.

Pure numpy, no ROS. This is how mechdeconv_ros computes distortion (docs/design.md section 2.4,
"trace the chief ray"): the real chief ray from each object point is found by ray aiming and
refracted exactly by Snell's law at every surface; where it crosses the sensor is the real
image height. :mod:`mechdeconv_ros.optics.prescription` holds the lens, its paraxial data and the
exact trace of given rays (its names, ``Surface``, ``Prescription``, ``paraxial``,
``image_plane``, ..., are importable from here too); the surface geometry is
:mod:`mechdeconv_ros.optics.surfaces`.

Chief ray
---------
The object plane is z = z_H - l (l from the front principal plane H, l = inf allowed).
A field point is given by tan(theta) = Y / l, the object height over the object distance
(for l = inf the tangent of the field angle): an object point above the axis (Y > 0) sends
its chief ray downwards and, through a real inverted image, images at a negative height.
The chief ray is the real ray from the object point that crosses the aperture-stop plane
z = z_s at height 0. When z_s lies in object space (before the first vertex) it is simply
the line through the stop centre. Otherwise it is found by ray aiming: the free parameter
is the height h at which the object-space ray crosses the first-vertex plane z = 0 (a start
point near the lens keeps the trace accurate for any l); a vectorised Newton iteration with
step control, its derivative by a forward difference in the same stacked trace, drives the
stop height to |y_s| <= 1e-10 mm x min(1, |tan| + 1e-6), starting from the paraxial chief
ray (the ray towards the paraxial entrance pupil) and keeping the paraxial sign of dy_s/dh,
i.e. on the branch of solutions that starts on the axis, so the map stays continuous.
Where that branch ends (it folds back, or its rays leave the lens, miss a surface or are
totally internally reflected) the result is NaN: the end of the valid field.
The ideal image height is v tan(theta) = |m| Y; ``radial_map`` maps ideal to real heights.
"""

from __future__ import annotations

import math

from mechdeconv_ros.optics.prescription import (
    AFOCAL_POWER_PER_MM, BACKWARD_TOLERANCE_MM, check_distance, finite_number, image_plane,
    Paraxial, paraxial, paraxial_matrix, Prescription, Rays, Surface, surfaces_before,
    trace_surfaces, transfer_to_plane, vertex_z)
import numpy as np

#: What callers import from here (the prescription names are re-exported).
__all__ = [
    'AFOCAL_POWER_PER_MM', 'BACKWARD_TOLERANCE_MM', 'finite_number', 'image_plane', 'paraxial',
    'Paraxial', 'Prescription', 'Rays', 'Surface', 'trace_surfaces',
    'transfer_to_plane', 'vertex_z',
    'aim_chief_rays', 'radial_map', 'trace_chief_rays', 'trace_field', 'trace_field_angles']

#: Ray aiming converges when |y_stop| <= STOP_TOLERANCE_MM (tighter for small fields).
STOP_TOLERANCE_MM = 1e-10
#: Newton iterations and step halvings of the ray aiming; halvings of a paraxial start that
#: fails; consecutive iterations that reduce |y_stop| by less than 10 % before a ray fails.
MAX_AIM_ITERATIONS = 40
MAX_STEP_HALVINGS = 20
MAX_START_HALVINGS = 12
STALL_ITERATIONS = 3
#: Step halvings of the first pass from the paraxial starts: a ray that needs more is aimed
#: again by continuation from its solved neighbours (cheaper than halving on).
FIRST_PASS_HALVINGS = 8
FIRST_PASS_ITERATIONS = 12
#: Largest window of samples aimed together by continuation.
MAX_WINDOW = 32
#: Longest step of field angle (rad) between consecutive samples continued from one another:
#: wider gaps of a sparse batch get guide samples (traced, then dropped) that split them to at
#: most this, so an angle's chief ray does not depend on the other angles asked with it (the
#: model's 512-sample trace steps 0.35 deg at most and gets none).
MAX_CONTINUATION_STEP_RAD = math.radians(1.0)
#: Shortest continuation step towards a sample, relative to the step from the last solved
#: sample (three halvings; see _bridge).
BRIDGE_MIN_FRACTION = 0.125
#: Newton iterations and step halvings from an extrapolated start (it is close: few needed).
CONTINUATION_ITERATIONS = 6
CONTINUATION_HALVINGS = 3

_ERRSTATE = {'invalid': 'ignore', 'divide': 'ignore', 'over': 'ignore'}


def _rays_from_slope(y0: np.ndarray, z0: float, slope: np.ndarray) -> Rays:
    with np.errstate(**_ERRSTATE):
        norm = np.hypot(1.0, slope)
        return Rays(y0, np.full_like(y0, z0), slope / norm, 1.0 / norm)


class _ChiefRayProblem:
    """
    Object geometry and stop of one chief-ray aiming problem.

    The field variable ``field`` of every method is the angle theta (rad) to the axis for a
    scene at infinity (it may pass 90 deg: a fisheye sees behind its first vertex) and
    tan(theta) = Y / l for a finite distance. The aiming variable ``height`` is the signed
    distance of the object-space ray from the first vertex, measured perpendicular to the ray
    for a scene at infinity (the point (h cos theta, h sin theta) in (y, z), so any angle
    works) and as the height at which it crosses the plane z = 0 for a finite distance.
    """

    def __init__(self, prescription: Prescription, object_distance_mm: float) -> None:
        distance = check_distance(object_distance_mm)
        self.prescription = prescription
        self.distance = distance
        self.infinite = math.isinf(distance)
        self.stop_z = float(prescription.stop_z_mm)
        self.n_before_stop = surfaces_before(prescription, self.stop_z)
        if not self.infinite:
            z_h = paraxial(prescription).front_principal_z_mm
            self.object_z = z_h - distance
            if not self.object_z < 0:
                raise ValueError(f'scene distance {distance:g} mm from the front principal '
                                 f'plane (z = {z_h:.4g} mm) puts the object at z = '
                                 f'{self.object_z:.4g} mm, not in front of the first surface')
        z_vertices = vertex_z(prescription)
        self.scale = max(1.0, float(z_vertices[-1]), abs(self.stop_z))

    def through_stop_centre(self, field: np.ndarray) -> Rays:
        """Return the rays from the object points through the stop centre (no refraction)."""
        if self.infinite:
            return Rays(np.zeros_like(field), np.full_like(field, self.stop_z),
                        -np.sin(field), np.cos(field))
        with np.errstate(**_ERRSTATE):
            slope = -(field * self.distance) / (self.stop_z - self.object_z)
        return _rays_from_slope(np.zeros_like(field), self.stop_z, slope)

    def object_rays(self, height: np.ndarray, field: np.ndarray) -> Rays:
        """Return the object-space rays at offset ``height`` (see the class docstring)."""
        if self.infinite:
            cos, sin = np.cos(field), np.sin(field)
            return Rays(height * cos, height * sin, -sin, cos)
        with np.errstate(**_ERRSTATE):
            slope = (height - field * self.distance) / (-self.object_z)
        return _rays_from_slope(height, 0.0, slope)

    def stop_height(self, height: np.ndarray, field: np.ndarray) -> np.ndarray:
        """Return the height at which the rays of :meth:`object_rays` cross the stop plane."""
        rays = trace_surfaces(self.prescription, self.object_rays(height, field), 0,
                              self.n_before_stop)
        return transfer_to_plane(rays, self.stop_z).y

    def paraxial_height(self, field: np.ndarray) -> np.ndarray:
        """Return the offset ``height`` of the paraxial chief ray (towards the entrance pupil)."""
        a, b, _, _ = paraxial_matrix(self.prescription, self.n_before_stop, 0.0, self.stop_z)
        n_object = self.prescription.object_index
        if self.infinite:
            denominator, numerator = a, b * n_object
        else:
            denominator = -a * self.object_z + b * n_object
            numerator = b * n_object * self.distance
        if abs(denominator) <= 1e-12 * (abs(numerator) + abs(a) * self.scale):
            raise ValueError('the paraxial entrance pupil is at infinity or on the object '
                             'plane: the chief ray is undefined')
        # Sign of the paraxial dy_stop/dh: the chief ray lies on the branch that keeps it.
        self.branch_sign = math.copysign(1.0, denominator)
        # At infinity the height at z = 0 is tan(theta) n/d; its perpendicular offset is
        # sin(theta) n/d (bounded at any angle).
        return (np.sin(field) if self.infinite else field) * (numerator / denominator)

    def field_size(self, field: np.ndarray) -> np.ndarray:
        """Return |sin theta| (infinity) or |tan theta| (finite): scales the tolerance."""
        return np.abs(np.sin(field)) if self.infinite else np.abs(field)

    def value_and_slope(self, height: np.ndarray,
                        field: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return y_stop(h) and dy_stop/dh by a forward difference (one stacked trace)."""
        step = np.copysign(1e-7 * (self.scale + np.abs(height)), height)
        both = self.stop_height(np.concatenate((height, height + step)),
                                np.concatenate((field, field)))
        value = both[:height.size]
        with np.errstate(**_ERRSTATE):
            return value, (both[height.size:] - value) / step


def _aim(problem: _ChiefRayProblem, field: np.ndarray, start: np.ndarray | None = None,
         iterations: int = MAX_AIM_ITERATIONS, halvings: int = MAX_STEP_HALVINGS) -> np.ndarray:
    """
    Return the aiming offsets h of the chief rays (NaN where aiming failed).

    Newton on y_stop(h) from the paraxial chief ray (or from ``start``), at most ``iterations``
    steps of at most ``halvings`` halvings each. A step is accepted when its ray exists, keeps
    the paraxial sign of dy_stop/dh (the branch of solutions that starts on the axis) and
    reduces |y_stop|; otherwise it is halved, or, past a fold of y_stop(h), shortened to the
    root of the local quadratic model. A ray fails (NaN) when that model shows no root ahead,
    after STALL_ITERATIONS iterations that each reduce |y_stop| by less than 10 %, or when no
    step can be accepted: there is no real chief ray (the end of the valid field).
    """
    tolerance = STOP_TOLERANCE_MM * np.minimum(1.0, problem.field_size(field) + 1e-6)
    height = problem.paraxial_height(field)
    if start is not None:
        height = np.array(start, dtype=float)
    branch = problem.branch_sign
    with np.errstate(**_ERRSTATE):
        height = np.where(np.isfinite(height), height, np.nan)
        value, slope = problem.value_and_slope(height, field)
        # A paraxial start that fails (large fields): pull it towards the axis.
        for _ in range(MAX_START_HALVINGS):
            retry = np.flatnonzero(~(np.isfinite(value) & (slope * branch > 0))
                                   & np.isfinite(height))
            if retry.size == 0:
                break
            height[retry] *= 0.5
            value[retry], slope[retry] = problem.value_and_slope(height[retry], field[retry])
        result = np.full(field.shape, np.nan)
        ok = np.isfinite(value) & (slope * branch > 0)
        done = ok & (np.abs(value) <= tolerance)
        result[done] = height[done]
        active = np.flatnonzero(ok & ~done)
        slow = np.zeros(field.shape, dtype=int)
        for _ in range(iterations):
            if active.size == 0:
                break
            h0, y0, g0 = height[active], value[active], slope[active]
            step = -y0 / g0
            lam = np.ones(active.size)
            accepted = np.zeros(active.size, dtype=bool)
            new_h, new_y, new_g = h0.copy(), y0.copy(), g0.copy()
            pending = np.flatnonzero(np.isfinite(step))
            for _ in range(halvings):
                if pending.size == 0:
                    break
                trial = h0[pending] + lam[pending] * step[pending]
                y1, g1 = problem.value_and_slope(trial, field[active[pending]])
                good = (np.isfinite(y1) & (g1 * branch > 0)
                        & ((np.abs(y1) < np.abs(y0[pending]))
                           | (np.abs(y1) <= tolerance[active[pending]])))
                take = pending[good]
                accepted[take] = True
                new_h[take], new_y[take], new_g[take] = trial[good], y1[good], g1[good]
                # Past a fold (the slope changed sign): shorten the step to the nearer root
                # of the quadratic through (y0, g0, g1), or half way to its vertex; else halve.
                shrink = np.full(pending.size, 0.5)
                fold = np.isfinite(y1) & np.isfinite(g1) & ~(g1 * branch > 0)
                length = lam[pending] * step[pending]
                curvature = (g1 - g0[pending]) / length
                a0, b0 = y0[pending], g0[pending]
                disc = b0 * b0 - 2.0 * curvature * a0
                to_root = -2.0 * a0 / (b0 + np.copysign(np.sqrt(disc), b0))
                to_vertex = -0.5 * b0 / curvature
                model = np.where(disc >= 0, to_root, to_vertex) / length
                model = np.where(np.isfinite(model), np.clip(model, 1e-3, 0.9), 0.5)
                shrink = np.where(fold, model, shrink)
                # ... and when that quadratic has no root and y kept its sign, neither has
                # the branch: no real chief ray (the end of the valid field).
                hopeless = fold & ~(disc >= 0) & (y1 * a0 > 0)
                lam[pending] *= shrink
                pending = pending[~good & ~hopeless]
            finished = accepted & (np.abs(new_y) <= tolerance[active])
            # No further decrease possible: accept what meets the contract tolerance.
            finished |= ~accepted & (np.abs(y0) <= STOP_TOLERANCE_MM)
            result[active[finished]] = new_h[finished]
            height[active], value[active], slope[active] = new_h, new_y, new_g
            slow[active] = np.where(np.abs(new_y) > 0.9 * np.abs(y0), slow[active] + 1, 0)
            keep = accepted & ~finished & (slow[active] < STALL_ITERATIONS)
            active = active[keep]
        # Out of iterations: keep what meets the contract tolerance.
        close = active[np.abs(value[active]) <= STOP_TOLERANCE_MM]
        result[close] = height[close]
    return result


def _aim_continued(problem: _ChiefRayProblem, field: np.ndarray,
                   guide: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """
    Return the aiming offsets of the chief rays, continuing the solution out along the field.

    Wide-angle lenses move their real entrance pupil far from the paraxial one, so a paraxial
    start fails at large angles. After :func:`_aim` from the paraxial starts, the first failed
    samples (in order of |field|, one side at a time) are aimed again from the linear
    extrapolation of the two solved samples below them, a window at a time (doubling up to
    MAX_WINDOW while every ray of a window converges, back to 4 when one fails), until a sample
    fails from an extrapolated start too: the branch of chief rays that starts on the axis ends
    there. ``guide`` (field variable, offset) of solved chief rays replaces the paraxial starts
    inside its range by interpolation (a dense trace after a coarse one converges in one or two
    steps). Gaps between samples (and from the axis) wider than MAX_CONTINUATION_STEP_RAD of
    field angle are split by extra samples (see :func:`_split_gaps`), aimed with the others and
    dropped from the result: a sparse batch continues in the steps of a dense one.
    """
    count = field.size
    field = np.concatenate((field, _split_gaps(problem, field)))
    start = None
    if guide is not None and guide[0].size > 1:
        known, offsets = guide
        start = problem.paraxial_height(field)
        inside = (np.abs(field) <= known[-1]) & np.isfinite(field)
        # Odd symmetry: the chief ray of -field is the mirror image of that of +field.
        start[inside] = np.sign(field[inside]) * np.interp(np.abs(field[inside]), known,
                                                           offsets)
    height = _aim(problem, field, start, FIRST_PASS_ITERATIONS, FIRST_PASS_HALVINGS)
    for sign in (1.0, -1.0):
        side = np.flatnonzero((field * sign > 0) & np.isfinite(field))
        order = side[np.argsort(np.abs(field[side]), kind='stable')]
        window = 8
        # Every pass solves the frontier sample or ends the loop: at most one per sample.
        for _ in range(order.size):
            solved = np.isfinite(height[order])
            first = int(np.argmin(solved)) if not solved.all() else order.size
            if first == order.size:
                break
            # Two solved samples below the frontier (the axis ray h = 0 at field 0 counts).
            below = order[:first]
            f1, h1 = (0.0, 0.0) if below.size < 1 else (field[below[-1]], height[below[-1]])
            # The solved sample before it at another field (repeated fields are common).
            distinct = below[:-1][field[below[:-1]] != f1]
            f0, h0 = ((0.0, 0.0) if distinct.size == 0
                      else (field[distinct[-1]], height[distinct[-1]]))
            todo = order[first:first + window]
            todo = todo[~np.isfinite(height[todo])]
            if f1 == f0:
                start = problem.paraxial_height(field[todo])
            else:
                start = h1 + (h1 - h0) / (f1 - f0) * (field[todo] - f1)
            result = _aim(problem, field[todo], start, CONTINUATION_ITERATIONS,
                          CONTINUATION_HALVINGS)
            if not np.isfinite(result[0]):
                # The step to the frontier may be too long for the extrapolation: walk to it
                # in shorter steps; if even those fail, the field ends before it.
                result[0] = _bridge(problem, (f0, h0), (f1, h1), float(field[todo[0]]))
                if not np.isfinite(result[0]):
                    break
            height[todo] = result
            window = min(2 * window, MAX_WINDOW) if np.isfinite(result).all() else 4
    return height[:count]


def _split_gaps(problem: _ChiefRayProblem, field: np.ndarray) -> np.ndarray:
    """
    Return extra field samples that split the wide gaps between the given ones.

    On each side of the axis, the angles theta of the finite samples (theta = field at
    infinity, arctan(field) for a finite distance) and the axis itself, in order of |theta|,
    leave gaps; one wider than MAX_CONTINUATION_STEP_RAD is split evenly into the fewest steps
    no longer than that. Empty for a dense batch.
    """
    finite = field[np.isfinite(field)]
    theta = finite if problem.infinite else np.arctan(finite)
    extra = []
    for sign in (1.0, -1.0):
        side = np.unique(theta[theta * sign > 0] * sign)
        if side.size == 0:
            continue
        edges = np.concatenate(([0.0], side))
        gaps = np.diff(edges)
        for low, gap in zip(edges[:-1][gaps > MAX_CONTINUATION_STEP_RAD],
                            gaps[gaps > MAX_CONTINUATION_STEP_RAD]):
            steps = math.ceil(gap / MAX_CONTINUATION_STEP_RAD)
            extra.append(sign * (low + gap * np.arange(1, steps) / steps))
    if not extra:
        return np.empty(0)
    split = np.concatenate(extra)
    return split if problem.infinite else np.tan(split)


def _bridge(problem: _ChiefRayProblem, before: tuple[float, float],
            last: tuple[float, float], target: float) -> float:
    """
    Aim the chief ray of ``target`` by continuation in steps that halve on failure.

    ``before`` and ``last`` are the two solved (field, offset) pairs below ``target``. A step
    that converges is taken and the next one tried at twice its length (up to the target);
    one that fails is halved, down to BRIDGE_MIN_FRACTION of the first step: there the branch
    of chief rays ends (NaN).
    """
    (f0, h0), (f1, h1) = before, last
    step = target - f1
    # From the axis (nothing solved yet) the walk may need many short steps.
    minimum = abs(step) * (BRIDGE_MIN_FRACTION if f1 != 0.0 else BRIDGE_MIN_FRACTION ** 3)
    while abs(step) >= minimum:
        trial = min(f1 + step, target) if step > 0 else max(f1 + step, target)
        if f1 == f0:
            start = float(problem.paraxial_height(np.array([trial]))[0])
        else:
            start = h1 + (h1 - h0) / (f1 - f0) * (trial - f1)
        solved = _aim(problem, np.array([trial]), np.array([start]), CONTINUATION_ITERATIONS,
                      CONTINUATION_HALVINGS)[0]
        if np.isfinite(solved):
            if trial == target:
                return float(solved)
            (f0, h0), (f1, h1) = (f1, h1), (trial, float(solved))
            step *= 2.0
        else:
            step *= 0.5
    return math.nan


def _field_variable(problem: _ChiefRayProblem, tan: np.ndarray | None,
                    theta: np.ndarray | None) -> np.ndarray:
    """Return the problem's field variable from tan(theta) or theta (exactly one given)."""
    if theta is None:
        return np.arctan(tan) if problem.infinite else tan
    if problem.infinite:
        return theta
    with np.errstate(**_ERRSTATE):
        # A finite object plane ends at 90 deg (its height l tan(theta) is infinite there).
        return np.where(np.abs(theta) < 0.5 * math.pi, np.tan(theta), np.nan)


def aim_chief_rays(prescription: Prescription, object_distance_mm: float,
                   tan_field: np.ndarray | None = None, *, aim: bool | None = None,
                   field_angle_rad: np.ndarray | None = None,
                   guide: tuple[np.ndarray, np.ndarray] | None = None) -> Rays:
    """
    Return the object-space chief rays of the given field points.

    :param prescription: the lens.
    :param object_distance_mm: l from the front principal plane H (``math.inf`` allowed).
    :param tan_field: tan of the field angle seen from H (Y / l), any shape; flattened.
    :param aim: None to aim only when the stop is behind the first vertex, True to force the
        aiming path (a stop in object space then converges in one Newton step), False to use
        the line through the stop centre (only valid for a stop in object space).
    :param field_angle_rad: instead of ``tan_field``, the field angle theta itself (rad), which
        may pass 90 deg for a scene at infinity (a finite scene plane ends before 90 deg:
        NaN there).
    :param guide: ``(theta_rad, offsets)`` of chief rays already aimed (increasing theta >= 0,
        offsets from :func:`trace_field`): their interpolation starts the aiming.
    :return: flat rays in object space, starting near the first vertex when aimed, at the stop
        centre otherwise; NaN where aiming failed.
    :raises ValueError: for a scene distance <= 0 or an object behind the first vertex, an
        afocal lens (finite l) or an undefined paraxial entrance pupil.
    """
    if (tan_field is None) == (field_angle_rad is None):
        raise ValueError('give exactly one of tan_field and field_angle_rad')
    problem = _ChiefRayProblem(prescription, object_distance_mm)
    field = _field_variable(
        problem, None if tan_field is None else np.asarray(tan_field, dtype=float).ravel(),
        None if field_angle_rad is None else np.asarray(field_angle_rad, dtype=float).ravel())
    if aim is None:
        aim = problem.n_before_stop > 0
    if not aim:
        if problem.n_before_stop > 0:
            raise ValueError('the aperture stop is behind the first vertex: the chief ray '
                             'must be aimed')
        return problem.through_stop_centre(field)
    return problem.object_rays(_aim_continued(problem, field, _guide(problem, guide)), field)


def _guide(problem: _ChiefRayProblem, guide: tuple[np.ndarray, np.ndarray] | None
           ) -> tuple[np.ndarray, np.ndarray] | None:
    """Return a guide of (theta, offset) in the problem's field variable."""
    if guide is None:
        return None
    theta, offsets = (np.asarray(a, dtype=float) for a in guide)
    keep = np.isfinite(theta) & np.isfinite(offsets)
    theta, offsets = theta[keep], offsets[keep]
    if not problem.infinite:
        keep = theta < 0.5 * math.pi
        theta, offsets = np.tan(theta[keep]), offsets[keep]
    return theta, offsets


def trace_field(prescription: Prescription, object_distance_mm: float, sensor_z_mm: float,
                field_angle_rad: np.ndarray,
                guide: tuple[np.ndarray, np.ndarray] | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the image heights of chief rays by field angle, and their aiming offsets.

    As :func:`trace_field_angles`, also returning the aiming offsets, which a later trace of
    the same lens and distance takes as its ``guide`` (NaN when the stop is in object space:
    those chief rays need no aiming).

    :param prescription: the lens.
    :param object_distance_mm: l from H (``math.inf`` allowed).
    :param sensor_z_mm: z of the sensor plane.
    :param field_angle_rad: theta in rad, 1-D.
    :param guide: ``(theta_rad, offsets)`` of an earlier trace (see :func:`aim_chief_rays`).
    :return: ``(heights_mm, offsets)``, NaN where the trace fails.
    :raises ValueError: as :func:`aim_chief_rays`.
    """
    theta = np.asarray(field_angle_rad, dtype=float).ravel()
    problem = _ChiefRayProblem(prescription, object_distance_mm)
    field = _field_variable(problem, None, theta)
    if problem.n_before_stop == 0:
        # A stop in object space: the chief ray is the line through its centre (no aiming).
        rays = problem.through_stop_centre(field)
        offsets = np.full(theta.shape, np.nan)
    else:
        offsets = _aim_continued(problem, field, _guide(problem, guide))
        rays = problem.object_rays(offsets, field)
    image = transfer_to_plane(trace_surfaces(prescription, rays), float(sensor_z_mm))
    return image.y, offsets


def trace_chief_rays(prescription: Prescription, object_distance_mm: float, sensor_z_mm: float,
                     tan_field: np.ndarray, *, aim: bool | None = None) -> np.ndarray:
    """
    Return the real image heights where the exact chief rays cross the sensor plane.

    :param prescription: the lens.
    :param object_distance_mm: l from the front principal plane H to the object
        (``math.inf`` allowed).
    :param sensor_z_mm: z of the sensor plane (usually from :func:`image_plane`).
    :param tan_field: tan of the object-side field angle seen from H: Y / l for an object
        point at height Y, the angle's tangent for l = inf. Any shape.
    :param aim: see :func:`aim_chief_rays` (None: automatic).
    :return: signed heights in mm, same shape as ``tan_field`` (a real inverted image puts
        +Y at a negative height); NaN where the ray misses a surface, exceeds a
        semi-diameter, is totally internally reflected or the aiming does not converge.
    :raises ValueError: as :func:`aim_chief_rays`.
    """
    tan = np.asarray(tan_field, dtype=float)
    rays = aim_chief_rays(prescription, object_distance_mm, tan, aim=aim)
    image = transfer_to_plane(trace_surfaces(prescription, rays), float(sensor_z_mm))
    return image.y.reshape(tan.shape)


def trace_field_angles(prescription: Prescription, object_distance_mm: float,
                       sensor_z_mm: float, field_angle_rad: np.ndarray, *,
                       aim: bool | None = None) -> np.ndarray:
    """
    Return the real image heights of chief rays given by their field angle theta.

    As :func:`trace_chief_rays`, with the field parametrised by the angle itself, so a scene at
    infinity can be traced to and beyond 90 deg (a fisheye); for a finite distance theta is
    the angle seen from H, tan(theta) = Y / l, and theta >= 90 deg gives NaN.

    :param prescription: the lens.
    :param object_distance_mm: l from H (``math.inf`` allowed).
    :param sensor_z_mm: z of the sensor plane.
    :param field_angle_rad: theta in rad, any shape.
    :param aim: see :func:`aim_chief_rays`.
    :return: signed heights in mm, same shape (NaN where the trace fails).
    :raises ValueError: as :func:`aim_chief_rays`.
    """
    theta = np.asarray(field_angle_rad, dtype=float)
    rays = aim_chief_rays(prescription, object_distance_mm, aim=aim, field_angle_rad=theta)
    image = transfer_to_plane(trace_surfaces(prescription, rays), float(sensor_z_mm))
    return image.y.reshape(theta.shape)


def radial_map(prescription: Prescription, object_distance_mm: float, sensor_z_mm: float,
               image_distance_mm: float, ideal_height_mm: np.ndarray) -> np.ndarray:
    """
    Map ideal (pinhole) image heights to real ones on the sensor.

    rho_ideal = v tan(theta) with v = ``image_distance_mm`` (the paraxial image height |m| Y
    in air), rho_real = -(chief-ray height), so both are positive for a real inverted image
    (a negative rho_real would mean the chief ray crossed the axis).

    :param prescription: the lens.
    :param object_distance_mm: l from H (``math.inf`` allowed).
    :param sensor_z_mm: z of the sensor plane.
    :param image_distance_mm: v from H' (see :func:`image_plane`).
    :param ideal_height_mm: rho_ideal >= 0, any shape.
    :return: rho_real, same shape; NaN where the trace failed.
    """
    ideal = np.asarray(ideal_height_mm, dtype=float)
    tan = ideal / float(image_distance_mm)
    return -trace_chief_rays(prescription, object_distance_mm, sensor_z_mm, tan)
