# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The pair's CameraInfos as their consumers read them: image_geometry and stereo_image_proc.

image_geometry's ``StereoCameraModel`` (Python, ros-perception/vision_opencv,
``image_geometry/image_geometry/cameramodels.py``, BSD licence) is not on PyPI: the few
formulas it applies to two CameraInfos are restated below (:class:`ConsumerStereo`), nothing
else of it. ``fromCameraInfo`` keeps K, D, R and P (no binning, no ROI here); Tx is the right
P's ``P[0, 3]`` and the baseline ``-Tx / fx``; ``rectifyPoint`` is ``cv2.undistortPoints(uv,
K, D, R=R, P=P)`` with OpenCV's default iterations; ``projectPixelTo3d(left_uv, d)`` is
``Q @ (u, v, d, 1)`` with Q built from the RIGHT P (``[1 0 0 -cx; 0 1 0 -cy; 0 0 0 fx;
0 0 1/baseline 0]``); ``getZ(d)`` is ``-P_right[0, 3] / d = fx baseline / d``.

The CameraInfos come from :func:`mechdeconv_ros.model.stereo.stereo_camera_infos` (what
stereo_node publishes) for config/stereo.yaml and for a pair with a turned, offset rig and a
different right lens and sensor, and from the camera_info_manager YAML files ``mechdeconv
stereo`` writes. A scene point at a known depth (1.5 to 8 m) in the left camera's frame is
projected through each camera's exact model (:func:`~mechdeconv_ros.model.projection.pixels_of`,
the scene at infinity: directions from each entrance pupil) to raw pixels; the consumer must
get it back, rectifyPoint then projectPixelTo3d with the two rectified points' disparity, within
:data:`DEPTH_RTOL` of its depth, on one rectified row (within :data:`ROW_TOL_PX`).
stereo_image_proc's disparity node refuses a pair whose P's differ in fx, fy, cx, cy (and
reads Ty = P[1, 3] as 0): checked too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import cv2
from mechdeconv_ros.model.projection import pixels_of
from mechdeconv_ros.model.stereo import build_stereo, stereo_camera_infos, StereoModel
from mechdeconv_ros.schema.stereo_params import load_stereo_params_file
from mechdeconv_ros.tools.cli import main
import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
#: What the consumer's 3-D point may be off by, relative to the depth.
DEPTH_RTOL = 0.002
#: How far apart the two rectified rows of one scene point may be (px).
ROW_TOL_PX = 0.05
#: The depths the points are placed at (mm): the range the issue's scenes span.
DEPTHS_MM = (1500.0, 3000.0, 8000.0)
#: A turned, offset rig with a different right lens and sensor (320x240, scene at infinity).
TURNED = {**{f'{side}.{name}': value for side in ('left', 'right')
             for name, value in (('sensor.width_px', 320), ('sensor.height_px', 240),
                                 ('scene.distance_mm', 0.0))},
          'left.sensor.pixel_size_x_um': 12.0, 'left.sensor.pixel_size_y_um': 12.0,
          'right.sensor.pixel_size_x_um': 10.0, 'right.sensor.pixel_size_y_um': 10.0,
          'right.lens.r1_mm': 5.0, 'right.lens.r2_mm': -5.0, 'right.lens.thickness_mm': 2.5,
          'rig.baseline_mm': 120.0, 'rig.offset_y_mm': 2.0, 'rig.offset_z_mm': -1.5,
          'rig.rotation_x_deg': 0.4, 'rig.rotation_y_deg': -1.2, 'rig.rotation_z_deg': 0.6}


class ConsumerStereo:
    """image_geometry's StereoCameraModel, its CameraInfo formulas only (module docstring)."""

    def __init__(self, left: Mapping[str, Any], right: Mapping[str, Any]):
        self.cams = {}
        for side, info in (('left', left), ('right', right)):
            self.cams[side] = {'K': np.reshape(np.asarray(info['K'], float), (3, 3)),
                               'D': np.asarray(info['D'], float),
                               'R': np.reshape(np.asarray(info['R'], float), (3, 3)),
                               'P': np.reshape(np.asarray(info['P'], float), (3, 4))}
        p_right = self.cams['right']['P']
        fx, cx, cy = p_right[0, 0], p_right[0, 2], p_right[1, 2]
        self.baseline = -p_right[0, 3] / fx
        self.Q = np.zeros((4, 4))
        self.Q[0, 0], self.Q[0, 3], self.Q[1, 1], self.Q[1, 3] = 1.0, -cx, 1.0, -cy
        self.Q[2, 3], self.Q[3, 2] = fx, 1.0 / self.baseline

    def rectify_point(self, side: str, uv_raw: np.ndarray) -> np.ndarray:
        """Return ``rectifyPoint`` of raw pixels ``(N, 2)`` (cv2.undistortPoints, K D R P)."""
        cam = self.cams[side]
        src = np.asarray(uv_raw, dtype=np.float64).reshape(-1, 1, 2)
        return cv2.undistortPoints(src, cam['K'], cam['D'], R=cam['R'], P=cam['P'])[:, 0]

    def project_pixel_to_3d(self, left_uv: np.ndarray, disparity: np.ndarray) -> np.ndarray:
        """Return ``projectPixelTo3d`` of rectified left pixels and disparities, metres."""
        src = np.column_stack([left_uv, disparity, np.ones(len(disparity))])
        dst = src @ self.Q.T
        return dst[:, :3] / dst[:, 3:]

    def get_z(self, disparity: np.ndarray) -> np.ndarray:
        """Return ``getZ``: -Tx / d with Tx the right P's P[0, 3]."""
        return -self.cams['right']['P'][0, 3] / disparity


def scene_points(stereo: StereoModel) -> np.ndarray:
    """Return left-frame points (mm) on a grid of the rectified image at :data:`DEPTHS_MM`."""
    u = np.linspace(0.2, 0.8, 5) * stereo.width
    v = np.linspace(0.15, 0.85, 5) * stereo.height
    uv = np.stack(np.meshgrid(u, v), -1).reshape(-1, 2)
    rays = np.column_stack([uv, np.ones(len(uv))]) @ np.linalg.inv(stereo.K_rect).T
    points = np.concatenate([rays * depth for depth in DEPTHS_MM])
    # The rectified left frame is R1 times the left camera's: back to the left camera's.
    return points @ stereo.R1


def raw_pixels(stereo: StereoModel, points_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return both cameras' raw pixels of left-frame points, through the exact models."""
    in_right = (points_mm - stereo.rig.t_mm) @ stereo.rig.R  # X_r = R^T (X_l - t)
    pixels = []
    for model, pts in ((stereo.left, points_mm), (stereo.right, in_right)):
        pixels.append(pixels_of(model, pts / np.linalg.norm(pts, axis=1, keepdims=True)))
    return pixels[0], pixels[1]


def assert_consumer_gets_the_points_back(stereo: StereoModel, left: Mapping[str, Any],
                                         right: Mapping[str, Any]) -> None:
    """Assert the consumer's 3-D points and rows (module docstring)."""
    consumer = ConsumerStereo(left, right)
    points = scene_points(stereo)
    raw_l, raw_r = raw_pixels(stereo, points)
    inside = np.all(np.isfinite(raw_l) & np.isfinite(raw_r), axis=1)
    for raw, model in ((raw_l, stereo.left), (raw_r, stereo.right)):
        inside &= (raw[:, 0] > 0) & (raw[:, 0] < model.width - 1) & (raw[:, 1] > 0) & (
            raw[:, 1] < model.height - 1)
    assert inside.sum() >= 0.6 * len(points), f'only {inside.sum()} points in both images'
    rect_l = consumer.rectify_point('left', raw_l[inside])
    rect_r = consumer.rectify_point('right', raw_r[inside])
    assert_allclose(rect_l[:, 1], rect_r[:, 1], atol=ROW_TOL_PX)
    disparity = rect_l[:, 0] - rect_r[:, 0]
    got_m = consumer.project_pixel_to_3d(rect_l, disparity)
    want_m = points[inside] @ stereo.R1.T / 1000.0
    depth = want_m[:, 2:]
    assert_allclose(got_m / depth, want_m / depth, atol=DEPTH_RTOL)
    assert_allclose(consumer.get_z(disparity), want_m[:, 2], rtol=DEPTH_RTOL)
    assert_allclose(consumer.baseline, np.linalg.norm(stereo.rig.t_mm) / 1000.0, rtol=1e-12)


def assert_stereo_image_proc_accepts(left: Mapping[str, Any], right: Mapping[str, Any]) -> None:
    """Assert what stereo_image_proc's disparity node checks: one fx, fy, cx, cy; Ty = 0."""
    p_left = np.reshape(np.asarray(left['P'], float), (3, 4))
    p_right = np.reshape(np.asarray(right['P'], float), (3, 4))
    for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)):
        assert p_left[i, j] == p_right[i, j], (i, j)
    assert p_right[1, 3] == 0.0 and p_left[0, 3] == 0.0
    assert p_right[0, 3] < 0.0


@pytest.fixture(scope='module')
def pairs() -> dict[str, StereoModel]:
    return {'config_stereo': build_stereo(load_stereo_params_file(REPO / 'config' /
                                                                  'stereo.yaml')),
            'turned_different_lenses': build_stereo(TURNED)}


@pytest.mark.parametrize('name', ['config_stereo', 'turned_different_lenses'])
def test_image_geometry_gets_the_scene_point_back_from_the_node_camera_infos(pairs, name):
    stereo = pairs[name]
    infos = stereo_camera_infos(stereo)
    assert_stereo_image_proc_accepts(infos['left'], infos['right'])
    assert_consumer_gets_the_points_back(stereo, infos['left'], infos['right'])


def test_a_transposed_r_or_a_baseline_in_mm_is_caught(pairs):
    """The two stereo bugs users report most must fail the consumer check above."""
    stereo = pairs['turned_different_lenses']
    infos = stereo_camera_infos(stereo)
    wrong_r = dict(infos['right'], R=list(np.reshape(infos['right']['R'], (3, 3)).T.ravel()))
    with pytest.raises(AssertionError):
        assert_consumer_gets_the_points_back(stereo, infos['left'], wrong_r)
    p_mm = np.reshape(infos['right']['P'], (3, 4)).copy()
    p_mm[0, 3] *= 1000.0
    with pytest.raises(AssertionError):
        assert_consumer_gets_the_points_back(stereo, infos['left'],
                                             dict(infos['right'], P=list(p_mm.ravel())))


def test_image_geometry_reads_the_files_mechdeconv_stereo_writes(pairs, tmp_path):
    """camera_info_manager YAML of ``mechdeconv stereo`` -> CameraInfo -> the same points."""
    stereo = pairs['turned_different_lenses']
    tree: dict = {}
    for key, value in TURNED.items():
        node = tree
        *parents, leaf = key.split('.')
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    params = tmp_path / 'stereo.yaml'
    params.write_text(yaml.safe_dump({'/**/stereo_node': {'ros__parameters': tree}}))
    blank = np.zeros((240, 320), np.uint8)
    for side in ('left', 'right'):
        cv2.imwrite(str(tmp_path / f'{side}.png'), blank)
    assert main(['stereo', '--params', str(params), str(tmp_path / 'left.png'),
                 str(tmp_path / 'right.png'), '-o', str(tmp_path / 'out')]) == 0
    infos = []
    for side in ('left', 'right'):
        doc = yaml.safe_load((tmp_path / 'out' / f'{side}_camera_info.yaml').read_text())
        assert (doc['image_width'], doc['image_height']) == (320, 240)
        infos.append({'K': doc['camera_matrix']['data'],
                      'D': doc['distortion_coefficients']['data'],
                      'R': doc['rectification_matrix']['data'],
                      'P': doc['projection_matrix']['data']})
    assert_stereo_image_proc_accepts(*infos)
    assert_consumer_gets_the_points_back(stereo, *infos)
