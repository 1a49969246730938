# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The camera as assembled: the sensor off the lens axis and tilted, met exactly by the chief rays.

Pure numpy, no ROS (docs/design.md section 2.16). Frames:

- the camera's optical frame (REP-103): X right, Y down, Z along the lens axis from the front
  principal plane H. A scene point (or direction) has the tangents ``tx = X / Z``,
  ``ty = Y / Z``; its field angle is ``theta = atan(hypot(tx, ty))`` and its azimuth
  ``phi = atan2(ty, tx)``.
- the read-out frame of the sensor: ``(a, b, z)`` with ``a`` along the rows (u grows), ``b``
  down the columns (v grows) and ``z`` along the axis towards the sensor. It is the physical
  image-space frame turned 180 deg about the axis (the real image is inverted; the read-out
  turns it upright), a proper rotation, so distances and tilts keep their meaning. A
  rotationally symmetric lens sends the chief ray of (theta, phi) into image space as a line in
  the meridional plane of azimuth phi: ``(a, b) = rho(z) (cos phi, sin phi)`` with
  ``rho(z) = h(theta) + s(theta) (z - z_s)``, ``h`` the real height on the paraxial sensor plane
  ``z_s`` and ``s`` its slope (:meth:`~mechdeconv_ros.lenses.lens_source.LensSource.chief_lines`).

The sensor (``sensor.axis_offset_*_mm``, ``sensor.tilt_*_deg``): the lens axis meets it at
the pixel ``c = ((W - 1) / 2 + dx / p_x, (H - 1) / 2 + dy / p_y)`` (the raw K's principal
point), and it is the plane through ``O = (0, 0, z_s)`` spanned by the columns of

    ``R = R_x(alpha) R_y(beta)``,  ``R_x(alpha) = [[1, 0, 0], [0, cos, sin], [0, -sin, cos]]``,
    ``R_y(beta) = [[cos, 0, sin], [0, 1, 0], [-sin, 0, cos]]``

(alpha = tilt_x, beta = tilt_y): first turned by alpha about its row line through O (``b > 0``
goes to ``z < z_s``: rows of larger v come closer to the lens), then by beta about its own
turned column line (``a > 0`` goes closer), as a Zemax coordinate break with tilts about x then
y. A pixel at in-plane offsets ``(a, b) = ((u - c_u) p_x, (v - c_v) p_y)`` is the point
``O + R (a, b, 0)``; ``n = R e_z`` is the plane's normal.

Projection (exact, no small angle): the line meets the plane where ``n . (P - O) = 0``. With
``k = n_x cos phi + n_y sin phi`` and ``q = h / (s k + n_z)``, ``P - O = (q n_z cos phi,
q n_z sin phi, -q k)``, and the pixel's in-plane offsets are ``(a, b) = (R^T (P - O))_{0,1}``.
A line parallel to the plane (``s k + n_z <= 0``) meets it nowhere in front: NaN.

Inverse (raw pixel -> direction): ``Q = R (a, b, 0)`` gives ``phi = atan2(Q_y, Q_x)`` and the
equation ``h(theta) + s(theta) Q_z = hypot(Q_x, Q_y)`` in theta, solved by Newton on the
cubic Hermite interpolation of the angle-uniform trace (the same interpolation the forward
projection uses, so the two agree to 1e-9 px).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Mapping

from mechdeconv_ros.lenses.lens_errors import FloatArray
from mechdeconv_ros.model.radial_map import hermite, RadialMap
import numpy as np

#: Newton iterations of the inverse projection (quadratic convergence from the untilted root).
INVERSE_ITERATIONS = 12
#: The parameters of the sensor's pose, in the order of :class:`SensorPose`.
POSE_PARAMS = ('sensor.axis_offset_x_mm', 'sensor.axis_offset_y_mm', 'sensor.tilt_x_deg',
               'sensor.tilt_y_deg')


@dataclass(frozen=True)
class SensorPose:
    """Where the sensor sits against the lens axis: offsets (mm) and tilts (rad)."""

    offset_x_mm: float = 0.0
    offset_y_mm: float = 0.0
    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> SensorPose:
        """
        Return the pose the ``sensor.*`` values give.

        :param values: parameter values (missing names are 0).
        :return: the pose.
        """
        dx, dy, tx, ty = (float(values.get(name, 0.0)) for name in POSE_PARAMS)
        return cls(dx, dy, math.radians(tx), math.radians(ty))

    @property
    def tilted(self) -> bool:
        """Return True when the sensor is not normal to the axis."""
        return self.tilt_x_rad != 0.0 or self.tilt_y_rad != 0.0

    @property
    def centred(self) -> bool:
        """Return True for the ideal assembly: no offset, no tilt."""
        return not self.tilted and self.offset_x_mm == 0.0 and self.offset_y_mm == 0.0

    def rotation(self) -> FloatArray:
        """Return ``R``: its columns are the row direction, the column direction, the normal."""
        ca, sa = math.cos(self.tilt_x_rad), math.sin(self.tilt_x_rad)
        cb, sb = math.cos(self.tilt_y_rad), math.sin(self.tilt_y_rad)
        rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, sa], [0.0, -sa, ca]])
        ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
        return rx @ ry


def axis_pixel(values: Mapping[str, Any], width: int, height: int,
               pixel_mm: tuple[float, float]) -> tuple[float, float]:
    """
    Return the pixel where the lens axis meets the sensor (the raw K's principal point).

    :param values: parameter values.
    :param width: raw width, px.
    :param height: raw height, px.
    :param pixel_mm: pixel pitches (x, y), mm.
    :return: ``(c_u, c_v)``.
    """
    pose = SensorPose.from_values(values)
    return ((width - 1) / 2.0 + pose.offset_x_mm / pixel_mm[0],
            (height - 1) / 2.0 + pose.offset_y_mm / pixel_mm[1])


def plane_offsets(height: FloatArray, slope: FloatArray, cos_phi: FloatArray,
                  sin_phi: FloatArray, rotation: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Intersect chief-ray lines with the sensor plane; return the in-plane offsets (a, b), mm.

    :param height: ``h``, the line's height on the plane ``z = z_s``, mm.
    :param slope: ``s = d rho / dz``.
    :param cos_phi: cos of the azimuth.
    :param sin_phi: sin of the azimuth.
    :param rotation: :meth:`SensorPose.rotation`.
    :return: ``(a, b)`` from the axis point along the rows and columns; NaN where the line
        does not meet the plane in front (parallel to it).
    """
    r = rotation
    k = r[0, 2] * cos_phi + r[1, 2] * sin_phi
    with np.errstate(invalid='ignore', divide='ignore'):
        denominator = slope * k + r[2, 2]
        q = np.where(denominator > 0.0, height / denominator, np.nan)
    radial_a = r[0, 0] * cos_phi + r[1, 0] * sin_phi
    radial_b = r[0, 1] * cos_phi + r[1, 1] * sin_phi
    a = q * (r[2, 2] * radial_a - k * r[2, 0])
    b = q * (r[2, 2] * radial_b - k * r[2, 1])
    return a, b


def lines_at(field: RadialMap, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return the chief-ray height and slope at field angles, from the angle-uniform trace.

    :param field: the trace (``LensModel.field_curve``), with slopes.
    :param theta: field angles, rad, any shape.
    :return: ``(h, s)``; NaN beyond the traced field.
    """
    theta = np.asarray(theta, dtype=np.float64)
    h = np.full(theta.shape, np.nan)
    s = np.full(theta.shape, np.nan)
    inside = (theta >= 0.0) & (theta <= field.max_field_angle_rad)
    slope = field.slope if field.slope is not None else field.real_mm * 0.0
    h[inside] = hermite(field.field_angle_rad, field.real_mm, theta[inside])
    s[inside] = hermite(field.field_angle_rad, slope, theta[inside])
    return h, s


def _scene_distance(model: Any) -> float:
    distance = float(model.values['scene.distance_mm'])
    return distance if distance > 0.0 else math.inf


def _traced_lines(model: Any, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return the lines at ``theta``: interpolated inside the model's trace, traced beyond it.

    Beyond the trace (a direction past the raw image) the chief rays are traced exactly,
    continued from the model's trace; where the trace ended the field (a failed ray or a
    fold) nothing beyond it is valid (NaN).
    """
    field = model.field_curve
    h, s = lines_at(field, theta)
    beyond = np.flatnonzero(np.isfinite(theta) & (theta > field.max_field_angle_rad))
    if beyond.size == 0 or field.folded:
        return h, s
    order = beyond[np.argsort(theta[beyond], kind='stable')]
    guide = None
    if field.aim_offsets is not None:
        guide = (field.field_angle_rad, field.aim_offsets)
    heights, slopes, _ = model.source.chief_lines(theta[order], _scene_distance(model), guide)
    heights, slopes = np.asarray(heights, dtype=np.float64), np.asarray(slopes, np.float64)
    # The field ends at the first failure or non-increase of the height past the trace.
    good = np.isfinite(heights) & np.isfinite(slopes)
    good &= np.diff(np.concatenate(([field.valid_real_mm], heights))) >= 0.0
    end = int(np.argmin(good)) if not good.all() else order.size
    h[order[:end]], s[order[:end]] = heights[:end], slopes[:end]
    return h, s


def project_angles(model: Any, theta: FloatArray,
                   phi: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Project scene directions given by field angle and azimuth to raw pixels.

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param theta: field angles seen from H, rad (past 90 deg for a fisheye at infinity).
    :param phi: azimuths ``atan2(ty, tx)``, rad.
    :return: ``(u, v)`` raw pixels (outside the image where the ray meets the sensor's plane
        beyond its pixels); NaN where no chief ray passes the lens.
    """
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    h, s = _traced_lines(model, theta.ravel())
    a, b = plane_offsets(h, s, np.cos(phi).ravel(), np.sin(phi).ravel(),
                         SensorPose.from_values(model.values).rotation())
    u = model.K[0, 2] + a / model.pixel_mm[0]
    v = model.K[1, 2] + b / model.pixel_mm[1]
    return u.reshape(theta.shape), v.reshape(theta.shape)


def project(model: Any, tx: FloatArray, ty: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Project scene directions (tangents in the camera's optical frame) to raw pixels.

    The contract of ``mechdeconv project``: ``tx = X / Z``, ``ty = Y / Z`` (X right, Y down, Z
    along the axis from H; the point on the plane at ``scene.distance_mm``, a direction at 0).

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param tx: X / Z, any shape.
    :param ty: Y / Z, same shape.
    :return: ``(u, v)``, see :func:`project_angles`.
    """
    tx = np.asarray(tx, dtype=np.float64)
    ty = np.asarray(ty, dtype=np.float64)
    return project_angles(model, np.arctan(np.hypot(tx, ty)), np.arctan2(ty, tx))


def unproject_angles(model: Any, u: FloatArray,
                     v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return the scene direction (theta, phi) each raw pixel sees: the inverse of projection.

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param u: raw pixel columns, any shape.
    :param v: raw pixel rows, same shape.
    :return: ``(theta, phi)`` in rad; theta NaN outside the traced field.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    r = SensorPose.from_values(model.values).rotation()
    a = (u - model.K[0, 2]) * model.pixel_mm[0]
    b = (v - model.K[1, 2]) * model.pixel_mm[1]
    qx = r[0, 0] * a + r[0, 1] * b
    qy = r[1, 0] * a + r[1, 1] * b
    qz = r[2, 0] * a + r[2, 1] * b
    radius = np.hypot(qx, qy)
    phi = np.arctan2(qy, qx)
    field = model.field_curve
    theta = field.angle_from_real(radius)
    if np.any(qz != 0.0):
        theta = _solve_theta(field, radius, qz, theta)
    return theta, phi


def _solve_theta(field: RadialMap, radius: FloatArray, dz: FloatArray,
                 start: FloatArray) -> FloatArray:
    """Solve ``h(theta) + s(theta) dz = radius`` by Newton from ``start`` (NaN: no root)."""
    top = field.max_field_angle_rad
    theta = np.where(np.isfinite(start), start, top)
    step = 1e-7 * max(top, 1e-3)
    for _ in range(INVERSE_ITERATIONS):
        h, s = lines_at(field, theta)
        other = np.where(theta + step <= top, theta + step, theta - step)
        h1, s1 = lines_at(field, other)
        value = h + s * dz
        with np.errstate(invalid='ignore', divide='ignore'):
            derivative = (h1 + s1 * dz - value) / (other - theta)
            theta = np.clip(theta - (value - radius) / derivative, 0.0, top)
    h, s = lines_at(field, theta)
    residual = np.abs(h + s * dz - radius)
    return np.where(residual <= 1e-9 * (1.0 + radius), theta, np.nan)


def unproject(model: Any, u: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return the tangents (tx, ty) of the scene direction each raw pixel sees.

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param u: raw pixel columns.
    :param v: raw pixel rows.
    :return: ``(tx, ty)``; NaN outside the field or at 90 deg and beyond.
    """
    theta, phi = unproject_angles(model, u, v)
    with np.errstate(invalid='ignore'):
        t = np.where(theta < 0.5 * math.pi, np.tan(theta), np.nan)
    return t * np.cos(phi), t * np.sin(phi)
