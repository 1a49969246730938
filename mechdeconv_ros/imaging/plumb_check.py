# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The live self-check: how straight the straight edges come out; the assembly that fits best.

Pure numpy and OpenCV, no ROS (docs/design.md section 2.17). The physics fixes the lens; what
a camera as assembled adds are a few unknowns: where the axis meets the sensor
(``sensor.axis_offset_x_mm``, ``sensor.axis_offset_y_mm``), the sensor's tilt
(``sensor.tilt_x_deg``, ``sensor.tilt_y_deg``) and its distance from the lens
(``lens.image_distance_mm``). Each has a 1-sigma tolerance parameter; a tolerance of 0 (or a
parameter the schema does not have) holds it fixed.

Estimate: the pose ``p`` minimises ``sum_i r_i(p)^2`` over the points ``i`` of the straight
edges, grouped into whole scene lines ``e`` (:mod:`~mechdeconv_ros.imaging.scene_lines`, once,
under the description), ``r_i`` the raw px distance of point i from the image of its line's
great circle to first order: ``r_i = n_e . d_i / hypot(n_theta / rho', n_phi sin(theta) /
rho)`` (``d_i`` the direction of point i under p, ``n_e`` the normal of the line's best great
circle, refitted
at every p: variable projection; ``n_theta``, ``n_phi`` its components along the field angle
and the azimuth at ``d_i``; ``rho'``, ``rho / sin(theta)`` the radial and tangential raw px
per rad under p). Every factor is taken at the pose being judged: a scale fixed at the
description let a larger image distance shrink the edges' raw noise in angle, and so pulled
the estimate there (docs/design.md section 2.17). By Levenberg-Marquardt with forward-
difference Jacobians, each parameter kept within ``BOUND_SIGMAS`` tolerances of the
description. Lines that stay curved after the fit (circles, arcs: RMS over
``REJECT_FACTOR`` x the median and ``REJECT_FLOOR_PX``) are dropped and the fit is redone.

Uncertainty: the larger of the classical ``s^2 (J^T J)^-1`` and the line-clustered sandwich
``(J^T J)^-1 (sum_e g_e g_e^T) (J^T J)^-1`` (``g_e = J_e^T r_e``), which does not believe
that the points along one line err independently, plus in quadrature a systematic floor
``eps^2 N [(J^T J)^-1]_kk`` with ``eps = SYSTEMATIC_FRACTION s`` (N points, s their RMS
residual): the largest move a straightness error of ``eps`` px RMS can fake, aligned with the
parameter's own signature. So a move counts only when it straightens the edges by more than
what rendering, blur and detection may bend them alike along the field. A direction the
edges cannot see (a tilt in a low-distortion lens: a homography keeps lines straight) has a
near-zero eigenvalue of ``J^T J`` and so a large sigma (capped at ``SIGMA_CAP``
tolerances), not a confident value: a parameter whose sigma exceeds its tolerance is
reported at the description's value with that sigma, and the others are refitted with it
held there.

Straightness: the edges and the short straight pieces are grouped into whole scene lines
(:mod:`~mechdeconv_ros.imaging.scene_lines`), and the RMS and largest distance of their
points from their whole lines are read, px of the corrected image.

Verdict: ``not_enough_edges`` under ``MIN_EDGES`` edges or ``MIN_COVERAGE`` of the field (no
estimate is made); else ``description_off`` when any of: (1) the RMS straightness with the
description exceeds ``check.max_rms_px``; (2) the estimate straightens: its RMS is below the
description's over ``OFF_RATIO`` and the bend it removes, ``sqrt(before^2 - after^2)``,
exceeds ``OFF_MIN_PX``; (3) an estimate differs from the description by more than
``OFF_SIGMAS`` sigma and one tolerance; else ``ok``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Mapping

from mechdeconv_ros.imaging.plumb_lines import (
    ChiefLines, edge_index, field_coverage, great_circles, line_pieces, MAX_POINTS_PER_EDGE,
    MIN_EDGE_POINTS, output_focal_px, straightness_px, thin)
from mechdeconv_ros.imaging.scene_lines import group_lines
from mechdeconv_ros.imaging.straight_edges import (
    detect_chains, frame_of, Points, sample_map, tagged)
from mechdeconv_ros.optics.prescription import vertex_z
import numpy as np
import numpy.typing as npt

#: The estimated parameters (pose order) and their tolerance parameters.
ESTIMATED = (('sensor.axis_offset_x_mm', 'sensor.tolerance.axis_offset_x_mm'),
             ('sensor.axis_offset_y_mm', 'sensor.tolerance.axis_offset_y_mm'),
             ('sensor.tilt_x_deg', 'sensor.tolerance.tilt_x_deg'),
             ('sensor.tilt_y_deg', 'sensor.tolerance.tilt_y_deg'),
             ('lens.image_distance_mm', 'lens.tolerance.image_distance_mm'))
#: The estimate stays within this many tolerances of the description.
BOUND_SIGMAS = 3.0
#: A reported sigma is at most this many tolerances (a direction the edges do not see).
SIGMA_CAP = 100.0
#: Fewest straight edges and smallest field coverage for a verdict other than
#: ``not_enough_edges``.
MIN_EDGES = 4
MIN_COVERAGE = 0.05
#: Robust refit: an edge whose RMS after the fit exceeds REJECT_FACTOR x the median edge RMS
#: and REJECT_FLOOR_PX is not a straight line of the scene.
REJECT_FACTOR = 3.0
REJECT_FLOOR_PX = 0.3
#: The systematic part of the edges' straightness error, as a fraction of their RMS residual
#: (raw px): the sigmas hold the parameter move such an error could fake (docs/design.md
#: section 2.17: true descriptions' estimates were off by the move of at most 0.067 of the
#: RMS, with 3 sigmas this covers 0.09).
SYSTEMATIC_FRACTION = 0.03
#: The verdict is also ``description_off`` when an estimate differs from the description by
#: more than OFF_SIGMAS of its sigma and one tolerance.
OFF_SIGMAS = 3.0
#: ... or when the estimate straightens the edges by more than this factor (RMS) and removes
#: a bend of more than OFF_MIN_PX (in quadrature: sqrt(before^2 - after^2)).
OFF_RATIO = 1.2
OFF_MIN_PX = 0.05
#: At most this many points of the straight edges enter the estimate (each edge thinned
#: evenly to its share, between MIN_EDGE_POINTS and MAX_POINTS_PER_EDGE).
MAX_FIT_POINTS = 6000
#: Levenberg-Marquardt iterations.
LM_ITERATIONS = 20
VERDICTS = ('ok', 'description_off', 'not_enough_edges')


@dataclass
class CheckResult:
    """The check of a set of frames; :meth:`as_dict` has the issue's key names."""

    straightness_rms_px: float | None = None
    straightness_max_px: float | None = None
    edges: int = 0
    lines: int = 0
    field_coverage: float = 0.0
    estimate: dict[str, dict[str, float]] = field(default_factory=dict)
    straightness_rms_px_after: float | None = None
    straightness_max_px_after: float | None = None
    verdict: str = 'not_enough_edges'
    points: int = 0
    rejected_edges: int = 0

    def as_dict(self) -> dict[str, Any]:
        """Return the result as JSON-ready values."""
        return {'straightness_rms_px': self.straightness_rms_px,
                'straightness_max_px': self.straightness_max_px,
                'edges': self.edges, 'lines': self.lines, 'field_coverage': self.field_coverage,
                'estimate': self.estimate,
                'straightness_rms_px_after': self.straightness_rms_px_after,
                'straightness_max_px_after': self.straightness_max_px_after,
                'verdict': self.verdict, 'points': self.points,
                'rejected_edges': self.rejected_edges}


def nominal_pose(model: Any) -> npt.NDArray[np.float64]:
    """Return the description's pose ``(dx, dy, alpha, beta, 0)``."""
    vals = model.values
    return np.array([float(vals.get(name, 0.0)) for name, _ in ESTIMATED[:4]] + [0.0])


def tolerances(model: Any) -> npt.NDArray[np.float64]:
    """Return the 1-sigma tolerance of each pose component (0 = held fixed)."""
    vals = model.values
    tol = []
    for name, tol_name in ESTIMATED:
        known = name in vals and tol_name in vals
        if name == 'lens.image_distance_mm' and model.prescription is None:
            known = False
        tol.append(float(vals[tol_name]) if known else 0.0)
    return np.array(tol)


def image_distance_base(model: Any) -> float:
    """Return the model's sensor distance from the last vertex, mm (NaN without surfaces)."""
    presc = model.prescription
    if presc is None:
        return math.nan
    distance = float(model.values.get('scene.distance_mm', 0.0))
    sensor_z, _ = model.source.image_plane(distance if distance > 0.0 else math.inf)
    return float(sensor_z - vertex_z(presc)[-1])


def raw_chains(images: list[np.ndarray]) -> list[Points]:
    """Return the edge chains of raw frames."""
    chains: list[Points] = []
    for image in images:
        chains.extend(detect_chains(image))
    return chains


def chains_from_corrected(image: np.ndarray, map_x: np.ndarray, map_y: np.ndarray
                          ) -> list[Points]:
    """
    Detect chains in a corrected frame and carry them to raw pixels through its remap maps.

    :param image: the corrected frame.
    :param map_x: the remap's float map of raw x per corrected pixel.
    :param map_y: the same for raw y.
    :return: raw chains (NaN-free), tagged with their frame.
    """
    valid = (map_x >= 0) & (map_y >= 0)
    out = []
    for chain in detect_chains(image, valid):
        raw = sample_map(map_x, map_y, chain)
        raw = raw[np.all(np.isfinite(raw), axis=1)]
        if raw.shape[0] >= 8:
            out.append(tagged(raw, frame_of(chain)))
    return out


class _Problem:
    """The straight edges' residuals (raw px) as a function of the free pose components."""

    def __init__(self, lines: ChiefLines, edges: list[Points], pose0: npt.NDArray[np.float64],
                 free: npt.NDArray[np.int64], ids: npt.NDArray[np.int64] | None = None):
        self.lines, self.pose0, self.free = lines, pose0, free
        self.set_edges(edges, np.arange(len(edges)) if ids is None else ids)

    def set_edges(self, edges: list[Points], ids: npt.NDArray[np.int64]) -> None:
        self.edges = edges
        self.ids = ids      # each edge's number among the description's straight edges
        self.points = np.concatenate(edges) if edges else np.zeros((0, 2))
        self.index = edge_index(edges)
        self.count = len(edges)

    def pose(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        pose = self.pose0.copy()
        pose[self.free] = x
        return pose

    def residuals(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        dirs, radial, tangential = self.lines.directions_and_scales(self.points, self.pose(x))
        good = np.all(np.isfinite(dirs), axis=1) & (radial > 0.0)
        dirs[~good] = 0.0       # no weight in the fit, zero residual
        normals, res = great_circles(dirs, self.index, self.count)
        # Each point's raw px distance from its great circle's image (first order): the
        # residual over its gradient per raw px, along the field angle and across the
        # azimuth, at the pose being judged (see the module docstring).
        n = normals[self.index]
        sin_t = np.hypot(dirs[:, 0], dirs[:, 1])
        with np.errstate(invalid='ignore', divide='ignore'):
            cos_p = np.where(sin_t > 0.0, dirs[:, 0] / sin_t, 1.0)
            sin_p = np.where(sin_t > 0.0, dirs[:, 1] / sin_t, 0.0)
            n_theta = (n[:, 0] * cos_p + n[:, 1] * sin_p) * dirs[:, 2] - n[:, 2] * sin_t
            n_phi = n[:, 1] * cos_p - n[:, 0] * sin_p
            out = res / np.hypot(n_theta / radial, n_phi / tangential)
        return np.where(good & np.isfinite(out), out, 0.0)

    def edge_rms(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        r = self.residuals(x)
        n = np.maximum(np.bincount(self.index, minlength=self.count), 1)
        return np.sqrt(np.bincount(self.index, r * r, self.count) / n)

    def keep_straight(self, x: npt.NDArray[np.float64], factor: float = REJECT_FACTOR,
                      whole_edges: bool = True) -> bool:
        """
        Drop the points off their lines and the edges that stay curved under x.

        A point is off when ``|r|`` exceeds ``REJECT_FACTOR`` robust sigmas (1.4826 x the
        median ``|r|``) and ``REJECT_FLOOR_PX``; an edge is curved when its RMS exceeds
        ``REJECT_FACTOR`` x the median edge RMS and ``REJECT_FLOOR_PX``.

        :param x: the free pose components.
        :param factor: ``REJECT_FACTOR`` or a more lenient one.
        :param whole_edges: False keeps every edge (only points go).
        :return: True when anything was dropped.
        """
        r = np.abs(self.residuals(x))
        point_ok = r <= max(factor * 1.4826 * float(np.median(r)), REJECT_FLOOR_PX)
        rms = self.edge_rms(x)
        edge_ok = rms <= max(factor * float(np.median(rms)), REJECT_FLOOR_PX)
        if not whole_edges:
            edge_ok[:] = True
        keep = point_ok & edge_ok[self.index]
        if keep.all():
            return False
        edges = [p[k] for p, k in zip(np.split(self.points, np.cumsum(
            np.bincount(self.index, minlength=self.count))[:-1]),
            np.split(keep, np.cumsum(np.bincount(self.index, minlength=self.count))[:-1]))]
        kept = [k for k, e in enumerate(edges) if e.shape[0] >= MIN_EDGE_POINTS]
        if len(kept) < MIN_EDGES:
            return False
        self.set_edges([edges[k] for k in kept], self.ids[kept])
        return True

    def jacobian(self, x: npt.NDArray[np.float64], r: npt.NDArray[np.float64],
                 steps: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        jac = np.empty((r.size, x.size))
        for k in range(x.size):
            xk = x.copy()
            xk[k] += steps[k]
            jac[:, k] = (self.residuals(xk) - r) / steps[k]
        return jac


def _levenberg_marquardt(problem: _Problem, x0: npt.NDArray[np.float64],
                         lo: npt.NDArray[np.float64], hi: npt.NDArray[np.float64],
                         scale: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Minimise the sum of squared residuals within [lo, hi] (steps clipped to the box)."""
    x = x0.copy()
    r = problem.residuals(x)
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(LM_ITERATIONS):
        jac = problem.jacobian(x, r, 1e-4 * scale) * scale
        a = jac.T @ jac
        g = jac.T @ r
        improved = False
        for _ in range(8):
            step = -np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-12), g) * scale
            xn = np.clip(x + step, lo, hi)
            rn = problem.residuals(xn)
            cost_n = float(rn @ rn)
            if cost_n < cost:
                # Done when the cost stalls or the step is a thousandth of a tolerance.
                improved = (cost - cost_n > 1e-7 * cost
                            and float(np.max(np.abs(xn - x) / scale)) > 1e-3)
                x, r, cost = xn, rn, cost_n
                lam = max(lam / 10.0, 1e-9)
                break
            lam *= 10.0
        if not improved:
            break
    return x


def _sigma(problem: _Problem, x: npt.NDArray[np.float64],
           scale: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return the 1-sigma of each free component (see the module docstring)."""
    r = problem.residuals(x)
    jac = problem.jacobian(x, r, 1e-4 * scale) * scale
    a = jac.T @ jac
    w, v = np.linalg.eigh(a)
    w = np.maximum(w, max(float(w[-1]), 1e-300) * 1e-14)
    a_inv = (v / w) @ v.T
    dof = max(r.size - 2 * problem.count - x.size, 1)
    classical = float(r @ r) / dof * a_inv
    grouped = np.stack([np.bincount(problem.index, jac[:, k] * r, problem.count)
                        for k in range(x.size)], axis=1)
    sandwich = a_inv @ (grouped.T @ grouped) @ a_inv
    # The systematic floor: a move a straightness error of SYSTEMATIC_FRACTION x the RMS
    # residual could make, aligned with the parameter's own signature (its part no other
    # parameter explains): eps sqrt(N [(J^T J)^-1]_kk), N the points.
    eps = SYSTEMATIC_FRACTION * math.sqrt(float(r @ r) / max(r.size, 1))
    var = np.maximum(np.diag(classical), np.diag(sandwich)) + eps ** 2 * r.size * np.diag(a_inv)
    return np.minimum(np.sqrt(var), SIGMA_CAP) * scale


def _fit_points(pieces: list[Points]) -> list[Points]:
    """Thin the edges to at most MAX_FIT_POINTS in all (the fit's time grows with them)."""
    per_edge = min(MAX_POINTS_PER_EDGE,
                   max(MIN_EDGE_POINTS, MAX_FIT_POINTS // max(len(pieces), 1)))
    return [thin(piece, per_edge) for piece in pieces]


def check_chains(model: Any, chains: list[Points], max_rms_px: float,
                 estimate: bool = True) -> CheckResult:
    """
    Check a model against raw edge chains and estimate the assembly that straightens them.

    :param model: the lens model (the description under test).
    :param chains: ordered raw edge chains of one or more frames.
    :param max_rms_px: the ``check.max_rms_px`` threshold of ``description_off``.
    :param estimate: False skips the estimate.
    :return: the result.
    """
    lines = ChiefLines.from_model(model)
    pose0 = nominal_pose(model)
    # The fit and the straightness are of whole scene lines, grouped once under the
    # description (the membership does not change with the pose): each point's residual is
    # from its whole line's great circle.
    fits, full, per_line = _scene_lines(model, lines, chains, pose0)
    result = CheckResult()
    tol = tolerances(model)
    free = np.flatnonzero(tol > 0.0) if estimate else np.zeros(0, dtype=np.int64)
    problem = _Problem(lines, fits, pose0, free)
    enough = int(per_line.sum()) >= MIN_EDGES
    x = pose0[free]
    if enough and free.size:
        scale = tol[free]
        lo, hi = x - BOUND_SIGMAS * scale, x + BOUND_SIGMAS * scale
        # Gross outliers first (junction remnants, crowded edges): a description that is
        # off bends every edge smoothly and a little, these by pixels.
        problem.keep_straight(x, 2.0 * REJECT_FACTOR, whole_edges=False)
        x = _levenberg_marquardt(problem, x, lo, hi, scale)
        # Robust refits without the points off their lines and the edges that stay curved
        # (circles, arcs, bent objects, crowded edges).
        for _ in range(2):
            if not problem.keep_straight(x):
                break
            x = _levenberg_marquardt(problem, x, lo, hi, scale)
    elif enough:
        problem.keep_straight(x)
    result.edges = int(per_line[problem.ids].sum()) if problem.count else 0
    result.lines = problem.count
    result.points = int(problem.points.shape[0])
    result.rejected_edges = int(per_line.sum()) - result.edges
    result.field_coverage = field_coverage(lines, pose0, problem.points)
    if problem.count == 0:
        return result
    # The straightness: every point of the kept lines (their edges and short pieces).
    whole = _WholeLines(model, lines, [full[k] for k in problem.ids])
    rms, worst = whole.straightness(pose0)
    result.straightness_rms_px, result.straightness_max_px = rms, worst
    if result.edges < MIN_EDGES or result.field_coverage < MIN_COVERAGE:
        return result
    result.verdict = 'description_off' if not rms <= max_rms_px else 'ok'
    if free.size == 0:
        return result
    sigma = _sigma(problem, x, tol[free])
    # What the edges do not see is held at the description (its sigma stays the full fit's),
    # and the rest is refitted without it: an unseen tilt at its bound would drag the offset.
    seen = sigma <= tol[free]
    if seen.any() and not seen.all():
        full_sigma = sigma
        reduced = _Problem(lines, problem.edges, pose0, free[seen])
        xs = _levenberg_marquardt(reduced, pose0[free[seen]], lo[seen], hi[seen],
                                  tol[free[seen]])
        x = pose0[free].copy()
        x[seen] = xs
        sigma = full_sigma.copy()
        sigma[seen] = _sigma(reduced, xs, tol[free[seen]])
    _judge(result, model, problem.pose(x), free, sigma, tol, whole)
    return result


def _judge(result: CheckResult, model: Any, pose: npt.NDArray[np.float64],
           free: npt.NDArray[np.int64], sigma: npt.NDArray[np.float64],
           tol: npt.NDArray[np.float64], whole: _WholeLines) -> None:
    """Fill in the estimate and the straightness after it; apply the rules (2) and (3)."""
    base_d = image_distance_base(model)
    for j, k in enumerate(free):
        name = ESTIMATED[k][0]
        value = float(pose[k]) if k < 4 else base_d + float(pose[4])
        result.estimate[name] = {'value': value, 'sigma': float(sigma[j]),
                                 'tolerance': float(tol[k])}
    after = whole.straightness(pose)
    result.straightness_rms_px_after, result.straightness_max_px_after = after[0], after[1]
    moved = [abs(est['value'] - base) > max(OFF_SIGMAS * est['sigma'], est['tolerance'])
             for est, base in zip(result.estimate.values(), _bases(model, free, base_d))]
    if straightens(result.straightness_rms_px, after[0]) or any(moved):
        result.verdict = 'description_off'


def straightens(before: float, after: float) -> bool:
    """
    Return True when an estimate straightens the edges enough to call the description off.

    Both: the RMS drops by more than ``OFF_RATIO`` and the bend it removes (in quadrature,
    ``sqrt(before^2 - after^2)``) exceeds ``OFF_MIN_PX``: on edges at a 0.03 px floor a
    0.005 px gain is a ratio of 1.2 and no bend anyone could see.

    :param before: the straightness RMS with the description, px.
    :param after: the same with the estimate, px.
    :return: the rule's answer.
    """
    removed = math.sqrt(max(before * before - after * after, 0.0))
    return after * OFF_RATIO < before and removed > OFF_MIN_PX


def _bases(model: Any, free: npt.NDArray[np.int64], base_d: float) -> list[float]:
    """Return the description's value of each free parameter."""
    pose0 = nominal_pose(model)
    return [float(pose0[k]) if k < 4 else base_d for k in free]


class _WholeLines:
    """The points of whole scene lines (their straight edges and short pieces), one label each."""

    def __init__(self, model: Any, lines: ChiefLines, parts: list[Points]):
        self.model, self.lines = model, lines
        self.points = np.concatenate(parts) if parts else np.zeros((0, 2))
        self.line = np.repeat(np.arange(len(parts)), [p.shape[0] for p in parts])
        self.count = len(parts)

    def straightness(self, pose: npt.NDArray[np.float64]) -> tuple[float, float]:
        """Return the RMS and largest distance from the whole lines under a pose, px."""
        dirs = self.lines.directions(self.points, pose)
        good = np.all(np.isfinite(dirs), axis=1)
        rms, worst, _ = straightness_px(self.model, dirs[good], self.line[good], self.count)
        return rms, worst


def _scene_lines(model: Any, lines: ChiefLines, chains: list[Points],
                 pose0: npt.NDArray[np.float64]
                 ) -> tuple[list[Points], list[Points], npt.NDArray[np.int64]]:
    """
    Return each scene line's fit points, all its points, and its count of straight edges.

    :param model: the description.
    :param lines: its inverse.
    :param chains: raw chains.
    :param pose0: the description's pose (the pieces and lines are made under it).
    :return: ``(fit points per line (edges thinned), all points per line (edges and short
        pieces), edges per line)``.
    """
    f_px = output_focal_px(model)
    pieces, short = line_pieces(chains, lines, pose0, f_px)
    if not pieces:
        return [], [], np.zeros(0, dtype=np.int64)
    on_edges, on_short = group_lines(pieces, lines, pose0, f_px, short)
    fit = _fit_points(pieces)
    count = int(on_edges.max()) + 1
    members = [np.flatnonzero(on_edges == k) for k in range(count)]
    fits = [np.concatenate([fit[j] for j in m]) for m in members]
    full = [np.concatenate([pieces[j] for j in m]
                           + [short[j] for j in np.flatnonzero(on_short == k)])
            for k, m in enumerate(members)]
    return fits, full, np.bincount(on_edges, minlength=count)


def check_images(model: Any, images: list[np.ndarray], max_rms_px: float,
                 estimate: bool = True) -> CheckResult:
    """
    Check raw frames (detection in the raw frame, points through the exact inverse).

    :param model: the description under test.
    :param images: raw frames.
    :param max_rms_px: the ``description_off`` threshold.
    :param estimate: False skips the estimate.
    :return: the result.
    """
    return check_chains(model, raw_chains(images), max_rms_px, estimate)


def to_apply(result: CheckResult, values: Mapping[str, Any],
             reference: Mapping[str, Any] | None = None) -> dict[str, float]:
    """
    Return the parameters ``check.apply`` may set: estimated within their tolerance.

    A parameter whose sigma exceeds its tolerance is left as it is (the edges do not see
    it); a value is never set outside ``BOUND_SIGMAS`` tolerances of the current one.

    :param result: a check with an estimate.
    :param values: the current parameter values.
    :param reference: the values the bounds are about (default ``values``): a node passes
        its start-up values, so repeated sets never walk away from the description.
    :return: name -> value (empty when nothing qualifies).
    """
    if result.verdict != 'description_off':
        return {}
    out = {}
    for name, est in result.estimate.items():
        tol = est['tolerance']
        if not est['sigma'] <= tol:
            continue
        current = float(values.get(name, 0.0))
        if name == 'lens.image_distance_mm' and current <= 0.0:
            continue        # the paraxial image plane stays a choice of the user
        centre = float((reference or values).get(name, current))
        out[name] = float(np.clip(est['value'], centre - BOUND_SIGMAS * tol,
                                  centre + BOUND_SIGMAS * tol))
    return out
