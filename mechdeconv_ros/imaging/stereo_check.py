# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The rig's rotation measured from the scene: matched features, the epipolar fit, the verdict.

Pure numpy and OpenCV, no ROS (docs/design.md section 8, "The rig measured live"). Frames
and signs are the rig's (section 8): in the left camera's optical frame (X right, Y down, Z
ahead) the right camera's entrance pupil is at ``t = (B, t_y, t_z)`` mm (``rig.baseline_mm``,
``rig.offset_y_mm``, ``rig.offset_z_mm``) and its axes are the columns of
``R = R_x(r_x) R_y(r_y) R_z(r_z)`` (``rig.rotation_*_deg``); a scene point is
``X_r = R^T (X_l - t)`` in the right camera's frame.

1. Matches. SIFT keypoints of the left and the right RAW frames (8-bit grey), Lowe's ratio
   test (:data:`RATIO`) both ways and only mutual best matches. OpenCV's SIFT reports a blob
   centred at ``p`` as ``p + 0.25`` px in x and y with its default (the octave of the doubled
   image is mapped back by a factor 2 without the half-pixel shift); between cameras of
   different focal length that offset is a rotation bias (0.0034 deg of pitch for 1092
   against 1449 px), so the detector runs with ``enable_precise_upscale`` which centres it
   (a test renders a blob and reads it back within 0.02 px). Each raw pixel is mapped to its
   exact unit scene direction by its camera's inverse, seen from its entrance pupil
   (:func:`~mechdeconv_ros.model.stereo.directions_from_pupil`): the lens, the sensor's pose
   and any port included, no fitted D.
2. The fit. A match's directions ``d_l``, ``d_r`` see one scene point only if ``d_l``, ``t``
   and ``R d_r`` are coplanar: ``e = d_l . (t_hat x R d_r) = 0``. Its residual in pixels is
   Sampson's first-order distance with one pixel of detection noise in each image:
   ``r = e / sqrt(|g_l|^2 / f_l^2 + |g_r|^2 / f_r^2)``, ``g_l``, ``g_r`` the gradients of
   ``e`` on the two unit spheres and ``f`` each raw camera's focal length in px. The free
   parameters are the three rotations and the offsets ``t_y``, ``t_z`` whose tolerance is
   above 0; the baseline length stays the drawing's (scale is not observable). RANSAC
   (minimal samples solved by Gauss-Newton from the description, :data:`RANSAC_ITERATIONS`)
   finds the inliers (``|r| <`` :data:`INLIER_PX`), then bounded Levenberg-Marquardt over all
   inliers of the pooled pairs, the inliers re-selected at ``max(INLIER_PX, 4 s)`` (``s`` the
   robust scatter) and refitted. Every parameter stays within its tolerance about the
   description. Sigma: the larger of ``s_r sqrt(diag((J^T J)^-1))`` (``s_r`` the residual
   RMS in px, matches independent) and the sandwich estimate clustered by 64 px cell of the
   left image (:func:`parameter_sigma`: one patch of texture seen in several pooled pairs
   errs alike); a parameter whose sigma exceeds its tolerance is held at
   the description and the rest refitted: the scene does not measure it (a far, flat scene
   does not measure yaw).
3. The verdict reads the vertical disparity of the inlier matches in the rectified pair
   (the pair's own rectification, :func:`vertical_disparity`):
   ``v_l - v_r = f_y' (a_y / a_z - b_y / b_z)``, ``a = R_1 d_l``, ``b = R_2 d_r``, in px of the
   rectified image of focal length ``f_y'``. ``not_enough_matches`` below
   :data:`MIN_MATCHES` inliers or when either half (left, right) of the left image holds under
   :data:`MIN_HALF_SHARE` of them (roll is measured by the horizontal lever of the matches;
   a featureless or one-sided pair gives no estimate, never a guess); else ``rig_off`` when
   the RMS with the description exceeds both :data:`FLOOR_PX` and :data:`AFTER_FACTOR` times
   the RMS with the estimate (the floor: a matcher's own scatter, ~0.1 px per SIFT match,
   never makes a rig "off"; the factor: a rig is off only if the estimate does clearly
   better), ``ok`` otherwise.
4. ``stereo_check.apply`` (:func:`apply_values`): the estimate's measured parameters in one
   set, each clamped to the user's value +- its tolerance (the user's, not an earlier
   applied estimate: applying again never walks beyond the tolerance).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Sequence

import cv2
from mechdeconv_ros.model.stereo import (
    directions_from_pupil, rectifying_rotations, Rig, rig_rotation)
import numpy as np

#: The rig's parameters the check may estimate, in the fit's order.
RIG_NAMES = ('rig.rotation_x_deg', 'rig.rotation_y_deg', 'rig.rotation_z_deg',
             'rig.offset_y_mm', 'rig.offset_z_mm')
#: Lowe's ratio of the best to the second-best descriptor distance.
RATIO = 0.8
#: Inlier limit of the epipolar residual (px) for RANSAC and the least refit.
INLIER_PX = 1.0
#: RANSAC samples.
RANSAC_ITERATIONS = 200
#: Fewest inlier matches (pooled) for an estimate and a verdict.
MIN_MATCHES = 40
#: Least share of the inliers in each half (left, right) of the left image.
MIN_HALF_SHARE = 0.1
#: Vertical disparity RMS (px) that never makes a rig ``rig_off``.
FLOOR_PX = 0.3
#: ``rig_off`` needs the description's RMS above this multiple of the estimate's.
AFTER_FACTOR = 2.0
#: Most SIFT keypoints per frame (the strongest).
MAX_FEATURES = 4000
#: Cells (px of the left raw image) whose matches the sigma takes as sharing their errors.
CELL_PX = 64
#: Finite-difference steps of the Jacobian (deg for rotations, mm for offsets).
_STEP = np.array([1e-4, 1e-4, 1e-4, 1e-3, 1e-3])


def sift() -> Any:
    """
    Return the SIFT detector with centred keypoints (``enable_precise_upscale``).

    :return: a ``cv2.SIFT`` instance.
    """
    return cv2.SIFT_create(MAX_FEATURES, 3, 0.04, 10, 1.6, cv2.CV_32F, True)


def to_grey(image: np.ndarray) -> np.ndarray:
    """
    Return an 8-bit single-channel copy of a frame (RGB order assumed for 3 channels).

    :param image: ``(h, w)`` or ``(h, w, 3|4)``, 8 or 16 bit.
    :return: ``(h, w)`` uint8.
    """
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img[..., :3], cv2.COLOR_RGB2GRAY)
    if img.dtype != np.uint8:
        img = cv2.convertScaleAbs(img, alpha=255.0 / max(float(img.max()), 1.0))
    return np.ascontiguousarray(img)


def _mutual_ratio_matches(desc_l: np.ndarray, desc_r: np.ndarray) -> np.ndarray:
    """Return ``(n, 2)`` index pairs passing the ratio test both ways and mutual."""
    if len(desc_l) < 2 or len(desc_r) < 2:
        return np.zeros((0, 2), int)
    # A k-d forest (FLANN) rather than brute force: 4000 x 4000 descriptors both ways cost
    # 1.5 s brute force here; the ratio test and the mutual check remove what it misses.
    bf = cv2.FlannBasedMatcher({'algorithm': 1, 'trees': 4}, {'checks': 64})

    def best(a: np.ndarray, b: np.ndarray) -> dict[int, int]:
        out = {}
        for pair in bf.knnMatch(a, b, k=2):
            if len(pair) == 2 and pair[0].distance < RATIO * pair[1].distance:
                out[pair[0].queryIdx] = pair[0].trainIdx
        return out

    fwd, back = best(desc_l, desc_r), best(desc_r, desc_l)
    pairs = [(i, j) for i, j in fwd.items() if back.get(j) == i]
    return np.array(pairs, int).reshape(-1, 2)


def match_pixels(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the matched raw pixels of a left and a right frame.

    :param left: the left raw frame.
    :param right: the right raw frame.
    :return: ``(p_l, p_r)``, each ``(n, 2)`` float64 raw pixels (u, v), pixel centres at
        integers (the detector's offset corrected).
    """
    det = sift()
    kl, dl = det.detectAndCompute(to_grey(left), None)
    kr, dr = det.detectAndCompute(to_grey(right), None)
    if dl is None or dr is None:
        return np.zeros((0, 2)), np.zeros((0, 2))
    idx = _mutual_ratio_matches(dl, dr)
    p_l = np.array([kl[i].pt for i in idx[:, 0]], float).reshape(-1, 2)
    p_r = np.array([kr[j].pt for j in idx[:, 1]], float).reshape(-1, 2)
    return p_l, p_r


def rotation(rx_deg: float, ry_deg: float, rz_deg: float) -> np.ndarray:
    """
    Return the rig's rotation matrix R_x(rx) R_y(ry) R_z(rz) (the model's one definition).

    :param rx_deg: rotation about X (deg).
    :param ry_deg: rotation about Y (deg).
    :param rz_deg: rotation about Z (deg).
    :return: ``(3, 3)`` rotation whose columns are the right camera's axes.
    """
    return rig_rotation(rx_deg, ry_deg, rz_deg)


def rig_of(params: np.ndarray, base_mm: float) -> Rig:
    """
    Return the rig of the fit's parameter vector.

    :param params: ``(rx, ry, rz, t_y, t_z)`` in deg and mm.
    :param base_mm: the baseline (mm).
    :return: the rig.
    """
    return Rig(float(base_mm), float(params[3]), float(params[4]), float(params[0]),
               float(params[1]), float(params[2]))


def vertical_disparity(d_l: np.ndarray, d_r: np.ndarray, rig: Rig, fy: float) -> np.ndarray:
    """
    Return each match's vertical disparity ``v_l - v_r`` (px) in the rig's rectified pair.

    The pair's own rectification (:func:`mechdeconv_ros.model.stereo.rectifying_rotations`).

    :param d_l: ``(n, 3)`` left directions.
    :param d_r: ``(n, 3)`` right directions.
    :param rig: the rig.
    :param fy: the rectified camera's focal length in rows (px).
    :return: ``(n,)`` px.
    """
    r1, r2 = rectifying_rotations(rig)
    a, b = d_l @ r1.T, d_r @ r2.T
    return fy * (a[:, 1] / a[:, 2] - b[:, 1] / b[:, 2])


def _tangent(g: np.ndarray, d: np.ndarray) -> np.ndarray:
    return g - np.sum(g * d, axis=1, keepdims=True) * d


def epipolar_px(params: np.ndarray, base_mm: float, d_l: np.ndarray, d_r: np.ndarray,
                f_l: float, f_r: float) -> np.ndarray:
    """
    Return the Sampson epipolar residual (px) of each match for the rig ``params``.

    :param params: ``(rx, ry, rz, t_y, t_z)`` in deg and mm.
    :param base_mm: the baseline's X component (mm).
    :param d_l: ``(n, 3)`` left unit directions.
    :param d_r: ``(n, 3)`` right unit directions.
    :param f_l: the left raw focal length (px).
    :param f_r: the right raw focal length (px).
    :return: ``(n,)`` residuals in px.
    """
    rot = rotation(*params[:3])
    t = np.array([base_mm, params[3], params[4]])
    t /= np.linalg.norm(t)
    rd = d_r @ rot.T
    n = np.cross(t, rd)
    e = np.sum(d_l * n, axis=1)
    g_l = _tangent(n, d_l)
    g_r = _tangent(np.cross(d_l, t) @ rot, d_r)
    scale = np.sqrt(np.sum(g_l ** 2, axis=1) / f_l ** 2 + np.sum(g_r ** 2, axis=1) / f_r ** 2)
    return e / np.maximum(scale, 1e-12)


@dataclasses.dataclass(frozen=True)
class FitProblem:
    """The matches of the pooled pairs and the rig's description they are fitted about."""

    d_l: np.ndarray
    d_r: np.ndarray
    p_l: np.ndarray
    f_l: float
    f_r: float
    base_mm: float
    described: np.ndarray
    tolerance: np.ndarray

    def residuals(self, params: np.ndarray, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """
        Return the selected matches' residuals in px.

        :param params: the five rig parameters.
        :param rows: which matches.
        :return: px.
        """
        return epipolar_px(params, self.base_mm, self.d_l[rows], self.d_r[rows], self.f_l,
                           self.f_r)

    def jacobian(self, params: np.ndarray, free: np.ndarray,
                 rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """
        Return d residual / d free parameter (central differences).

        :param params: the five rig parameters.
        :param free: indices of the free parameters.
        :param rows: which matches.
        :return: ``(n, len(free))``.
        """
        cols = []
        for k in free:
            step = np.zeros(5)
            step[k] = _STEP[k]
            cols.append((self.residuals(params + step, rows)
                         - self.residuals(params - step, rows)) / (2 * _STEP[k]))
        return np.stack(cols, axis=1)

    def clamp(self, params: np.ndarray) -> np.ndarray:
        """
        Return the parameters clamped to the description +- tolerance.

        :param params: the five rig parameters.
        :return: clamped copy.
        """
        return np.clip(params, self.described - self.tolerance, self.described + self.tolerance)


def levenberg_marquardt(problem: FitProblem, params: np.ndarray, free: np.ndarray,
                        rows: np.ndarray | slice, iterations: int = 12) -> np.ndarray:
    """
    Return the bounded least-squares rig parameters over the selected matches.

    :param problem: the matches.
    :param params: the start (five parameters).
    :param free: indices of the free parameters.
    :param rows: which matches.
    :param iterations: the most steps.
    :return: the fitted five parameters (the held ones unchanged).
    """
    p = params.copy()
    lam = 1e-3
    cost = float(np.sum(problem.residuals(p, rows) ** 2))
    for _ in range(iterations):
        r = problem.residuals(p, rows)
        jac = problem.jacobian(p, free, rows)
        jtj = jac.T @ jac
        grad = jac.T @ r
        while True:
            step = np.linalg.solve(jtj + lam * np.diag(np.diag(jtj) + 1e-12), -grad)
            trial = p.copy()
            trial[free] += step
            trial = problem.clamp(trial)
            new_cost = float(np.sum(problem.residuals(trial, rows) ** 2))
            if new_cost <= cost or lam > 1e8:
                break
            lam *= 10.0
        if new_cost > cost:
            break
        done = np.all(np.abs(trial - p)[free] < 1e-7 * (1 + np.abs(p[free])))
        p, cost, lam = trial, new_cost, max(lam / 10.0, 1e-9)
        if done:
            break
    return p


def ransac_inliers(problem: FitProblem, free: np.ndarray, rng: np.random.Generator
                   ) -> np.ndarray:
    """
    Return the inlier mask of the best minimal-sample fit (``|r| <`` :data:`INLIER_PX`).

    :param problem: the matches.
    :param free: indices of the free parameters.
    :param rng: the sampler.
    :return: ``(n,)`` bool.
    """
    n = len(problem.d_l)
    best = np.zeros(n, bool)
    size = len(free) + 2
    needed, done = RANSAC_ITERATIONS, 0
    while done < min(needed, RANSAC_ITERATIONS):
        done += 1
        rows = rng.choice(n, size, replace=False)
        p = levenberg_marquardt(problem, problem.described, free, rows, iterations=3)
        mask = np.abs(problem.residuals(p)) < INLIER_PX
        if mask.sum() > best.sum():
            best = mask
            # The usual adaptive stop: enough samples for one all-inlier sample at 99.9 %.
            share = max(float(mask.mean()), 1e-3) ** size
            needed = int(math.log(1e-3) / math.log(max(1.0 - share, 1e-12))) + 1 \
                if share < 1.0 else 1
    return best


def parameter_sigma(problem: FitProblem, params: np.ndarray, free: np.ndarray,
                    inliers: np.ndarray) -> np.ndarray:
    """
    Return the 1-sigma of the free parameters: the larger of the iid and the cell-clustered one.

    iid: ``s_r sqrt(diag((J^T J)^-1))``. Clustered (the sandwich ``B M B``, ``B = (J^T J)^-1``,
    ``M = G/(G-1) sum_c (J_c^T r_c)(J_c^T r_c)^T`` over the :data:`CELL_PX` cells ``c`` of the
    left raw image): matches of one patch of texture share their errors (the same scene in
    every pooled pair of a still camera), which the iid sigma would count as independent.

    :param problem: the matches.
    :param params: the fitted parameters.
    :param free: the free parameters' indices.
    :param inliers: the inlier mask.
    :return: ``(len(free),)`` sigmas.
    """
    r = problem.residuals(params, inliers)
    jac = problem.jacobian(params, free, inliers)
    bread = np.linalg.pinv(jac.T @ jac)
    s_r = math.sqrt(float(np.sum(r ** 2)) / max(len(r) - free.size, 1))
    iid = s_r * np.sqrt(np.diag(bread))
    cells = np.floor(problem.p_l[inliers] / CELL_PX).astype(np.int64)
    _, cluster = np.unique(cells, axis=0, return_inverse=True)
    groups = int(cluster.max()) + 1 if len(cluster) else 0
    if groups < 2:
        return iid
    scores = np.zeros((groups, free.size))
    np.add.at(scores, cluster.reshape(-1), jac * r[:, None])
    meat = scores.T @ scores * (groups / (groups - 1.0))
    clustered = np.sqrt(np.abs(np.diag(bread @ meat @ bread)))
    return np.maximum(iid, clustered)


@dataclasses.dataclass
class StereoCheckResult:
    """One stereo check: the verdict, the matches and the rig's estimate."""

    verdict: str
    matches: int
    matches_total: int
    pairs: int
    vertical_disparity_rms_px: float
    vertical_disparity_rms_px_after: float
    residual_rms_px: float
    estimate: dict[str, dict[str, float]]

    def as_dict(self) -> dict[str, Any]:
        """
        Return the JSON / diagnostics form (the keys of ``mechdeconv stereo-check --json``).

        :return: a plain dict.
        """
        return dataclasses.asdict(self)


def _coverage_ok(p_l: np.ndarray, width: int) -> bool:
    if len(p_l) < MIN_MATCHES:
        return False
    share = float(np.mean(p_l[:, 0] < 0.5 * width))
    return min(share, 1.0 - share) >= MIN_HALF_SHARE


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2))) if len(x) else float('nan')


def fit_rig(problem: FitProblem, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                         np.ndarray]:
    """
    Return the robust fit of the rig to the matches.

    :param problem: the matches and the description.
    :param seed: the RANSAC sampler's seed (the check is reproducible).
    :return: ``(params, sigma, free, inliers)``: the five parameters (held ones at the
        description), their 1-sigma (inf where not free), the indices that were fitted and
        the inlier mask.
    """
    free = np.flatnonzero(problem.tolerance > 0)
    sigma = np.full(5, np.inf)
    if free.size == 0:
        return problem.described.copy(), sigma, free, np.ones(len(problem.d_l), bool)
    inliers = ransac_inliers(problem, free, np.random.default_rng(seed))
    params = problem.described.copy()
    for _ in range(2):
        if inliers.sum() <= free.size + 2:
            break
        params = levenberg_marquardt(problem, problem.described, free, inliers)
        r = problem.residuals(params)
        spread = 1.4826 * float(np.median(np.abs(r[inliers])))
        inliers = np.abs(r) < max(INLIER_PX, 4.0 * spread)
    for _ in range(5):
        if inliers.sum() <= free.size + 2:
            break
        sig = parameter_sigma(problem, params, free, inliers)
        sigma[free] = sig
        seen = free[sig <= problem.tolerance[free]]
        if seen.size == free.size:
            break
        free = seen
        params = problem.described.copy()
        if free.size:
            params = levenberg_marquardt(problem, params, free, inliers)
    return params, sigma, free, inliers


def make_problem(d_l: np.ndarray, d_r: np.ndarray, p_l: np.ndarray, f_l: float, f_r: float,
                 rig: Mapping[str, Any]) -> FitProblem:
    """
    Return the fit problem of matched directions about the rig's described values.

    :param d_l: ``(n, 3)`` left unit directions.
    :param d_r: ``(n, 3)`` right unit directions.
    :param p_l: ``(n, 2)`` left raw pixels (coverage).
    :param f_l: the left raw focal length (px).
    :param f_r: the right raw focal length (px).
    :param rig: the rig's values (``rig.*`` and ``rig.tolerance.*``).
    :return: the problem (matches with a NaN direction dropped).
    """
    ok = np.all(np.isfinite(d_l), axis=1) & np.all(np.isfinite(d_r), axis=1)
    described = np.array([float(rig.get(n, 0.0)) for n in RIG_NAMES])
    tol = np.array([float(rig.get(tolerance_name(n), 0.0)) for n in RIG_NAMES])
    return FitProblem(d_l[ok], d_r[ok], p_l[ok], float(f_l), float(f_r),
                      float(rig['rig.baseline_mm']), described, tol)


def tolerance_name(name: str) -> str:
    """
    Return the tolerance parameter of a rig parameter (``rig.x`` -> ``rig.tolerance.x``).

    :param name: a full rig parameter name.
    :return: its tolerance's name.
    """
    return 'rig.tolerance.' + name[len('rig.'):]


def check_problem(problem: FitProblem, width: int, fy_rect: float,
                  seed: int = 0) -> StereoCheckResult:
    """
    Fit the rig to pooled matches and return the verdict and the estimate.

    :param problem: the pooled matches and the description.
    :param width: the left raw image's width (px; coverage).
    :param fy_rect: the rectified camera's focal length in rows (px).
    :param seed: the RANSAC seed.
    :return: the result; no estimate (empty) with ``not_enough_matches``.
    """
    total = len(problem.d_l)
    nan = float('nan')
    if total < MIN_MATCHES or not _coverage_ok(problem.p_l, width):
        return StereoCheckResult('not_enough_matches', total, total, 0, nan, nan, nan, {})
    params, sigma, free, inliers = fit_rig(problem, seed)
    if not _coverage_ok(problem.p_l[inliers], width):
        return StereoCheckResult('not_enough_matches', int(inliers.sum()), total, 0, nan,
                                 nan, nan, {})
    d_l, d_r = problem.d_l[inliers], problem.d_r[inliers]

    before = _rms(vertical_disparity(d_l, d_r, rig_of(problem.described, problem.base_mm),
                                     fy_rect))
    after = _rms(vertical_disparity(d_l, d_r, rig_of(params, problem.base_mm), fy_rect))
    off = before > max(FLOOR_PX, AFTER_FACTOR * after)
    estimate = {
        RIG_NAMES[k]: {'value': float(params[k]), 'sigma': float(sigma[k]),
                       'tolerance': float(problem.tolerance[k])}
        for k in range(5) if problem.tolerance[k] > 0}
    return StereoCheckResult('rig_off' if off else 'ok', int(inliers.sum()), total, 0, before,
                             after, _rms(problem.residuals(params, inliers)), estimate)


def apply_values(result: StereoCheckResult, user: Mapping[str, Any]) -> dict[str, float]:
    """
    Return what ``stereo_check.apply`` sets: the measured parameters, within tolerance.

    :param result: a check with an estimate.
    :param user: the user's values (``rig.*`` and ``rig.tolerance.*``): the clamp's centre.
    :return: ``{name: value}`` of the parameters the matches measured (sigma within the
        tolerance); empty when there is nothing to set.
    """
    out = {}
    for name, est in (result.estimate or {}).items():
        tol = float(user.get(tolerance_name(name), 0.0))
        if not (est['sigma'] <= est['tolerance']) or tol <= 0:
            continue
        centre = float(user.get(name, 0.0))
        out[name] = float(np.clip(est['value'], centre - tol, centre + tol))
    return out


def pair_directions(left_model: Any, right_model: Any, p_l: np.ndarray,
                    p_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the unit scene directions of matched raw pixels, each from its entrance pupil.

    The pair's own inverse (:func:`mechdeconv_ros.model.stereo.directions_from_pupil`: the
    exact inverse refined on the forward trace, seen from the entrance pupil, the rig's
    origin).

    :param left_model: the left :class:`~mechdeconv_ros.model.model.LensModel`.
    :param right_model: the right one.
    :param p_l: ``(n, 2)`` left raw pixels.
    :param p_r: ``(n, 2)`` right raw pixels.
    :return: ``(d_l, d_r)``, ``(n, 3)`` each (NaN outside a traced field).
    """
    return directions_from_pupil(left_model, p_l), directions_from_pupil(right_model, p_r)


def check_pairs(left_model: Any, right_model: Any, rig: Mapping[str, Any],
                pairs: Sequence[tuple[np.ndarray, np.ndarray]] | Sequence[
                    tuple[np.ndarray, np.ndarray]], fy_rect: float,
                matched: bool = False) -> StereoCheckResult:
    """
    Check the rig on raw frame pairs (or on their matched pixels) pooled together.

    :param left_model: the left camera's model.
    :param right_model: the right camera's model.
    :param rig: the rig's values (``rig.*``, ``rig.tolerance.*``).
    :param pairs: ``(left, right)`` raw frames, or ``(p_l, p_r)`` matched pixels when
        ``matched``.
    :param fy_rect: the rectified camera's focal length in rows (px).
    :param matched: ``pairs`` are already matched pixels (the node's window).
    :return: the result.
    """
    p_ls, p_rs = [], []
    for a, b in pairs:
        p_l, p_r = (np.asarray(a, float), np.asarray(b, float)) if matched else \
            match_pixels(a, b)
        p_ls.append(p_l.reshape(-1, 2))
        p_rs.append(p_r.reshape(-1, 2))
    p_l = np.concatenate(p_ls) if p_ls else np.zeros((0, 2))
    p_r = np.concatenate(p_rs) if p_rs else np.zeros((0, 2))
    d_l, d_r = pair_directions(left_model, right_model, p_l, p_r)
    problem = make_problem(d_l, d_r, p_l, left_model.K[0, 0], right_model.K[0, 0], rig)
    result = check_problem(problem, int(left_model.width), fy_rect)
    result.pairs = len(pairs)
    return result
