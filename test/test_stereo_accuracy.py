# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The rectification's accuracy on pairs rendered by an independent route (issue 38, item 7).

The raw pairs come from test/stereo_scenes.py: every raw pixel's rays by the cameras' exact
inverse (``directions_of``), the right camera's through the true rig, into a textured scene
from 1.5 to 8 m; the rectification under test traces the other way (``pixels_of`` per
rectified pixel). The right camera's sensor is off-centre and tilted and the rig is turned
about all three axes and offset, so a convention error anywhere (R against R^T, the half
turns, the sensor pose) shows. Measures:

- rows: the RMS over the image of the per-64-px-cell median vertical disparity of matched
  SIFT features (a matcher's own scatter, ~0.08 px per match, averages out; a rectification
  error does not), within 0.1 px;
- OpenCV's StereoSGBM disparity against the true ``f B / Z``: median absolute error within
  0.25 px on pixels seen by both cameras away from depth edges.

Each measure is also shown to fail on a description that is wrong by 0.05 deg. A 160 deg lens
with 2400 px of distortion (config/wide_angle.yaml) passes the same two limits.
"""

from __future__ import annotations

from pathlib import Path

import cv2
from mechdeconv_ros.imaging.stereo_remap import StereoRectifier
from mechdeconv_ros.model.stereo import build_stereo
from mechdeconv_ros.schema.params import load_params_file
import numpy as np
import pytest
from stereo_scenes import depth_scene, rectified_truth, render_pair

SIZE = (480, 360)
#: The lenses: Case 2 (f = 4.44 mm, 4.06 x 4.44 um pixels: fx != fy), the scene at infinity;
#: the right camera's sensor off-centre and tilted.
LENSES = {'left.scene.distance_mm': 0.0, 'right.scene.distance_mm': 0.0,
          'right.sensor.axis_offset_x_mm': 0.02, 'right.sensor.axis_offset_y_mm': -0.01,
          'right.sensor.tilt_x_deg': 1.0, 'right.sensor.tilt_y_deg': -0.5}
TRUE_RIG = {'rig.baseline_mm': 120.0, 'rig.offset_y_mm': 1.0, 'rig.offset_z_mm': -0.5,
            'rig.rotation_x_deg': 0.3, 'rig.rotation_y_deg': -0.4, 'rig.rotation_z_deg': 0.25}
#: A 160 deg lens (config/wide_angle.yaml, Laikin) on 480x300 px of 8 um (its sensor at a
#: quarter of the pixels): 2400 px of distortion at the corner; the right sensor again
#: off-centre and tilted.
WIDE_SIZE = (480, 300)
WIDE_LENSES = {
    **{f'{camera}.{name}': value for camera in ('left', 'right') for name, value in
       load_params_file(Path(__file__).resolve().parents[1] / 'config' / 'wide_angle.yaml')
       .items() if not name.startswith(('output.', 'check.'))},
    **{f'{camera}.sensor.{name}': value for camera in ('left', 'right') for name, value in
       (('width_px', 480), ('height_px', 300), ('pixel_size_x_um', 8.0),
        ('pixel_size_y_um', 8.0))},
    'right.sensor.axis_offset_x_mm': 0.02, 'right.sensor.tilt_x_deg': 1.0}
ROWS_MAX_PX = 0.1
SGBM_MAX_PX = 0.25
CELL_PX = 64
NUM_DISPARITIES = 112


@pytest.fixture(scope='module')
def pair():
    """Return the raw pair and its truth (rendered once per module)."""
    return render_pair(LENSES, TRUE_RIG, depth_scene(0), SIZE)


@pytest.fixture(scope='module')
def wide_pair():
    """Return the 160 deg lenses' raw pair (textures of 2.5 px at the rectified focal length)."""
    focal = build_stereo({**WIDE_LENSES, **TRUE_RIG}, WIDE_SIZE, WIDE_SIZE).K_rect[0, 0]
    return render_pair(WIDE_LENSES, TRUE_RIG, depth_scene(0, focal_px=focal), WIDE_SIZE)


def rectified(pair, rig_values, lenses=LENSES, size=SIZE):
    """Return the pair rectified with ``rig_values`` described, and that stereo model."""
    left, right, _ = pair
    stereo = build_stereo({**lenses, **rig_values}, size, size)
    return (*StereoRectifier(stereo).rectify(left, right), stereo)


def row_error_px(left_rect: np.ndarray, right_rect: np.ndarray) -> tuple[float, int]:
    """
    Return the RMS over 64 px cells of the cells' median vertical disparity, and the matches.

    SIFT, Lowe's ratio 0.75, matches within 3 px of a row and of positive disparity; cells
    with at least 3 matches. (SIFT's +0.25 px blob offset is the same in both images of one
    rectified camera and cancels.)
    """
    sift = cv2.SIFT_create()
    k1, d1 = sift.detectAndCompute(left_rect, None)
    k2, d2 = sift.detectAndCompute(right_rect, None)
    matches = [m for m, n in cv2.BFMatcher().knnMatch(d1, d2, k=2)
               if m.distance < 0.75 * n.distance]
    p1 = np.array([k1[m.queryIdx].pt for m in matches])
    p2 = np.array([k2[m.trainIdx].pt for m in matches])
    dy = p1[:, 1] - p2[:, 1]
    keep = (np.abs(dy) < 3.0) & (p1[:, 0] - p2[:, 0] > -1.0)
    cells: dict[tuple[int, int], list[float]] = {}
    for (x, y), e in zip(p1[keep], dy[keep]):
        cells.setdefault((int(x // CELL_PX), int(y // CELL_PX)), []).append(float(e))
    medians = [np.median(v) for v in cells.values() if len(v) >= 3]
    return float(np.sqrt(np.mean(np.square(medians)))), int(keep.sum())


def sgbm_error_px(left_rect: np.ndarray, right_rect: np.ndarray, truth: dict,
                  num_disparities: int = NUM_DISPARITIES) -> tuple[float, float, int]:
    """
    Return SGBM's median absolute and median signed disparity error, and the pixels compared.

    Compared: pixels whose surface both cameras see (the right image's true disparity there
    agrees), 4 px or more from a depth edge, inside the search range.
    """
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=num_disparities, blockSize=5,
                                 P1=8 * 25, P2=32 * 25, uniquenessRatio=10, disp12MaxDiff=1)
    found = sgbm.compute(left_rect, right_rect).astype(np.float32) / 16.0
    want, want_right = truth['disparity'], truth['disparity_right']
    h, w = want.shape
    cols = np.clip(np.round(np.arange(w)[None, :] - np.nan_to_num(want)).astype(int), 0, w - 1)
    with np.errstate(invalid='ignore'):
        both = np.abs(want_right[np.arange(h)[:, None], cols] - want) < 0.5
    flat = np.nan_to_num(want).astype(np.float32)
    step = np.abs(cv2.Sobel(flat, cv2.CV_32F, 1, 0)) + np.abs(cv2.Sobel(flat, cv2.CV_32F, 0, 1))
    edge = cv2.dilate((step > 1.0).astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    valid = both & ~edge & (found > 0) & (left_rect > 0)
    valid[:, :num_disparities] = False
    err = found[valid] - want[valid]
    return float(np.median(np.abs(err))), float(np.median(err)), int(valid.sum())


def test_the_scene_spans_1_5_to_8_m(pair):
    depth = pair[2]['depth_mm']
    assert 1400.0 < np.nanmin(depth) < 1600.0
    assert 6000.0 < np.nanmax(depth) <= 8000.0
    assert np.isfinite(depth).mean() > 0.99


def test_rows_are_aligned_with_the_true_rig(pair):
    left_rect, right_rect, _ = rectified(pair, TRUE_RIG)
    rms, matches = row_error_px(left_rect, right_rect)
    assert matches > 300
    assert rms < ROWS_MAX_PX, f'rows off by {rms:.3f} px RMS over the cells'


def test_the_row_measure_sees_a_pitch_of_0_05_deg(pair):
    """At f' ~ 1040 px, 0.05 deg of pitch is 0.9 px of vertical disparity."""
    wrong = {**TRUE_RIG, 'rig.rotation_x_deg': TRUE_RIG['rig.rotation_x_deg'] + 0.05}
    rms, _ = row_error_px(*rectified(pair, wrong)[:2])
    assert rms > 5 * ROWS_MAX_PX


def test_sgbm_disparity_is_f_b_over_z_with_the_true_rig(pair):
    left_rect, right_rect, stereo = rectified(pair, TRUE_RIG)
    assert stereo.K_rect[0, 0] == pytest.approx(pair[2]['stereo'].K_rect[0, 0])
    median_abs, median, pixels = sgbm_error_px(left_rect, right_rect, pair[2])
    assert pixels > 0.4 * SIZE[0] * SIZE[1]
    assert median_abs < SGBM_MAX_PX, f'SGBM off by {median_abs:.3f} px (median)'
    assert abs(median) < SGBM_MAX_PX


def test_the_disparity_measure_sees_a_yaw_of_0_05_deg(pair):
    """A yaw error biases every disparity by about f' x 0.05 deg = 0.9 px."""
    wrong = {**TRUE_RIG, 'rig.rotation_y_deg': TRUE_RIG['rig.rotation_y_deg'] + 0.05}
    left_rect, right_rect, stereo = rectified(pair, wrong)
    # The truth the wrong description claims: its own rectified frame and rig.
    claimed = rectified_truth(stereo, depth_scene(0))
    median_abs, _, _ = sgbm_error_px(left_rect, right_rect, claimed)
    assert median_abs > 2 * SGBM_MAX_PX


def test_a_160_deg_lens_with_2400_px_of_distortion_is_rectified_exactly(wide_pair):
    left_rect, right_rect, stereo = rectified(wide_pair, TRUE_RIG, WIDE_LENSES, WIDE_SIZE)
    assert stereo.left.max_displacement_px > 2000.0
    rms, matches = row_error_px(left_rect, right_rect)
    assert matches > 300
    assert rms < ROWS_MAX_PX, f'rows off by {rms:.3f} px RMS over the cells'
    median_abs, median, pixels = sgbm_error_px(left_rect, right_rect, wide_pair[2], 48)
    assert pixels > 0.4 * WIDE_SIZE[0] * WIDE_SIZE[1]
    assert median_abs < SGBM_MAX_PX and abs(median) < SGBM_MAX_PX
