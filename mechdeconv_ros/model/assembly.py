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

from mechdeconv_ros.lenses.lens_errors import FloatArray, ModelError
from mechdeconv_ros.model.radial_map import hermite, RadialMap
from mechdeconv_ros.optics.prescription import vertex_z
from mechdeconv_ros.optics.surfaces import domain_limit_mm, sag
from mechdeconv_ros.schema.params import scene_distance
import numpy as np

#: Newton iterations of the inverse projection (quadratic convergence from the untilted root).
INVERSE_ITERATIONS = 12
#: Points per side of the sensor grid on which a tilted sensor's clearance from the last
#: lens surface is checked.
CLEARANCE_GRID = 33
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
    point = r[:, :2] @ np.stack([(uu - camera.K[0, 2]) * px, (vv - camera.K[1, 2]) * py])
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
