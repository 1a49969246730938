# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The stereo pair's core (issue 38): schema, rig convention, rectification, CameraInfos, CLI.

The accuracy against independently rendered pairs is test_stereo_accuracy.py.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
from mechdeconv_ros.imaging.stereo_remap import stereo_maps, StereoRectifier
from mechdeconv_ros.model.model import ModelError
from mechdeconv_ros.model.projection import directions_of, pixels_of
from mechdeconv_ros.model.stereo import (
    build_stereo, exact_directions, half_rotation, rectified_points, rectifying_rotations, Rig,
    rig_rotation, stereo_camera_infos)
from mechdeconv_ros.optics.ports import entrance_pupil_z
from mechdeconv_ros.schema.params import load_params_file, SCHEMA
from mechdeconv_ros.schema.stereo_params import (
    check_stereo_values, load_stereo_params_file, split_values, STEREO_SCHEMA, STEREO_SPECS)
from mechdeconv_ros.tools.cli import main
import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
STEREO_YAML = REPO / 'config' / 'stereo.yaml'


def pair_of(size: tuple[int, int] = (320, 240), **rig: float) -> dict:
    """Return pair values: two Case 2 cameras (scene at infinity) of ``size`` on a rig."""
    values: dict = {}
    for camera in ('left', 'right'):
        values[f'{camera}.sensor.width_px'] = size[0]
        values[f'{camera}.sensor.height_px'] = size[1]
        values[f'{camera}.scene.distance_mm'] = 0.0
    values.update({f'rig.{k}': v for k, v in rig.items()})
    return values


@pytest.fixture(scope='module')
def turned():
    """Return a pair whose right camera is turned about every axis and offset."""
    return build_stereo(pair_of(rotation_x_deg=0.4, rotation_y_deg=-1.5, rotation_z_deg=0.7,
                                offset_y_mm=3.0, offset_z_mm=-2.0))


# --- schema ---------------------------------------------------------------------------------

def test_every_camera_parameter_is_there_twice_but_output_and_check_once():
    single = [s.name for s in SCHEMA if not s.name.startswith(('output.', 'check.'))]
    for name in single:
        assert f'left.{name}' in STEREO_SPECS and f'right.{name}' in STEREO_SPECS, name
    outputs = [s.name for s in SCHEMA if s.name.startswith('output.')]
    assert all(name in STEREO_SPECS for name in outputs)
    assert not any(s.name.startswith(('left.check.', 'right.check.', 'left.output.',
                                      'check.')) for s in STEREO_SCHEMA)
    for name in ('rig.baseline_mm', 'rig.tolerance.rotation_z_deg', 'sync.slop_s',
                 'stereo_check.rate_hz', 'stereo_check.window', 'stereo_check.apply'):
        assert name in STEREO_SPECS, name
    assert len(STEREO_SPECS) == len(STEREO_SCHEMA)


@pytest.mark.parametrize('name, value, match', [
    ('rig.baseline_mm', 0.0, r'^rig\.baseline_mm: must be > 0'),
    ('left.lens.r1_mm', 'x', r'^left\.lens\.r1_mm: expected a number'),
    ('right.sensor.tilt_x_deg', 30.0, r'^right\.sensor\.tilt_x_deg: 30 deg is above'),
    ('rig.tolerance.rotation_x_deg', -1.0, r'^rig\.tolerance\.rotation_x_deg: -1'),
    ('left.check.rate_hz', 1.0, r"unknown parameter 'left\.check\.rate_hz'"),
], ids=['baseline-0', 'left-type', 'right-range', 'tolerance-negative', 'camera-check'])
def test_schema_refusals_name_the_full_parameter(name, value, match):
    with pytest.raises(ValueError, match=match):
        check_stereo_values({name: value})


def test_split_gives_two_full_cameras_with_the_pairs_output():
    values = check_stereo_values({'left.lens.r1_mm': 5.0, 'right.sensor.axis_offset_x_mm': 0.1,
                                  'output.alpha': 0.5, 'rig.rotation_y_deg': 0.2})
    left, right, pair = split_values(values)
    assert set(left) == set(right) == {s.name for s in SCHEMA}
    assert (left['lens.r1_mm'], right['lens.r1_mm']) == (5.0, 4.0)
    assert (left['sensor.axis_offset_x_mm'], right['sensor.axis_offset_x_mm']) == (0.0, 0.1)
    assert left['output.alpha'] == right['output.alpha'] == 0.5
    assert pair['rig.rotation_y_deg'] == 0.2
    assert not any(k.startswith(('left.', 'right.')) for k in pair)


def test_the_example_config_loads_and_builds():
    values = load_stereo_params_file(STEREO_YAML)
    assert set(values) == set(STEREO_SPECS)
    stereo = build_stereo(values)
    assert (stereo.width, stereo.height) == (1280, 720)
    assert stereo.left.width == stereo.right.width == 1280
    assert_allclose(stereo.baseline_m, 0.120)


# --- the rig's convention -------------------------------------------------------------------

def test_rotation_is_rx_ry_rz_right_handed_about_the_left_axes():
    a = math.radians(10.0)
    # R_x(+a) turns the camera's Z (view) axis toward -Y (up): its third column.
    assert_allclose(rig_rotation(10.0, 0.0, 0.0)[:, 2], [0.0, -math.sin(a), math.cos(a)],
                    atol=1e-15)
    # R_y(+a) turns it toward +X.
    assert_allclose(rig_rotation(0.0, 10.0, 0.0)[:, 2], [math.sin(a), 0.0, math.cos(a)],
                    atol=1e-15)
    # R_z(+a) turns the X axis toward +Y.
    assert_allclose(rig_rotation(0.0, 0.0, 10.0)[:, 0], [math.cos(a), math.sin(a), 0.0],
                    atol=1e-15)
    composed = rig_rotation(3.0, -4.0, 5.0)
    assert_allclose(composed, rig_rotation(3.0, 0, 0) @ rig_rotation(0, -4.0, 0)
                    @ rig_rotation(0, 0, 5.0), atol=1e-15)
    rig = Rig.from_values({'rig.baseline_mm': 100.0, 'rig.offset_y_mm': 2.0,
                           'rig.rotation_x_deg': 3.0, 'rig.rotation_y_deg': -4.0,
                           'rig.rotation_z_deg': 5.0})
    assert_allclose(rig.R, composed)
    assert_allclose(rig.t_mm, [100.0, 2.0, 0.0])


def test_half_rotation_squares_to_the_rotation():
    rot = rig_rotation(20.0, -30.0, 15.0)
    half = half_rotation(rot)
    assert_allclose(half @ half, rot, atol=1e-14)
    assert_allclose(half @ half.T, np.eye(3), atol=1e-14)


@pytest.mark.parametrize('rig', [
    Rig(120.0, 3.0, -2.0, 0.4, -1.5, 0.7), Rig(120.0, 0.0, 0.0, 0.0, 2.0, 0.0),
    Rig(60.0, 10.0, 5.0, -3.0, 4.0, 2.0)], ids=['turned', 'toe-in', 'large'])
def test_rotations_are_opencvs_stereo_rectify_of_the_rig(rig):
    """Compare with OpenCV's extrinsics: X_r = R_cv X_l + T_cv, R_cv = R^T, T_cv = -R^T t."""
    k = np.array([[1000.0, 0.0, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]])
    r1, r2, _, p2, _, _, _ = cv2.stereoRectify(
        k, np.zeros(5), k, np.zeros(5), (640, 480), rig.R.T, -rig.R.T @ rig.t_mm,
        flags=cv2.CALIB_ZERO_DISPARITY, alpha=-1)
    ours = rectifying_rotations(rig)
    assert_allclose(ours[0], r1, atol=1e-12)
    assert_allclose(ours[1], r2, atol=1e-12)
    assert_allclose(-p2[0, 3] / p2[0, 0], np.linalg.norm(rig.t_mm))


def test_rectified_frames_share_an_orientation_with_the_baseline_along_x(turned):
    rig = turned.rig
    # R2 = R1 R: a direction seen by both cameras is one rectified direction.
    assert_allclose(turned.R2, turned.R1 @ rig.R, atol=1e-14)
    assert_allclose(turned.R1 @ rig.t_mm, [np.linalg.norm(rig.t_mm), 0.0, 0.0], atol=1e-12)
    for rot in (turned.R1, turned.R2):
        assert_allclose(rot @ rot.T, np.eye(3), atol=1e-14)
        assert_allclose(np.linalg.det(rot), 1.0)
    # Each camera is turned by about half the relative angle (stereoRectify's split).
    angle = [math.degrees(math.acos((np.trace(r) - 1.0) / 2.0)) for r in turned.rotations]
    assert abs(angle[0] - angle[1]) < 0.5 * max(angle)


def test_a_scene_point_projects_to_one_row_with_the_disparity_of_its_depth(turned):
    """X_r = R^T (X_l - t); in the rectified pair: same row, u_l - u_r = f B / Z."""
    rng = np.random.default_rng(0)
    rig = turned.rig
    points = np.column_stack([rng.uniform(-1500, 1500, 50), rng.uniform(-800, 800, 50),
                              rng.uniform(2000, 8000, 50)])      # mm, left frame
    right = (points - rig.t_mm) @ rig.R        # R^T (X - t), as rows
    left_rect = points @ turned.R1.T
    right_rect = right @ turned.R2.T
    f = turned.K_rect[0, 0]
    ul = f * left_rect[:, 0] / left_rect[:, 2]
    ur = f * right_rect[:, 0] / right_rect[:, 2]
    vl = f * left_rect[:, 1] / left_rect[:, 2]
    vr = f * right_rect[:, 1] / right_rect[:, 2]
    assert_allclose(vl, vr, atol=1e-9)
    assert_allclose(ul - ur, f * np.linalg.norm(rig.t_mm) / left_rect[:, 2], rtol=1e-12)
    # The same through P1 and P2 (B in metres, depth in metres).
    homog = np.column_stack([left_rect / 1000.0, np.ones(50)])
    p1, p2 = homog @ turned.P1.T, homog @ turned.P2.T
    assert_allclose(p1[:, 0] / p1[:, 2] - p2[:, 0] / p2[:, 2],
                    f * turned.baseline_m / (left_rect[:, 2] / 1000.0), rtol=1e-12)


# --- camera infos ---------------------------------------------------------------------------

def test_camera_infos_follow_the_ros_stereo_contract(turned):
    infos = stereo_camera_infos(turned)
    assert set(infos) == {'left', 'right', 'left_rect', 'right_rect'}
    left, right = infos['left'], infos['right']
    p1 = np.reshape(left['P'], (3, 4))
    p2 = np.reshape(right['P'], (3, 4))
    # Equal fx', fy', cx', cy'; Tx = -fx' B with B = |t| in metres; Ty = Tz = 0.
    assert_allclose(p1[:, :3], p2[:, :3])
    assert p1[0, 0] == p1[1, 1]
    assert_allclose(p2[0, 3], -p2[0, 0] * np.linalg.norm(turned.rig.t_mm) / 1000.0)
    assert p2[0, 3] < 0.0
    assert p1[0, 3] == p1[1, 3] == p2[1, 3] == p2[2, 3] == 0.0
    assert_allclose(np.reshape(left['R'], (3, 3)), turned.R1)
    assert_allclose(np.reshape(right['R'], (3, 3)), turned.R2)
    assert_allclose(np.reshape(left['K'], (3, 3)), turned.left.K)
    assert left['D'] == list(turned.left.D)
    assert (left['width'], left['height']) == (turned.left.width, turned.left.height)
    for name, proj in (('left_rect', p1), ('right_rect', p2)):
        rect = infos[name]
        assert_allclose(np.reshape(rect['K'], (3, 3)), proj[:, :3])
        assert rect['D'] == [0.0] * 5 and rect['distortion_model'] == 'plumb_bob'
        assert_allclose(np.reshape(rect['R'], (3, 3)), np.eye(3))
        assert_allclose(np.reshape(rect['P'], (3, 4)), proj)


def test_opencv_rectifies_from_the_camera_infos_as_the_exact_maps(turned):
    """
    Run initUndistortRectifyMap(K, D, R, P), as image_proc does: the exact maps, nearly.

    R's direction (rectified-from-camera) and P are OpenCV's; the only difference left is the
    fitted D's (section 2.8).
    """
    infos = stereo_camera_infos(turned)
    for side, (mx, my) in zip(('left', 'right'), stereo_maps(turned)):
        info = infos[side]
        cv_x, cv_y = cv2.initUndistortRectifyMap(
            np.reshape(info['K'], (3, 3)), np.array(info['D']), np.reshape(info['R'], (3, 3)),
            np.reshape(info['P'], (3, 4)), (turned.width, turned.height), cv2.CV_32FC1)
        gap = np.hypot(cv_x - mx, cv_y - my)
        assert gap.max() < 0.05, f'{side}: {gap.max():.3f} px'
    # R transposed (the most common mistake) would be off by pixels.
    wrong = cv2.initUndistortRectifyMap(
        turned.left.K, np.array(turned.left.D), turned.R1.T, turned.P1,
        (turned.width, turned.height), cv2.CV_32FC1)
    (mx, my), _ = stereo_maps(turned)
    assert np.hypot(wrong[0] - mx, wrong[1] - my).max() > 1.0


def test_image_geometry_reads_the_baseline_and_depth_back(turned):
    """StereoCameraModel: baseline = -Tx_right / fx_right; Z = -Tx / (d - (cx_l - cx_r))."""
    infos = stereo_camera_infos(turned)
    p1 = np.reshape(infos['left']['P'], (3, 4))
    p2 = np.reshape(infos['right']['P'], (3, 4))
    assert_allclose(-p2[0, 3] / p2[0, 0], turned.baseline_m)
    depth_m, f = 3.0, p2[0, 0]
    disparity = f * turned.baseline_m / depth_m
    assert_allclose(-p2[0, 3] / (disparity - (p1[0, 2] - p2[0, 2])), depth_m)


# --- refusals -------------------------------------------------------------------------------

@pytest.mark.parametrize('values, name', [
    ({'rig.baseline_mm': 0.0}, 'rig.baseline_mm'),
    ({'left.lens.r1_mm': 0.1}, 'left.lens.'),
    ({'right.scene.distance_mm': 2.0}, 'right.scene.distance_mm'),
    ({'right.sensor.axis_offset_x_mm': 50.0}, 'right.sensor.axis_offset_x_mm'),
    ({'rig.rotation_y_deg': 45.0, 'rig.rotation_x_deg': 45.0,
      'left.lens.r1_mm': 30.0, 'left.lens.r2_mm': -30.0,
      'right.lens.r1_mm': 30.0, 'right.lens.r2_mm': -30.0}, 'rig.rotation_'),
    ({'output.projection': 'equidistant'}, 'output.projection'),
], ids=['baseline-0', 'left-lens', 'right-scene', 'right-pose', 'no-overlap', 'fisheye-out'])
def test_build_refuses_naming_the_pair_parameter(values, name):
    with pytest.raises(ModelError) as err:
        build_stereo({**pair_of(), **values})
    assert str(err.value).startswith(name), str(err.value)
    assert err.value.parameter.startswith(name)


# --- the maps -------------------------------------------------------------------------------

def test_maps_are_the_forward_trace_of_each_rectified_ray(turned):
    (lx, ly), (rx, ry) = stereo_maps(turned)
    assert lx.shape == (turned.height, turned.width) and lx.dtype == np.float32
    rng = np.random.default_rng(0)
    u = rng.integers(0, turned.width, 40)
    v = rng.integers(0, turned.height, 40)
    rect = np.column_stack([u, v, np.ones(40)]) @ np.linalg.inv(turned.K_rect).T
    for model, rot, mx, my in ((turned.left, turned.R1, lx, ly),
                               (turned.right, turned.R2, rx, ry)):
        raw = np.column_stack([mx[v, u], my[v, u]]).astype(np.float64)
        # The raw pixel's direction (the inverse) is the rectified ray turned back.
        seen = directions_of(model, raw) @ rot.T
        want = rect / np.linalg.norm(rect, axis=1, keepdims=True)
        assert_allclose(seen, want, atol=2e-6)
        assert_allclose(raw, pixels_of(model, rect @ rot), atol=1e-3)


def test_rectified_points_invert_the_maps(turned):
    rng = np.random.default_rng(0)
    u = rng.integers(0, turned.width, 30)
    v = rng.integers(0, turned.height, 30)
    for side, (mx, my) in zip(('left', 'right'), stereo_maps(turned)):
        raw = np.column_stack([mx[v, u], my[v, u]]).astype(np.float64)
        # The maps are float32: 1e-4 px at these coordinates.
        assert_allclose(rectified_points(turned, side, raw), np.column_stack([u, v]),
                        atol=1e-3)


def test_a_finite_scene_is_seen_from_the_entrance_pupil():
    """A point of the plane at l from H is at l + z_E - z_H from E, the pair's origin."""
    values = {**pair_of(), 'left.scene.distance_mm': 500.0, 'right.scene.distance_mm': 500.0}
    stereo = build_stereo(values)
    left = stereo.left
    offset = entrance_pupil_z(left.prescription) - left.source.first_order().front_principal_z_mm
    assert abs(offset) > 0.1            # the Case 2 lens: E is 0.47 mm in front of H
    (mx, my), _ = stereo_maps(stereo)
    v, u = np.mgrid[0:stereo.height:20, 0:stereo.width:20]
    d = np.stack([u, v, np.ones_like(u)], axis=-1).reshape(-1, 3).astype(float) @ \
        np.linalg.inv(stereo.K_rect).T @ stereo.R1
    point_e = d * ((500.0 + offset) / d[:, 2:3])        # on the plane, from E
    point_h = point_e - [0.0, 0.0, offset]               # the same point from H
    want = pixels_of(left, point_h)
    got = np.column_stack([mx[v, u].ravel(), my[v, u].ravel()])
    assert_allclose(got, want, atol=2e-3)
    # Seen from H instead, the corners would be off by a tenth of a pixel.
    assert np.abs(pixels_of(left, d) - want).max() > 0.1


def test_alpha_0_shows_only_valid_pixels_and_1_every_raw_pixel(turned):
    values = {**pair_of(rotation_x_deg=0.4, rotation_y_deg=-1.5, rotation_z_deg=0.7,
                        offset_y_mm=3.0, offset_z_mm=-2.0)}
    for alpha in (0.0, 1.0):
        stereo = build_stereo({**values, 'output.alpha': alpha})
        for mx, my in stereo_maps(stereo):
            inside = (mx >= -0.5) & (mx <= stereo.left.width - 0.5) & \
                (my >= -0.5) & (my <= stereo.left.height - 0.5)
            if alpha == 0.0:
                assert inside.all()
            else:
                assert not inside.all()
                # Every raw edge is in view: the maps reach all four borders.
                assert mx[inside].min() < 1.0 and mx[inside].max() > stereo.left.width - 2
                assert my[inside].min() < 1.0 and my[inside].max() > stereo.left.height - 2


def test_rectifier_refuses_a_frame_of_the_wrong_size(turned):
    rectifier = StereoRectifier(turned)
    good = np.zeros((turned.left.height, turned.left.width), np.uint8)
    with pytest.raises(ValueError, match='right frame is 10x10 px'):
        rectifier.rectify(good, np.zeros((10, 10), np.uint8))
    left, right = rectifier.rectify(good, good)
    assert left.shape == right.shape == (turned.height, turned.width)


def camera_pair(path: Path, size: tuple[int, int], **extra) -> dict:
    """Return pair values with both cameras from a single camera's params file."""
    single = load_params_file(path)
    values = {f'{camera}.{k}': v for camera in ('left', 'right') for k, v in single.items()
              if not k.startswith(('output.', 'check.'))}
    for camera in ('left', 'right'):
        values[f'{camera}.sensor.width_px'], values[f'{camera}.sensor.height_px'] = size
    values.update(extra)
    return values


@pytest.fixture(scope='module')
def ported():
    """Return a pair behind flat ports in seawater, the right port tilted by 2 deg."""
    return build_stereo(camera_pair(REPO / 'config' / 'underwater_flat.yaml', (160, 120),
                                    **{'right.port.tilt_x_deg': 2.0}))


def test_a_tilted_port_frames_the_pair_by_its_exact_chief_rays(ported):
    """The inverse of the symmetric model misses a tilted port; the outline must not."""
    pixels = np.array([[-0.5, -0.5], [159.5, 119.5], [40.0, 100.0]])
    model = ported.right
    assert_allclose(pixels_of(model, exact_directions(model, pixels)), pixels, atol=1e-6)
    # alpha 0: every rectified pixel of both maps is inside its raw image.
    for mx, my in stereo_maps(ported):
        assert mx.min() >= -0.5 and mx.max() <= 159.5
        assert my.min() >= -0.5 and my.max() <= 119.5


def test_a_fisheye_pair_is_framed_inside_its_image_circle():
    """The image circle inside the sensor: alpha 0 shows only pixels inside it, in both."""
    single = load_params_file(REPO / 'config' / 'fisheye.yaml')
    scale = single['sensor.width_px'] / 160.0
    extra = {f'{camera}.sensor.pixel_size_{axis}_um': single[f'sensor.pixel_size_{axis}_um']
             * scale for camera in ('left', 'right') for axis in ('x', 'y')}
    stereo = build_stereo(camera_pair(REPO / 'config' / 'fisheye.yaml', (160, 120), **extra,
                                      **{'rig.rotation_y_deg': 2.0}))
    for model, (mx, my) in zip(stereo.models, stereo_maps(stereo)):
        raw = np.column_stack([mx.ravel(), my.ravel()]).astype(np.float64)
        assert np.isfinite(directions_of(model, raw)).all()
        assert mx.min() >= -0.5 and mx.max() <= 159.5 and my.min() >= -0.5
    # The corners of the raw image lie outside the image circle: not all of it is framed.
    corner = directions_of(stereo.left, np.array([[-0.5, -0.5]]))
    assert not np.isfinite(corner).all()


def test_lateral_colour_gives_each_channel_its_own_exact_map():
    values = {**pair_of((160, 120)), 'left.lens.glass': 'N-BK7', 'right.lens.glass': 'N-BK7',
              'output.lateral_color_correction': True}
    stereo = build_stereo(values)
    rectifier = StereoRectifier(stereo)
    assert rectifier.colour is not None
    maps = rectifier.colour[0].maps
    red, blue = maps[0], maps[2]
    # Lateral colour: the red and blue channels' rays land apart in the corner.
    assert abs(float(red[0][0, 0] - blue[0][0, 0])) > 0.05
    rng = np.random.default_rng(0)
    raw = (rng.random((120, 160, 3)) * 255).astype(np.uint8)
    left, _ = rectifier.rectify(raw, raw, colours=(2, 1, 0))     # BGR
    for channel, colour in enumerate((2, 1, 0)):
        want = cv2.remap(raw[..., channel], *maps[colour], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT)
        assert np.abs(left[..., channel].astype(int) - want).max() <= 1


def test_vignetting_gain_is_one_over_ri_where_each_ray_lands():
    values = {**pair_of((480, 360)), 'output.vignetting_correction': True}
    stereo = build_stereo(values)
    rectifier = StereoRectifier(stereo)
    assert rectifier.gains is not None
    gain = rectifier.gains[0]
    centre = gain[180, 240]
    assert_allclose(centre, 1.0, atol=0.02)
    assert gain[0, 0] > centre + 0.05          # the corner is darker: a larger gain
    raw = np.full((360, 480), 100, np.uint8)
    left, right = rectifier.rectify(raw, raw)
    assert_allclose(left.astype(float), np.round(np.minimum(100.0 * gain, 255.0)), atol=1.0)
    ri = stereo.left.illumination(with_fraction=False)
    x, y = rectifier.left_x[0, 0], rectifier.left_y[0, 0]
    rho = np.hypot((x - stereo.left.K[0, 2]) * stereo.left.pixel_mm[0],
                   (y - stereo.left.K[1, 2]) * stereo.left.pixel_mm[1])
    assert_allclose(gain[0, 0], 1.0 / ri.at(rho), rtol=1e-5)


def test_two_different_cameras_share_the_rectified_pinhole():
    """A right camera of another size and pitch: one K_rect, the left camera's size."""
    values = {**pair_of((320, 240), rotation_y_deg=0.5), 'right.sensor.width_px': 400,
              'right.sensor.height_px': 300, 'right.sensor.pixel_size_x_um': 3.5,
              'right.sensor.pixel_size_y_um': 3.5}
    stereo = build_stereo(values)
    assert (stereo.width, stereo.height) == (320, 240)
    assert (stereo.right.width, stereo.right.height) == (400, 300)
    (lx, ly), (rx, ry) = stereo_maps(stereo)
    assert rx.shape == lx.shape == (240, 320)
    # alpha 0: every rectified pixel reads inside both raw images.
    assert rx.min() >= -0.5 and rx.max() <= 399.5 and ry.min() >= -0.5 and ry.max() <= 299.5
    # A scene direction lands on one rectified row in both images.
    d_rect = np.array([[0.1, -0.05, 1.0], [-0.08, 0.07, 1.0]])
    rect = d_rect @ stereo.K_rect.T
    rect = rect[:, :2] / rect[:, 2:]
    for model, rot, mx, my in ((stereo.left, stereo.R1, lx, ly),
                               (stereo.right, stereo.R2, rx, ry)):
        raw = pixels_of(model, d_rect @ rot)
        got = np.column_stack([cv2.remap(m, rect[:, :1].astype(np.float32),
                                         rect[:, 1:].astype(np.float32), cv2.INTER_LINEAR)
                               .ravel() for m in (mx, my)])
        assert_allclose(got, raw, atol=0.02)


# --- the command line -----------------------------------------------------------------------

@pytest.fixture(scope='module')
def cli_pair(tmp_path_factory):
    folder = tmp_path_factory.mktemp('stereo_cli')
    params = folder / 'stereo.yaml'
    values = pair_of((320, 240), rotation_x_deg=0.2)
    tree = {'stereo_node': {'ros__parameters': {}}}
    for name, value in values.items():
        node = tree['stereo_node']['ros__parameters']
        *parents, leaf = name.split('.')
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    params.write_text(yaml.safe_dump(tree))
    rng = np.random.default_rng(0)
    image = cv2.GaussianBlur((rng.random((240, 320, 3)) * 255).astype(np.uint8), (0, 0), 2)
    cv2.imwrite(str(folder / 'l.png'), image)
    cv2.imwrite(str(folder / 'r.png'), image)
    return folder, params, values


def test_cli_writes_the_rectified_pair_and_both_camera_info_files(cli_pair):
    folder, params, values = cli_pair
    out = folder / 'out'
    assert main(['stereo', '--params', str(params), str(folder / 'l.png'),
                 str(folder / 'r.png'), '-o', str(out)]) == 0
    stereo = build_stereo(values, (320, 240), (320, 240))
    infos = stereo_camera_infos(stereo)
    for side in ('left', 'right'):
        image = cv2.imread(str(out / f'{side}_rect.png'), cv2.IMREAD_UNCHANGED)
        assert image.shape == (240, 320, 3)
        doc = yaml.safe_load((out / f'{side}_camera_info.yaml').read_text())
        assert doc['camera_name'] == side
        assert (doc['image_width'], doc['image_height']) == (320, 240)
        assert_allclose(doc['rectification_matrix']['data'], infos[side]['R'])
        assert_allclose(doc['projection_matrix']['data'], infos[side]['P'])
        assert_allclose(doc['camera_matrix']['data'], infos[side]['K'])
        assert doc['distortion_model'] == infos[side]['distortion_model']
    right_p = yaml.safe_load((out / 'right_camera_info.yaml').read_text())[
        'projection_matrix']['data']
    assert_allclose(right_p[3], -right_p[0] * 0.120)
    raw = cv2.imread(str(folder / 'l.png'))
    maps = stereo_maps(stereo)[0]
    want = cv2.remap(raw, *maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    assert_allclose(cv2.imread(str(out / 'left_rect.png')), want, atol=0)


@pytest.mark.parametrize('extra, words', [
    (['-p', 'rig.baseline_mm=0'], 'rig.baseline_mm'),
    (['-p', 'left.lens.r1_mm=0.1'], 'left.lens.'),
    (['-p', 'left.check.rate_hz=1'], '-p left.check.rate_hz=1'),
    (['-p', 'right.sensor.width_px=640'], 'RIGHT: the image is 320x240'),
], ids=['baseline', 'left-lens', 'unknown', 'size'])
def test_cli_refusals_exit_2_naming_the_parameter(cli_pair, capsys, extra, words):
    folder, params, _ = cli_pair
    code = main(['stereo', '--params', str(params), *extra, str(folder / 'l.png'),
                 str(folder / 'r.png'), '-o', str(folder / 'bad')])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith(f'mechdeconv: error: {words}'), err


def test_cli_refuses_a_single_camera_params_file(cli_pair, capsys):
    folder, _, _ = cli_pair
    code = main(['stereo', '--params', str(REPO / 'config' / 'case2.yaml'),
                 str(folder / 'l.png'), str(folder / 'r.png'), '-o', str(folder / 'bad')])
    assert code == 2
    assert "unknown parameter 'lens." in capsys.readouterr().err


def test_design_section_8_lists_the_pairs_own_parameters():
    """docs/design.md section 8's table has every rig.*, sync.* and stereo_check.* spec."""
    text = (REPO / 'docs' / 'design.md').read_text(encoding='utf-8')
    section = text.split('## 8. Stereo', 1)[1]
    for spec in STEREO_SCHEMA:
        if spec.name.startswith(('rig.', 'sync.', 'stereo_check.')):
            assert f'| `{spec.name}` |' in section, spec.name
            assert spec.description in section, spec.name
