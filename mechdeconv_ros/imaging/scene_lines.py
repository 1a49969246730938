# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Scene lines: the straight edges that are pieces of one line of the scene, grouped.

Pure numpy, no ROS. A chain of edge points is cut where it crosses another edge (a junction)
or leaves its great circle (:mod:`~mechdeconv_ros.imaging.plumb_lines`), so one line of the
scene (a bar of a grid crossed by the other bars, a wall edge behind a lamp) arrives as
several pieces. Judged piece by piece, a description that bends the whole line by pixels
reads a fraction of a pixel: each short piece fits its own great circle. So the pieces are
grouped into lines first and each line is judged whole (docs/design.md section 2.17).

Under the description's pose, within one frame
(:class:`~mechdeconv_ros.imaging.straight_edges.FrameChain`: the node pools the chains of
``check.window`` frames, and a moving camera's frames hold different lines), by union-find
over the straight edges, two lines A and B (at first one edge each) join when an edge a of A
and an edge b of B

1. run the same way: their normals, signed so that ``n . (d_first x d_last) > 0`` (the chain
   order carries the polarity, dark to light on the left:
   :mod:`~mechdeconv_ros.imaging.straight_edges`), agree within ``MERGE_ANGLE_DEG``: the two
   sides of a bar (opposite polarity) never join;
2. fit one great circle together: the largest residual angle of ``a u b`` times the output
   focal length ``f`` (px per rad) is at most ``max(MERGE_PX, PIECE_FRACTION x (chord(a) +
   chord(b)))``, chords of the pieces themselves (the gap between them adds no room:
   neighbours along a bent line join, its far pieces join through them, and two lines far
   apart on nearly one circle do not);

and A and B, whole,

3. fit one great circle: largest residual at most ``max(MERGE_PX, MERGE_FRACTION x chord(A
   u B))`` (lines crossing at a small angle fit one circle near the crossing, not whole);
4. lie side by side along it: a frame sees a line once, so no piece of A overlaps a piece of
   B along the common circle by more than ``OVERLAP_PX`` (lines that cross or converge do).

A short piece (12 to 48 px) joins the one line with an edge it fits within ``MERGE_PX`` (1,
2 with no fraction) and 4; a line of short pieces alone is none. The bounds are in px at the
centre scale of the output: a bend of more than about 3.5 px RMS splits some lines (measured:
docs/design.md section 2.17), and two lines of one frame within 2 px of one great circle
read as one (in a pinhole output, px grow towards its edge by up to ``1 / cos^2(theta)``).
"""

from __future__ import annotations

import math

from mechdeconv_ros.imaging.plumb_lines import ChiefLines, great_circles
from mechdeconv_ros.imaging.straight_edges import frame_of
import numpy as np
import numpy.typing as npt

#: Oriented normals of two pieces of one line agree within this angle, deg (a pre-filter:
#: the union's fit decides).
MERGE_ANGLE_DEG = 6.0
#: The union of two pieces of one line leaves its great circle by at most this (px at the
#: output focal length) or this fraction of its chord, whichever is larger.
MERGE_PX = 2.0
MERGE_FRACTION = 0.01
#: ... two pieces (neighbours along a bent line join; far ones join through them) by this
#: fraction of their own chords (the gap between them adds none): two lines of a frame far
#: apart on nearly one circle do not.
PIECE_FRACTION = 0.003
#: Pieces of one line lie side by side along it (one frame sees a line once): their extents
#: along the common circle may overlap by this much, px (the ends cut at a junction).
OVERLAP_PX = 3.0

Points = npt.NDArray[np.float64]


def _find(parent: list[int], k: int) -> int:
    """Return the root of k (path halving)."""
    while parent[k] != k:
        parent[k] = parent[parent[k]]
        k = parent[k]
    return k


def _joins(a: Points, b: Points, f_px: float, fraction: float = MERGE_FRACTION,
           own: bool = False) -> bool:
    """
    Return True when the directions a and b fit one great circle within the bound.

    The fraction is of the union's chord, or (``own``) of the sum of the two pieces' chords.
    """
    d = np.concatenate([a, b])
    _, vectors = np.linalg.eigh(d.T @ d)
    worst = float(np.max(np.abs(d @ vectors[:, 0]))) * f_px
    if own:
        # The pieces' own chords, not the gap: far pieces get no more room than near ones.
        chord = (_arc(a[0], a[-1]) + _arc(b[0], b[-1])) * f_px
    else:
        ends = np.stack([a[0], a[-1], b[0], b[-1]])
        chord = math.acos(float(np.clip(np.min(ends @ ends.T), -1.0, 1.0))) * f_px
    return worst <= max(MERGE_PX, fraction * chord)


def _arc(p: Points, q: Points) -> float:
    """Return the angle between two unit directions, rad."""
    return math.acos(float(np.clip(p @ q, -1.0, 1.0)))


def _side_by_side(parts_a: list[Points], parts_b: list[Points], f_px: float) -> bool:
    """
    Return True when no piece of a overlaps a piece of b along their common great circle.

    Each piece's extent is its interval of angle about the normal of the union's circle
    (from the union's mean direction); two intervals may overlap by ``OVERLAP_PX`` (the ends
    of pieces cut at a junction).
    """
    d = np.concatenate(parts_a + parts_b)
    _, vectors = np.linalg.eigh(d.T @ d)
    normal = vectors[:, 0]
    e1 = d.mean(axis=0)
    e1 = e1 - (e1 @ normal) * normal
    e1 /= max(float(np.linalg.norm(e1)), 1e-12)
    e2 = np.cross(normal, e1)
    spans = [(float(np.min(a)), float(np.max(a)))
             for a in (np.arctan2(p @ e2, p @ e1) for p in parts_a + parts_b)]
    slack = OVERLAP_PX / f_px
    for lo_a, hi_a in spans[:len(parts_a)]:
        for lo_b, hi_b in spans[len(parts_a):]:
            if min(hi_a, hi_b) - max(lo_a, lo_b) > slack:
                return False
    return True


def _one_line(parts_a: list[Points], parts_b: list[Points], f_px: float) -> bool:
    """Return True when two lines, whole, are one: one circle, pieces side by side."""
    return (_joins(np.concatenate(parts_a), np.concatenate(parts_b), f_px)
            and _side_by_side(parts_a, parts_b, f_px))


def oriented_normals(dirs: list[Points]) -> Points:
    """
    Return each piece's great-circle normal, signed by the piece's order.

    :param dirs: per piece, ``(n, 3)`` finite unit directions in the chain's order.
    :return: ``(count, 3)`` unit normals with ``n . (d_first x d_last) >= 0``.
    """
    out = np.zeros((len(dirs), 3))
    for k, d in enumerate(dirs):
        normal, _ = great_circles(d, np.zeros(d.shape[0], dtype=np.int64), 1)
        n = normal[0]
        out[k] = -n if float(n @ np.cross(d[0], d[-1])) < 0.0 else n
    return out


def group_lines(edges: list[Points], lines: ChiefLines, pose: npt.NDArray[np.float64],
                f_px: float, short: list[Points] | None = None
                ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """
    Return the scene line of each straight edge and of each short piece.

    Edges are linked into lines (the connected components of the relation in the module
    docstring); a short piece joins the one line whose edges it fits, if exactly one (a line
    of short pieces alone is no line: too short to tell a curve).

    :param edges: raw points of the straight edges, each in its chain's order.
    :param lines: the inverse.
    :param pose: the pose the edges are judged with (the description's).
    :param f_px: the output focal length, px per rad.
    :param short: raw points of shorter straight pieces, each in its chain's order.
    :return: ``(edge lines (len(edges),), short lines (len(short),))``, line numbers ``0 ..
        lines - 1`` (-1: a short piece on no edge's line).
    """
    edge_dirs = _directions(edges, lines, pose)
    parent = list(range(len(edges)))
    usable = [k for k in range(len(edges)) if edge_dirs[k].shape[0] >= 3]
    normals = oriented_normals([edge_dirs[k] for k in usable])
    cos_limit = math.cos(math.radians(MERGE_ANGLE_DEG))
    close = normals @ normals.T > cos_limit
    members = {k: [edge_dirs[k]] for k in range(len(edges))}
    frames = [frame_of(edge) for edge in edges]
    for i, j in zip(*np.nonzero(np.triu(close, 1))):
        a, b = _find(parent, usable[int(i)]), _find(parent, usable[int(j)])
        # Two lines join when their pieces do and the two lines, whole, fit one circle: the
        # pieces of lines that cross at a small angle fit near the crossing, the whole lines
        # do not; and their pieces lie side by side along it (a line is seen once a frame).
        if a != b and frames[usable[int(i)]] == frames[usable[int(j)]] and _joins(
                edge_dirs[usable[int(i)]], edge_dirs[usable[int(j)]], f_px,
                PIECE_FRACTION, own=True) and _one_line(members[a], members[b], f_px):
            parent[a] = b
            members[b] = members[b] + members.pop(a)
    roots = np.array([_find(parent, k) for k in range(len(edges))], dtype=np.int64)
    _, on_edges = np.unique(roots, return_inverse=True)
    # A short piece joins the one line one of whose edges it fits within MERGE_PX (it never
    # links two: a few px of a line near a vanishing point fit several of its neighbours).
    short = list(short or [])
    on_short = np.full(len(short), -1, dtype=np.int64)
    short_dirs = _directions(short, lines, pose)
    for k, d in enumerate(short_dirs):
        if d.shape[0] < 3 or not usable:
            continue
        n = oriented_normals([d])[0]
        near = [usable[int(i)] for i in np.flatnonzero(normals @ n > cos_limit)]
        frame = frame_of(short[k])
        fits = {int(on_edges[e]) for e in near
                if frames[e] == frame and _joins(edge_dirs[e], d, f_px, 0.0)
                and _side_by_side(members[_find(parent, e)], [d], f_px)}
        if len(fits) == 1:
            on_short[k] = fits.pop()
    return on_edges.astype(np.int64), on_short


def _directions(pieces: list[Points], lines: ChiefLines, pose: npt.NDArray[np.float64]
                ) -> list[Points]:
    """Return each piece's finite unit directions under a pose, in order (one inverse)."""
    if not pieces:
        return []
    sizes = [piece.shape[0] for piece in pieces]
    points = np.concatenate([np.asarray(piece).reshape(-1, 2) for piece in pieces])
    dirs = lines.directions(points, pose)
    return [d[np.all(np.isfinite(d), axis=1)]
            for d in np.split(dirs, np.cumsum(sizes)[:-1])]
