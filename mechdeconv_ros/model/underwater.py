# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The underwater camera as a model: exact projection and the non-central error (issue 27).

Pure numpy, no ROS (docs/underwater.md). A model whose source is a
:class:`~mechdeconv_ros.lenses.port_source.PortedSource` has the radial map of its symmetric
port (flat untilted, dome centred on the axis; K, D and the remap from it as for any lens).

Projection (``mechdeconv project``): :mod:`mechdeconv_ros.model.projection` owns it
(:func:`~mechdeconv_ros.model.projection.project_points`, re-exported here with
``is_exact_3d``): a symmetric port as any lens (the traced chief-ray lines); a tilted flat
port or a decentred dome: each point's chief ray traced exactly in 3-D
(:meth:`PortedSource.sensor_points`), pixel = c + (a / p_x, b / p_y).

Remap (:func:`residual_maps`): exact per-pixel Newton over 1080p is too slow, so a non-symmetric
port's maps are the symmetric port's (radial, exact to the curve's interpolation) plus a
residual (exact 3-D pixel minus the radial one) traced on a RESIDUAL_GRID of output pixels
(corners included) and carried to every pixel by a separable natural cubic spline. A node's
direction is the output projection's own (no angle clamped); nodes without a ray (beyond the
valid field, past 90 deg on a finite scene plane) are filled harmonically from the others
(Laplace), so the spline stays smooth elsewhere, and the pixels of every grid cell they are a
corner of are masked (NaN: the remap leaves them outside) rather than given a made-up residual.
A scene at infinity (``scene.distance_mm`` 0, :func:`mechdeconv_ros.schema.params.scene_distance`)
is traced exactly too, direction by direction. Its error against the exact trace is measured by
test/test_underwater.py (well under 0.05 px for 1 deg of tilt and 1 mm of decentring).

Non-central error (:func:`noncentral_errors`): a camera behind a flat port has no single
viewpoint (Treibitz et al., IEEE PAMI 2012). Take the corner pixel (W - 1, H - 1), the scene
point P at distance l whose chief ray lands on it, and the apparent entrance pupil E' (the
paraxial entrance pupil of medium, port and lens, on the axis, in the water). A central camera
would image every point of the line E'P on the same pixel; here the points of that line at
Z = l / 2 and Z = 2 l land elsewhere (a corner outside the valid field: 95 % of the valid field on
its diagonal), by ``noncentral_error_px_half`` and
``noncentral_error_px_twice`` (px, radial, in the corner's direction). A dome centred on the
entrance pupil leaves only the lens's own pupil aberration (nearly 0); a flat port does not.
It is the error of any single-viewpoint model (K, D, the remap) used at another range. The
tilt or decentring of a port is left out of this number (its symmetric port is traced).
"""

from __future__ import annotations

import math
from typing import Any

from mechdeconv_ros.lenses.lens_errors import FloatArray
from mechdeconv_ros.lenses.port_source import PortedSource
from mechdeconv_ros.model.projection import (  # noqa: F401 (re-exported)
    exact_pixels, is_exact_3d, project_points)
from mechdeconv_ros.optics.ports import entrance_pupil_z
from mechdeconv_ros.schema.params import scene_distance
import numpy as np

#: The keys of the model report.
KEYS = ('noncentral_error_px_half', 'noncentral_error_px_twice')
#: Nodes (across, down) of the exact 3-D grid whose spline carries a non-symmetric port into
#: the remap: test/test_underwater.py measures the interpolation error (docs/underwater.md).
RESIDUAL_GRID = (97, 55)


def noncentral_errors(model: Any) -> dict[str, float | None]:
    """
    Return the non-central error at half and twice the scene distance (module docstring).

    :param model: the model.
    :return: ``{'noncentral_error_px_half': e_half, 'noncentral_error_px_twice': e_twice}``;
        None for a camera in air without a port, or a scene at infinity (every point of the
        line is at infinity), NaN where a chief ray fails.
    """
    source = model.source
    distance = scene_distance(model.values)
    if not isinstance(source, PortedSource) or math.isinf(distance):
        return dict.fromkeys(KEYS)
    corner_u, corner_v = model.width - 1.0, model.height - 1.0
    dx = (corner_u - model.K[0, 2]) * model.pixel_mm[0]
    dy = (corner_v - model.K[1, 2]) * model.pixel_mm[1]
    # A corner outside the valid field (black in image_rect: a flat port ends a wide lens's
    # field near the critical angle): 95 % of the valid field on its diagonal stands for it.
    reach = 0.95 * float(model.field_curve.valid_real_mm)
    r_corner = math.hypot(dx, dy)
    if r_corner > reach:
        dx, dy, r_corner = dx * reach / r_corner, dy * reach / r_corner, reach
    theta = float(model.field_curve.angle_from_real(np.array(r_corner)))
    if not math.isfinite(theta):
        return dict.fromkeys(KEYS, math.nan)
    z_h = source.first_order().front_principal_z_mm
    z_scene = z_h - distance
    # The apparent entrance pupil in the water, in the lens frame.
    z_pupil = entrance_pupil_z(source.combined) - source.shift_mm
    height = distance * math.tan(theta)
    sensor_z = source.image_plane(distance)[0]
    out: dict[str, float | None] = {}
    for key, factor in zip(KEYS, (0.5, 2.0)):
        z_other = z_h - factor * distance
        other = height * (z_other - z_pupil) / (z_scene - z_pupil)
        tan = other / (factor * distance)
        try:
            real = float(source.heights_to_sensor(np.array([tan]), factor * distance,
                                                  sensor_z)[0])
        except ValueError:
            real = math.nan
        shift = real - r_corner
        out[key] = float(math.hypot(shift * dx / r_corner / model.pixel_mm[0],
                                    shift * dy / r_corner / model.pixel_mm[1]))
    return out


def spline_weights(count: int, queries: FloatArray) -> FloatArray:
    """
    Return the weights of a natural cubic spline through ``count`` nodes at 0, 1, ..., n - 1.

    :param count: nodes (>= 2), unit spacing.
    :param queries: positions in [0, count - 1].
    :return: ``(len(queries), count)``: f(q) = W @ f(nodes).
    """
    q = np.clip(np.asarray(queries, dtype=float), 0.0, count - 1.0)
    i = np.minimum(np.floor(q).astype(int), count - 2)
    t = q - i
    rows = np.arange(q.size)
    linear = np.zeros((q.size, count))
    linear[rows, i] = 1.0 - t
    linear[rows, i + 1] += t
    # Second derivatives M = S y: tridiag(1, 4, 1) M_inner = 6 (second differences of y).
    curvature = np.zeros((count, count))
    if count > 2:
        inner = count - 2
        a = 4.0 * np.eye(inner) + np.eye(inner, k=1) + np.eye(inner, k=-1)
        d = np.zeros((inner, count))
        for k in range(inner):
            d[k, k:k + 3] = (6.0, -12.0, 6.0)
        curvature[1:-1] = np.linalg.solve(a, d)
    u = 1.0 - t
    cubic = np.zeros((q.size, count))
    cubic[rows, i] = (u ** 3 - u) / 6.0
    cubic[rows, i + 1] += (t ** 3 - t) / 6.0
    return linear + cubic @ curvature


def ideal_directions(model: Any, xn: FloatArray, yn: FloatArray) -> FloatArray:
    """
    Return the unit scene directions of normalised output coordinates (output projection).

    Pinhole: (xn, yn, 1). Equidistant: theta = hypot(xn, yn), past 90 deg too (no angle is
    clamped: a direction the scene plane does not reach is NaN in the exact trace, not the
    residual of another angle).

    :return: ``(..., 3)``.
    """
    xn, yn = np.broadcast_arrays(np.asarray(xn, dtype=float), np.asarray(yn, dtype=float))
    if model.projection == 'pinhole':
        d = np.stack([xn, yn, np.ones(xn.shape)], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)
    theta = np.hypot(xn, yn)
    with np.errstate(invalid='ignore', divide='ignore'):
        scale = np.where(theta > 0.0, np.sin(theta) / theta, 1.0)
    return np.stack([xn * scale, yn * scale, np.cos(theta)], axis=-1)


def residual_nodes(model: Any) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """
    Return the residual grid: node columns u, rows v (output px) and the residual (du, dv).

    :return: ``(u_nodes, v_nodes, du, dv)``, du/dv ``(rows, cols)`` in raw px (NaN where a
        node has no ray).
    """
    cols, rows = RESIDUAL_GRID
    u_nodes = np.linspace(0.0, model.out_width - 1.0, cols)
    v_nodes = np.linspace(0.0, model.out_height - 1.0, rows)
    xn = (u_nodes[None, :] - model.K_new[0, 2]) / model.K_new[0, 0]
    yn = (v_nodes[:, None] - model.K_new[1, 2]) / model.K_new[1, 1]
    xn, yn = np.broadcast_arrays(xn, yn)
    exact_u, exact_v = exact_pixels(model, ideal_directions(model, xn, yn))
    radial = model.raw_from_rect(np.stack([u_nodes[None, :] + 0.0 * yn,
                                           v_nodes[:, None] + 0.0 * xn], axis=-1))
    return u_nodes, v_nodes, exact_u - radial[..., 0], exact_v - radial[..., 1]


def _filled(grid: FloatArray, sweeps: int = 400) -> FloatArray:
    """Return the grid with its NaN nodes (no ray) filled harmonically from the others."""
    grid = np.array(grid, dtype=float)
    missing = ~np.isfinite(grid)
    if missing.all():
        return np.zeros_like(grid)
    grid[missing] = np.nanmean(grid)
    for _ in range(sweeps if missing.any() else 0):
        padded = np.pad(grid, 1, mode='edge')
        mean = 0.25 * (padded[:-2, 1:-1] + padded[2:, 1:-1] + padded[1:-1, :-2]
                       + padded[1:-1, 2:])
        grid[missing] = mean[missing]
    return grid


def residual_maps(model: Any) -> tuple[FloatArray, FloatArray] | None:
    """
    Return the residual (du, dv) of a non-symmetric port at every output pixel, or None.

    A node without an exact ray (beyond a flat port's critical angle, past the scene plane's
    90 deg) is filled harmonically so the spline stays smooth elsewhere, but every pixel of a
    grid cell with such a corner is NaN (masked: the remap leaves it outside) rather than
    given a made-up residual.

    :param model: the model.
    :return: two ``(out_height, out_width)`` float32 arrays; None for a symmetric port.
    """
    if not is_exact_3d(model):
        return None
    cached = model._lateral_cache.get('port_residual')
    if cached is None:
        u_nodes, v_nodes, du, dv = residual_nodes(model)
        qu = np.arange(model.out_width) * ((u_nodes.size - 1) / max(model.out_width - 1, 1))
        qv = np.arange(model.out_height) * ((v_nodes.size - 1) / max(model.out_height - 1, 1))
        wu = spline_weights(u_nodes.size, qu)
        wv = spline_weights(v_nodes.size, qv)
        missing = ~(np.isfinite(du) & np.isfinite(dv))
        masked = _cells_touching(missing, qu, qv)
        out = []
        for grid in (du, dv):
            full = (wv @ _filled(grid) @ wu.T).astype(np.float32)
            full[masked] = np.nan
            out.append(full)
        cached = (out[0], out[1])
        model._lateral_cache['port_residual'] = cached
    return cached


def _cells_touching(missing: np.ndarray, qu: FloatArray, qv: FloatArray) -> np.ndarray:
    """Return, per pixel (grid positions qu across, qv down), whether a cell corner is missing."""
    if not missing.any():
        return np.zeros((qv.size, qu.size), dtype=bool)
    c0 = np.minimum(np.floor(qu).astype(int), missing.shape[1] - 1)
    c1 = np.minimum(np.ceil(qu).astype(int), missing.shape[1] - 1)
    r0 = np.minimum(np.floor(qv).astype(int), missing.shape[0] - 1)
    r1 = np.minimum(np.ceil(qv).astype(int), missing.shape[0] - 1)
    return (missing[r0][:, c0] | missing[r0][:, c1] | missing[r1][:, c0]
            | missing[r1][:, c1])
