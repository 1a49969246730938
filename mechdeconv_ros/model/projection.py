# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The one public projection: scene direction <-> raw pixel, for any lens, pose and port.

Pure numpy, no ROS. Frames, rotations and signs: docs/design.md section 1.1 and
:mod:`mechdeconv_ros.optics.pose` (the sensor's pose ``T``, its axis pixel). A scene direction
is a unit vector ``d = (x, y, z)`` in the camera's optical frame (X right, Y down, Z ahead;
``z <= 0`` is behind the lens plane: a fisheye sees past 90 deg), or its tangents
``tx = X / Z``, ``ty = Y / Z``, field angle ``theta = atan(hypot(tx, ty))``, azimuth
``phi = atan2(ty, tx)``. A raw pixel is ``(u, v)``, u along the rows, v down the columns, the
centre of the top-left pixel at (0, 0). The scene is at ``scene.distance_mm`` (0: infinity).

- :func:`pixels_of` (forward) and :func:`directions_of` (inverse): the public pair that
  ``mechdeconv project``, the remap and the self-check compute; :func:`project_points` is the
  same forward in tangents (the CLI's input). Nothing else in the package solves the chief-ray
  lines for a pose.

The chief-ray lines: a rotationally symmetric lens sends the chief ray of (theta, phi) into
image space as a line in the meridional plane of azimuth phi, in the read-out frame
``(a, b) = rho(z) (cos phi, sin phi)``, ``rho(z) = h(theta) + s(theta) (z - z_s)`` (``h`` the
real height on the paraxial sensor plane ``z_s``, ``s`` its slope; :meth:`~mechdeconv_ros.
lenses.lens_source.LensSource.chief_lines`).

Forward (exact, no small angle): the sensor is the plane through ``O = (0, 0, z_s)`` with
normal ``n = T e_z``; the line meets it where ``n . (P - O) = 0``: with ``k = n_x cos phi +
n_y sin phi`` and ``q = h / (s k + n_z)``, ``P - O = (q n_z cos phi, q n_z sin phi, -q k)``
and the pixel is ``c + ((T^T (P - O))_{0,1}) / p`` (``c`` the axis pixel, ``p`` the pitches).
A line parallel to the plane (``s k + n_z <= 0``) meets it nowhere in front: NaN. ``h`` and
``s`` come from the cubic Hermite interpolation of the angle-uniform field trace; beyond it
the chief rays are traced exactly, continued from it.

Inverse (raw pixel -> direction, :func:`pixel_rays`): ``Q = T (a, b, 0)`` (``(a, b) = (u -
c_u, v - c_v) p``, :func:`mechdeconv_ros.optics.pose.sensor_points`) gives ``phi = atan2(Q_y,
Q_x)`` and the equation ``h(theta) + s(theta) (Q_z + dz) = hypot(Q_x, Q_y)`` in theta (``dz``
a defocus of the sensor, the self-check's fifth pose parameter), solved by Newton either on
the same cubic interpolant as the forward (:func:`unproject_angles`: the two agree to 1e-9 px,
tilted or not) or, for the self-check's many points, on a dense uniform table
(:class:`LineTable`, linear pieces, error below 1e-8 mm).

A tilted flat port or a decentred dome breaks the symmetry: the forward traces each
direction's chief ray in 3-D (:meth:`~mechdeconv_ros.lenses.port_source.PortedSource.
sensor_points`), and the inverse is a 2-D Newton on that forward from the symmetric port's
inverse (finite-difference Jacobian, to 1e-9 px).

The maps' form (:class:`MapForm`, :func:`raw_from_normalised`): the forward written linear in
a corrected pixel's normalised coordinates, for the remap (docs/design.md section 2.16).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

from mechdeconv_ros.lenses.lens_errors import FloatArray
from mechdeconv_ros.lenses.port_source import PortedSource
from mechdeconv_ros.model.radial_map import hermite, RadialMap
from mechdeconv_ros.optics.pose import sensor_points, SensorPose
from mechdeconv_ros.schema.params import scene_distance
import numpy as np

#: Newton iterations of the inverse projection (quadratic convergence from the untilted root).
INVERSE_ITERATIONS = 12
#: Samples of the dense table of h(theta), s(theta) the self-check's inverse interpolates
#: linearly (its error h'' dtheta^2 / 8 is below 1e-8 mm for the wide-angle and fisheye).
TABLE_SAMPLES = 8192
#: Newton steps of the table inverse from the untilted root.
NEWTON_STEPS = 4
#: The 2-D Newton of a non-symmetric port's inverse: iterations, its finite-difference step
#: (in tangent) and its tolerance (px).
PORT_ITERATIONS = 8
PORT_STEP = 1e-7
PORT_TOLERANCE_PX = 1e-9


def is_exact_3d(model: Any) -> bool:
    """Return True when the model's port breaks the rotational symmetry (traced in 3-D)."""
    source = model.source
    return (isinstance(source, PortedSource) and source.port is not None
            and not source.port.symmetric)


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


def plane_offsets(height: FloatArray, slope: FloatArray, cos_phi: FloatArray,
                  sin_phi: FloatArray, rotation: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Intersect chief-ray lines with the sensor plane; return the in-plane offsets (a, b), mm.

    :param height: ``h``, the line's height on the plane ``z = z_s``, mm.
    :param slope: ``s = d rho / dz``.
    :param cos_phi: cos of the azimuth.
    :param sin_phi: sin of the azimuth.
    :param rotation: :meth:`~mechdeconv_ros.optics.pose.SensorPose.rotation`.
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
    heights, slopes, _ = model.source.chief_lines(theta[order], scene_distance(model.values),
                                                  guide)
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
    Project scene directions given by field angle and azimuth to raw pixels (no 3-D port).

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel` (or one with its
        ``values``, ``K``, ``pixel_mm``, ``field_curve`` and ``source``).
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
    Project scene tangents through the chief-ray lines (the symmetric port's, if any).

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param tx: X / Z, any shape.
    :param ty: Y / Z, same shape.
    :return: ``(u, v)``, see :func:`project_angles`.
    """
    tx = np.asarray(tx, dtype=np.float64)
    ty = np.asarray(ty, dtype=np.float64)
    return project_angles(model, np.arctan(np.hypot(tx, ty)), np.arctan2(ty, tx))


def project_points(model: Any, tx: FloatArray, ty: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return the raw pixels of scene tangents: ``mechdeconv project``'s contract.

    ``tx = X / Z``, ``ty = Y / Z`` (the point on the plane at ``scene.distance_mm``, a
    direction at 0). A tilted flat port or a decentred dome: each chief ray traced in 3-D.

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param tx: X / Z, any shape.
    :param ty: Y / Z, same shape.
    :return: ``(u, v)`` raw pixel coordinates; NaN where no chief ray passes.
    """
    tx, ty = np.broadcast_arrays(np.asarray(tx, dtype=float), np.asarray(ty, dtype=float))
    if is_exact_3d(model):
        return exact_pixels(model, np.stack([tx, ty, np.ones(tx.shape)], axis=-1))
    return project(model, tx, ty)


def exact_pixels(model: Any, directions: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return the raw pixels of scene directions traced exactly in 3-D through the model's port.

    :param model: a model whose source is a :class:`PortedSource`.
    :param directions: ``(..., 3)`` in the optical frame (X right, Y down, Z ahead); a finite
        scene has none at Z <= 0 (NaN); a scene at infinity (``scene.distance_mm`` 0) is
        traced at any angle to the axis.
    :return: ``(u, v)``, NaN where no chief ray passes.
    """
    a, b = model.source.sensor_directions(directions, scene_distance(model.values))
    return model.K[0, 2] + a / model.pixel_mm[0], model.K[1, 2] + b / model.pixel_mm[1]


def pixel_rays(pose: SensorPose, u: FloatArray, v: FloatArray, axis: tuple[float, float],
               pixel_mm: tuple[float, float], defocus_mm: float = 0.0
               ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """
    Return what the inverse solves for each raw pixel: ``hypot(Q_x, Q_y)``, phi, ``Q_z + dz``.

    :param pose: the sensor's pose (its rotation).
    :param u: raw columns.
    :param v: raw rows.
    :param axis: the axis pixel ``c`` (:meth:`SensorPose.axis_pixel`, the raw K's).
    :param pixel_mm: pitches, mm.
    :param defocus_mm: the sensor moved along the axis from ``z_s`` (> 0 away from the lens).
    :return: ``(radius_mm, phi, dz_mm)``.
    """
    a = (np.asarray(u, dtype=np.float64) - axis[0]) * pixel_mm[0]
    b = (np.asarray(v, dtype=np.float64) - axis[1]) * pixel_mm[1]
    qx, qy, qz = sensor_points(pose.rotation(), a, b)
    return np.hypot(qx, qy), np.arctan2(qy, qx), qz + defocus_mm


def unproject_angles(model: Any, u: FloatArray,
                     v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return the scene direction (theta, phi) each raw pixel sees through the chief-ray lines.

    The exact inverse of :func:`project_angles` (Newton on the same interpolant).

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param u: raw pixel columns, any shape.
    :param v: raw pixel rows, same shape.
    :return: ``(theta, phi)`` in rad; theta NaN outside the traced field.
    """
    pose = SensorPose.from_values(model.values)
    radius, phi, dz = pixel_rays(pose, u, v, (model.K[0, 2], model.K[1, 2]), model.pixel_mm)
    field = model.field_curve
    start = field.angle_from_real(radius)
    theta = _solve_theta(field, radius, dz, start)
    if not pose.tilted:
        # Untilted, the field ends where the trace's valid heights end.
        theta = np.where(np.isfinite(start), theta, np.nan)
    return theta, phi


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


class _Cubic:
    """The cubic Hermite interpolant of :func:`~mechdeconv_ros.model.radial_map.hermite`."""

    def __init__(self, x: FloatArray, y: FloatArray) -> None:
        self.x0, self.h, self.y = float(x[0]), float(x[1] - x[0]), y
        self.d = _knot_slopes(self.y, self.h)

    def __call__(self, query: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return the value and the derivative at ``query`` (within the knots)."""
        h, y, d = self.h, self.y, self.d
        k = np.clip(((query - self.x0) / h).astype(np.int64), 0, y.size - 2)
        t = (query - (self.x0 + k * h)) / h
        t2 = t * t
        t3 = t2 * t
        value = ((2.0 * t3 - 3.0 * t2 + 1.0) * y[k] + (t3 - 2.0 * t2 + t) * h * d[k]
                 + (3.0 * t2 - 2.0 * t3) * y[k + 1] + (t3 - t2) * h * d[k + 1])
        slope = ((6.0 * t2 - 6.0 * t) * (y[k] - y[k + 1]) / h + (3.0 * t2 - 4.0 * t + 1.0) * d[k]
                 + (3.0 * t2 - 2.0 * t) * d[k + 1])
        return value, slope


def _knot_slopes(y: FloatArray, h: float) -> FloatArray:
    """Return the knot slopes :func:`~mechdeconv_ros.model.radial_map.hermite` uses."""
    d = np.empty(y.size)
    d[2:-2] = (y[:-4] - 8.0 * y[1:-3] + 8.0 * y[3:-1] - y[4:]) / (12.0 * h)
    d[0] = (-25.0 * y[0] + 48.0 * y[1] - 36.0 * y[2] + 16.0 * y[3] - 3.0 * y[4]) / (12.0 * h)
    d[1] = (-3.0 * y[0] - 10.0 * y[1] + 18.0 * y[2] - 6.0 * y[3] + y[4]) / (12.0 * h)
    d[-1] = (25.0 * y[-1] - 48.0 * y[-2] + 36.0 * y[-3] - 16.0 * y[-4] + 3.0 * y[-5]) / (12.0 * h)
    d[-2] = (3.0 * y[-1] + 10.0 * y[-2] - 18.0 * y[-3] + 6.0 * y[-4] - y[-5]) / (12.0 * h)
    return d


def _solve_theta(field: RadialMap, radius: FloatArray, dz: FloatArray,
                 start: FloatArray) -> FloatArray:
    """Solve ``h(theta) + s(theta) dz = radius`` by Newton from ``start`` (NaN: no root)."""
    top = field.max_field_angle_rad
    theta = np.where(np.isfinite(start), start, top)
    slope = field.slope if field.slope is not None else field.real_mm * 0.0
    height_of, slope_of = _Cubic(field.field_angle_rad, field.real_mm), \
        _Cubic(field.field_angle_rad, slope)
    for _ in range(INVERSE_ITERATIONS):
        h, dh = height_of(theta)
        s, ds = slope_of(theta)
        with np.errstate(invalid='ignore', divide='ignore'):
            step = (h + s * dz - radius) / (dh + ds * dz)
        theta = np.clip(theta - step, 0.0, top)
        if not np.nanmax(np.abs(step), initial=0.0) > 1e-14:
            break
    h, _ = height_of(theta)
    s, _ = slope_of(theta)
    residual = np.abs(h + s * dz - radius)
    return np.where(residual <= 1e-9 * (1.0 + radius), theta, np.nan)


def _unit(theta: FloatArray, phi: FloatArray) -> FloatArray:
    """Return ``(sin theta cos phi, sin theta sin phi, cos theta)`` stacked on the last axis."""
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def pixels_of(model: Any, directions: FloatArray) -> FloatArray:
    """
    Return the raw pixel of each scene direction.

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param directions: ``(..., 3)`` directions in the optical frame (need not be unit).
    :return: ``(..., 2)`` raw pixels ``(u, v)``; NaN where no chief ray passes.
    """
    d = np.asarray(directions, dtype=np.float64)
    norm = np.linalg.norm(d, axis=-1)
    with np.errstate(invalid='ignore', divide='ignore'):
        z = np.clip(d[..., 2] / norm, -1.0, 1.0)
        theta = np.arccos(z)
        phi = np.arctan2(d[..., 1], d[..., 0])
    if is_exact_3d(model):
        # Traced exactly in 3-D through the port, scene at scene.distance_mm (0: infinity,
        # any angle; a finite scene plane has no point at z <= 0: NaN).
        u, v = exact_pixels(model, d)
    else:
        u, v = project_angles(model, theta, phi)
    return np.stack([np.asarray(u, float), np.asarray(v, float)], axis=-1)


def directions_of(model: Any, pixels: FloatArray) -> FloatArray:
    """
    Return the unit scene direction each raw pixel sees (the inverse of :func:`pixels_of`).

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param pixels: ``(..., 2)`` raw pixels ``(u, v)``.
    :return: ``(..., 3)`` unit directions in the optical frame; NaN outside the traced field.
    """
    p = np.asarray(pixels, dtype=np.float64)
    theta, phi = unproject_angles(model, p[..., 0], p[..., 1])
    if is_exact_3d(model):
        return _port_inverse(model, p, theta, phi)
    return _unit(theta, phi)


def _port_inverse(model: Any, pixels: FloatArray, theta: FloatArray,
                  phi: FloatArray) -> FloatArray:
    """Invert the 3-D port's forward by a 2-D Newton in tangents from the symmetric inverse."""
    shape = pixels.shape[:-1]
    target = pixels.reshape(-1, 2)
    with np.errstate(invalid='ignore'):
        t = np.where(theta < 0.5 * math.pi, np.tan(theta), np.nan).ravel()
    tan = np.stack([t * np.cos(phi).ravel(), t * np.sin(phi).ravel()], axis=1)
    todo = np.flatnonzero(np.all(np.isfinite(tan), axis=1))
    done = np.zeros(tan.shape[0], dtype=bool)
    for _ in range(PORT_ITERATIONS):
        if todo.size == 0:
            break
        x, y = tan[todo, 0], tan[todo, 1]
        value = np.stack(project_points(model, x, y), axis=1)
        err = value - target[todo]
        close = np.hypot(err[:, 0], err[:, 1]) <= PORT_TOLERANCE_PX
        done[todo[close]] = True
        bad = ~np.all(np.isfinite(err), axis=1)
        tan[todo[bad]] = np.nan
        keep = ~close & ~bad
        todo, x, y, value, err = todo[keep], x[keep], y[keep], value[keep], err[keep]
        fx = (np.stack(project_points(model, x + PORT_STEP, y), axis=1) - value) / PORT_STEP
        fy = (np.stack(project_points(model, x, y + PORT_STEP), axis=1) - value) / PORT_STEP
        with np.errstate(invalid='ignore', divide='ignore'):
            det = fx[:, 0] * fy[:, 1] - fy[:, 0] * fx[:, 1]
            tan[todo, 0] = x - (fy[:, 1] * err[:, 0] - fy[:, 0] * err[:, 1]) / det
            tan[todo, 1] = y - (-fx[:, 1] * err[:, 0] + fx[:, 0] * err[:, 1]) / det
    tan[~done] = np.nan
    d = np.concatenate([tan, np.ones((tan.shape[0], 1))], axis=1)
    return (d / np.linalg.norm(d, axis=1, keepdims=True)).reshape(*shape, 3)


@dataclass(frozen=True)
class LineTable:
    """The model's chief-ray lines on a dense uniform table: the inverse for many points."""

    theta: FloatArray
    height: FloatArray
    slope: FloatArray

    @classmethod
    def of(cls, model: Any) -> LineTable:
        """
        Tabulate a model's field trace (its slopes, or ``h / v`` when it has none).

        :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
        :return: the table.
        """
        field = model.field_curve
        theta0 = np.asarray(field.field_angle_rad, dtype=np.float64)
        h0 = np.asarray(field.real_mm, dtype=np.float64)
        s0 = getattr(field, 'slope', None)
        if s0 is None:
            s0 = h0 / model.image_distance_mm
        theta = np.linspace(0.0, float(theta0[-1]), TABLE_SAMPLES)
        return cls(theta, hermite(theta0, h0, theta), hermite(theta0, np.asarray(s0), theta))

    def solve(self, radius: FloatArray, dz: FloatArray) -> FloatArray:
        """Solve ``h(theta) + s(theta) dz = radius`` on the table (linear pieces; NaN: none)."""
        t, h, s = self.theta, self.height, self.slope
        step = float(t[1] - t[0])
        theta = np.interp(radius, h, t)
        for _ in range(NEWTON_STEPS):
            k = np.clip((theta / step).astype(np.int64), 0, t.size - 2)
            frac = theta / step - k
            value = h[k] + frac * (h[k + 1] - h[k]) + dz * (s[k] + frac * (s[k + 1] - s[k]))
            slope = (h[k + 1] - h[k] + dz * (s[k + 1] - s[k])) / step
            with np.errstate(invalid='ignore', divide='ignore'):
                theta = theta - (value - radius) / slope
        bad = ~np.isfinite(theta) | (theta < 0.0) | (theta > t[-1])
        return np.where(bad, np.nan, theta)

    def directions_and_scales(self, pose: SensorPose, points: FloatArray,
                              size: tuple[int, int], pixel_mm: tuple[float, float],
                              defocus_mm: float = 0.0
                              ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """
        Return the unit directions raw pixels see and, at each, the raw px per rad.

        Radial: ``(dh / dtheta + ds / dtheta (Q_z + dz)) / p`` (a step of the field angle);
        tangential: ``hypot(Q_x, Q_y) / (p sin theta)`` (a step across the azimuth), ``p``
        the geometric mean pixel pitch (docs/design.md section 2.17).

        :param pose: the sensor's pose (its axis pixel and rotation).
        :param points: ``(N, 2)`` raw (u, v).
        :param size: raw ``(width, height)``, px.
        :param pixel_mm: pitches, mm.
        :param defocus_mm: the sensor moved along the axis from ``z_s``, mm.
        :return: ``(directions (N, 3), radial (N,), tangential (N,))``; NaN outside the field.
        """
        axis = pose.axis_pixel(size[0], size[1], pixel_mm)
        radius, phi, dz = pixel_rays(pose, points[:, 0], points[:, 1], axis, pixel_mm,
                                     defocus_mm)
        theta = self.solve(radius, dz)
        dirs = _unit(theta, phi)
        pitch = math.sqrt(pixel_mm[0] * pixel_mm[1])
        with np.errstate(invalid='ignore'):
            radial = (np.interp(theta, self.theta, np.gradient(self.height, self.theta))
                      + dz * np.interp(theta, self.theta, np.gradient(self.slope, self.theta)))
        radial = radial / pitch
        with np.errstate(invalid='ignore', divide='ignore'):
            tangential = np.where(theta > 1e-6, radius / (pitch * np.sin(theta)), radial)
        return dirs, radial, tangential


@dataclass(frozen=True)
class MapForm:
    """
    The projection of a corrected pixel, linear in its normalised ideal coordinates.

    For a corrected pixel with normalised ideal coordinates ``(x, y)`` (``K_new``), radius
    ``r = hypot(x, y)`` (tan theta or theta), the curve gives ``g = h / (v r)`` (the real over
    the ideal height, 1 on the axis) and ``sigma = s / r`` (the chief ray's slope per unit of
    normalised radius). With ``L = n_x x + n_y y`` and ``D = sigma L + n_z``, the plane
    intersection of the module docstring becomes

        ``u = c_u + g (v / D) (ax x + ay y)``,  ``v = c_v + g (v / D) (bx x + by y)``

    with ``ax = (n_z R00 - n_x R20) / p_x``, ``ay = (n_z R10 - n_y R20) / p_x`` and
    ``bx``, ``by`` likewise from the second column over ``p_y``: a few multiply-adds per
    pixel (no trigonometry). ``D <= 0``: the line does not meet the plane (invalid).
    Untilted, ``D = 1`` and ``u = c_u + f_x x g``: the radial map.
    """

    cu: float
    cv: float
    v_mm: float
    ax: float
    ay: float
    bx: float
    by: float
    nx: float
    ny: float
    nz: float
    tilted: bool

    @classmethod
    def of(cls, model: Any) -> MapForm:
        """
        Return the form of a model (its K, pixel pitches, image distance and sensor pose).

        :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
        :return: the form.
        """
        pose = SensorPose.from_values(model.values)
        r = pose.rotation()
        nx, ny, nz = r[0, 2], r[1, 2], r[2, 2]
        px, py = model.pixel_mm
        return cls(float(model.K[0, 2]), float(model.K[1, 2]), float(model.image_distance_mm),
                   (nz * r[0, 0] - nx * r[2, 0]) / px, (nz * r[1, 0] - ny * r[2, 0]) / px,
                   (nz * r[0, 1] - nx * r[2, 1]) / py, (nz * r[1, 1] - ny * r[2, 1]) / py,
                   float(nx), float(ny), float(nz), pose.tilted)


def curve_tables(curve: RadialMap, v_mm: float) -> tuple[FloatArray, FloatArray]:
    """
    Return ``g = h / ideal`` and ``sigma = s / r`` over a curve's samples (ideal = v r).

    :param curve: a radial map with slopes (the model's, in the output projection).
    :param v_mm: the image distance (normalised radius = ideal / v).
    :return: ``(g, sigma)``, each the curve's length; on the axis their limits (1, and the
        slope's derivative by extrapolation).
    """
    ideal = curve.ideal_mm
    with np.errstate(invalid='ignore', divide='ignore'):
        g = np.where(ideal > 0.0, curve.real_mm / ideal, 1.0)
        slope = curve.slope if curve.slope is not None else curve.real_mm / v_mm
        sigma = np.where(ideal > 0.0, slope * v_mm / ideal, np.nan)
    if sigma.size > 2:
        sigma[0] = 2.0 * sigma[1] - sigma[2]
    elif sigma.size:
        sigma[0] = sigma[-1] if sigma.size > 1 else 1.0
    return g, sigma


def raw_from_normalised(model: Any, x: FloatArray, y: FloatArray, curve: RadialMap | None = None,
                        hold: bool = False) -> tuple[FloatArray, FloatArray]:
    """
    Return the raw pixel of normalised ideal coordinates (the maps' equation, in float64).

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param x: ideal ``x`` (tan theta cos phi for a pinhole output, theta cos phi equidistant).
    :param y: ideal ``y``.
    :param curve: the radial map (default ``model.curve``; a colour channel's).
    :param hold: beyond the curve keep its last sample (a moving lens's node map) instead of
        NaN.
    :return: ``(u, v)``; NaN outside the valid field or where no line meets the plane.
    """
    form = MapForm.of(model)
    curve = model.curve if curve is None else curve
    g_table, sigma_table = curve_tables(curve, form.v_mm)
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    ideal = np.hypot(x, y) * form.v_mm
    g = np.interp(ideal, curve.ideal_mm, g_table)
    sigma = np.interp(ideal, curve.ideal_mm, sigma_table)
    if not hold:
        g = np.where(ideal <= curve.valid_ideal_mm, g, np.nan)
    denominator = sigma * (form.nx * x + form.ny * y) + form.nz
    with np.errstate(invalid='ignore', divide='ignore'):
        q = np.where(denominator > 0.0, g * form.v_mm / denominator, np.nan)
    return (form.cu + q * (form.ax * x + form.ay * y),
            form.cv + q * (form.bx * x + form.by * y))
