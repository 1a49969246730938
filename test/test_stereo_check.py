# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The stereo check's pieces on exact synthetic matches (no images): fit, sigma, verdict, apply.

Matches are made from scene points at 1.5 to 8 m projected into two different cameras by the
public projection (``pixels_of``) and the rig's convention written out here (``X_r = R^T (X_l -
t)``), with 0.1 px of Gaussian noise; the accuracy on rendered pairs is in
test_stereo_accuracy.py. The detector's convention is read from a rendered blob.
"""

from __future__ import annotations

import math

import cv2
from mechdeconv_ros.imaging import stereo_check as sc
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.model.projection import directions_of, pixels_of
from mechdeconv_ros.schema.params import load_params_file
import numpy as np
from numpy.testing import assert_allclose
import pytest

TOL = {'rig.tolerance.rotation_x_deg': 1.0, 'rig.tolerance.rotation_y_deg': 1.0,
       'rig.tolerance.rotation_z_deg': 1.0}


@pytest.fixture(scope='module')
def cameras():
    """Two cameras of different focal length (818 and 728 px) and size."""
    values = load_params_file('config/case1.yaml')
    values['scene.distance_mm'] = 0.0
    left = dict(values, **{'sensor.pixel_size_x_um': 8.0, 'sensor.pixel_size_y_um': 8.0,
                           'sensor.width_px': 960, 'sensor.height_px': 540})
    right = dict(values, **{'sensor.pixel_size_x_um': 9.0, 'sensor.pixel_size_y_um': 9.0,
                            'sensor.width_px': 860, 'sensor.height_px': 480})
    return build_model(left, 960, 540), build_model(right, 860, 480)


def synthetic_matches(cameras, rot_deg, t_mm=(120.0, 0.0, 0.0), n=1500, noise=0.1,
                      u_max=None, seed=0):
    """Return matched raw pixels of random scene points seen by both cameras."""
    left, right = cameras
    rng = np.random.default_rng(seed)
    u_max = left.width if u_max is None else u_max
    p_l = np.stack([rng.uniform(5, u_max - 5, n), rng.uniform(5, left.height - 5, n)], 1)
    d_l = directions_of(left, p_l)
    depth = rng.uniform(1500.0, 8000.0, n)
    x_l = d_l / d_l[:, 2:3] * depth[:, None]
    x_r = (x_l - np.asarray(t_mm)) @ sc.rotation(*rot_deg)
    p_r = pixels_of(right, x_r)
    keep = (p_r[:, 0] > 5) & (p_r[:, 0] < right.width - 5) & (p_r[:, 1] > 5) & \
        (p_r[:, 1] < right.height - 5)
    p_l, p_r = p_l[keep], p_r[keep]
    return (p_l + rng.normal(0, noise, p_l.shape), p_r + rng.normal(0, noise, p_r.shape))


def run(cameras, matches, rig):
    left, right = cameras
    return sc.check_pairs(left, right, dict({'rig.baseline_mm': 120.0}, **rig), [matches],
                          left.K[1, 1], matched=True)


@pytest.mark.parametrize('sigma', [2.0, 4.0], ids=['sigma2', 'sigma4'])
def test_the_detector_reports_a_blob_at_its_centre(sigma):
    """A Gaussian blob centred at p (pixel centres at integers) is read back at p, not +0.25."""
    rng = np.random.default_rng(0)
    ys, xs = np.mgrid[0:200, 0:200].astype(float)
    errors = []
    for _ in range(8):
        cx, cy = rng.uniform(80, 120, 2)
        img = 230 - 180 * np.exp(-((xs - cx) ** 2 + (ys - cy) ** 2) / (2 * sigma ** 2))
        kps = sc.sift().detect(np.round(img).astype(np.uint8), None)
        best = min(kps, key=lambda k: math.hypot(k.pt[0] - cx, k.pt[1] - cy))
        errors.append((best.pt[0] - cx, best.pt[1] - cy))
    assert_allclose(np.mean(errors, axis=0), [0.0, 0.0], atol=0.02)


def test_opencv_default_sift_is_off_by_a_quarter_pixel():
    """The convention the check corrects (if OpenCV changes it, this test says so)."""
    ys, xs = np.mgrid[0:200, 0:200].astype(float)
    img = 230 - 180 * np.exp(-((xs - 100.3) ** 2 + (ys - 97.6) ** 2) / 8.0)
    kps = cv2.SIFT_create().detect(np.round(img).astype(np.uint8), None)
    best = min(kps, key=lambda k: math.hypot(k.pt[0] - 100.3, k.pt[1] - 97.6))
    assert_allclose([best.pt[0] - 100.3, best.pt[1] - 97.6], [0.25, 0.25], atol=0.03)


def test_the_epipolar_residual_is_zero_for_the_true_rig_only(cameras):
    """Exact matches fit ``X_r = R^T (X_l - t)``; the transposed rotation does not."""
    rot = (0.3, -0.4, 0.2)
    p_l, p_r = synthetic_matches(cameras, rot, noise=0.0)
    d_l, d_r = sc.pair_directions(*cameras, p_l, p_r)
    args = (120.0, d_l, d_r, cameras[0].K[0, 0], cameras[1].K[0, 0])
    exact = sc.epipolar_px(np.array([*rot, 0.0, 0.0]), *args)
    assert np.max(np.abs(exact)) < 1e-3  # the projection round trip's own 1e-4 px
    wrong = sc.epipolar_px(np.array([-0.3, 0.4, -0.2, 0.0, 0.0]), *args)
    assert np.sqrt(np.mean(wrong ** 2)) > 1.0


def test_rectifying_rotations_align_the_rows_of_the_true_rig(cameras):
    """With the true rig every exact match has no vertical disparity, with another it has."""
    rot = (0.3, -0.4, 0.2)
    p_l, p_r = synthetic_matches(cameras, rot, t_mm=(120.0, 3.0, -2.0), noise=0.0)
    d_l, d_r = sc.pair_directions(*cameras, p_l, p_r)
    rig = sc.rig_of(np.array([*rot, 3.0, -2.0]), 120.0)
    assert np.max(np.abs(sc.vertical_disparity(d_l, d_r, rig, 800.0))) < 1e-3
    off = sc.vertical_disparity(d_l, d_r, sc.rig_of(np.zeros(5), 120.0), 800.0)
    assert np.sqrt(np.mean(off ** 2)) > 2.0


@pytest.mark.parametrize('rot', [(0.3, -0.4, 0.2), (-0.5, 0.5, -0.5), (0.0, 0.0, 0.0)],
                         ids=['mixed', 'corner', 'zero'])
def test_the_fit_recovers_the_rotation_within_its_sigma(cameras, rot):
    """Described as 0, the true rotation comes back within 4 sigma (yaw's ~0.005 deg here)."""
    result = run(cameras, synthetic_matches(cameras, rot), TOL)
    got = [result.estimate[n]['value'] for n in sc.RIG_NAMES[:3]]
    sig = np.array([result.estimate[n]['sigma'] for n in sc.RIG_NAMES[:3]])
    assert_allclose(got, rot, atol=0.02)
    assert_allclose(got[0], rot[0], atol=0.002)
    assert np.all(np.abs(np.array(got) - rot) < 4 * sig)
    assert result.verdict == ('ok' if rot == (0.0, 0.0, 0.0) else 'rig_off')
    assert result.vertical_disparity_rms_px_after < 0.2


def test_outliers_are_rejected(cameras):
    """A fifth of the matches swapped at random does not move the estimate."""
    p_l, p_r = synthetic_matches(cameras, (0.2, 0.1, -0.3))
    rng = np.random.default_rng(0)
    bad = rng.choice(len(p_r), len(p_r) // 5, replace=False)
    p_r = p_r.copy()
    p_r[bad] = p_r[rng.permutation(bad)]
    result = run(cameras, (p_l, p_r), TOL)
    got = [result.estimate[n]['value'] for n in sc.RIG_NAMES[:3]]
    sig = np.array([result.estimate[n]['sigma'] for n in sc.RIG_NAMES[:3]])
    assert np.all(np.abs(np.array(got) - [0.2, 0.1, -0.3]) < 4 * sig)
    assert result.matches < 0.85 * result.matches_total


def test_the_offsets_are_fitted_when_their_tolerance_lets_them(cameras):
    """With offset tolerances the fit moves t_y, t_z; without, they are not estimated."""
    matches = synthetic_matches(cameras, (0.1, 0.0, 0.0), t_mm=(120.0, 2.0, 0.0), n=3000,
                                noise=0.05)
    free = run(cameras, matches, dict(TOL, **{'rig.tolerance.offset_y_mm': 5.0,
                                              'rig.tolerance.offset_z_mm': 5.0}))
    assert_allclose(free.estimate['rig.offset_y_mm']['value'], 2.0, atol=0.3)
    fixed = run(cameras, matches, TOL)
    assert 'rig.offset_y_mm' not in fixed.estimate


def test_a_parameter_the_matches_cannot_see_is_held(cameras):
    """A tolerance below the sigma holds that parameter at the description."""
    matches = synthetic_matches(cameras, (0.0, 0.02, 0.0), n=200, noise=0.3)
    result = run(cameras, matches, dict(TOL, **{'rig.tolerance.rotation_y_deg': 1e-5}))
    yaw = result.estimate['rig.rotation_y_deg']
    assert yaw['value'] == 0.0 and yaw['sigma'] > yaw['tolerance']
    user = dict(TOL, **{'rig.rotation_y_deg': 0.0, 'rig.tolerance.rotation_y_deg': 1e-5})
    assert sc.apply_values(result, user).keys() == {'rig.rotation_x_deg', 'rig.rotation_z_deg'}


def test_apply_never_goes_beyond_the_tolerance_about_the_user_value(cameras):
    """A true pitch of 0.5 deg with a 0.2 deg tolerance: the estimate and the set stop at 0.2."""
    tol = dict(TOL, **{'rig.tolerance.rotation_x_deg': 0.2})
    result = run(cameras, synthetic_matches(cameras, (0.5, 0.0, 0.0)), tol)
    assert result.estimate['rig.rotation_x_deg']['value'] <= 0.2 + 1e-12
    user = dict(tol, **{'rig.rotation_x_deg': 0.0})
    assert sc.apply_values(result, user)['rig.rotation_x_deg'] <= 0.2
    narrower = dict(user, **{'rig.tolerance.rotation_x_deg': 0.1})
    assert_allclose(sc.apply_values(result, narrower)['rig.rotation_x_deg'], 0.1)


@pytest.mark.parametrize('case', ['one_sided', 'few'], ids=['one_sided', 'few'])
def test_too_few_or_one_sided_matches_give_no_estimate(cameras, case):
    """Matches only in the left half, or under MIN_MATCHES: not_enough_matches, no estimate."""
    if case == 'one_sided':
        matches = synthetic_matches(cameras, (0.3, 0.0, 0.0), u_max=400)
    else:
        p_l, p_r = synthetic_matches(cameras, (0.3, 0.0, 0.0))
        matches = (p_l[:sc.MIN_MATCHES - 1], p_r[:sc.MIN_MATCHES - 1])
    result = run(cameras, matches, TOL)
    assert result.verdict == 'not_enough_matches'
    assert not result.estimate


def test_a_quarter_pixel_in_both_images_biases_the_pitch_between_focal_lengths(cameras):
    """Why the detector's convention is corrected: +0.25 px in both is a rotation bias."""
    p_l, p_r = synthetic_matches(cameras, (0.0, 0.0, 0.0), noise=0.0)
    exact = run(cameras, (p_l, p_r), TOL).estimate['rig.rotation_x_deg']['value']
    shifted = run(cameras, (p_l + 0.25, p_r + 0.25), TOL).estimate['rig.rotation_x_deg']['value']
    f_l, f_r = cameras[0].K[1, 1], cameras[1].K[1, 1]
    assert abs(exact) < 2e-4
    assert_allclose(shifted, math.degrees(0.25 / f_r - 0.25 / f_l), rtol=0.2)
    assert abs(shifted) > 0.0015
