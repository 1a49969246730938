# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Vignetting correction and export: gain map, saturation, depth, limits, CLI, lensfun fit.

A uniform Lambertian scene photographed through the lens gives a raw frame proportional to RI
at each raw pixel; the corrected image of that frame must be flat (up to the gain limit).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
from mechdeconv_ros.imaging.remap import build_gain_map, Rectifier
from mechdeconv_ros.model.model import build_model, ModelError
from mechdeconv_ros.optics import illumination as il
from mechdeconv_ros.schema.params import check_values, load_params_file
from mechdeconv_ros.tools.cli import main
import numpy as np
from numpy.testing import assert_allclose
import pytest

ROOT = Path(__file__).resolve().parents[1]
CASE2 = str(ROOT / 'config' / 'case2.yaml')
COOKE = str(ROOT / 'config' / 'cooke_triplet.yaml')


def _case2(**overrides):
    values = load_params_file(CASE2)
    values.update(overrides)
    return build_model(values)


def _clipped_cooke(**overrides):
    """Return the Cooke triplet on a wide sensor with a tight front rim (mechanical loss)."""
    values = load_params_file(COOKE)
    values.update({'sensor.width_px': 1800, 'sensor.height_px': 1200,
                   'sensor.pixel_size_x_um': 16.0, 'sensor.pixel_size_y_um': 16.0})
    values['lens.surfaces.semi_diameter_mm'][0] = 8.0
    values['lens.surfaces.semi_diameter_mm'][5] = 6.8
    values.update(overrides)
    return build_model(values)


def test_uniform_scene_comes_out_flat():
    model = _case2(**{'output.vignetting_correction': True, 'output.alpha': 0.0})
    rect = Rectifier(model)
    # The raw frame of a uniform Lambertian scene: 200 x RI at each raw pixel.
    raw = (200.0 * il.raw_attenuation(model)).astype(np.float32)
    out = rect.correct(raw)
    plain = Rectifier(model, vignetting=False).correct(raw)
    inside = out > 0
    assert inside.mean() > 0.95
    # Bilinear resampling of a smooth field: flat to a few 1e-4.
    assert_allclose(out[inside], 200.0, rtol=2e-3)
    # Without the correction the corners stay dark.
    assert plain[0, 0] < 0.9 * 200.0
    assert plain[0, 0] == pytest.approx(out[0, 0] / rect.gain[0, 0], rel=1e-5)


def test_integer_frames_saturate_and_depth_is_untouched():
    model = _case2(**{'output.vignetting_correction': True})
    rect = Rectifier(model)
    bright = np.full((model.height, model.width, 3), 250, np.uint8)
    out = rect.correct(bright)
    assert out[model.out_height // 2, model.out_width // 2, 0] == 250
    assert out[0, 0, 0] == 255 and out.max() == 255   # saturated, not wrapped
    mono16 = np.full((model.height, model.width), 60000, np.uint16)
    assert rect.correct(mono16).max() == 65535
    depth = np.full((model.height, model.width), 1500, np.uint16)
    kept = rect.correct(depth, nearest=True, gain=False)
    assert kept.max() == 1500


def test_gain_map_follows_ri_at_the_source_position():
    model = _case2(**{'output.alpha': 1.0})
    curve = model.illumination(with_fraction=False)
    gain = build_gain_map(model, curve, 4.0)
    rect = Rectifier(model, vignetting=False)
    v, u = np.mgrid[0:model.out_height:37, 0:model.out_width:41]
    raw = model.raw_from_rect(np.stack([u, v], axis=-1).astype(np.float64))
    radius = np.hypot((raw[..., 0] - model.K[0, 2]) * model.pixel_mm[0],
                      (raw[..., 1] - model.K[1, 2]) * model.pixel_mm[1])
    valid = np.isfinite(radius)
    expected = 1.0 / curve.at(radius[valid])
    assert_allclose(gain[v, u][valid], expected, rtol=2e-4)
    assert rect.gain is None


def test_gain_limit_ends_the_corrected_field_with_a_warning():
    model = _clipped_cooke(**{'output.vignetting_correction': True, 'output.alpha': 1.0,
                              'output.max_vignetting_gain': 1.2})
    curve = model.illumination(with_fraction=False)
    assert curve.corner_ri < 1 / 1.2
    rect = Rectifier(model)
    assert 'output.max_vignetting_gain' in rect.vignetting_warning
    assert rect.gain.max() <= 1.2 + 1e-6
    assert rect.gain[0, 0] == 0.0          # beyond the corrected field: black
    frame = np.full((model.height, model.width), 100, np.uint8)
    out = rect.correct(frame)
    assert out[0, 0] == 0 and out[model.out_height // 2, model.out_width // 2] == 100
    assert np.all(np.isfinite(rect.gain))


def test_mechanical_share_and_fraction():
    model = _clipped_cooke()
    curve = model.illumination()
    assert curve.pupil_pass_fraction[0] == pytest.approx(1.0)
    assert curve.pupil_pass_fraction[-1] < 0.9
    assert np.all(np.diff(curve.ri) <= 1e-9)
    # The fraction is the clipped beam over the stop-only beam: RI / fraction is the natural
    # fall-off, which decreases slowly (cos^4-like) and stays above RI.
    natural = curve.ri / curve.pupil_pass_fraction
    assert np.all(natural >= curve.ri - 1e-12)
    assert natural[-1] > 0.85


@pytest.mark.parametrize('value', [0.5, math.nan, math.inf])
def test_max_gain_below_one_or_not_finite_is_refused(value):
    with pytest.raises(ValueError, match='output.max_vignetting_gain'):
        check_values({'output.max_vignetting_gain': value})
    with pytest.raises(ModelError, match='output.max_vignetting_gain'):
        build_model({'output.max_vignetting_gain': value, 'sensor.width_px': 64,
                     'sensor.height_px': 48})


def test_lensfun_fit_reproduces_the_curve():
    model = _case2()
    fit = il.lensfun_fit(model)
    assert fit.max_error_pts < 0.5
    half = math.hypot(model.width / 2 * model.pixel_mm[0], model.height / 2 * model.pixel_mm[1])
    r = np.linspace(0, 1, 11)
    poly = 1 + fit.k1 * r ** 2 + fit.k2 * r ** 4 + fit.k3 * r ** 6
    assert_allclose(poly, model.illumination().at(r * half), atol=fit.max_error_pts / 100 + 1e-9)
    assert fit.distance_m == pytest.approx(1.0)
    assert fit.f_number == pytest.approx(model.summary['f_number'])


def test_cli_info_and_exports(capsys, tmp_path):
    assert main(['info', '--params', CASE2, '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    ri = report['relative_illumination']
    assert len(ri['image_height_mm']) == len(ri['ri']) == len(ri['pupil_pass_fraction'])
    assert ri['ri'][0] == 1.0 and 0.8 < ri['corner_ri'] < 0.87
    # Real radii on the sensor: the last sample is just past the raw half-diagonal.
    half = math.hypot(320 * 4.0625e-3, 240 * 4.4375e-3)
    assert ri['image_height_mm'][-1] == pytest.approx(1.02 * half)

    png = tmp_path / 'vignette.png'
    assert main(['vignetting', '--params', CASE2, '--png', str(png), '--lensfun']) == 0
    out = capsys.readouterr().out
    image = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
    assert image.dtype == np.uint16 and image.shape == (480, 640)
    assert image.max() == 65535
    assert image[0, 0] / 65535 == pytest.approx(ri['corner_ri'], abs=2e-3)
    assert '<vignetting model="pa" focal="4.437" aperture="4.44" distance="1" k1="' in out
    assert 'max fit error ' in out and ' pts' in out
    assert main(['vignetting', '--params', CASE2]) == 2


def test_lensfun_fit_stops_at_the_fisheye_image_circle(capsys):
    model = build_model(load_params_file(ROOT / 'config' / 'fisheye.yaml'))
    curve = model.illumination()
    assert curve.corner_ri == 0.0                  # the corners lie beyond the image circle
    fit = il.lensfun_fit(model, curve)
    half = math.hypot(model.width / 2 * model.pixel_mm[0], model.height / 2 * model.pixel_mm[1])
    assert 0.7 < fit.fit_radius < 0.8
    assert fit.fit_radius * half <= model.curve.valid_real_mm + 0.01
    assert fit.max_error_pts < 0.5
    # It ends where the rim starts to cut the f/1.8 beam (the whole beam still passes there),
    # wherever the curve's samples fall.
    end = fit.fit_radius * half
    assert np.interp(end, curve.height_mm, curve.pupil_pass_fraction) > 0.99
    assert np.interp(end + 0.04, curve.height_mm, curve.ri) < 0.05     # the rim ends it
    finer = il.lensfun_fit(model, il.relative_illumination(model, samples=97))
    assert abs(finer.fit_radius - fit.fit_radius) < 0.01 and finer.max_error_pts < 0.5
    assert main(['vignetting', '--params', str(ROOT / 'config' / 'fisheye.yaml'),
                 '--lensfun']) == 0
    assert 'max fit error' in capsys.readouterr().out
