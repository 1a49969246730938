# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The camera as assembled (issue 25): projection, its inverse, offsets and tilts, the CLI."""

from __future__ import annotations

import math

from mechdeconv_ros.model.assembly import (
    plane_offsets, project, SensorPose, unproject, unproject_angles)
from mechdeconv_ros.model.model import build_model, ModelError
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


@pytest.mark.parametrize('extra, parameter, words', [
    ({'sensor.axis_offset_x_mm': 1.4}, 'sensor.axis_offset_x_mm', 'off the sensor'),
    ({'sensor.axis_offset_y_mm': -1.1}, 'sensor.axis_offset_y_mm', 'off the sensor'),
    # A sensor 0.05 mm behind the vertex of the convex rear surface (r2 = -4 mm): tilted
    # 10 deg, its pixels 0.4 to 1 mm from the axis would cut the glass.
    ({'lens.image_distance_mm': 0.05, 'sensor.tilt_y_deg': 10.0}, 'sensor.tilt_y_deg',
     'hit the lens'),
    ({'lens.image_distance_mm': 0.05, 'sensor.tilt_x_deg': -9.0, 'sensor.tilt_y_deg': 3.0},
     'sensor.tilt_x_deg', 'hit the lens'),
])
def test_refusals_name_the_parameter(extra, parameter, words):
    with pytest.raises(ModelError) as err:
        build_model({**SIZE, **extra})
    assert err.value.parameter == parameter and words in str(err.value)


def test_refusal_on_the_cli(capsys):
    status = main(['project', '--width', '640', '--height', '480', '-p',
                   'sensor.axis_offset_x_mm=2', '-'])
    _, err = capsys.readouterr()
    assert status == 2 and 'sensor.axis_offset_x_mm' in err


def _consumer_error(model, every_px=(41, 31)):
    """Largest distance between a raw pixel and where cv2 projects its traced direction."""
    import cv2
    us = np.linspace(0, model.width - 1, every_px[0])
    vs = np.linspace(0, model.height - 1, every_px[1])
    uu, vv = (a.ravel() for a in np.meshgrid(us, vs))
    theta, phi = unproject_angles(model, uu, vv)
    keep = np.isfinite(theta) & (theta < math.radians(89.0))
    t = np.tan(theta[keep])
    points = np.stack([t * np.cos(phi[keep]), t * np.sin(phi[keep]), np.ones(t.size)], axis=1)
    projected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), model.K,
                                     np.array(model.D))
    projected = projected.reshape(-1, 2)
    return float(np.max(np.hypot(projected[:, 0] - uu[keep], projected[:, 1] - vv[keep])))


def test_camera_info_of_an_offset_sensor_is_exact_for_consumers():
    model = build_model({**SIZE, 'sensor.axis_offset_x_mm': 0.04,
                         'sensor.axis_offset_y_mm': -0.025})
    assert model.distortion_model == 'plumb_bob'
    assert _consumer_error(model) <= 0.05
    assert model.equivalent_max_error_px <= 0.05
    # A consumer's rectification (cv2.initUndistortRectifyMap on K, D, to our K_new) against
    # the traced maps.
    import cv2
    map_x, map_y = cv2.initUndistortRectifyMap(model.K, np.array(model.D), None, model.K_new,
                                               (model.out_width, model.out_height),
                                               cv2.CV_32FC1)
    uu, vv = np.meshgrid(np.arange(0, model.out_width, 7), np.arange(0, model.out_height, 7))
    raw = model.raw_from_rect(np.stack([uu, vv], axis=-1).astype(float))
    inside = ((raw[..., 0] >= 0) & (raw[..., 0] <= model.width - 1) & (raw[..., 1] >= 0)
              & (raw[..., 1] <= model.height - 1))
    error = np.hypot(map_x[vv, uu] - raw[..., 0], map_y[vv, uu] - raw[..., 1])[inside]
    assert inside.sum() > 1000 and error.max() <= 0.05


def test_camera_info_of_a_tilted_sensor_fits_tangential_terms():
    model = build_model({**SIZE, 'sensor.tilt_x_deg': 0.3, 'sensor.tilt_y_deg': -0.2})
    assert model.distortion_model in ('plumb_bob', 'rational_polynomial')
    assert model.D[2] != 0.0 and model.D[3] != 0.0          # p1, p2
    # The published error is what a consumer (cv2's own projection) sees.
    assert _consumer_error(model) == pytest.approx(model.equivalent_max_error_px, rel=0.2,
                                                   abs=0.005)
    if model.equivalent_max_error_px > 0.05:
        assert any('no ROS distortion model' in w for w in model.warnings)


# --- .zmx: a coordinate break before the image surface places the sensor --------------------

def _singlet_with_break(params: str, disz: str = '0') -> str:
    from test_zmx import SINGLET
    block = ('SURF 3\n  TYPE COORDBRK\n  CURV 0.0\n' + params + f'  DISZ {disz}\nSURF 4\n')
    return SINGLET.replace('  DISZ 47.5', '  DISZ 46.5').replace('SURF 3\n', block)


def _import(text: str):
    from mechdeconv_ros.lenses.lens_import import zmx_values
    from mechdeconv_ros.lenses.zmx import parse
    from test_zmx import fixed_index
    return zmx_values(parse(text, 'cb.zmx'), resolve=fixed_index)


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(b):
    c, s = math.cos(b), math.sin(b)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def test_zmx_break_before_the_image_decenters_the_sensor():
    values = _import(_singlet_with_break('  PARM 1 0.1\n  PARM 2 -0.05\n')).values
    assert values['sensor.axis_offset_x_mm'] == pytest.approx(0.1)
    # The file's +y is up in the image; v grows downwards.
    assert values['sensor.axis_offset_y_mm'] == pytest.approx(0.05)
    assert values['sensor.tilt_x_deg'] == 0.0 and values['sensor.tilt_y_deg'] == 0.0
    assert values['lens.image_distance_mm'] == pytest.approx(46.5)
    dummy = _import(_singlet_with_break('  PARM 1 0\n', disz='1')).values
    assert 'sensor.axis_offset_x_mm' not in dummy
    assert dummy['lens.image_distance_mm'] == pytest.approx(47.5)


@pytest.mark.parametrize('order', [0, 1])
def test_zmx_break_geometry_is_the_sensor_plane(order):
    dx, dy, a, b, t = 0.3, -0.2, 2.0, -1.5, 0.4
    text = _singlet_with_break(f'  PARM 1 {dx}\n  PARM 2 {dy}\n  PARM 3 {a}\n  PARM 4 {b}\n'
                               f'  PARM 6 {order}\n', disz=str(t))
    values = _import(text).values
    # The break, as Zemax places it: frame F = R_x(a) R_y(b), origin decentred (before or
    # after the tilt), the image surface t along the new z.
    frame = _rx(math.radians(a)) @ _ry(math.radians(b))
    origin = (np.array([dx, dy, 46.5]) if order == 0
              else frame @ np.array([dx, dy, 0.0]) + np.array([0.0, 0.0, 46.5]))
    vertex = origin + t * frame[:, 2]
    # Our sensor: the axis point at image_distance, R = R_x(tilt_x) R_y(tilt_y) in the read-out
    # frame (a, b, z) = (-x, y, z); the centre at (a, b) = -offset.
    pose = SensorPose.from_values(values)
    r = pose.rotation()
    centre = np.array([0.0, 0.0, values['lens.image_distance_mm']]) + r @ np.array(
        [-pose.offset_x_mm, -pose.offset_y_mm, 0.0])
    centre_lens = np.array([-centre[0], centre[1], centre[2]])
    np.testing.assert_allclose(centre_lens, vertex, atol=1e-12)
    # Same plane: the normals agree (read-out normal turned to the lens frame).
    normal = r[:, 2] * np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(np.abs(normal @ frame[:, 2]), 1.0, atol=1e-12)
    # And the rows: the read-out a axis is the lens frame's -x turned.
    np.testing.assert_allclose(r[:, 0] * np.array([-1.0, 1.0, 1.0]), -frame[:, 0],
                               atol=1e-12)


@pytest.mark.parametrize('params, words', [
    ('  PARM 3 45\n', ['line 39', 'PARM 3', '45 deg']),
    ('  PARM 1 nan\n', ['line 39', 'PARM']),
    ('  PARM 5 3\n', ['line 39', 'about the axis']),
    ('  PARM 1 1e6\n', ['line 39', 'off the axis']),
])
def test_zmx_hostile_breaks_are_refused_naming_the_line(params, words):
    from mechdeconv_ros.lenses.zmx import LensImportError
    with pytest.raises(LensImportError) as err:
        _import(_singlet_with_break(params))
    for word in words:
        assert word in str(err.value), (word, str(err.value))


def test_zmx_element_decenter_stays_refused():
    from mechdeconv_ros.lenses.zmx import LensImportError
    from test_zmx import SINGLET
    text = SINGLET.replace('SURF 2\n', 'SURF 2\n  TYPE COORDBRK\n  PARM 1 0.2\n  DISZ 0\n'
                                       'SURF 3\n').replace('SURF 3\n  TYPE STANDARD\n  CURV 0.0'
                                                           '\n  DISZ 0', 'SURF 4\n  TYPE '
                                                           'STANDARD\n  CURV 0.0\n  DISZ 0')
    with pytest.raises(LensImportError, match='inside the lens'):
        _import(text)


def test_datasheet_and_colour_channels_take_the_pose():
    from mechdeconv_ros.imaging.remap import Rectifier
    from mechdeconv_ros.schema.params import load_params_file
    # A datasheet table: its chief rays run through the rear principal point (s = h / v).
    table = {**SIZE, 'lens.focal_length_mm': 4.0,
             'lens.datasheet.field_angle_deg': [0.0, 10.0, 20.0, 30.0, 40.0],
             'lens.datasheet.image_height_mm': [0.0, 0.7045, 1.4499, 2.2893, 3.2826],
             'scene.distance_mm': 0.0, 'sensor.tilt_x_deg': 1.0,
             'sensor.axis_offset_x_mm': 0.03}
    model = build_model(table)
    assert model.K[0, 2] == pytest.approx(319.5 + 0.03 / model.pixel_mm[0])
    theta, phi = unproject_angles(model, np.array([10.0, 600.0]), np.array([20.0, 400.0]))
    u, v = project(model, np.tan(theta) * np.cos(phi), np.tan(theta) * np.sin(phi))
    assert_allclose(u, [10.0, 600.0], atol=1e-6)
    assert_allclose(v, [20.0, 400.0], atol=1e-6)
    # Lateral colour: each channel's maps meet the same tilted plane.
    values = load_params_file('config/cooke_triplet.yaml')
    values.update({'sensor.width_px': 480, 'sensor.height_px': 270,
                   'sensor.pixel_size_x_um': 32.0, 'sensor.pixel_size_y_um': 32.0,
                   'sensor.tilt_y_deg': 1.0, 'output.lateral_color_correction': True})
    colour = Rectifier(build_model(values))
    assert colour.colour is not None
    frame = np.full((270, 480, 3), 128, np.uint8)
    assert colour.correct(frame, colours=(0, 1, 2)).shape == frame.shape


@pytest.mark.parametrize('pose', [
    {'sensor.axis_offset_x_mm': 0.15, 'sensor.axis_offset_y_mm': -0.1},
    {'sensor.axis_offset_x_mm': 0.15, 'sensor.tilt_x_deg': 1.0, 'sensor.tilt_y_deg': -0.7}])
def test_maps_are_the_projection(pose):
    from mechdeconv_ros.imaging.remap import build_float_maps
    from mechdeconv_ros.schema.params import load_params_file
    values = load_params_file('config/wide_angle.yaml')
    values.update({'sensor.width_px': 240, 'sensor.height_px': 150,
                   'sensor.pixel_size_x_um': 16.0, 'sensor.pixel_size_y_um': 16.0,
                   'output.alpha': 1.0, **pose})
    model = build_model(values)
    # The principal point (the lens axis's projection) on the half-pixel grid, off-centre.
    assert model.K_new[0, 2] != (model.out_width - 1) / 2
    assert 2 * model.K_new[0, 2] == round(2 * model.K_new[0, 2])
    map_x, map_y = build_float_maps(model)
    uu, vv = np.meshgrid(np.arange(model.out_width), np.arange(model.out_height))
    raw = model.raw_from_rect(np.stack([uu, vv], axis=-1).astype(float))
    valid = np.isfinite(raw[..., 0])
    # alpha 1: the field ends inside the output. float32 maps: within 0.01 px (the remap
    # itself rounds to 1/32 px).
    assert 0 < valid.sum() < valid.size
    assert np.max(np.abs(map_x[valid] - raw[..., 0][valid])) < 0.01
    assert np.max(np.abs(map_y[valid] - raw[..., 1][valid])) < 0.01
    # Invalid pixels point far outside the source (BORDER_CONSTANT paints them black).
    outside = np.abs(map_x[~valid] - model.width / 2) > model.width / 2 + 500
    assert np.all(outside)
    # And the maps send each corrected pixel's direction where project puts it.
    k = model.K_new
    tx = (uu[valid][::97] - k[0, 2]) / k[0, 0]
    ty = (vv[valid][::97] - k[1, 2]) / k[1, 1]
    u, v = project(model, tx, ty)
    assert_allclose(u, map_x[valid][::97], atol=0.01)
    assert_allclose(v, map_y[valid][::97], atol=0.01)


def test_cli_project_nan_where_no_chief_ray_passes(tmp_path, capsys):
    path = tmp_path / 'in.csv'
    # The Cooke triplet's clear apertures pass about 25 deg: 63 deg has no chief ray; 25 deg
    # lands beyond the 1920 px sensor.
    path.write_text('0.1,0\n0.47,0\n2,0\n')
    status = main(['project', '--params', 'config/cooke_triplet.yaml', str(path)])
    out, _ = capsys.readouterr()
    rows = [line.split(',') for line in out.splitlines()]
    assert status == 0 and len(rows) == 3
    assert 959.5 < float(rows[0][2]) < 1919.5
    assert float(rows[1][2]) > 1919.5
    assert rows[2][2:] == ['nan', 'nan']


@pytest.mark.parametrize('pose', [
    {'sensor.axis_offset_x_mm': 0.2, 'sensor.axis_offset_y_mm': -0.15},
    {'sensor.axis_offset_x_mm': 0.2, 'sensor.tilt_x_deg': 1.0, 'sensor.tilt_y_deg': -0.7}])
def test_alpha_zero_keeps_only_valid_pixels_off_centre(pose):
    from mechdeconv_ros.imaging.remap import Rectifier
    model = build_model({**SIZE, **pose})
    # The principal point follows the axis (the raw image is framed as it was).
    assert model.K_new[0, 2] > 319.5 + 0.5 * 0.2 / model.pixel_mm[0]
    out = Rectifier(model).correct(np.full((480, 640), 200, np.uint8))
    assert int((out < 100).sum()) == 0


def test_info_reports_the_sensor_tolerances_at_the_corner(capsys):
    import json
    status = main(['info', '--json', '--width', '640', '--height', '480', '-p',
                   'sensor.tilt_x_deg=0.5', '-p', 'sensor.tolerance.axis_offset_x_mm=0.01'])
    report = json.loads(capsys.readouterr()[0])
    pose = report['sensor_pose']
    sigma = pose['corner_sigma_px']
    px = build_model(SIZE).pixel_mm[0]
    assert status == 0 and pose['tilt_x_deg'] == 0.5
    # An offset moves every pixel by itself; a tilt the corner by a fraction of a pixel.
    assert sigma['axis_offset_x_mm'] == pytest.approx(0.01 / px, rel=1e-6)
    assert 0.0 < sigma['tilt_x_deg'] < sigma['axis_offset_x_mm']
    assert sigma['total'] == pytest.approx(math.sqrt(sum(
        sigma[k] ** 2 for k in ('axis_offset_x_mm', 'axis_offset_y_mm', 'tilt_x_deg',
                                'tilt_y_deg'))))
    status = main(['info', '--width', '640', '--height', '480'])
    assert 'corner sigma from the sensor tolerances' in capsys.readouterr()[0]
