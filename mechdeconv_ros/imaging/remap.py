# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Remap maps from a LensModel, and the per-frame correction.

For a corrected (output) pixel ``(u, v)`` with normalised ideal coordinates
``x_n = (u - c'_x) / f'_x``, ``y_n = (v - c'_y) / f'_y`` (``K_new``), the ideal sensor radius is
``rho_i = v_img * hypot(x_n, y_n)`` and the source pixel is

    ``map_x = c_x + f_x x_n s(rho_i)``,  ``map_y = c_y + f_y y_n s(rho_i)``,
    ``s = R(rho_i) / rho_i``

with ``R`` the traced radial map: no inversion is needed, the forward trace maps ideal to real.
``s`` depends on the radius only, and ``K_new`` is centred, so ``s`` is computed on one quadrant
of the output and mirrored; the quadrant's radius look-up runs through ``cv2.remap`` on a
two-row table (both rows equal), several times faster than ``np.interp`` per pixel. Pixels
outside the valid field are sent far outside the source so ``BORDER_CONSTANT`` paints them 0.

The maps are kept as two CV_32FC1 arrays, which ``cv2.remap`` converts to its fixed-point form
block by block in cache: on the benchmark machine (Intel Xeon, OpenCV 4.14) that was the
fastest bilinear remap at 1280x720 and above (1080p mono8: 3.45 ms against 4.07 ms for
converted CV_16SC2 + CV_16UC1 maps, 2 threads; ``make bench``, speed section), and it spares
the rebuild a ``cv2.convertMaps`` pass over the whole frame. The output is the same as with
converted maps (both round to 1/32 px). A nearest-neighbour CV_16SC2 map is derived for depth
images on first use (no invented depths).
"""

from __future__ import annotations

import math
import time
from typing import Any, Sequence

import cv2
from mechdeconv_ros.imaging.channel_remap import ChannelRemap
from mechdeconv_ros.model import underwater
from mechdeconv_ros.model.lateral_color import channel_model
from mechdeconv_ros.model.model import LensModel
from mechdeconv_ros.model.projection import curve_tables, MapForm
from mechdeconv_ros.optics.illumination import Illumination
import numpy as np
import numpy.typing as npt

#: Where invalid output pixels point: far enough outside any source for BORDER_CONSTANT.
_OUTSIDE = -1000.0
#: Pixels per band of the off-centre/tilted maps (a band's dozen float32 arrays stay in L2).
_BAND_PIXELS = 16384


def set_remap_threads(threads: int) -> None:
    """
    Set the threads OpenCV's remap uses (``remap_threads``).

    :param threads: the count; 0 or less = OpenCV's default (every core).
    """
    cv2.setNumThreads(threads if threads > 0 else -1)


def _quadrant_scale(model: LensModel, xn: npt.NDArray[np.float32],
                    yn: npt.NDArray[np.float32],
                    gain_table: npt.NDArray[np.float64] | None = None) -> Any:
    """
    Return ``s = R(rho) / rho`` on the grid ``yn x xn`` (both >= 0); -1 outside the field.

    :param model: the lens model.
    :param xn: normalised ideal x of the quadrant's columns.
    :param yn: normalised ideal y of the quadrant's rows.
    :param gain_table: the vignetting gain at each ideal radius of ``model.curve`` (or None);
        it is looked up in the same ``cv2.remap`` pass, as a second channel of the table.
    :return: ``(len(yn), len(xn))`` float32, or ``(scale, gain)`` with a gain table (the gain
        is 0 outside the field).
    """
    curve = model.curve
    v = model.image_distance_mm
    samples = len(curve.ideal_mm)
    step = curve.valid_ideal_mm / (samples - 1)
    # Table of s over the uniformly spaced ideal radii (s(0) = 1: paraxial at the centre).
    with np.errstate(invalid='ignore', divide='ignore'):
        table = np.where(curve.ideal_mm > 0.0, curve.real_mm / curve.ideal_mm, 1.0)
    if gain_table is not None:
        table = np.stack([table, gain_table], axis=-1)
    # Two equal rows: cv2.remap's bilinear read of row y = 0 then has its 2x2 neighbourhood
    # inside the table; on a one-row table every pixel took the per-pixel border path (4 x
    # slower at 1080p). The weight of the second row is 0 either way; the sums differ in the
    # last float32 bit at most (~6e-8 relative in s, 6e-5 px at 1000 px from the centre,
    # below the 1/32 px of the remap's fixed-point weights).
    table = np.ascontiguousarray(np.repeat(table[None], 2, axis=0), dtype=np.float32)
    # The table index x = hypot(xn, yn) v / step, as sqrt(a^2 + b^2) of pre-scaled coordinates
    # into a contiguous array (numpy's hypot calls libm per element, and writing into one
    # channel of a CV_32FC2 map is a strided write: both several times slower at 1080p); the
    # y map is all 0 (the table's first row), a calloc'ed array that is never written.
    scale = np.float32(v / step)
    index = np.add(np.square(xn * scale)[None, :], np.square(yn * scale)[:, None])
    np.sqrt(index, out=index)
    looked_up = cv2.remap(table, index, np.zeros(index.shape, np.float32), cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=(-1.0, 0.0, 0.0, 0.0))
    outside = index > samples - 1
    if gain_table is None:
        looked_up[outside] = -1.0
        return looked_up
    looked_up[outside] = (-1.0, 0.0)
    return looked_up[..., 0], looked_up[..., 1]


Map = npt.NDArray[np.float32]


def build_float_maps(model: LensModel) -> tuple[Map, Map]:
    """
    Build the float source-pixel maps of the corrected image.

    :param model: the lens model.
    :return: ``(map_x, map_y)``, each ``(out_height, out_width)`` float32, raw-image pixels;
        invalid pixels point outside the source.
    """
    map_x, map_y, _ = _build_maps(model, None)
    return map_x, map_y


def _gain_table(model: LensModel, illumination: Illumination,
                max_gain: float) -> npt.NDArray[np.float64]:
    """
    Tabulate the gain min(1/RI, max_gain) at the ideal radii of ``model.curve``.

    RI is taken at the real radius each ideal radius images to; the gain is 0 where
    RI < 1 / max_gain (the corrected field ends there).
    """
    ri = illumination.at(model.curve.real_mm)
    with np.errstate(divide='ignore'):
        gain = np.where(ri >= 1.0 / max_gain, 1.0 / np.maximum(ri, 1e-12), 0.0)
    return np.minimum(gain, max_gain)


def build_gain_map(model: LensModel, illumination: Illumination, max_gain: float) -> Map:
    """
    Build the vignetting gain of each corrected pixel, from RI at its source position.

    gain = min(1 / RI(rho_real), max_gain), rho_real the real sensor radius of the output
    pixel's source; 0 where RI < 1 / max_gain (the corrected field ends) and outside the
    valid field.

    :param model: the lens model.
    :param illumination: its relative illumination.
    :param max_gain: the largest gain (>= 1).
    :return: ``(out_height, out_width)`` float32.
    """
    return _build_maps(model, _gain_table(model, illumination, max_gain))[2]


def _build_general_maps(model: LensModel, gain_table: npt.NDArray[np.float64] | None
                        ) -> tuple[Map, Map, Map | None]:
    """
    Build the maps over the whole output without mirroring (float32 arithmetic).

    For a principal point off the half-pixel grid or outside the output, which
    :func:`~mechdeconv_ros.model.model.build_model` never makes; the same equations as
    :func:`mechdeconv_ros.model.projection.raw_from_normalised`.
    """
    ow, oh = model.out_width, model.out_height
    form = MapForm.of(model)
    curve = model.curve
    xn = (np.arange(ow) - model.K_new[0, 2]) / model.K_new[0, 0]
    yn = (np.arange(oh) - model.K_new[1, 2]) / model.K_new[1, 1]
    ideal = np.hypot(xn[None, :], yn[:, None]) * form.v_mm
    g, sigma = curve_tables(curve, form.v_mm)
    q = np.interp(ideal, curve.ideal_mm, g * form.v_mm).astype(np.float32)
    q[ideal > curve.valid_ideal_mm] = np.nan
    sig = np.interp(ideal, curve.ideal_mm, sigma).astype(np.float32)
    map_x, map_y = _plane_maps(form, xn, yn, q, sig)
    gain = None
    if gain_table is not None:
        gain = np.interp(ideal, curve.ideal_mm, gain_table).astype(np.float32)
        gain[map_x == np.float32(_OUTSIDE)] = 0.0
    return map_x, map_y, gain


def _mirror_plan(n: int, c: float) -> tuple[int, int, int] | None:
    """
    Return how an axis of ``n`` pixels mirrors about ``c``: ``(a, t, count)``, or None.

    ``c`` must be a multiple of 1/2 within ``[-1/2, n - 1/2]``. The quadrant holds the
    offsets ``d = (a - c) + i``, ``i < count`` (``a = ceil(c)``); pixel ``j >= a`` is its
    entry ``j - a`` and pixel ``j < a`` its entry ``t + a - 1 - j`` (``t = 1`` when ``c`` is a
    pixel centre, which is its own mirror image).
    """
    if 2.0 * c != round(2.0 * c) or not -0.5 <= c <= n - 0.5:
        return None
    a = math.ceil(c)
    t = 1 if c == a else 0
    return a, t, max(n - a, t + a)


def _unfold(quad: np.ndarray, out: np.ndarray, rows: tuple[int, int, int],
            cols: tuple[int, int, int], col_flip: float | None = None,
            row_flip: float | None = None) -> None:
    """
    Fill ``out`` from its quadrant by mirroring (:func:`_mirror_plan`).

    A value mirrored across the columns becomes ``col_flip - value`` (map_x: ``2 c_x - x``),
    across the rows ``row_flip - value`` (map_y); None copies it unchanged.
    """
    oh, ow = out.shape
    (ar, tr, _), (ac, tc, _) = rows, cols
    parts = ((slice(ar, oh), slice(ac, ow), quad[:oh - ar, :ow - ac], False, False),
             (slice(ar, oh), slice(0, ac), quad[:oh - ar, tc:tc + ac][:, ::-1], True, False),
             (slice(0, ar), slice(ac, ow), quad[tr:tr + ar, :ow - ac][::-1], False, True),
             (slice(0, ar), slice(0, ac), quad[tr:tr + ar, tc:tc + ac][::-1, ::-1], True,
              True))
    for rsl, csl, block, col_mirrored, row_mirrored in parts:
        if block.size == 0:
            continue
        if col_mirrored and col_flip is not None:
            np.subtract(np.float32(col_flip), block, out=out[rsl, csl])
        elif row_mirrored and row_flip is not None:
            np.subtract(np.float32(row_flip), block, out=out[rsl, csl])
        else:
            out[rsl, csl] = block


def _quadrant_axes(model: LensModel) -> tuple[Any, Any, Any, Any] | None:
    """Return the mirror plans and quadrant coordinates (xn, yn >= 0), or None."""
    cols = _mirror_plan(model.out_width, float(model.K_new[0, 2]))
    rows = _mirror_plan(model.out_height, float(model.K_new[1, 2]))
    if cols is None or rows is None:
        return None
    xq = ((np.arange(cols[2]) + (cols[0] - model.K_new[0, 2])) / model.K_new[0, 0])
    yq = ((np.arange(rows[2]) + (rows[0] - model.K_new[1, 2])) / model.K_new[1, 1])
    return rows, cols, xq.astype(np.float32), yq.astype(np.float32)


def _build_maps(model: LensModel, gain_table: npt.NDArray[np.float64] | None
                ) -> tuple[Map, Map, Map | None]:
    """Build the float maps and, given a gain table over the curve's ideal radii, the gain."""
    map_x, map_y, gain = _build_radial_maps(model, gain_table)
    # A tilted flat port or a decentred dome: the exact 3-D residual, splined from a grid
    # (mechdeconv_ros.model.underwater.residual_maps); pixels outside stay outside, and so
    # do those whose residual is masked (NaN: a grid cell with a node no exact ray reaches).
    residual = underwater.residual_maps(model)
    if residual is not None:
        inside = map_x != np.float32(_OUTSIDE)
        map_x[inside] += residual[0][inside]
        map_y[inside] += residual[1][inside]
        masked = inside & ~np.isfinite(residual[0])
        map_x[masked] = np.float32(_OUTSIDE)
        map_y[masked] = np.float32(_OUTSIDE)
        if gain is not None:
            gain[masked] = 0.0
    return map_x, map_y, gain


def _build_radial_maps(model: LensModel, gain_table: npt.NDArray[np.float64] | None
                       ) -> tuple[Map, Map, Map | None]:
    """Build the maps of the rotationally symmetric model (and its sensor pose)."""
    axes = _quadrant_axes(model)
    if axes is None:
        return _build_general_maps(model, gain_table)
    rows, cols, xq, yq = axes
    if MapForm.of(model).tilted:
        return _build_tilted_maps(model, gain_table, rows, cols, xq, yq)
    ow, oh = model.out_width, model.out_height
    fx, fy, cx, cy = model.K[0, 0], model.K[1, 1], model.K[0, 2], model.K[1, 2]
    # Output column u and 2 c'_x - u have opposite xn (likewise rows): compute the quadrant
    # xn, yn >= 0, then mirror it: map_x(2 c'_x - u) = 2 c_x - map_x(u), and map_y likewise.
    gain = None
    if gain_table is None:
        scale = _quadrant_scale(model, xq, yq)
    else:
        # The gain depends on the ideal radius only, as s does: one look-up for both.
        scale, quad_gain = _quadrant_scale(model, xq, yq, gain_table)
        gain = np.empty((oh, ow), np.float32)
        _unfold(quad_gain, gain, rows, cols)
    invalid = scale < 0.0
    quad_x = np.multiply(scale, (xq * np.float32(fx))[None, :])
    quad_x += np.float32(cx)
    quad_y = np.multiply(scale, (yq * np.float32(fy))[:, None])
    quad_y += np.float32(cy)
    if invalid.any():
        # Far outside, and still outside after the mirroring (2 c - outside is far beyond).
        quad_x[invalid] = _OUTSIDE
        quad_y[invalid] = _OUTSIDE
    map_x = np.empty((oh, ow), np.float32)
    map_y = np.empty((oh, ow), np.float32)
    _unfold(quad_x, map_x, rows, cols, col_flip=2.0 * cx)
    _unfold(quad_y, map_y, rows, cols, row_flip=2.0 * cy)
    return map_x, map_y, gain


def _build_tilted_maps(model: LensModel, gain_table: npt.NDArray[np.float64] | None,
                       rows: Any, cols: Any, xq: Any, yq: Any) -> tuple[Map, Map, Map | None]:
    """
    Build the maps of a tilted sensor: radial look-ups on the quadrant, the plane per pixel.

    ``g`` and ``sigma`` (and the gain) depend on the ideal radius only: they are looked up on
    the quadrant (one ``cv2.remap``, as the centred maps); the plane intersection
    (:class:`~mechdeconv_ros.model.projection.MapForm`) is not symmetric and runs per pixel, in
    bands of rows that stay in cache, each band unfolding its rows of the quadrant first.
    """
    ow, oh = model.out_width, model.out_height
    form = MapForm.of(model)
    curve = model.curve
    samples = len(curve.ideal_mm)
    step = curve.valid_ideal_mm / (samples - 1)
    g, sigma = curve_tables(curve, form.v_mm)
    columns = [g * form.v_mm, sigma] + ([] if gain_table is None else [gain_table])
    table = np.ascontiguousarray(np.repeat(np.stack(columns, axis=-1)[None], 2, axis=0),
                                 dtype=np.float32)
    scale = np.float32(form.v_mm / step)
    index = np.add(np.square(xq * scale)[None, :], np.square(yq * scale)[:, None])
    np.sqrt(index, out=index)
    looked_up = cv2.remap(table, index, np.zeros(index.shape, np.float32), cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=(0.0, 0.0, 0.0, 0.0))
    channels = cv2.split(looked_up)
    outside = index > samples - 1
    if outside.any():
        channels[0][outside] = np.nan
    gain = None
    if gain_table is not None:
        gain = np.empty((oh, ow), np.float32)
        _unfold(channels[2], gain, rows, cols)
    xn = ((np.arange(ow) - model.K_new[0, 2]) / model.K_new[0, 0])
    yn = ((np.arange(oh) - model.K_new[1, 2]) / model.K_new[1, 1])
    map_x, map_y = _plane_maps(form, xn, yn, channels[0], channels[1], rows, cols)
    if gain is not None:
        np.putmask(gain, map_x == np.float32(_OUTSIDE), np.float32(0.0))
    return map_x, map_y, gain


def _plane_maps(form: MapForm, xn: Any, yn: Any, q: Map, sigma: Map, rows: Any = None,
                cols: Any = None) -> tuple[Map, Map]:
    """
    Return the maps of the plane from ``q = g v`` and ``sigma`` (NaN q: invalid).

    ``q`` and ``sigma`` are per output pixel, or their quadrants with the mirror plans
    ``rows`` and ``cols`` (:func:`_mirror_plan`), unfolded a band at a time. The arithmetic
    runs in bands of rows that stay in cache (about ten passes over each).
    """
    oh, ow = yn.size, xn.size
    coefficients = tuple(np.asarray(c, dtype=np.float32) for c in (
        xn * form.ax, yn * form.ay, xn * form.bx, yn * form.by, xn * form.nx, yn * form.ny))
    map_x = np.empty((oh, ow), np.float32)
    map_y = np.empty((oh, ow), np.float32)
    band = max(1, min(oh, _BAND_PIXELS // max(ow, 1)))
    quad_row = None
    if rows is not None:
        ar, tr, _ = rows
        # The quadrant row of each output row (mirrored above the principal point).
        line = np.arange(oh)
        quad_row = np.where(line >= ar, line - ar, tr + ar - 1 - line)
    # Invalid pixels (outside the field: NaN q; a line that misses the plane: D <= 0) are
    # looked for only where they can occur: D >= n_z - max|sigma| max|L|.
    reach = float(np.max(np.abs(coefficients[4])) + np.max(np.abs(coefficients[5])))
    check = bool(np.isnan(q).any()) or not (
        form.nz - float(np.nanmax(np.abs(sigma))) * reach > 0.0)
    _plane_bands(form, coefficients, q, sigma, quad_row, cols, map_x, map_y,
                 list(range(0, oh, band)), band, check)
    return map_x, map_y


def _plane_bands(form: MapForm, coefficients: tuple[Any, ...], q: Map, sigma: Map,
                 quad_row: Any, cols: Any, map_x: Map, map_y: Map, tops: list[int],
                 band: int, check: bool) -> None:
    """Compute the bands of the plane maps that start at ``tops`` (``check``: invalid ones)."""
    ax, ay, bx, by, lx, ly = coefficients
    oh, ow = map_x.shape
    cu, cv, nz = np.float32(form.cu), np.float32(form.cv), np.float32(form.nz)
    work = np.empty((band, ow), np.float32)
    if quad_row is not None:
        q_band = np.empty((band, ow), np.float32)
        s_band = np.empty((band, ow), np.float32)
    for top in tops:
        span = slice(top, min(oh, top + band))
        n = span.stop - span.start
        if quad_row is None:
            qb, denominator = q[span], sigma[span]
        else:
            picked = quad_row[span]
            qb, denominator = q_band[:n], s_band[:n]
            _unfold_columns(q[picked], qb, cols)
            _unfold_columns(sigma[picked], denominator, cols)
        lin = work[:n]
        np.add(lx[None, :], ly[span, None], out=lin)
        denominator *= lin
        denominator += nz
        np.divide(qb, denominator, out=qb)
        out_x, out_y = map_x[span], map_y[span]
        np.add(ax[None, :], ay[span, None], out=out_x)
        out_x *= qb
        out_x += cu
        np.add(bx[None, :], by[span, None], out=out_y)
        out_y *= qb
        out_y += cv
        # NaN (outside the field) propagates into the sum; a line that does not meet the
        # plane in front (denominator <= 0) is invalid too.
        if check and (not math.isfinite(float(np.add.reduce(out_x, axis=None)))
                      or float(denominator.min()) <= 0.0):
            invalid = ~np.isfinite(out_x) | ~(denominator > 0.0)
            np.putmask(out_x, invalid, np.float32(_OUTSIDE))
            np.putmask(out_y, invalid, np.float32(_OUTSIDE))


def _unfold_columns(quad_rows: np.ndarray, out: np.ndarray, cols: tuple[int, int, int]) -> None:
    """Fill rows of the output from the same rows of the quadrant, mirrored in columns."""
    ow = out.shape[1]
    ac, tc, _ = cols
    out[:, ac:] = quad_rows[:, :ow - ac]
    if ac:
        out[:, :ac] = quad_rows[:, tc:tc + ac][:, ::-1]


def _same_curve(a: Any, b: Any) -> bool:
    """Return True when two radial maps are the same samples."""
    return bool(a.ideal_mm.shape == b.ideal_mm.shape and np.array_equal(a.real_mm, b.real_mm)
                and np.array_equal(a.ideal_mm, b.ideal_mm))


class Rectifier:
    """
    The maps of one LensModel, built once, and the per-frame correction.

    ``correct`` is safe to call from one thread at a time per instance; build a new Rectifier
    for a new model instead of mutating one, so a frame never sees two models.

    With ``output.vignetting_correction`` the Rectifier also holds the gain map (float32, in
    output coordinates, :func:`build_gain_map`) and ``correct`` multiplies the remapped frame
    by it in place (cv2.multiply saturates integer images). ``vignetting_warning`` says, once
    per model, where the gain limit ends the corrected field.

    With ``output.lateral_color_correction`` it also holds one map per colour channel
    (:attr:`colour`, :mod:`mechdeconv_ros.model.lateral_color`), and ``correct`` given the
    frame's channel colours (``colours``) remaps each channel with its own map in one pass
    (:class:`~mechdeconv_ros.imaging.channel_remap.ChannelRemap`); ``lateral_color_ms`` is the time
    of its three traces and maps.
    """

    def __init__(self, model: LensModel, vignetting: bool | None = None,
                 fixed_point: bool = False, lateral: bool | None = None) -> None:
        """
        Build the float maps (``map1`` = x, ``map2`` = y, CV_32FC1, raw-image pixels).

        :param model: the lens model.
        :param vignetting: build the vignetting gain map; None = ``output.vignetting_correction``.
        :param fixed_point: convert the maps to CV_16SC2 + CV_16UC1 (the same output; the
            stage benchmark compares the two forms in a running relay).
        :param lateral: build the per-channel maps; None = ``output.lateral_color_correction``.
        """
        self.model = model
        if vignetting is None:
            vignetting = bool(model.values['output.vignetting_correction'])
        self.gain: Map | None = None
        self.vignetting_warning: str | None = None
        table = None
        if vignetting:
            max_gain = float(model.values['output.max_vignetting_gain'])
            curve = model.illumination(with_fraction=False)
            table = _gain_table(model, curve, max_gain)
            ends = np.flatnonzero(curve.ri < 1.0 / max_gain)
            if ends.size and curve.height_mm[ends[0]] < curve.corner_height_mm:
                self.vignetting_warning = (
                    f'output.max_vignetting_gain: the relative illumination falls below '
                    f'1/{max_gain:g} at {curve.height_mm[ends[0]]:.3g} mm from the centre, '
                    f'inside the {curve.corner_height_mm:.3g} mm corner: the corrected field '
                    'ends there (black beyond)')
        self.map1, self.map2, self.gain = _build_maps(model, table)
        float_maps = (self.map1, self.map2)
        if fixed_point:
            self.map1, self.map2 = cv2.convertMaps(self.map1, self.map2, cv2.CV_16SC2)
        self._nearest_map: np.ndarray | None = None
        self._gains: dict[int, Map] = {}
        # --- lateral colour (issue #20): a map per colour channel, on the same K_new ---
        self.colour: ChannelRemap | None = None
        self.lateral_color_ms = 0.0
        if lateral is None:
            lateral = bool(model.values.get('output.lateral_color_correction', False))
        if lateral:
            start = time.perf_counter()
            # A channel at the focus wavelength has the model's own curve: reuse its maps.
            maps = [float_maps if _same_curve(channel.curve, model.curve)
                    else build_float_maps(channel_model(model, channel))
                    for channel in model.lateral_color().channels]
            self.colour = ChannelRemap(maps, model.width, model.height)
            self.lateral_color_ms = (time.perf_counter() - start) * 1e3

    def gain_for(self, channels: int) -> Map | None:
        """
        Return the gain map replicated for ``channels`` interleaved channels (cached).

        Call it at rebuild time for the channel count the frames have, so the first frame
        does not pay for the replication.

        :param channels: 1 to 4.
        :return: ``(out_height, out_width[, channels])`` float32, or None without correction.
        """
        if self.gain is None:
            return None
        gain = self._gains.get(channels)
        if gain is None:
            gain = self.gain if channels == 1 else cv2.merge([self.gain] * channels)
            self._gains[channels] = gain
        return gain

    @property
    def nearest_map(self) -> np.ndarray:
        """
        Return the nearest-neighbour CV_16SC2 map, derived on first use.

        Only depth images need it, so a rebuild does not pay for it: the float maps rounded
        to the nearest source pixel (``cv2.convertMaps`` with ``nninterpolation``).
        """
        if self._nearest_map is None:
            if self.map1.dtype == np.int16:         # fixed point: to the nearer 1/32 px
                self._nearest_map = cv2.convertMaps(*cv2.convertMaps(
                    self.map1, self.map2, cv2.CV_32FC1), cv2.CV_16SC2, nninterpolation=True)[0]
            else:
                self._nearest_map = cv2.convertMaps(self.map1, self.map2, cv2.CV_16SC2,
                                                    nninterpolation=True)[0]
        return self._nearest_map

    @property
    def out_shape(self) -> tuple[int, int]:
        """Return ``(out_height, out_width)``."""
        return self.model.out_height, self.model.out_width

    def prepare_colours(self, colours: Sequence[int] | None) -> None:
        """
        Build the folded per-channel maps for a channel order now (rebuild time).

        :param colours: the colour of each channel (``lateral_color.COLOUR_ORDER``), or None.
        """
        if self.colour is not None and colours:
            self.colour.prepare(colours, self.model.interpolation == cv2.INTER_NEAREST)

    def correct(self, src: np.ndarray, dst: np.ndarray | None = None, *,
                nearest: bool = False, gain: bool = True,
                colours: Sequence[int] | None = None) -> np.ndarray:
        """
        Correct one frame.

        :param src: ``(H, W)`` or ``(H, W, C)`` (C <= 4) uint8, uint16 or float32 raw image; a
            row-padded view is fine.
        :param dst: optional preallocated ``(out_height, out_width[, C])`` output of the same
            dtype, written in place (e.g. a view on an outgoing message's buffer).
        :param nearest: use nearest-neighbour regardless of the model's interpolation (depth).
        :param gain: apply the vignetting gain when the Rectifier has one; False for depth
            images, which are never gain-corrected.
        :param colours: the colour (0 R, 1 G, 2 B) of each channel of ``src``; with lateral
            colour correction each channel is remapped with its colour's map. None (mono,
            depth, unknown order): one map for every channel.
        :return: the corrected image (``dst`` when given). Pixels outside the valid field or
            the source are 0.
        :raises ValueError: when ``src`` does not have the model's size.
        """
        if src.shape[:2] != (self.model.height, self.model.width):
            raise ValueError(f'frame is {src.shape[1]}x{src.shape[0]} px but the model is '
                             f'{self.model.width}x{self.model.height} px')
        if colours and self.colour is not None and not nearest and src.ndim == 3:
            out = self.colour.remap(src, colours, self.model.interpolation, dst)
        elif nearest or self.model.interpolation == cv2.INTER_NEAREST:
            out = cv2.remap(src, self.nearest_map, None, cv2.INTER_NEAREST, dst=dst,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        else:
            out = cv2.remap(src, self.map1, self.map2, self.model.interpolation, dst=dst,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if gain and self.gain is not None:
            channels = 1 if out.ndim == 2 else out.shape[2]
            # In place; cv2 saturates uint8/uint16 instead of wrapping.
            cv2.multiply(out, self.gain_for(channels), dst=out, dtype=_CV_DEPTH[out.dtype])
        return out


#: OpenCV depth of each image dtype the correction handles.
_CV_DEPTH = {np.dtype(np.uint8): cv2.CV_8U, np.dtype(np.uint16): cv2.CV_16U,
             np.dtype(np.int16): cv2.CV_16S, np.dtype(np.float32): cv2.CV_32F,
             np.dtype(np.float64): cv2.CV_64F}


def distortion_maps(model: LensModel, ideal_K: npt.NDArray[np.float64] | None = None
                    ) -> tuple[Map, Map]:
    """
    Build maps that render what the camera sees from an ideal pinhole image.

    For each raw pixel the real radius is inverted to the ideal radius (the map is monotonic),
    giving the position in an ideal image with camera matrix ``ideal_K``. Used to synthesise
    distorted test frames and the demo camera; the correction never needs it.

    :param model: the lens model.
    :param ideal_K: camera matrix of the ideal image (default: ``model.K_new``).
    :return: ``(map_x, map_y)`` over the raw image, float32; invalid pixels point outside.
    """
    ideal_K = model.K_new if ideal_K is None else ideal_K
    u, v = np.meshgrid(np.arange(model.width, dtype=np.float64),
                       np.arange(model.height, dtype=np.float64))
    rect = model.rect_from_raw(np.stack([u, v], axis=-1))
    xn = (rect[..., 0] - model.K_new[0, 2]) / model.K_new[0, 0]
    yn = (rect[..., 1] - model.K_new[1, 2]) / model.K_new[1, 1]
    map_x = ideal_K[0, 2] + ideal_K[0, 0] * xn
    map_y = ideal_K[1, 2] + ideal_K[1, 1] * yn
    bad = ~np.isfinite(map_x) | ~np.isfinite(map_y)
    map_x[bad] = _OUTSIDE
    map_y[bad] = _OUTSIDE
    return map_x.astype(np.float32), map_y.astype(np.float32)


def distort_image(model: LensModel, ideal: np.ndarray,
                  ideal_K: npt.NDArray[np.float64] | None = None) -> np.ndarray:
    """
    Render the raw (distorted) image of an ideal pinhole image through the lens model.

    :param model: the lens model.
    :param ideal: the ideal image, camera matrix ``ideal_K`` (default ``model.K_new``).
    :param ideal_K: its camera matrix.
    :return: the raw image, ``(model.height, model.width[, C])``.
    """
    map_x, map_y = distortion_maps(model, ideal_K)
    return cv2.remap(ideal, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=0)
