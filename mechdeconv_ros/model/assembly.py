# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The camera as assembled: which sensor poses a camera can have (docs/design.md section 2.16).

Pure numpy, no ROS. The sensor (``sensor.axis_offset_*_mm``, ``sensor.tilt_*_deg``) is the
plane through the axis point ``O = (0, 0, z_s)`` turned by ``T = R_x(-tilt_x) R_y(tilt_y)``
(docs/design.md section 1.1; :class:`mechdeconv_ros.optics.pose.SensorPose`), the lens axis
meeting it at the pixel ``c = ((W - 1) / 2 + dx / p_x, (H - 1) / 2 + dy / p_y)``; a pixel at
in-plane offsets ``(a, b)`` is the point ``O + T (a, b, 0)``. Where the chief rays meet it, and
which direction a raw pixel sees, is :mod:`mechdeconv_ros.model.projection` (the one public
projection); this module refuses the poses no camera can have (:func:`check_pose`).

The names of before issue 37 (``project``, ``unproject``, ``project_angles``,
``unproject_angles``, ``SensorPose``, ``axis_pixel``, ``MapForm``, ``curve_tables``,
``raw_from_normalised``, ``POSE_PARAMS``) are re-exported from their owners for callers not yet
moved; new code imports them from :mod:`~mechdeconv_ros.model.projection` and
:mod:`~mechdeconv_ros.optics.pose`.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from mechdeconv_ros.lenses.lens_errors import ModelError
from mechdeconv_ros.model.projection import (  # noqa: F401 (re-exported, docstring)
    curve_tables, lines_at, MapForm, plane_offsets, project, project_angles,
    raw_from_normalised, unproject, unproject_angles)
from mechdeconv_ros.optics.pose import (  # noqa: F401 (POSE_PARAMS re-exported)
    POSE_PARAMS, sensor_points, SensorPose)
from mechdeconv_ros.optics.prescription import vertex_z
from mechdeconv_ros.optics.surfaces import domain_limit_mm, sag
import numpy as np

#: Points per side of the sensor grid on which a tilted sensor's clearance from the last
#: lens surface is checked.
CLEARANCE_GRID = 33


def axis_pixel(values: Mapping[str, Any], width: int, height: int,
               pixel_mm: tuple[float, float]) -> tuple[float, float]:
    """
    Return the pixel where the lens axis meets the sensor (:meth:`SensorPose.axis_pixel`).

    :param values: parameter values.
    :param width: raw width, px.
    :param height: raw height, px.
    :param pixel_mm: pixel pitches (x, y), mm.
    :return: ``(c_u, c_v)``.
    """
    return SensorPose.from_values(values).axis_pixel(width, height, pixel_mm)


def check_pose(values: Mapping[str, Any], source: Any, camera: Any, width: int,
               height: int, sensor_z_mm: float) -> None:
    """
    Refuse a sensor pose no camera can have (docs/design.md section 7).

    - ``sensor.axis_offset_*_mm``: the lens axis must meet the sensor (within its outer pixel
      edges): ``|offset| <= W p / 2``.
    - ``sensor.tilt_*_deg``: the tilted sensor must clear the last lens surface: every corner
      and edge midpoint of the sensor lies behind that surface (its sagitta at the point's
      distance from the axis, clamped at its rim); and every chief ray of the raw image's
      field must meet the plane in front of the lens (``s k + n_z > 0``: the image would
      otherwise leave the sensor along a line that grazes it). The larger tilt is named.

    :param values: checked parameter values.
    :param source: the lens source (a traced one has the last surface).
    :param camera: the raw camera so far (``K``, ``pixel_mm``, ``field_curve``).
    :param width: raw width, px.
    :param height: raw height, px.
    :param sensor_z_mm: z of the sensor's axis point (the lens's z, first vertex at 0).
    :raises ModelError: naming the parameter.
    """
    pose = SensorPose.from_values(values)
    px, py = camera.pixel_mm
    for name, offset, size, pitch in (('sensor.axis_offset_x_mm', pose.offset_x_mm, width, px),
                                      ('sensor.axis_offset_y_mm', pose.offset_y_mm, height, py)):
        half = size * pitch / 2.0
        if abs(offset) > half:
            raise ModelError(name, f'{offset:g} mm puts the lens axis off the sensor, which '
                                   f'reaches {half:.4g} mm from its centre ({size} px of '
                                   f'{pitch * 1e3:.4g} um): the axis must meet the sensor')
    if not pose.tilted:
        return
    blame = ('sensor.tilt_x_deg' if abs(pose.tilt_x_rad) >= abs(pose.tilt_y_rad)
             else 'sensor.tilt_y_deg')
    tilt = math.degrees(pose.tilt_x_rad if blame.endswith('x_deg') else pose.tilt_y_rad)
    r = pose.rotation()
    field = camera.field_curve
    if field.slope is not None and field.slope.size:
        steepest = float(np.max(np.abs(field.slope)))
        margin = r[2, 2] - steepest * math.hypot(r[0, 2], r[1, 2])
        if not margin > 0.0:
            raise ModelError(blame, f'{tilt:g} deg tilts the sensor so far that chief rays '
                                    f'of the field (slope {steepest:.3g}) run parallel to it: '
                                    'the image leaves the sensor')
    prescription = getattr(source, 'prescription', None)
    if prescription is None or not prescription.surfaces:
        return
    last = prescription.surfaces[-1]
    z_last = float(vertex_z(prescription)[-1])
    # The sensor's pixels on a grid (the closest approach may lie inside: a convex surface).
    us = np.linspace(-0.5, width - 0.5, CLEARANCE_GRID)
    vs = np.linspace(-0.5, height - 0.5, CLEARANCE_GRID)
    uu, vv = (g.ravel() for g in np.meshgrid(us, vs))
    point = np.stack(sensor_points(r, (uu - camera.K[0, 2]) * px, (vv - camera.K[1, 2]) * py))
    radius = np.minimum(np.hypot(point[0], point[1]), domain_limit_mm(last))
    surface_z = z_last + sag(last, radius * radius)
    clearance = sensor_z_mm + point[2] - surface_z
    worst = int(np.argmin(clearance))
    if not clearance[worst] > 0.0:
        raise ModelError(blame, f"{tilt:g} deg brings the sensor's pixel ({uu[worst]:.0f}, "
                                f'{vv[worst]:.0f}) to z = {sensor_z_mm + point[2, worst]:.4g} '
                                f'mm, into the last lens surface (z = {surface_z[worst]:.4g} '
                                f'mm at {radius[worst]:.3g} mm from the axis): the sensor '
                                'would hit the lens')
