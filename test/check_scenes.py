# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Raw frames of straight-line scenes rendered through an independent route (test helper).

The lens: optiland's chief rays of the wide-angle and fisheye configs as lines in image
space, ``rho(z) = h(theta) + s(theta) (z - z_s)`` (heights ``h`` on the paraxial image plane
``z_s``: test/data/optiland_wide_reference.json, traced by tools/make_optiland_reference.py
with optiland's robust aimer; slopes ``s = d rho / dz``, z towards the sensor, at the same
angles: test/data/optiland_chief_slopes.json, tools/make_optiland_chief_slopes.py),
interpolated by natural cubic splines of this file (not the package's Hermite tables). No
remap and no code of the package is used.

The sensor: the lens axis meets it at the pixel ``c`` (the centre plus the true axis offset);
a raw pixel (u, v) is the point ``Q = a e_u + b e_v`` from the axis point, ``(a, b) = ((u -
c_u) p, (v - c_v) p)``, with the row and column directions of :func:`sensor_axes` (tilt_x
then tilt_y, the words of docs/design.md section 2.16, built here from those words; a test
ties them to the package's ``project``). It sees the direction of azimuth ``atan2(Q_y, Q_x)``
and of the field angle whose chief-ray line passes through it: ``h(theta) + s(theta) Q_z =
hypot(Q_x, Q_y)`` (untilted: ``theta = h^-1(hypot(a, b))``).

Scenes (central camera, directions only): a planar grid of dark bars on a bounded light
plane at any orientation, a box room (six walls of different greys with dark doors and
windows), and discs (circles) on a plane. Edges are anti-aliased analytically (the box
filter of the pixel: a linear ramp one footprint wide) and wall-to-wall edges by 4 x 4
supersampling; then a Gaussian blur of ``BLUR_PX`` (the optics) and 8-bit quantisation.

Ground truth for the straightness (issue 36): :func:`grid_lines` and :func:`room_lines` give
the scene lines the renderer draws (end directions of each arc of a great circle),
:func:`assign_to_lines` gives each detected edge point its known line through the renderer's
own geometry, and :func:`whole_line_rms` measures the RMS distance from whole known lines.
:func:`as_sent` turns a render into what a real camera sends (JPEG, Bayer, motion blur,
10/12-bit ``mono16``, dim).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np

DATA = Path(__file__).resolve().parent / 'data' / 'optiland_wide_reference.json'
SLOPES = Path(__file__).resolve().parent / 'data' / 'optiland_chief_slopes.json'
LENSES = {'wide': ('wide_angle_160', 'config/wide_angle.yaml', 1920, 1200),
          'fisheye': ('fisheye_170', 'config/fisheye.yaml', 1280, 960)}
PIXEL_MM = 0.002
BLUR_PX = 0.7
LINE_ITERATIONS = 2


def _natural_spline(x: np.ndarray, y: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Evaluate the natural cubic spline through (x, y) at q."""
    n = x.size
    h = np.diff(x)
    a = np.zeros((n, n))
    rhs = np.zeros(n)
    a[0, 0] = a[-1, -1] = 1.0
    for i in range(1, n - 1):
        a[i, i - 1], a[i, i], a[i, i + 1] = h[i - 1], 2 * (h[i - 1] + h[i]), h[i]
        rhs[i] = 6 * ((y[i + 1] - y[i]) / h[i] - (y[i] - y[i - 1]) / h[i - 1])
    m = np.linalg.solve(a, rhs)
    k = np.clip(np.searchsorted(x, q) - 1, 0, n - 2)
    t = q - x[k]
    hk = h[k]
    return (m[k] * (x[k + 1] - q) ** 3 / (6 * hk) + m[k + 1] * t ** 3 / (6 * hk)
            + (y[k] / hk - m[k] * hk / 6) * (x[k + 1] - q) + (y[k + 1] / hk - m[k + 1] * hk / 6)
            * t)


class Lens:
    """The optiland chief-ray lines of one lens, as a raw pixel -> direction map."""

    def __init__(self, name: str):
        key, self.config, self.width, self.height = LENSES[name]
        curve = json.loads(DATA.read_text())['lenses'][key]['curve']
        theta = np.radians(np.asarray(curve['field_angle_deg'], dtype=float))
        height = np.abs(np.asarray(curve['real_height_mm'], dtype=float))
        lines = json.loads(SLOPES.read_text())['lenses'][key]
        if not np.allclose(np.radians(lines['field_angle_deg']), theta, rtol=0, atol=1e-12):
            raise ValueError(f'{SLOPES.name} is not traced at the curve angles of {DATA.name}')
        self.theta = np.linspace(0.0, theta[-1], 200001)
        self.h = _natural_spline(theta, height, self.theta)
        self.s = _natural_spline(theta, np.asarray(lines['slope'], dtype=float), self.theta)
        # h^-1 on a uniform grid of heights too: the tilted solve indexes both tables directly.
        self.rho = np.linspace(0.0, self.h[-1], self.theta.size)
        self.theta_of_rho = np.interp(self.rho, self.h, self.theta)
        self._frame_key: tuple | None = None
        self._frame = np.zeros((0, 3))

    def directions(self, u: np.ndarray, v: np.ndarray, offset_px: tuple[float, float],
                   tilt_deg: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """
        Return the unit direction of each raw pixel, shape (..., 3); NaN outside the field.

        :param u: raw columns.
        :param v: raw rows.
        :param offset_px: the axis pixel's offset from the sensor centre.
        :param tilt_deg: ``(tilt_x, tilt_y)``: the sensor turned about its row line through
            the axis point (rows of larger v closer to the lens), then about its turned
            column line (columns of larger u closer).
        :return: directions.
        """
        a = (u - (self.width - 1) / 2.0 - offset_px[0]) * PIXEL_MM
        b = (v - (self.height - 1) / 2.0 - offset_px[1]) * PIXEL_MM
        if tilt_deg[0] == 0.0 and tilt_deg[1] == 0.0:
            rho = np.hypot(a, b)
            theta = np.interp(rho, self.h, self.theta, right=np.nan)
            phi = np.arctan2(b, a)
            s = np.sin(theta)
            return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)
        e_u, e_v = sensor_axes(*tilt_deg)
        qx, qy = a * e_u[0] + b * e_v[0], a * e_u[1] + b * e_v[1]
        rho = np.hypot(qx, qy)
        theta = self.line_through(rho, a * e_u[2] + b * e_v[2])
        # The azimuth's cosine and sine straight from Q (the axis pixel itself: along +a).
        with np.errstate(invalid='ignore', divide='ignore'):
            scale = np.where(rho > 0.0, np.sin(theta) / rho, 0.0)
        return np.stack([qx * scale, qy * scale, np.cos(theta)], axis=-1)

    def frame(self, offset_px: tuple[float, float],
              tilt_deg: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """Return the directions of every raw pixel (read-only; the last pose is cached)."""
        key = (tuple(offset_px), tuple(tilt_deg))
        if self._frame_key != key:
            u, v = np.meshgrid(np.arange(self.width, dtype=float),
                               np.arange(self.height, dtype=float))
            self._frame = self.directions(u, v, offset_px, tilt_deg)
            self._frame.flags.writeable = False
            self._frame_key = key
        return self._frame

    def line_through(self, rho: np.ndarray, dz: np.ndarray) -> np.ndarray:
        """
        Return the field angle whose chief-ray line passes ``rho`` from the axis at ``dz``.

        Solves ``h(theta) + s(theta) dz = rho`` by the fixed point ``theta = h^-1(rho -
        s(theta) dz)`` (a contraction: ``|s' dz / h'|`` is about ``dz`` over the exit pupil's
        distance, 3e-3 here: two steps reach 1e-5 px); NaN beyond the traced field.
        """
        theta = _uniform_interp(self.rho, self.theta_of_rho, rho)
        for _ in range(LINE_ITERATIONS):
            slope = _uniform_interp(self.theta, self.s, theta)
            theta = _uniform_interp(self.rho, self.theta_of_rho, rho - slope * dz)
        return theta


def _uniform_interp(x: np.ndarray, y: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Interpolate linearly on the uniform grid x (from 0); NaN past its end, y[0] below."""
    step = x[1] - x[0]
    with np.errstate(invalid='ignore'):
        t = np.clip(q / step, 0.0, x.size - 1.0)
        k = np.minimum(t.astype(np.int64), x.size - 2)
        k[~np.isfinite(t)] = 0
        t -= k
        out = y[k] * (1.0 - t) + y[k + 1] * t
        return np.where(q <= x[-1], out, np.nan)


def sensor_axes(tilt_x_deg: float, tilt_y_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the tilted sensor's row and column directions in the read-out frame (a, b, z).

    ``z`` runs along the axis towards the sensor. tilt_x turns the column direction to
    ``(0, cos a, -sin a)`` (rows of larger v come closer to the lens) and the normal to
    ``(0, sin a, cos a)``; tilt_y then turns the row direction about the turned column line:
    ``cos b e_u - sin b n`` (columns of larger u come closer).
    """
    a, b = math.radians(tilt_x_deg), math.radians(tilt_y_deg)
    e_v = np.array([0.0, math.cos(a), -math.sin(a)])
    normal = np.array([0.0, math.sin(a), math.cos(a)])
    e_u = math.cos(b) * np.array([1.0, 0.0, 0.0]) - math.sin(b) * normal
    return e_u, e_v


def _rot(yaw_deg: float, pitch_deg: float, roll_deg: float = 0.0) -> np.ndarray:
    y, p, r = (math.radians(a) for a in (yaw_deg, pitch_deg, roll_deg))
    ry = np.array([[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]])
    rx = np.array([[1, 0, 0], [0, math.cos(p), -math.sin(p)], [0, math.sin(p), math.cos(p)]])
    rz = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
    return ry @ rx @ rz


def _ramp(dist: np.ndarray, half_width: float) -> np.ndarray:
    """Return the pixel-area coverage of |dist| < half_width (dist in px, signed)."""
    return np.clip(0.5 + (half_width - np.abs(dist)), 0.0, 1.0)


def _plane_coords(d: np.ndarray, rot: np.ndarray, distance: float) -> tuple[np.ndarray, ...]:
    """Intersect directions with the plane z' = distance of the frame rot; (s, t, hit)."""
    local = d @ rot
    with np.errstate(invalid='ignore', divide='ignore'):
        k = distance / local[..., 2]
        hit = np.isfinite(k) & (k > 0)
        return local[..., 0] * k, local[..., 1] * k, hit


def _px_dist(coord: np.ndarray, period: float, half: float) -> np.ndarray:
    """Return the distance (px) of each pixel to the nearest bar centre of a periodic grid."""
    gy, gx = np.gradient(coord)
    foot = np.hypot(gx, gy)
    wrapped = (coord + 0.5 * period) % period - 0.5 * period
    with np.errstate(invalid='ignore', divide='ignore'):
        return wrapped / foot, half / foot


def grid(lens: Lens, offset_px: tuple[float, float], yaw: float, pitch: float,
         roll: float, circles: bool = False, tilt_deg: tuple[float, float] = (0.0, 0.0),
         half_width: float = 0.08) -> np.ndarray:
    """Render a bounded grid of bars (half-width of the 0.55 period) or discs; 8-bit frame."""
    d = lens.frame(offset_px, tilt_deg)
    s, t, hit = _plane_coords(d, _rot(yaw, pitch, roll), 1.0)
    img = np.full(d.shape[:-1], 0.35)
    limit = 2.2
    inside = hit & (np.abs(s) < limit) & (np.abs(t) < limit)
    if circles:
        period = 0.9
        cs = (s + 0.5 * period) % period - 0.5 * period
        ct = (t + 0.5 * period) % period - 0.5 * period
        r = np.hypot(cs, ct)
        gy, gx = np.gradient(np.where(inside, r, 0.0))
        foot = np.hypot(gx, gy)
        with np.errstate(invalid='ignore', divide='ignore'):
            cover = np.clip(0.5 + (0.3 - r) / foot, 0.0, 1.0)
        plane = 0.85 - 0.6 * np.nan_to_num(cover)
    else:
        # The footprints from the plane's coordinates wherever the ray meets it, not only
        # inside its border: a border in the gradient's difference would shrink the bar the
        # border runs through to a light line along it (the border's edge 1.4 px off).
        ds, hs = _px_dist(np.where(hit, s, 0.0), 0.55, half_width)
        dt, ht = _px_dist(np.where(hit, t, 0.0), 0.55, half_width)
        bars = np.maximum(np.nan_to_num(_ramp(ds, hs)), np.nan_to_num(_ramp(dt, ht)))
        plane = 0.85 - 0.6 * bars
    # The plane's own border, anti-aliased (a linear ramp one footprint wide).
    box = np.where(hit, np.maximum(np.abs(s), np.abs(t)), 0.0)
    foot = np.maximum(np.hypot(*np.gradient(box)), 1e-9)
    edge = np.where(hit, np.clip(0.5 + (limit - box) / foot, 0.0, 1.0), 0.0)
    img = img * (1 - edge) + np.nan_to_num(plane) * edge
    return _finish(img, d)


def _room_sample(d: np.ndarray) -> np.ndarray:
    """Return the grey of each direction in the box room (no anti-aliasing)."""
    lo = np.array([-2.0, -1.3, -3.0])
    hi = np.array([2.6, 1.1, 3.5])
    grey = np.array([0.3, 0.5, 0.7, 0.4, 0.6, 0.8])
    best = np.full(d.shape[:-1], np.inf)
    out = np.zeros(d.shape[:-1])
    for axis in range(3):
        with np.errstate(invalid='ignore', divide='ignore'):
            for k, bound in enumerate((lo[axis], hi[axis])):
                t = bound / d[..., axis]
                ok = np.isfinite(t) & (t > 0) & (t < best)
                point = d * t[..., None]
                wall = grey[2 * axis + k]
                # A dark door / window on each wall: a rectangle in the other two axes.
                others = [a for a in range(3) if a != axis]
                p0, p1 = point[..., others[0]], point[..., others[1]]
                door = (np.abs(p0 - 0.3) < 0.6) & (np.abs(p1 + 0.2) < 0.5)
                value = np.where(door, wall - 0.22, wall)
                out = np.where(ok, value, out)
                best = np.where(ok, t, best)
    return out


def box_room(lens: Lens, offset_px: tuple[float, float], yaw: float = 20.0,
             pitch: float = -8.0, tilt_deg: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Render a box room (walls, doors), 4 x 4 supersampled at its edges; an 8-bit frame."""
    rot = _rot(yaw, pitch)
    d = lens.frame(offset_px, tilt_deg)
    img = np.nan_to_num(_room_sample(d @ rot.T))
    # Supersample only where the grey changes within a pixel's neighbourhood.
    kernel = np.ones((3, 3), np.uint8)
    spread = (cv2.dilate(img.astype(np.float32), kernel)
              - cv2.erode(img.astype(np.float32), kernel))
    rows, cols = np.nonzero(spread > 0)
    acc = np.zeros(rows.size)
    for du in (-0.375, -0.125, 0.125, 0.375):
        for dv in (-0.375, -0.125, 0.125, 0.375):
            ds = lens.directions(cols + du, rows + dv, offset_px, tilt_deg) @ rot.T
            acc += np.nan_to_num(_room_sample(ds))
    img[rows, cols] = acc / 16.0
    return _finish(img, d)


def discs(lens: Lens, offset_px: tuple[float, float], seed: int = 3) -> np.ndarray:
    """Render dark circular spots, cones of directions seen along their axes; no lines."""
    d = lens.frame(offset_px)
    rng = np.random.default_rng(seed)
    img = np.full(d.shape[:-1], 0.75)
    for _ in range(14):
        theta, phi = rng.uniform(0.0, 1.3), rng.uniform(-math.pi, math.pi)
        centre = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                           math.cos(theta)])
        angle = np.arccos(np.clip(np.nan_to_num(d @ centre), -1.0, 1.0))
        foot = np.maximum(np.hypot(*np.gradient(angle)), 1e-9)
        cover = np.clip(0.5 + (rng.uniform(0.08, 0.3) - angle) / foot, 0.0, 1.0)
        img = img * (1 - cover) + 0.25 * cover
    return _finish(img, d)


def featureless(lens: Lens, noise: float = 6.0, seed: int = 1) -> np.ndarray:
    """Return a flat frame with Gaussian noise (grey levels)."""
    rng = np.random.default_rng(seed)
    img = 120.0 + noise * rng.standard_normal((lens.height, lens.width))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _finish(img: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Black outside the field, blur, quantise to 8 bits with a little noise."""
    img = np.where(np.isfinite(d[..., 2]), img, 0.0) * 255.0
    img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), BLUR_PX)
    rng = np.random.default_rng(7)
    img = img + 0.5 * rng.standard_normal(img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


# The scene lines the renderer draws, as arcs of great circles (ground truth for the
# straightness): each line is its two end directions in the camera's optical frame.

def grid_lines(yaw: float, pitch: float, roll: float,
               half_width: float = 0.08) -> list[tuple[np.ndarray, np.ndarray]]:
    """Return the bar edges and the border of :func:`grid`'s plane as (start, end) directions."""
    rot = _rot(yaw, pitch, roll)
    limit, period = 2.2, 0.55
    coords = [k * period + sign * half_width for k in range(-4, 5) for sign in (-1.0, 1.0)]
    coords = [c for c in coords if abs(c) < limit] + [-limit, limit]
    lines = []
    for c in coords:
        for swap in (False, True):
            ends = [(c, t) if not swap else (t, c) for t in (-limit, limit)]
            lines.append(tuple(rot @ np.array([s, t, 1.0]) for s, t in ends))
    return [(a / np.linalg.norm(a), b / np.linalg.norm(b)) for a, b in lines]


def room_lines(yaw: float = 20.0, pitch: float = -8.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Return the box room's wall-to-wall edges and its doors' edges (:func:`box_room`)."""
    rot = _rot(yaw, pitch)
    lo = np.array([-2.0, -1.3, -3.0])
    hi = np.array([2.6, 1.1, 3.5])
    segments = []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        for va in (lo[a], hi[a]):
            for vb in (lo[b], hi[b]):
                p, q = np.zeros(3), np.zeros(3)
                p[a], p[b], q[a], q[b] = va, vb, va, vb
                p[axis], q[axis] = lo[axis], hi[axis]
                segments.append((p, q))
        for bound in (lo[axis], hi[axis]):
            # The door of this wall: |p0 - 0.3| < 0.6, |p1 + 0.2| < 0.5 (_room_sample).
            e0 = (-0.3, 0.9)
            e1 = (-0.7, 0.3)
            corners = [(e0[0], e1[0]), (e0[1], e1[0]), (e0[1], e1[1]), (e0[0], e1[1])]
            for k in range(4):
                p, q = np.zeros(3), np.zeros(3)
                p[axis] = q[axis] = bound
                (p[a], p[b]), (q[a], q[b]) = corners[k], corners[(k + 1) % 4]
                segments.append((p, q))
    # Room coordinates are rot @ (camera direction): a camera direction is rot^T @ room.
    out = []
    for p, q in segments:
        dp, dq = rot.T @ p, rot.T @ q
        out.append((dp / np.linalg.norm(dp), dq / np.linalg.norm(dq)))
    return out


def raw_pixels(lens: Lens, dirs: np.ndarray, offset_px: tuple[float, float]) -> np.ndarray:
    """Return the raw pixel (u, v) of each direction (untilted sensor); NaN outside the field."""
    theta = np.arccos(np.clip(dirs[..., 2], -1.0, 1.0))
    rho = np.interp(theta, lens.theta, lens.h, right=np.nan) / PIXEL_MM
    phi = np.arctan2(dirs[..., 1], dirs[..., 0])
    return np.stack([(lens.width - 1) / 2.0 + offset_px[0] + rho * np.cos(phi),
                     (lens.height - 1) / 2.0 + offset_px[1] + rho * np.sin(phi)], axis=-1)


def assign_to_lines(lens: Lens, offset_px: tuple[float, float], points: np.ndarray,
                    lines: list[tuple[np.ndarray, np.ndarray]], tol_px: float = 1.0,
                    clear_px: float = 3.0) -> np.ndarray:
    """
    Return the known line each raw edge point lies on (-1: none, or two lines are near).

    A point belongs to line L when its true direction lies within L's arc and its raw px
    distance from L's image (the foot on the great circle, carried back to raw px) is under
    ``tol_px``, and no other line's image is within ``clear_px``.

    :param lens: the renderer's lens.
    :param offset_px: the true axis offset.
    :param points: ``(N, 2)`` raw points.
    :param lines: (start, end) directions.
    :return: ``(N,)`` line numbers.
    """
    d = lens.directions(points[:, 0], points[:, 1], offset_px)
    dist = np.full((points.shape[0], len(lines)), np.inf)
    for k, (a, b) in enumerate(lines):
        n = np.cross(a, b)
        n /= np.linalg.norm(n)
        along = (np.cross(a, d) @ n >= 0.0) & (np.cross(d, b) @ n >= 0.0)
        foot = d - (d @ n)[:, None] * n
        foot /= np.linalg.norm(foot, axis=1, keepdims=True)
        gap = np.hypot(*(raw_pixels(lens, foot, offset_px) - points).T)
        dist[:, k] = np.where(along & np.isfinite(gap), gap, np.inf)
    order = np.argsort(dist, axis=1)
    best = np.take_along_axis(dist, order[:, :1], axis=1)[:, 0]
    second = (np.take_along_axis(dist, order[:, 1:2], axis=1)[:, 0] if len(lines) > 1
              else np.full(best.shape, np.inf))
    return np.where((best < tol_px) & (second > clear_px), order[:, 0], -1)


def whole_line_rms(model: object, points: np.ndarray, line: np.ndarray,
                   min_points: int = 24) -> float:
    """
    Return the RMS distance of points from their whole known line, px of the corrected image.

    The measure of docs/design.md section 2.17 with the grouping known: a pinhole output
    fits each line's corrected pixels a total-least-squares line; an equidistant one takes
    the angle from each line's best great circle times the output focal length. Written
    here from those words (the package's :func:`directions_of` only carries the points).

    :param model: the description under test.
    :param points: ``(N, 2)`` raw edge points.
    :param line: ``(N,)`` their line numbers (-1: none).
    :param min_points: lines with fewer points are left out.
    :return: RMS px.
    """
    from mechdeconv_ros.model.projection import directions_of
    dirs = directions_of(model, points)
    k = model.K_new
    f = float(np.sqrt(k[0, 0] * k[1, 1]))
    squares = []
    for label in np.unique(line[line >= 0]):
        d = dirs[(line == label) & np.all(np.isfinite(dirs), axis=1)]
        if model.projection == 'pinhole':
            d = d[d[:, 2] > 0.02]
            xy = np.stack([k[0, 0] * d[:, 0] / d[:, 2] + k[0, 2],
                           k[1, 1] * d[:, 1] / d[:, 2] + k[1, 2]], axis=1)
            xy = xy[(xy[:, 0] >= 0) & (xy[:, 1] >= 0) & (xy[:, 0] <= model.out_width - 1)
                    & (xy[:, 1] <= model.out_height - 1)]
            if xy.shape[0] < min_points:
                continue
            centred = xy - xy.mean(axis=0)
            normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
            squares.append((centred @ normal) ** 2)
        else:
            if d.shape[0] < min_points:
                continue
            normal = np.linalg.eigh(d.T @ d)[1][:, 0]
            squares.append((d @ normal * f) ** 2)
    return float(np.sqrt(np.mean(np.concatenate(squares)))) if squares else float('nan')


#: The kinds of frame a real camera sends (:func:`as_sent`).
KINDS = ('jpeg80', 'bayer', 'motion3', 'mono16_10bit', 'mono16_12bit', 'dim20')


def half_size(frame: np.ndarray) -> np.ndarray:
    """Return a frame at half the size (2 x 2 pixel means: a sensor of twice the pitch)."""
    h, w = frame.shape[:2]
    return cv2.resize(frame, (w // 2, h // 2), interpolation=cv2.INTER_AREA)


def as_sent(frame: np.ndarray, kind: str, seed: int = 0) -> np.ndarray:
    """
    Return an 8-bit grey render as a real camera would send it.

    ``jpeg80``: JPEG at quality 80, decoded; ``bayer``: a tinted colour frame (R 0.9, B 0.7
    of the grey) mosaicked RGGB and demosaiced by OpenCV (BGR); ``motion3``: a 3 px
    horizontal box blur; ``mono16_10bit`` and ``mono16_12bit``: uint16 up to 1023 and
    4095 with the sensor's own noise (1 LSB); ``dim20``: scaled to a mean of 20 grey levels,
    noise 0.5 level, 8 bits.
    """
    rng = np.random.default_rng(seed)
    grey = frame.astype(np.float64)
    if kind == 'jpeg80':
        ok, data = cv2.imencode('.jpg', frame, [cv2.IMWRITE_JPEG_QUALITY, 80])
        return cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if kind == 'bayer':
        bgr = np.stack([0.7 * grey, grey, 0.9 * grey], axis=-1)
        mosaic = np.empty(grey.shape)
        mosaic[0::2, 0::2] = bgr[0::2, 0::2, 2]
        mosaic[0::2, 1::2] = bgr[0::2, 1::2, 1]
        mosaic[1::2, 0::2] = bgr[1::2, 0::2, 1]
        mosaic[1::2, 1::2] = bgr[1::2, 1::2, 0]
        raw = np.clip(np.rint(mosaic), 0, 255).astype(np.uint8)
        return cv2.cvtColor(raw, cv2.COLOR_BayerRG2BGR)
    if kind == 'motion3':
        return cv2.blur(frame, (3, 1))
    if kind in ('mono16_10bit', 'mono16_12bit'):
        top = 1023.0 if kind == 'mono16_10bit' else 4095.0
        value = grey * top / 255.0 + rng.standard_normal(grey.shape)
        return np.clip(np.rint(value), 0, top).astype(np.uint16)
    if kind == 'dim20':
        value = grey * 20.0 / max(float(grey.mean()), 1e-9)
        value += 0.5 * rng.standard_normal(grey.shape)
        return np.clip(np.rint(value), 0, 255).astype(np.uint8)
    raise ValueError(f'unknown kind {kind}')
