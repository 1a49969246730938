# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The camera as assembled (issue 25): projection, its inverse, offsets and tilts, the CLI."""

from __future__ import annotations

import math

from mechdeconv_ros.model.assembly import (
    plane_offsets, project, SensorPose, unproject, unproject_angles)
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.tools.cli import main
import numpy as np
from numpy.testing import assert_allclose
import pytest

SIZE = {'sensor.width_px': 640, 'sensor.height_px': 480}


def _directions(n=9, reach=0.5):
    t = np.linspace(-reach, reach, n)
    tx, ty = np.meshgrid(t, 0.75 * t)
    return tx.ravel(), ty.ravel()


@pytest.fixture(scope='module')
def centred():
    return build_model(SIZE)


def test_centred_projection_is_the_radial_model(centred):
    tx, ty = _directions()
    u, v = project(centred, tx, ty)
    # The radial model: corrected pixel of the direction -> raw pixel (its own interpolation).
    k_new = centred.K_new
    rect = np.stack([k_new[0, 2] + k_new[0, 0] * tx, k_new[1, 2] + k_new[1, 1] * ty], axis=-1)
    raw = centred.raw_from_rect(rect)
    inside = np.isfinite(raw[:, 0])     # the radial map ends past the output corner
    assert inside.sum() > 20 and np.all(np.isfinite(u))
    assert_allclose(u[inside], raw[inside, 0], atol=1e-5)
    assert_allclose(v[inside], raw[inside, 1], atol=1e-5)


def test_offset_moves_every_pixel_by_the_offset(centred):
    model = build_model({**SIZE, 'sensor.axis_offset_x_mm': 0.04,
                         'sensor.axis_offset_y_mm': -0.025})
    px, py = model.pixel_mm
    assert model.K[0, 2] == pytest.approx(319.5 + 0.04 / px)
    assert model.K[1, 2] == pytest.approx(239.5 - 0.025 / py)
    tx, ty = _directions()
    u0, v0 = project(centred, tx, ty)
    u, v = project(model, tx, ty)
    assert_allclose(u - u0, 0.04 / px, atol=1e-9)
    assert_allclose(v - v0, -0.025 / py, atol=1e-9)


def test_rotation_follows_the_issue_conventions():
    pose = SensorPose(tilt_x_rad=math.radians(1.0))
    r = pose.rotation()
    # Rows of larger v (b > 0) come closer to the lens (smaller z).
    assert r[2, 1] < 0 and r[2, 0] == 0
    r = SensorPose(tilt_y_rad=math.radians(1.0)).rotation()
    assert r[2, 0] < 0 and r[2, 1] == 0
    # Both: tilt_y about the turned column line, which keeps R e_y = R_x e_y.
    r = SensorPose(tilt_x_rad=0.3, tilt_y_rad=0.2).rotation()
    assert_allclose(r[:, 1], [0.0, math.cos(0.3), -math.sin(0.3)])
    assert_allclose(r.T @ r, np.eye(3), atol=1e-15)


def test_plane_offsets_by_hand():
    # tilt_x = 45 deg, a ray at phi = 90 deg (down the columns), h = 1, slope 0.5: the plane
    # b (0, cos, -sin) meets the line (0, 1 + 0.5 t, t) where t = -(1 + 0.5 t) -> t = -2/3,
    # at b = sqrt(2) * 2/3.
    r = SensorPose(tilt_x_rad=math.pi / 4).rotation()
    a, b = plane_offsets(np.array([1.0]), np.array([0.5]), np.array([0.0]), np.array([1.0]), r)
    assert a[0] == pytest.approx(0.0, abs=1e-15)
    assert b[0] == pytest.approx(math.sqrt(2.0) * 2.0 / 3.0, rel=1e-12)


def test_tilt_moves_rows_of_larger_v_inwards(centred):
    model = build_model({**SIZE, 'sensor.tilt_x_deg': 1.0})
    _, v0 = project(centred, np.array([0.0, 0.0]), np.array([0.2, -0.2]))
    _, v = project(model, np.array([0.0, 0.0]), np.array([0.2, -0.2]))
    # Diverging image-space chief rays: the nearer half of the sensor sees them closer in.
    assert v[0] < v0[0] and v[1] < v0[1]
    assert model.K[1, 2] == centred.K[1, 2]


@pytest.mark.parametrize('pose', [
    {'sensor.tilt_x_deg': 1.0, 'sensor.tilt_y_deg': -0.7},
    {'sensor.axis_offset_x_mm': 0.2, 'sensor.axis_offset_y_mm': -0.1,
     'sensor.tilt_x_deg': -1.0, 'sensor.tilt_y_deg': 1.0}])
def test_round_trip(pose):
    model = build_model({**SIZE, **pose})
    u = np.linspace(-0.5, 639.5, 23)
    v = np.linspace(-0.5, 479.5, 19)
    uu, vv = (a.ravel() for a in np.meshgrid(u, v))
    tx, ty = unproject(model, uu, vv)
    assert np.all(np.isfinite(tx))
    u2, v2 = project(model, tx, ty)
    assert_allclose(u2, uu, atol=1e-6)
    assert_allclose(v2, vv, atol=1e-6)
    theta, phi = unproject_angles(model, np.array([model.K[0, 2]]), np.array([model.K[1, 2]]))
    assert theta[0] == pytest.approx(0.0, abs=1e-9)


def test_cli_project(tmp_path, capsys):
    path = tmp_path / 'in.csv'
    path.write_text('# tx,ty\n0,0\n0.1, -0.05\n\n50,50\n')
    status = main(['project', '--width', '640', '--height', '480', '-p',
                   'sensor.axis_offset_x_mm=0.04', '-p', 'sensor.tilt_y_deg=0.5', str(path)])
    out, _ = capsys.readouterr()
    assert status == 0
    rows = [line.split(',') for line in out.splitlines()]
    assert len(rows) == 3 and all(len(r) == 4 for r in rows)
    model = build_model({**SIZE, 'sensor.axis_offset_x_mm': 0.04, 'sensor.tilt_y_deg': 0.5})
    u, v = project(model, np.array([0.0, 0.1]), np.array([0.0, -0.05]))
    assert float(rows[0][2]) == pytest.approx(model.K[0, 2])
    assert [float(rows[1][2]), float(rows[1][3])] == pytest.approx([u[1], v[1]], abs=1e-9)
    # 89.2 deg: the chief ray still passes the bare thick lens, far beyond the pixels.
    assert float(rows[2][2]) > 640 and float(rows[2][3]) > 480


def test_cli_project_names_the_bad_line(tmp_path, capsys):
    path = tmp_path / 'in.csv'
    path.write_text('0,0\n1;2\n')
    status = main(['project', '--width', '64', '--height', '48', str(path)])
    _, err = capsys.readouterr()
    assert status == 2 and 'in.csv:2' in err
