# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Edge chains for the plumb-line check: sub-pixel edge points, linked, cut at junctions.

Pure OpenCV and numpy, no ROS. Works on any single frame (raw or corrected); the geometry
(which chains are straight in the scene) is :mod:`mechdeconv_ros.imaging.plumb_lines`.

1. The frame, as 8-bit-range float grey at its own depth and contrast (:func:`grey`: 10-,
   12- and 16-bit data scaled from its bits, a dim frame brightened), is smoothed by a
   Gaussian of ``EDGE_SIGMA_PX`` and differentiated by 3x3 Sobel kernels (gx, gy); Canny (L2
   gradient, hysteresis
   ``CANNY_LOW`` / ``CANNY_HIGH`` in Sobel units, i.e. 8x the grey step per pixel of the
   smoothed frame) keeps the one-pixel-wide ridge of the gradient magnitude ``g``.
2. Sub-pixel position: along the unit gradient ``n`` the parabola through ``g`` at the
   pixel and one pixel either side (bilinear samples) has its vertex at
   ``d = (g- - g+) / (2 (g- - 2 g0 + g+))``, ``|d| <= 0.5``; the point is ``p + d n``
   (Devernay 1995, along the gradient rather than the nearer axis).
3. Chains: a ridge pixel whose 8-neighbourhood holds three or more separate runs of ridge
   pixels (the crossing number) is a junction (a T, an X), one whose unit gradient turns by
   more than ``CORNER_DEG`` to a ridge neighbour's is a corner (an L: the outline of a
   rectangle would otherwise be one closed chain), and both are dropped with their
   neighbours; the rest are split into 8-connected components, each a simple curve. The
   points of a chain are ordered along its principal axis (the chains are arcs of less than
   a half turn after the split of :mod:`~mechdeconv_ros.imaging.plumb_lines`), in the
   direction that has the gradient (dark to light) on its left, ``t_x g_y - t_y g_x > 0``
   (x right, y down): the order carries the edge's polarity, which
   :mod:`~mechdeconv_ros.imaging.scene_lines` uses to keep the two sides of a bar apart.

Sign conventions: pixel (x, y) = (column, row) with the centre of the top-left pixel at
(0, 0), as OpenCV's remap maps.
"""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np
import numpy.typing as npt

#: A frame whose BRIGHT_PERCENTILE is below BRIGHT_LEVEL (8-bit range) is scaled up to it, by
#: at most MAX_GAIN (:func:`grey`): a dim frame's edges are as strong as a normal one's.
BRIGHT_PERCENTILE = 99.0
BRIGHT_LEVEL = 128.0
MAX_GAIN = 16.0
#: Gaussian smoothing before the gradient, px (sigma).
EDGE_SIGMA_PX = 1.0
#: Canny hysteresis thresholds on the L2 Sobel gradient (3x3 kernel: 8 x grey step / px).
CANNY_LOW = 24.0
CANNY_HIGH = 64.0
#: Grey level (8-bit range) below which a pixel is black: outside the image circle or the
#: corrected field. Ridges near black are its border, not the scene's.
DARK_LEVEL = 6.0
#: A ridge pixel whose unit gradient differs from a ridge neighbour's by more than this, deg,
#: is a corner (of a rectangle's outline: an L, which the crossing number does not see) and
#: is cut like a junction. Along a smooth edge neighbours differ by a degree or two.
CORNER_DEG = 30.0
#: Points dropped at each end of a chain (rounded corners where it met a junction).
TRIM_POINTS = 4
#: A chain shorter than this many ridge pixels is dropped (too short to tell a curve).
MIN_CHAIN_POINTS = 24

Points = npt.NDArray[np.float64]

#: Each call of :func:`detect_chains` tags its chains with the next number (their frame).
_FRAMES = itertools.count()


class FrameChain(np.ndarray):
    """
    An edge chain (``(N, 2)`` float points) that knows the frame it was found in.

    ``frame`` is a number unique to one call of :func:`detect_chains`; slices and copies keep
    it, so pieces of a chain pooled with other frames' (the node's window, several images)
    still say where they came from: lines are grouped within one frame
    (:mod:`~mechdeconv_ros.imaging.scene_lines`).
    """

    frame: int | None

    def __array_finalize__(self, obj: object) -> None:
        """Keep the frame of the array this one is made from."""
        self.frame = getattr(obj, 'frame', None)


def tagged(points: np.ndarray, frame: int | None) -> FrameChain:
    """
    Return points as a :class:`FrameChain` of a frame.

    :param points: ``(N, 2)``.
    :param frame: the frame's number (None: unknown).
    :return: a view of the points.
    """
    out = np.asarray(points).view(FrameChain)
    out.frame = frame
    return out


def frame_of(points: np.ndarray) -> int | None:
    """Return the frame number of a chain or piece (None: untagged)."""
    return getattr(points, 'frame', None)


def grey(image: np.ndarray) -> npt.NDArray[np.float32]:
    """
    Return the frame as float32 grey in the 8-bit range, at its depth and contrast.

    Integer data wider than 8 bits (``mono16`` of a 10-, 12- or 16-bit sensor) is scaled by
    ``255 / (2^b - 1)``, ``b`` the bits its largest value needs (at least 8); then a dim
    frame is brightened so that its ``BRIGHT_PERCENTILE`` reaches ``BRIGHT_LEVEL`` (a gain of
    at most ``MAX_GAIN``, never below 1): the edge thresholds are relative to the frame's
    contrast, not to full scale.

    :param image: ``(H, W)`` or ``(H, W, C)`` (C = 3 or 4, BGR order), uint8, uint16 or float
        (8-bit range).
    :return: ``(H, W)`` float32.
    """
    img = np.asarray(image)
    out = (img[..., :3].astype(np.float32).mean(axis=2) if img.ndim == 3
           else img.astype(np.float32))
    if np.issubdtype(img.dtype, np.integer) and img.dtype.itemsize > 1 and img.size:
        bits = max(8, int(img.max()).bit_length())
        out *= np.float32(255.0 / (2.0 ** bits - 1.0))
    if out.size:
        bright = float(np.percentile(out[::4, ::4], BRIGHT_PERCENTILE))
        gain = min(max(BRIGHT_LEVEL / max(bright, 1e-6), 1.0), MAX_GAIN)
        if gain > 1.0:
            out *= np.float32(gain)
    return out


def _crossing_number(ridge: npt.NDArray[np.uint8]) -> npt.NDArray[np.int32]:
    """Return, per pixel, how many separate runs of ridge pixels surround it (0..4)."""
    padded = np.pad(ridge, 1)
    h, w = ridge.shape
    ring = [(0, 1), (0, 2), (1, 2), (2, 2), (2, 1), (2, 0), (1, 0), (0, 0)]
    values = [padded[r:r + h, c:c + w].astype(np.int32) for r, c in ring]
    count = np.zeros((h, w), dtype=np.int32)
    for k in range(8):
        count += (values[k] == 0) & (values[(k + 1) % 8] == 1)
    return count


def _corners(ridge: npt.NDArray[np.uint8], gx: np.ndarray, gy: np.ndarray
             ) -> npt.NDArray[np.bool_]:
    """Return the ridge pixels whose gradient turns by over ``CORNER_DEG`` to a neighbour."""
    h, w = ridge.shape
    rows, cols = np.nonzero(ridge)
    out = np.zeros((h, w), dtype=bool)
    if rows.size == 0:
        return out
    mag = np.maximum(np.hypot(gx[rows, cols], gy[rows, cols]), 1e-9)
    ux, uy = gx[rows, cols] / mag, gy[rows, cols] / mag
    # The unit gradient of every ridge pixel, 0 elsewhere (only ridge pixels are read).
    field = np.zeros((h + 2, w + 2, 2), dtype=np.float32)
    field[rows + 1, cols + 1, 0], field[rows + 1, cols + 1, 1] = ux, uy
    limit = math.cos(math.radians(CORNER_DEG))
    corner = np.zeros(rows.size, dtype=bool)
    for dr, dc in ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)):
        near = field[rows + 1 + dr, cols + 1 + dc]
        on = (near[:, 0] != 0.0) | (near[:, 1] != 0.0)
        corner |= on & (ux * near[:, 0] + uy * near[:, 1] < limit)
    out[rows[corner], cols[corner]] = True
    return out


def detect_chains(image: np.ndarray, valid: npt.NDArray[np.bool_] | None = None
                  ) -> list[Points]:
    """
    Return the sub-pixel edge chains of a frame, each ``(N, 2)`` (x, y), ordered.

    :param image: the frame (see :func:`grey`).
    :param valid: optional mask of the pixels that hold image (False: black outside the
        image circle or the corrected field); ridges within 4 px of its border, or of a
        black (below ``DARK_LEVEL``) region, are dropped.
    :return: the chains with at least ``MIN_CHAIN_POINTS`` points, tagged with one new frame
        number (:class:`FrameChain`).
    """
    g = cv2.GaussianBlur(grey(image), (0, 0), EDGE_SIGMA_PX)
    lit = g > DARK_LEVEL
    valid = lit if valid is None else (valid & lit)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)
    ridge = cv2.Canny(np.clip(np.rint(gx), -32767, 32767).astype(np.int16),
                      np.clip(np.rint(gy), -32767, 32767).astype(np.int16),
                      CANNY_LOW, CANNY_HIGH, L2gradient=True)
    ridge = (ridge > 0).astype(np.uint8)
    ridge[:2, :] = 0
    ridge[-2:, :] = 0
    ridge[:, :2] = 0
    ridge[:, -2:] = 0
    ridge &= cv2.erode(valid.astype(np.uint8), np.ones((9, 9), np.uint8))
    junction = ((_crossing_number(ridge) >= 3) | _corners(ridge, gx, gy)) & (ridge > 0)
    if junction.any():
        ridge[cv2.dilate(junction.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0] = 0
    count, labels = cv2.connectedComponents(ridge, connectivity=8)
    if count <= 1:
        return []
    rows, cols = np.nonzero(labels)
    lab = labels[rows, cols]
    mag = np.hypot(gx, gy)
    # Sub-pixel offset along the unit gradient n: the parabola through g(p - n), g(p),
    # g(p + n) (bilinear samples).
    g_zero = mag[rows, cols].astype(np.float64)
    nx = gx[rows, cols] / np.maximum(g_zero, 1e-9)
    ny = gy[rows, cols] / np.maximum(g_zero, 1e-9)
    g_minus = _bilinear(mag, cols - nx, rows - ny)
    g_plus = _bilinear(mag, cols + nx, rows + ny)
    curvature = g_minus - 2.0 * g_zero + g_plus
    with np.errstate(invalid='ignore', divide='ignore'):
        offset = np.where(curvature < 0.0, 0.5 * (g_minus - g_plus) / curvature, 0.0)
    offset = np.clip(offset, -0.5, 0.5)
    x = cols + offset * nx
    y = rows + offset * ny
    order = np.argsort(lab, kind='stable')
    lab, x, y, nx, ny = lab[order], x[order], y[order], nx[order], ny[order]
    bounds = np.flatnonzero(np.diff(lab)) + 1
    chains = []
    frame = next(_FRAMES)
    for xs, ys, gxs, gys in zip(*(np.split(a, bounds) for a in (x, y, nx, ny))):
        if xs.size < MIN_CHAIN_POINTS + 2 * TRIM_POINTS:
            continue
        pts = order_along(np.stack([xs, ys], axis=1).astype(np.float64))
        # The polarity in the order: the gradient (dark to light) on the left of the travel
        # direction (x right, y down: t_x g_y - t_y g_x > 0), so that pieces of one scene
        # edge run the same way and the two sides of a bar run opposite ways.
        travel = pts[-1] - pts[0]
        if travel[0] * float(np.mean(gys)) - travel[1] * float(np.mean(gxs)) < 0.0:
            pts = pts[::-1]
        chains.append(tagged(pts[TRIM_POINTS:-TRIM_POINTS], frame))
    return chains


def _bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Sample an image bilinearly at (x, y) (inside by at least one pixel)."""
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    return ((1 - fx) * (1 - fy) * img[y0, x0] + fx * (1 - fy) * img[y0, x0 + 1]
            + (1 - fx) * fy * img[y0 + 1, x0] + fx * fy * img[y0 + 1, x0 + 1])


def order_along(points: Points) -> Points:
    """
    Order points along their principal axis (the chord of an arc of less than a half turn).

    :param points: ``(N, 2)``.
    :return: the same points, sorted.
    """
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    return points[np.argsort(centred @ vt[0], kind='stable')]


def sample_map(map_x: np.ndarray, map_y: np.ndarray, points: Points) -> Points:
    """
    Bilinearly sample a remap's maps at sub-pixel points of the corrected image.

    :param map_x: ``(H, W)`` float raw x of each corrected pixel (cv2.remap's map1).
    :param map_y: ``(H, W)`` float raw y.
    :param points: ``(N, 2)`` corrected (x, y).
    :return: ``(N, 2)`` raw (x, y); NaN outside the maps or where they are invalid.
    """
    h, w = map_x.shape
    x, y = points[:, 0], points[:, 1]
    x0 = np.clip(np.floor(x).astype(np.int64), 0, w - 2)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, h - 2)
    fx, fy = x - x0, y - y0
    out = np.empty_like(points)
    for k, m in enumerate((map_x, map_y)):
        m = m.astype(np.float64)
        out[:, k] = ((1 - fx) * (1 - fy) * m[y0, x0] + fx * (1 - fy) * m[y0, x0 + 1]
                     + (1 - fx) * fy * m[y0 + 1, x0] + fx * fy * m[y0 + 1, x0 + 1])
    bad = (x < 0) | (y < 0) | (x > w - 1) | (y > h - 1) | (out[:, 0] < -1e3) | (out[:, 1] < -1e3)
    out[bad] = np.nan
    return out
