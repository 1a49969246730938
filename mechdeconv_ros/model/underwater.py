# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The underwater camera as a model: exact projection and the non-central error (issue 27).

Pure numpy, no ROS (docs/underwater.md). A model whose source is a
:class:`~mechdeconv_ros.lenses.port_source.PortedSource` has the radial map of its symmetric
port (flat untilted, dome centred on the axis; K, D and the remap from it as for any lens).

Projection (:func:`project_points`): scene directions (tx, ty) = (X/Z, Y/Z) at Z =
``scene.distance_mm`` to raw pixels. A symmetric port: through the radial map (the remap's own
interpolation of the traced chief rays). A tilted flat port or a decentred dome: each point's
chief ray traced exactly in 3-D (:meth:`PortedSource.sensor_points`), pixel =
c + (a / p_x, b / p_y).

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
from mechdeconv_ros.optics.ports import entrance_pupil_z
import numpy as np

#: The keys of the model report.
KEYS = ('noncentral_error_px_half', 'noncentral_error_px_twice')


def is_exact_3d(model: Any) -> bool:
    """Return True when the model's port breaks the rotational symmetry."""
    source = model.source
    return (isinstance(source, PortedSource) and source.port is not None
            and not source.port.symmetric)


def project_points(model: Any, tx: FloatArray, ty: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return the raw pixels of scene directions (module docstring), NaN where none passes.

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param tx: X / Z, any shape.
    :param ty: Y / Z, same shape.
    :return: ``(u, v)`` raw pixel coordinates.
    """
    tx, ty = np.broadcast_arrays(np.asarray(tx, dtype=float), np.asarray(ty, dtype=float))
    if is_exact_3d(model):
        a, b = model.source.sensor_points(tx, ty, float(model.values['scene.distance_mm']))
        return model.K[0, 2] + a / model.pixel_mm[0], model.K[1, 2] + b / model.pixel_mm[1]
    rect = np.stack([model.K_new[0, 2] + model.K_new[0, 0] * tx,
                     model.K_new[1, 2] + model.K_new[1, 1] * ty], axis=-1)
    raw = model.raw_from_rect(rect)
    return raw[..., 0], raw[..., 1]


def noncentral_errors(model: Any) -> dict[str, float | None]:
    """
    Return the non-central error at half and twice the scene distance (module docstring).

    :param model: the model.
    :return: ``{'noncentral_error_px_half': e_half, 'noncentral_error_px_twice': e_twice}``;
        None for a camera in air without a port, or a scene at infinity (every point of the
        line is at infinity), NaN where a chief ray fails.
    """
    source = model.source
    distance = float(model.values.get('scene.distance_mm', 0.0))
    if not isinstance(source, PortedSource) or distance <= 0.0:
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
