# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""LensModel: intrinsics, radial map, K_new, equivalent D, reasons for refusals."""

from __future__ import annotations

import math

from benchmarks.metrics import radii_mean_error_percent
import cv2
from mechdeconv_ros.imaging.remap import build_float_maps, Rectifier
from mechdeconv_ros.model.camera_yaml import camera_info_yaml
from mechdeconv_ros.model.model import build_model, ModelError
from mechdeconv_ros.optics.raytrace import image_plane, trace_chief_rays
from mechdeconv_ros.optics.thick_lens import thick_lens_focal_length
import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

CASE2 = {'sensor.width_px': 640, 'sensor.height_px': 480}


@pytest.fixture(scope='module')
def case2():
    return build_model(CASE2)


def _scene_grid(model, nx=20, ny=18, fill=0.95):
    """
    Return ideal (corrected) and true raw pixel positions of a straight scene grid.

    The grid is straight in the ideal pinhole image (a planar scene grid); each point's raw
    position comes from its own exact chief-ray trace, not from the model's interpolated curve.
    """
    xn, yn = np.meshgrid(np.linspace(-fill, fill, nx) * (model.width - 1) / 2 / model.K[0, 0],
                         np.linspace(-fill, fill, ny) * (model.height - 1) / 2 / model.K[1, 1])
    tan_field = np.hypot(xn, yn)
    lens = model.prescription
    distance = model.values['scene.distance_mm'] or math.inf
    sensor_z, image_distance = image_plane(lens, distance)
    real_mm = -trace_chief_rays(lens, distance, sensor_z, tan_field.ravel()).reshape(xn.shape)
    with np.errstate(invalid='ignore', divide='ignore'):
        gain = np.where(tan_field > 0, real_mm / (tan_field * image_distance), 1.0)
    raw = np.stack([model.K[0, 2] + model.K[0, 0] * xn * gain,
                    model.K[1, 2] + model.K[1, 1] * yn * gain], axis=-1)
    rect = np.stack([model.K_new[0, 2] + model.K_new[0, 0] * xn,
                     model.K_new[1, 2] + model.K_new[1, 1] * yn], axis=-1)
    return rect.reshape(-1, 2), raw.reshape(-1, 2)


def test_raw_intrinsics_follow_paraxial_optics(case2):
    f = thick_lens_focal_length(1.5168, 4.0, -4.0, 3.0)
    v = f * 1000.0 / (1000.0 - f)
    assert_allclose(case2.focal_length_mm, f, rtol=1e-12)
    assert_allclose(case2.image_distance_mm, v, rtol=1e-12)
    assert_allclose(case2.K, [[v / 4.0625e-3, 0, 319.5], [0, v / 4.4375e-3, 239.5], [0, 0, 1]],
                    rtol=1e-12)
    assert case2.P.shape == (3, 4)
    assert_allclose(case2.P[:, :3], case2.K_new)


def test_radial_map_is_dense_monotonic_and_paraxial_at_centre(case2):
    curve = case2.curve
    assert curve.ideal_mm.size >= 1024
    assert np.all(np.diff(curve.real_mm) > 0)
    assert curve.real_mm[0] == 0.0
    assert_allclose(curve.real_mm[1] / curve.ideal_mm[1], 1.0, atol=1e-6)
    # Past the output corner (docs/design.md section 2.5).
    corner = math.hypot(320 / case2.K_new[0, 0], 240 / case2.K_new[1, 1])
    assert curve.valid_ideal_mm >= corner * case2.image_distance_mm
    # This lens with its stop inside the glass is barrel-distorted at the corner.
    assert curve.real_mm[-1] < curve.ideal_mm[-1]


def test_maps_reproduce_the_exact_trace(case2):
    """The float and fixed-point maps send each ideal grid point to its traced raw position."""
    rect, raw = _scene_grid(case2)
    map_x, map_y = build_float_maps(case2)
    # Bilinear sampling in float64 (cv2.remap would quantise positions to 1/32 px).
    sampled = np.stack([_bilinear(map_x, rect), _bilinear(map_y, rect)], axis=-1)
    error_px = np.hypot(*(sampled - raw).T)
    # Bilinear interpolation of a smooth map between pixel centres: well below 0.01 px.
    assert error_px.max() < 0.01
    assert radii_mean_error_percent(sampled, raw, (case2.K[0, 2], case2.K[1, 2])) < 0.01


def _bilinear(image, points):
    x, y = points[:, 0], points[:, 1]
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    img = image.astype(np.float64)
    return ((1 - fx) * (1 - fy) * img[y0, x0] + fx * (1 - fy) * img[y0, x0 + 1]
            + (1 - fx) * fy * img[y0 + 1, x0] + fx * fy * img[y0 + 1, x0 + 1])


def test_point_round_trip(case2):
    rng = np.random.default_rng(0)
    points = rng.uniform([0, 0], [639, 479], size=(500, 2))
    back = case2.raw_from_rect(case2.rect_from_raw(points))
    assert_allclose(back, points, atol=1e-6)
    rect = case2.rect_from_raw(points)
    center = (case2.K_new[0, 2], case2.K_new[1, 2])
    assert radii_mean_error_percent(case2.rect_from_raw(back), rect, center) < 1e-4


def test_image_round_trip(case2):
    """A smooth scene rendered through the lens and corrected comes back (< 1 % mean error)."""
    v, u = np.mgrid[0:480, 0:640].astype(np.float32)
    scene = 127.5 + 100.0 * np.sin(u / 23.0) * np.cos(v / 31.0)
    raw = cv2.remap(scene, *_distortion(case2), cv2.INTER_LINEAR)
    corrected = Rectifier(case2).correct(raw)
    inner = (slice(8, 472), slice(8, 632))
    error_corrected = np.mean(np.abs(corrected[inner] - scene[inner]))
    error_raw = np.mean(np.abs(raw[inner] - scene[inner]))
    # Two bilinear resamplings of a smooth scene cost a few hundredths of a grey level; the
    # uncorrected image is off by more than a grey level.
    assert error_corrected < 0.1
    assert error_raw > 10 * error_corrected


def _distortion(model):
    from mechdeconv_ros.imaging.remap import distortion_maps
    return distortion_maps(model)


def test_straight_lines_stay_straight(case2):
    """Scene lines traced through the lens bend; the corrected points are collinear again."""
    rect, raw = _scene_grid(case2, nx=21, ny=5)
    rows_raw = raw.reshape(5, 21, 2)
    rows_fixed = case2.rect_from_raw(raw).reshape(5, 21, 2)
    top_raw, top_fixed = rows_raw[0], rows_fixed[0]
    bow_raw = np.ptp(top_raw[:, 1])
    bow_fixed = np.ptp(top_fixed[:, 1])
    assert bow_raw > 1.0, 'the test line must be visibly bent by this lens'
    assert bow_fixed < 0.01


@pytest.mark.parametrize('alpha', [0.0, 0.5, 1.0], ids=['alpha0', 'alpha05', 'alpha1'])
def test_alpha_like_get_optimal_new_camera_matrix(alpha):
    model = build_model({**CASE2, 'output.alpha': alpha})
    map_x, map_y = build_float_maps(model)
    inside = (map_x >= -0.5) & (map_x <= 639.5) & (map_y >= -0.5) & (map_y <= 479.5)
    corners = model.rect_from_raw(np.array([[0, 0], [639, 0], [0, 479], [639, 479],
                                            [319.5, 0], [0, 239.5]], dtype=float))
    if alpha == 0.0:
        assert inside.all(), 'alpha = 0 must show no pixel from outside the source'
    if alpha == 1.0:
        assert np.all((corners >= -0.5) & (corners <= [639.5, 479.5])), \
            'alpha = 1 must keep every source pixel in view'
        assert not inside.all()


def test_alpha_scales_monotonically():
    scales = [build_model({**CASE2, 'output.alpha': a}).K_new[0, 0] for a in (0.0, 0.5, 1.0)]
    assert scales[0] > scales[1] > scales[2]


def test_non_square_pixels_and_output_size():
    model = build_model({**CASE2, 'output.width_px': 320, 'output.height_px': 200})
    assert (model.out_width, model.out_height) == (320, 200)
    assert_allclose(model.K[0, 0] / model.K[1, 1], 4.4375 / 4.0625)
    assert_allclose(model.K_new[0, 0] / model.K_new[1, 1], 4.4375 / 4.0625)
    assert build_float_maps(model)[0].shape == (200, 320)


def test_equivalent_d_matches_opencv(case2):
    """Check that OpenCV's own undistortPoints with the published K, D, P agrees with the trace."""
    rng = np.random.default_rng(1)
    points = rng.uniform([0, 0], [639, 479], size=(400, 2))
    ours = case2.rect_from_raw(points)
    theirs = cv2.undistortPoints(points[:, None, :], case2.K, np.array(case2.D), R=np.eye(3),
                                 P=case2.P)[:, 0, :]
    assert case2.distortion_model == 'plumb_bob'
    assert case2.fit_rms_px < 0.1
    assert np.abs(ours - theirs).max() < 0.05


def test_rational_model_when_plumb_bob_misses():
    """A strongly distorting field (4K on the Case 2 lens) needs rational_polynomial."""
    model = build_model({'sensor.width_px': 3840, 'sensor.height_px': 2160})
    assert model.distortion_model == 'rational_polynomial'
    assert len(model.D) == 8
    fits = {fit.distortion_model: fit for fit in model.equivalent_fits}
    assert fits['plumb_bob'].max_error_px > 0.05
    assert model.equivalent_max_error_px == fits['rational_polynomial'].max_error_px <= 0.05
    assert model.fit_rms_px < fits['plumb_bob'].rms_error_px


def test_stop_offset_changes_the_distortion():
    near = build_model({**CASE2, 'lens.stop_offset_mm': 0.0})
    far = build_model({**CASE2, 'lens.stop_offset_mm': 1.0})
    thick = build_model({**CASE2, 'lens.thickness_mm': 5.0})
    assert near.D != far.D
    assert abs(near.max_displacement_px - far.max_displacement_px) > 0.5
    assert thick.focal_length_mm != near.focal_length_mm


def test_nominal_focal_length_builds_a_symmetric_biconvex():
    model = build_model({**CASE2, 'lens.focal_length_mm': 6.0})
    assert_allclose(model.focal_length_mm, 6.0, rtol=1e-9)
    r1 = model.prescription.surfaces[0].radius_mm
    assert_allclose(model.prescription.surfaces[1].radius_mm, -r1)


def test_object_at_infinity():
    model = build_model({**CASE2, 'scene.distance_mm': 0.0})
    assert_allclose(model.image_distance_mm, model.focal_length_mm, rtol=1e-12)
    report = model.report()
    assert report['scene_distance_mm'] is None
    assert report['footprint_mm']['x'] is None


@pytest.mark.parametrize('values, parameter, words', [
    ({'lens.r1_mm': 4.0, 'lens.r2_mm': 4.0, 'lens.thickness_mm': 0.0}, 'lens.r1_mm', 'afocal'),
    ({'scene.distance_mm': 3.0}, 'scene.distance_mm', 'inside the focal length'),
    ({'lens.refractive_index': 0.9}, 'lens.refractive_index', 'below the minimum'),
    ({'lens.thickness_mm': -1.0}, 'lens.thickness_mm', 'below the minimum'),
    ({'lens.r1_mm': -4.0, 'lens.r2_mm': 4.0}, 'lens.r1_mm', 'diverges'),
    ({'lens.r1_mm': math.nan}, 'lens.r1_mm', 'finite'),
    ({'output.interpolation': 'bogus'}, 'output.interpolation', 'one of'),
    ({'lens.surfaces.radius_mm': [10.0, -10.0], 'lens.surfaces.thickness_mm': [2.0],
      'lens.surfaces.refractive_index': [1.5, 1.0]}, 'lens.surfaces.thickness_mm', 'per surface'),
    ({'lens.surfaces.radius_mm': [10.0, -10.0], 'lens.surfaces.thickness_mm': [2.0, 0.0],
      'lens.surfaces.refractive_index': [1.5, 1.0], 'lens.stop_surface': 5},
     'lens.stop_surface', 'not a surface'),
    ({'output.width_px': 16000, 'output.height_px': 16000}, 'output.width_px', 'Mpx'),
], ids=['afocal', 'scene-inside-f', 'n-0.9', 't-negative', 'diverging', 'nan',
        'interpolation', 'surface-arrays', 'stop-surface', 'huge-output'])
def test_refusals_name_the_parameter(values, parameter, words):
    with pytest.raises(ModelError) as info:
        build_model({**CASE2, **values})
    assert info.value.parameter == parameter
    assert str(info.value).startswith(parameter)
    assert words in str(info.value)


def test_prescription_mode_matches_thick_lens():
    """The thick lens written as a two-surface prescription gives the same model."""
    thick = build_model({**CASE2, 'lens.stop_offset_mm': 0.0})
    z_h = thick.summary['principal_planes_mm']['front']
    # Stop at the front principal plane of the thick lens = a flat dummy surface in the glass.
    values = {**CASE2, 'lens.surfaces.radius_mm': [4.0, 0.0, -4.0],
              'lens.surfaces.thickness_mm': [z_h, 3.0 - z_h, 0.0],
              'lens.surfaces.refractive_index': [1.5168, 1.5168, 1.0],
              'lens.stop_surface': 1}
    surfaces = build_model(values)
    assert_allclose(surfaces.K, thick.K, rtol=1e-9)
    assert_allclose(surfaces.curve.real_mm[:1000], thick.curve.real_mm[:1000], atol=1e-9)


def test_report_has_the_documented_keys(case2):
    report = case2.report()
    for key in ('focal_length_mm', 'focal_length_sigma_mm', 'image_distance_mm', 'fov_deg',
                'f_number', 'hyperfocal_mm', 'hyperfocal_sigma_mm', 'depth_of_field_mm',
                'feature_resolution_mm', 'footprint_mm', 'K', 'D', 'distortion_model', 'P',
                'fit_rms_px', 'max_displacement_px', 'distortion_curve', 'corner_sigma_px'):
        assert key in report
    assert report['f_number'] == pytest.approx(case2.focal_length_mm / 1.0)
    # c = 0.1 % of f and n_f = f / d_a give h = d_a / 0.001 = 1000 mm for d_a = 1 mm.
    assert report['hyperfocal_mm'] == pytest.approx(1000.0)
    assert report['depth_of_field_mm']['near'] == pytest.approx(500.0)
    assert report['depth_of_field_mm']['far'] is None
    assert 0.0 < report['focal_length_sigma_mm'] < 0.1
    assert report['corner_sigma_px'] > 0.0


def test_depth_of_field_warning():
    model = build_model({**CASE2, 'scene.focus_distance_mm': 300.0})
    assert any('depth of field' in w for w in model.summary['warnings'])


def test_camera_info_yaml(case2):
    data = yaml.safe_load(camera_info_yaml(case2))
    assert data['image_width'] == 640 and data['image_height'] == 480
    assert data['distortion_model'] == 'plumb_bob'
    assert_allclose(np.reshape(data['camera_matrix']['data'], (3, 3)), case2.K)
    assert_allclose(np.reshape(data['projection_matrix']['data'], (3, 4)), case2.P)
    assert data['rectification_matrix']['data'] == [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]


def test_radii_mean_error_definition():
    true = np.array([[10.0, 0.0], [0.0, 20.0], [0.0, 0.0]])
    est = np.array([[11.0, 0.0], [0.0, 19.0], [5.0, 5.0]])
    # |11-10|/10 = 10 %, |19-20|/20 = 5 %; the point on the axis carries no radius.
    assert radii_mean_error_percent(est, true, (0.0, 0.0)) == pytest.approx(7.5)
