# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Plumb lines: raw edge points to scene directions, great-circle fits, straightness.

Pure numpy, no ROS. A straight line of the scene and the projection centre span a plane, so
the directions a central camera sees along it lie on a great circle of the unit sphere
(Devernay & Faugeras 2001, "Straight lines have to be straight", on the sphere so that a
fisheye past 90 deg is no special case). The check maps edge points of the raw frame through
the model's exact inverse to directions, fits to each chain the plane through the origin
that minimises the sum of squared sines ``(n . d)^2`` (``n`` the eigenvector of the smallest
eigenvalue of ``sum d d^T``), and reads the residuals.

The inverse for any assembly (:class:`ChiefLines`) is the projection's
(:meth:`mechdeconv_ros.model.projection.LineTable.directions_and_scales`: the same sensor
geometry, :mod:`mechdeconv_ros.optics.pose`, on a dense table of the chief-ray lines ``h``,
``s`` with Newton, for many points). The pose vector ``p = (dx, dy, alpha, beta, dz)`` is the
sensor's ``(sensor.axis_offset_x_mm, _y_mm, sensor.tilt_x_deg, _y_deg)`` (docs/design.md
section 1.1: the axis pixel ``((W - 1) / 2 + dx / p_x, (H - 1) / 2 + dy / p_y)``, the plane
turned by ``T = R_x(-alpha) R_y(beta)``) and a defocus ``dz`` along the axis from ``z_s`` (mm,
> 0 away from the lens). The direction is ``(sin theta cos phi, sin theta sin phi, cos theta)``
in the camera's optical frame (X right, Y down, Z ahead).

Straightness in px of the corrected image: for a ``pinhole`` output, the points' corrected
pixels (``x = f_x X / Z + c_x``, within the image) get a total-least-squares line each and
the distances from it are read; for ``equidistant`` (a fisheye, where the corrected image
bends scene lines) the great-circle residual angle times the output focal length (px per rad
at the centre of the corrected image).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

from mechdeconv_ros.model.projection import LineTable
from mechdeconv_ros.optics.pose import SensorPose
import numpy as np
import numpy.typing as npt

#: A chain is cut where it leaves a great circle by more than this (px at the output focal
#: length) or this fraction of its length, whichever is larger.
SPLIT_PX = 1.5
SPLIT_FRACTION = 0.006
#: Shortest straight edge kept, px (its chord at the output focal length).
MIN_EDGE_PX = 48.0
#: Shortest piece kept as part of a longer line (px, its chord): between crossings near the
#: periphery a line's pieces are short, and its bend is largest there.
MIN_PIECE_PX = 12.0
#: Fewest raw points of a straight edge.
MIN_EDGE_POINTS = 24
#: At most this many points per edge enter the fits (evenly spaced along the edge).
MAX_POINTS_PER_EDGE = 160
#: The field coverage counts the cells of a COVERAGE_CELLS x COVERAGE_CELLS grid over the raw
#: frame (those inside the lens's field) that hold points of a straight edge.
COVERAGE_CELLS = 8

Points = npt.NDArray[np.float64]


@dataclass
class ChiefLines:
    """The model's chief-ray lines on a dense table, and the raw frame's geometry."""

    table: LineTable
    width: int
    height_px: int
    pixel_mm: tuple[float, float]

    @classmethod
    def from_model(cls, model: Any) -> ChiefLines:
        """
        Tabulate a :class:`~mechdeconv_ros.model.model.LensModel`'s field trace.

        :param model: the lens model.
        :return: the table (:meth:`~mechdeconv_ros.model.projection.LineTable.of`).
        """
        return cls(LineTable.of(model), model.width, model.height, model.pixel_mm)

    def directions(self, points: Points, pose: npt.NDArray[np.float64]) -> Points:
        """
        Return the unit scene directions raw pixels see under a sensor pose.

        :param points: ``(N, 2)`` raw (x, y).
        :param pose: ``(dx_mm, dy_mm, alpha_deg, beta_deg, dz_mm)``.
        :return: ``(N, 3)``; NaN outside the traced field.
        """
        return self.directions_and_scales(points, pose)[0]

    def directions_and_scales(self, points: Points, pose: npt.NDArray[np.float64]
                              ) -> tuple[Points, Points, Points]:
        """
        Return the directions and, at each, the raw px per rad under the same pose.

        Taken at the pose being judged, so a pose that shrinks the angle a raw pixel spans
        does not shrink the edges' raw noise with it (docs/design.md section 2.17).

        :param points: ``(N, 2)`` raw (x, y).
        :param pose: ``(dx_mm, dy_mm, alpha_deg, beta_deg, dz_mm)``.
        :return: ``(directions (N, 3), radial (N,), tangential (N,))``; NaN outside the field
            (:meth:`~mechdeconv_ros.model.projection.LineTable.directions_and_scales`).
        """
        sensor = SensorPose(float(pose[0]), float(pose[1]), math.radians(pose[2]),
                            math.radians(pose[3]))
        return self.table.directions_and_scales(sensor, points, (self.width, self.height_px),
                                                self.pixel_mm, float(pose[4]))


def edge_index(edges: list[Points]) -> npt.NDArray[np.int64]:
    """Return the edge number of each point of the concatenated edges."""
    return np.repeat(np.arange(len(edges)), [e.shape[0] for e in edges])


def great_circles(dirs: Points, index: npt.NDArray[np.int64], count: int
                  ) -> tuple[Points, Points]:
    """
    Fit a plane through the origin to the directions of each edge.

    :param dirs: ``(N, 3)`` unit directions (finite).
    :param index: ``(N,)`` edge number of each.
    :param count: number of edges.
    :return: ``(normals (count, 3), residuals (N,))``, residual = ``n . d`` (sine of the
        angle from the great circle).
    """
    scatter = np.zeros((count, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            value = np.bincount(index, dirs[:, i] * dirs[:, j], minlength=count)
            scatter[:, i, j] = value
            scatter[:, j, i] = value
    _, vectors = np.linalg.eigh(scatter)
    normals = vectors[:, :, 0]
    return normals, np.einsum('ij,ij->i', normals[index], dirs)


def _cut(dirs: Points, tol_px: float, f_px: float, out: list[tuple[int, int, bool]],
         start: int) -> None:
    """Cut an ordered run of directions into great-circle pieces (recursive; long or not)."""
    n = dirs.shape[0]
    if n < 8:
        return
    chord = math.acos(float(np.clip(dirs[0] @ dirs[-1], -1.0, 1.0))) * f_px
    if chord < MIN_PIECE_PX:
        return
    _, res = great_circles(dirs, np.zeros(n, dtype=np.int64), 1)
    worst = int(np.argmax(np.abs(res)))
    if abs(res[worst]) * f_px <= max(tol_px, SPLIT_FRACTION * chord):
        out.append((start, start + n, chord >= MIN_EDGE_PX))
        return
    cut = worst if n // 8 < worst < n - n // 8 else n // 2
    _cut(dirs[:cut], tol_px, f_px, out, start)
    _cut(dirs[cut:], tol_px, f_px, out, start + cut)


def line_pieces(chains: list[Points], lines: ChiefLines, pose: npt.NDArray[np.float64],
                f_px: float) -> tuple[list[Points], list[Points]]:
    """
    Return the pieces of raw chains that are straight in the scene under a pose, all points.

    :param chains: ordered raw chains (:func:`~mechdeconv_ros.imaging.straight_edges.
        detect_chains`).
    :param lines: the inverse.
    :param pose: the pose the pieces are judged with (the description's).
    :param f_px: output focal length, px per rad.
    :return: ``(edges, short)``: the straight edges (chord at least ``MIN_EDGE_PX``, at least
        ``MIN_EDGE_POINTS`` points) and the shorter straight pieces (chord at least
        ``MIN_PIECE_PX``), raw points in chain order; a short piece only counts as part of a
        line that has an edge (:mod:`~mechdeconv_ros.imaging.scene_lines`).
    """
    edges, short = [], []
    if not chains:
        return edges, short
    # One inverse for all the chains (its tables' derivatives are made per call).
    every = lines.directions(np.concatenate([np.asarray(c) for c in chains]), pose)
    for chain, dirs in zip(chains, np.split(every, np.cumsum([c.shape[0] for c in chains])[:-1])):
        good = np.all(np.isfinite(dirs), axis=1)
        chain, dirs = chain[good], dirs[good]
        pieces: list[tuple[int, int, bool]] = []
        _cut(dirs, SPLIT_PX, f_px, pieces, 0)
        for lo, hi, long in pieces:
            if long and hi - lo >= MIN_EDGE_POINTS:
                edges.append(chain[lo:hi])
            else:
                short.append(chain[lo:hi])
    return edges, short


def thin(piece: Points, count: int = MAX_POINTS_PER_EDGE) -> Points:
    """Return at most ``count`` points of a piece, evenly spaced along it (ends kept)."""
    if piece.shape[0] <= count:
        return piece
    pick = np.linspace(0, piece.shape[0] - 1, count).round().astype(np.int64)
    return piece[pick]


def straight_edges(chains: list[Points], lines: ChiefLines, pose: npt.NDArray[np.float64],
                   f_px: float) -> list[Points]:
    """
    Return the straight edges of raw chains under a pose, thinned for the fits.

    :param chains: ordered raw chains.
    :param lines: the inverse.
    :param pose: the pose the pieces are judged with (the description's).
    :param f_px: output focal length, px per rad.
    :return: raw point arrays, each thinned to at most ``MAX_POINTS_PER_EDGE`` points.
    """
    return [thin(edge) for edge in line_pieces(chains, lines, pose, f_px)[0]]


def output_focal_px(model: Any) -> float:
    """Return the corrected image's focal length (geometric mean of fx, fy), px."""
    return float(math.sqrt(model.K_new[0, 0] * model.K_new[1, 1]))


def straightness_px(model: Any, dirs: Points, index: npt.NDArray[np.int64], count: int
                    ) -> tuple[float, float, Points]:
    """
    Return the RMS and largest distance from the fitted lines, px of the corrected image.

    :param model: the lens model (its output projection, K_new and size).
    :param dirs: ``(N, 3)`` finite directions.
    :param index: edge number of each.
    :param count: number of edges.
    :return: ``(rms, max, per-edge rms)``; NaN when no edge has points.
    """
    if model.projection != 'pinhole':
        _, res = great_circles(dirs, index, count)
        dist = np.abs(res) * output_focal_px(model)
    else:
        cos_limit = math.cos(math.radians(89.0))
        with np.errstate(invalid='ignore', divide='ignore'):
            x = model.K_new[0, 0] * dirs[:, 0] / dirs[:, 2] + model.K_new[0, 2]
            y = model.K_new[1, 1] * dirs[:, 1] / dirs[:, 2] + model.K_new[1, 2]
        keep = ((dirs[:, 2] > cos_limit) & (x >= 0) & (y >= 0)
                & (x <= model.out_width - 1) & (y <= model.out_height - 1))
        keep &= np.bincount(index[keep], minlength=count)[index] >= 3
        x, y, index = x[keep], y[keep], index[keep]
        if index.size == 0:
            return math.nan, math.nan, np.full(count, np.nan)
        n = np.maximum(np.bincount(index, minlength=count), 1)
        mx = np.bincount(index, x, count) / n
        my = np.bincount(index, y, count) / n
        dx, dy = x - mx[index], y - my[index]
        sxx = np.bincount(index, dx * dx, count)
        syy = np.bincount(index, dy * dy, count)
        sxy = np.bincount(index, dx * dy, count)
        # The normal of the TLS line: the eigenvector of the smaller eigenvalue.
        angle = 0.5 * np.arctan2(2.0 * sxy, sxx - syy) + 0.5 * math.pi
        dist = np.abs(dx * np.cos(angle[index]) + dy * np.sin(angle[index]))
    per_edge = np.sqrt(np.bincount(index, dist ** 2, count)
                       / np.maximum(np.bincount(index, minlength=count), 1))
    if dist.size == 0:
        return math.nan, math.nan, per_edge
    return float(np.sqrt(np.mean(dist ** 2))), float(dist.max()), per_edge


def field_coverage(lines: ChiefLines, pose: npt.NDArray[np.float64], points: Points) -> float:
    """
    Return the fraction of the field's cells that hold edge points.

    :param lines: the inverse (its raw frame size and field).
    :param pose: the pose that decides which cells are inside the field.
    :param points: ``(N, 2)`` raw points of the straight edges.
    :return: 0..1.
    """
    n = COVERAGE_CELLS
    cx = (np.arange(n) + 0.5) * lines.width / n - 0.5
    cy = (np.arange(n) + 0.5) * lines.height_px / n - 0.5
    grid = np.stack(np.meshgrid(cx, cy), axis=-1).reshape(-1, 2)
    inside = np.all(np.isfinite(lines.directions(grid, pose)), axis=1)
    if points.size == 0 or not inside.any():
        return 0.0
    col = np.clip((points[:, 0] + 0.5) * n / lines.width, 0, n - 1).astype(np.int64)
    row = np.clip((points[:, 1] + 0.5) * n / lines.height_px, 0, n - 1).astype(np.int64)
    hit = np.zeros(n * n, dtype=bool)
    hit[row * n + col] = True
    return float(np.count_nonzero(hit & inside) / np.count_nonzero(inside))
