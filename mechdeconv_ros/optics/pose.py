# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The pose of every tilted thing (sensor, flat port, stereo rig): one set of rotations.

Pure numpy, no ROS. docs/design.md section 1.1 states these conventions once; this module is
the only place that builds a rotation. Angles in rad unless a name ends in ``_deg``.

Frames
------
- C, the camera's optical frame (REP-103): X right, Y down, Z ahead along the lens axis
  (towards the scene); right-handed. Every rotation below is a matrix of C.
- the lens frame of prescriptions, Zemax and optiland: z along the light (``-Z``), y up in the
  image (``-Y``), ``x = X``: C turned half a turn about X (right-handed).
- the sensor's read-out frame ``(a, b, z)``: a along u (the rows), b along v (the columns), z
  along the axis towards the sensor. The raw image is the inverted image read upright, so
  ``(a, b, z) = -(X, Y, Z)`` (a point reflection of C): a matrix is the same in both frames.
- the frame of :mod:`mechdeconv_ros.optics.ports`: ``x = X``, ``y = Y``, z along the light
  (``-Z``): C mirrored in its XY plane (refraction does not mind the mirror).

Elementary rotations (right-handed, active: a vector turned by +t about an axis turns
counter-clockwise seen from the axis's tip)::

    R_x(t) = [[1, 0, 0], [0, c, -s], [0, s, c]]
    R_y(t) = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    R_z(t) = [[c, -s, 0], [s, c, 0], [0, 0, 1]]

A tilted plane, ``tilt_x``, ``tilt_y`` (the sensor's ``sensor.tilt_*_deg``, a flat port's
``port.tilt_*_deg``): :func:`tilt_rotation` ``T = R_x(-tilt_x) R_y(tilt_y)`` of C: the plane
is turned by tilt_x about its row line (X) first, then by tilt_y about its own turned column
line. tilt_x > 0 brings the part of the plane imaged at larger v (image rows further down)
closer to the lens, tilt_y > 0 the part imaged at larger u. One rotation for both: behind the
lens the image is inverted (larger v is at -Y on the sensor, +Y on the port) and "closer" is
+Z behind the lens, -Z in front; the two sign changes cancel.

- The sensor: its read-out axes (row, column, normal away from the lens) are the columns of
  ``T`` in the read-out frame (:meth:`SensorPose.rotation`); a pixel at in-plane offsets
  ``(a, b)`` from the axis point is the point ``T (a, b, 0)`` from it.
- A flat port: its normal towards the scene is ``T e_Z`` in C; :func:`port_normal` gives the
  one towards the lens in the ports' frame.
- The stereo rig (:func:`rig_rotation`): ``R = R_x(rx) R_y(ry) R_z(rz)``, right-handed active
  rotations about the left camera's axes (C of the left camera), applied z first; R's columns
  are the right camera's axes in the left frame, and a point goes from the left frame to the
  right one as ``X_r = R^T (X_l - t)``, ``t`` the right camera's centre in the left frame.

Zemax (:func:`sensor_tilts_of_break`): a coordinate break's ``PARM 3, 4`` tilt about x, then
about the new y (deg, right-handed in the lens frame): its frame ``F = R_x(a) R_y(b)`` in the
lens frame. In the read-out frame (``a = -x``, ``b = y``: a mirror of x) it is
``R_x(a) R_y(-b) = T(-a, -b)``: ``sensor.tilt_x_deg = -a``, ``sensor.tilt_y_deg = -b`` (a
right-handed tilt about x lifts the file's +y, the image's larger v, away from the lens).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Mapping

import numpy as np
import numpy.typing as npt

Matrix = npt.NDArray[np.float64]
Array = npt.NDArray[np.float64]

#: The parameters of the sensor's pose, in the order of :class:`SensorPose`.
POSE_PARAMS = ('sensor.axis_offset_x_mm', 'sensor.axis_offset_y_mm', 'sensor.tilt_x_deg',
               'sensor.tilt_y_deg')


def rot_x(angle: float) -> Matrix:
    """Return ``R_x(angle)``, the right-handed active rotation about x (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> Matrix:
    """Return ``R_y(angle)``, the right-handed active rotation about y (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> Matrix:
    """Return ``R_z(angle)``, the right-handed active rotation about z (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def tilt_rotation(tilt_x: float, tilt_y: float) -> Matrix:
    """
    Return the rotation of a tilted plane (sensor or flat port): ``R_x(-tilt_x) R_y(tilt_y)``.

    :param tilt_x: rad; > 0 brings the part imaged at larger v closer to the lens.
    :param tilt_y: rad, about the plane's turned column line; > 0: larger u closer.
    :return: 3 x 3, in C (and in the sensor's read-out frame).
    """
    return rot_x(-tilt_x) @ rot_y(tilt_y)


def port_normal(tilt_x: float, tilt_y: float) -> Array:
    """
    Return a flat port's unit normal towards the lens, in the frame of optics/ports.py.

    ``T e_Z`` faces the scene in C; towards the lens it is ``-T e_Z``, and the ports' frame
    has z = -Z: ``(-T_02, -T_12, T_22)``, i.e. ``(-sin b, -sin a cos b, cos a cos b)``.

    :param tilt_x: ``port.tilt_x_deg`` in rad.
    :param tilt_y: ``port.tilt_y_deg`` in rad.
    :return: ``(3,)``.
    """
    t = tilt_rotation(tilt_x, tilt_y)
    return np.array([-t[0, 2], -t[1, 2], t[2, 2]])


def tilts_from_fixed_axes(tilt_x: float, tilt_y: float) -> tuple[float, float]:
    """
    Return the tilts that turn a plane as ``tilt_x`` then ``tilt_y`` about the FIXED y axis.

    The flat port's convention before issue 37 (``n = R_y R_x``, optiland's ``rx``, ``ry``
    order): the same plane (normal) in this module's convention has ``sin b' = sin b cos a``
    and ``sin a' = sin a / cos b'``. Single tilts are unchanged.

    :param tilt_x: rad, applied first.
    :param tilt_y: rad, about the fixed y axis.
    :return: ``(tilt_x', tilt_y')`` in rad for :func:`tilt_rotation` / :func:`port_normal`.
    """
    b = math.asin(math.sin(tilt_y) * math.cos(tilt_x))
    return math.asin(math.sin(tilt_x) / math.cos(b)), b


def rig_rotation(rx_deg: float, ry_deg: float, rz_deg: float) -> Matrix:
    """
    Return a stereo rig's rotation ``R = R_x(rx) R_y(ry) R_z(rz)`` (module docstring).

    :param rx_deg: about the left camera's X (right), deg.
    :param ry_deg: about its Y (down), deg.
    :param rz_deg: about its Z (ahead), deg; applied first.
    :return: 3 x 3: its columns are the right camera's axes in the left camera's frame.
    """
    return (rot_x(math.radians(rx_deg)) @ rot_y(math.radians(ry_deg))
            @ rot_z(math.radians(rz_deg)))


def right_from_left(points: Array, rotation: Matrix, translation: Array) -> Array:
    """
    Return points of the left camera's frame in the right camera's: ``R^T (X_l - t)``.

    :param points: ``(..., 3)`` in the left camera's optical frame.
    :param rotation: :func:`rig_rotation`.
    :param translation: ``t``, the right camera's centre in the left frame (same unit).
    :return: ``(..., 3)`` in the right camera's optical frame.
    """
    p = np.asarray(points, dtype=np.float64) - np.asarray(translation, dtype=np.float64)
    return p @ np.asarray(rotation, dtype=np.float64)


def sensor_tilts_of_break(a_deg: float, b_deg: float) -> tuple[float, float]:
    """
    Return ``(sensor.tilt_x_deg, sensor.tilt_y_deg)`` of a Zemax break's tilts (docstring).

    :param a_deg: the break's ``PARM 3``, tilt about x, deg.
    :param b_deg: its ``PARM 4``, then about the new y, deg.
    :return: ``(-a, -b)``.
    """
    return -a_deg, -b_deg


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

    def rotation(self) -> Matrix:
        """Return ``T``: its columns are the row direction, the column direction, the normal."""
        return tilt_rotation(self.tilt_x_rad, self.tilt_y_rad)

    def axis_pixel(self, width: int, height: int,
                   pixel_mm: tuple[float, float]) -> tuple[float, float]:
        """
        Return the pixel where the lens axis meets the sensor (the raw K's principal point).

        :param width: raw width, px.
        :param height: raw height, px.
        :param pixel_mm: pixel pitches (x, y), mm.
        :return: ``c = ((W - 1) / 2 + dx / p_x, (H - 1) / 2 + dy / p_y)``.
        """
        return ((width - 1) / 2.0 + self.offset_x_mm / pixel_mm[0],
                (height - 1) / 2.0 + self.offset_y_mm / pixel_mm[1])


def sensor_points(rotation: Matrix, a: Array, b: Array) -> tuple[Array, Array, Array]:
    """
    Return ``Q = T (a, b, 0)``: pixels at in-plane offsets from the axis point, read-out frame.

    :param rotation: :meth:`SensorPose.rotation`.
    :param a: offsets along the rows (u), mm.
    :param b: offsets down the columns (v), mm.
    :return: ``(Q_x, Q_y, Q_z)``; ``Q_z`` > 0 away from the lens.
    """
    r = rotation
    return (r[0, 0] * a + r[0, 1] * b, r[1, 0] * a + r[1, 1] * b, r[2, 0] * a + r[2, 1] * b)
