# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The rotation conventions of optics/pose.py by value (docs/design.md section 1.1).

Each statement of the conventions (which part of a tilted plane comes closer to the lens, the
rig's order, the Zemax break's signs) is checked on numbers, not on the module's own formulas.
"""

from __future__ import annotations

import math

from mechdeconv_ros.optics.pose import (
    port_normal, rig_rotation, right_from_left, rot_x, rot_y, rot_z, sensor_points,
    sensor_tilts_of_break, SensorPose, tilt_rotation, tilts_from_fixed_axes)
import numpy as np
from numpy.testing import assert_allclose
import pytest

E_X, E_Y, E_Z = np.eye(3)


@pytest.mark.parametrize('rotation, start, towards', [
    (rot_x, E_Y, E_Z), (rot_y, E_Z, E_X), (rot_z, E_X, E_Y)], ids=['x', 'y', 'z'])
def test_elementary_rotations_are_right_handed(rotation, start, towards) -> None:
    # A small positive turn about an axis moves the next axis towards the one after it.
    turned = rotation(0.01) @ start
    assert turned @ towards == pytest.approx(math.sin(0.01))
    assert_allclose(rotation(0.3) @ rotation(-0.3), np.eye(3), atol=1e-15)
    assert np.linalg.det(rotation(0.3)) == pytest.approx(1.0)


def test_sensor_tilt_x_brings_rows_of_larger_v_closer() -> None:
    # Read-out frame: b along v, z > 0 away from the lens.
    r = SensorPose(tilt_x_rad=math.radians(1.0)).rotation()
    _, _, qz = sensor_points(r, np.array([0.0, 0.0]), np.array([1.0, -1.0]))
    assert qz[0] == pytest.approx(-math.sin(math.radians(1.0)))
    assert qz[1] > 0.0
    _, _, qz_u = sensor_points(r, np.array([1.0]), np.array([0.0]))
    assert qz_u[0] == pytest.approx(0.0, abs=1e-15)


def test_sensor_tilt_y_is_about_the_turned_column_line() -> None:
    a, b = math.radians(0.6), math.radians(0.9)
    r = SensorPose(tilt_x_rad=a, tilt_y_rad=b).rotation()
    # tilt_y > 0 brings the columns of larger u closer: the turned row direction's z is
    # -cos a sin b, and the normal leans by exactly b towards +a.
    assert r[2, 0] == pytest.approx(-math.cos(a) * math.sin(b))
    assert r[0, 2] == pytest.approx(math.sin(b))
    # The column direction is the one tilt_x made, untouched by tilt_y (the turned line).
    assert_allclose(r[:, 1], [0.0, math.cos(a), -math.sin(a)], atol=1e-15)
    # The matrix the sensor has always had (assembly's R_x(alpha) R_y(beta) as written).
    ca, sa, cb, sb = math.cos(a), math.sin(a), math.cos(b), math.sin(b)
    old = (np.array([[1, 0, 0], [0, ca, sa], [0, -sa, ca]])
           @ np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]]))
    assert_allclose(r, old, atol=1e-16)


@pytest.mark.parametrize('tilt_x, tilt_y', [(1.0, 0.0), (0.0, 1.0), (1.0, -0.5)],
                         ids=['x', 'y', 'both'])
def test_port_tilts_bring_the_part_seen_at_larger_v_and_u_closer(tilt_x, tilt_y) -> None:
    # The ports' frame: x = X, y = Y, z along the light; the lens is at larger z.
    a, b = math.radians(tilt_x), math.radians(tilt_y)
    n = port_normal(a, b)
    assert np.linalg.norm(n) == pytest.approx(1.0)
    # The point of the plane at unit distance along +y (+x) from the axis point: z = -n.p/n_z.
    for axis, tilt in ((1, a), (0, b)):
        z = -n[axis] / n[2]
        assert np.sign(z) == np.sign(tilt)
    # Single tilts: the plane turned by exactly the tilt.
    if tilt_y == 0.0:
        assert_allclose(n, [0.0, -math.sin(a), math.cos(a)], atol=1e-16)
    # Both: about the port's own turned column line, as the sensor (sin b exactly in x).
    assert n[0] == pytest.approx(-math.sin(b))


def test_sensor_and_port_tilts_are_one_rotation() -> None:
    # The same tilt_rotation for both: the port's normal is the sensor's turned into the
    # ports' frame (toward the lens, z = -Z).
    a, b = 0.3, -0.2
    t = tilt_rotation(a, b)
    assert_allclose(SensorPose(tilt_x_rad=a, tilt_y_rad=b).rotation(), t)
    assert_allclose(port_normal(a, b), [-t[0, 2], -t[1, 2], t[2, 2]])


def test_rig_rotation_order_and_transform() -> None:
    # z first: a quarter turn about Z takes X to Y; then about Y.
    assert_allclose(rig_rotation(0.0, 0.0, 90.0) @ E_X, E_Y, atol=1e-15)
    r = rig_rotation(2.0, -3.0, 5.0)
    assert_allclose(r, rot_x(math.radians(2.0)) @ rot_y(math.radians(-3.0))
                    @ rot_z(math.radians(5.0)))
    assert_allclose(r.T @ r, np.eye(3), atol=1e-15)
    # A point on the right camera's axis, the right camera 120 mm to the right, turned about
    # Y by 10 deg (its Z towards +X): X_r = R^T (X_l - t).
    t = np.array([120.0, 0.0, 0.0])
    r = rig_rotation(0.0, 10.0, 0.0)
    point = t + 500.0 * (r @ E_Z)
    assert_allclose(right_from_left(point, r, t), [0.0, 0.0, 500.0], atol=1e-12)
    assert (r @ E_Z)[0] > 0.0


def test_zemax_break_signs() -> None:
    # The break's frame F = R_x(a) R_y(b) in the lens frame (x = X, y = -Y, z = -Z); the
    # read-out frame has a = -x, b = y, z = z: there F is M F M, M = diag(-1, 1, 1).
    rng = np.random.default_rng(0)
    for a_deg, b_deg in rng.uniform(-5.0, 5.0, (5, 2)):
        f = rot_x(math.radians(a_deg)) @ rot_y(math.radians(b_deg))
        m = np.diag([-1.0, 1.0, 1.0])
        tx, ty = sensor_tilts_of_break(a_deg, b_deg)
        assert_allclose(tilt_rotation(math.radians(tx), math.radians(ty)), m @ f @ m,
                        atol=1e-15)
    # A right-handed break tilt about x lifts the file's +y (larger v) away from the lens.
    assert sensor_tilts_of_break(1.0, 0.0)[0] < 0.0


def test_axis_pixel() -> None:
    pose = SensorPose(offset_x_mm=0.02, offset_y_mm=-0.01)
    assert pose.axis_pixel(641, 481, (0.005, 0.004)) == pytest.approx((324.0, 237.5))


@pytest.mark.parametrize('tilt_x, tilt_y', [(1.0, -0.5), (20.0, 30.0), (-40.0, 10.0)],
                         ids=['small', 'large', 'negative'])
def test_tilts_from_fixed_axes_keep_the_old_port_plane(tilt_x, tilt_y) -> None:
    # Before issue 37 the flat port turned about the fixed y axis: n = R_y(b) R_x(a) e_z in the
    # ports' frame, with R_x(a) e_y = (0, cos a, sin a) and R_y(b) e_x = (cos b, 0, sin b).
    a, b = math.radians(tilt_x), math.radians(tilt_y)
    old = np.array([-math.sin(b) * math.cos(a), -math.sin(a), math.cos(a) * math.cos(b)])
    assert_allclose(port_normal(*tilts_from_fixed_axes(a, b)), old, atol=1e-15)
    assert tilts_from_fixed_axes(a, 0.0) == pytest.approx((a, 0.0))
    # Both tilts at once: the two conventions differ (the reason the conversion exists).
    assert np.max(np.abs(port_normal(a, b) - old)) > 1e-7
