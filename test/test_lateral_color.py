# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Tests of lateral colour correction (issue #20): channel traces, the folded remap, registration.

Layers: the green channel at the focus wavelength is the model itself (identity); every
channel's real height against an independent trace by optiland at its wavelength to the same
sensor plane (test/data/lateral_color_reference.json, tools/make_lateral_color_reference.py),
within 0.01 px over the whole field; the folded per-channel remap equals remapping each channel
alone; a rendered dot chart whose channels are each distorted by their own trace registers
after the correction within 0.05 px (and does not without it); the switch is refused for a lens
without glass names.
"""

from __future__ import annotations

from dataclasses import replace
import json
import math
from pathlib import Path
from typing import Any

import cv2
from mechdeconv_ros.imaging import channel_remap
from mechdeconv_ros.imaging.channel_remap import ChannelRemap
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model import lateral_color
from mechdeconv_ros.model.model import build_model, LensModel, ModelError
from mechdeconv_ros.schema.params import load_params_file, to_params_yaml
from mechdeconv_ros.tools.cli import main
import numpy as np
import numpy.testing as npt
import pytest

REPO = Path(__file__).resolve().parents[1]
REFERENCE = json.loads((REPO / 'test' / 'data' / 'lateral_color_reference.json').read_text())
LENSES = sorted(REFERENCE['lenses'])
#: The accuracy and registration targets of issue #20, px.
CURVE_TOLERANCE_PX = 0.01
REGISTRATION_TOLERANCE_PX = 0.05


def glass_values(key: str, **overrides: Any) -> dict[str, Any]:
    """Return the parameter values of a reference lens, with its glass names."""
    entry = REFERENCE['lenses'][key]
    values = load_params_file(REPO / entry['params_file'])
    glass = entry['glass']
    if isinstance(glass, list):
        values['lens.surfaces.glass'] = list(glass)
    else:
        values['lens.glass'] = glass
    values['lens.wavelength_nm'] = entry['focus_wavelength_nm']
    values.update(overrides)
    return values


def glass_model(key: str, width: int = 0, height: int = 0, **overrides: Any) -> LensModel:
    """Build a reference lens's model with its glass names (and ``overrides``)."""
    return build_model(glass_values(key, **overrides), width, height)


@pytest.mark.parametrize('key', LENSES)
def test_each_channel_matches_optiland_over_the_whole_field(key: str) -> None:
    entry = REFERENCE['lenses'][key]
    model = glass_model(key)
    traces = model.lateral_color()
    theta = np.radians(entry['field_angle_deg'])
    pixel = min(model.pixel_mm)
    assert [ch.wavelength_nm for ch in traces.channels] == REFERENCE['channels_nm']
    for channel, reference in zip(traces.channels, entry['channels']):
        assert channel.field.max_field_angle_rad >= theta[-1], 'the trace must cover the field'
        ours = channel.height_at(theta)
        npt.assert_allclose(ours / pixel, np.array(reference['real_height_abs_mm']) / pixel,
                            rtol=0.0, atol=CURVE_TOLERANCE_PX,
                            err_msg=f'{key} {channel.name} at {channel.wavelength_nm} nm')


def test_sensor_plane_is_optilands_paraxial_image_at_the_focus_wavelength() -> None:
    entry = REFERENCE['lenses']['case2_bk7']
    model = glass_model('case2_bk7')
    sensor_z, _ = model.source.image_plane(float(model.values['scene.distance_mm']))
    assert sensor_z == pytest.approx(entry['sensor_z_mm'], abs=1e-9)


def rb_separation_from_optiland(key: str) -> float:
    """
    Return the red-blue separation at the raw corner, px, from optiland's traces alone.

    The raw corner is where the separation is largest for these lenses (it grows with the
    field). Its radius on the sensor is taken on optiland's green curve to a field angle, and
    optiland's red minus blue height there (linear in the angle between its 0.5-deg samples,
    of the difference, which is smooth) is converted to px along the diagonal.
    """
    entry = REFERENCE['lenses'][key]
    model = glass_model(key)
    px, py = model.pixel_mm
    x, y = model.K[0, 2] * px, model.K[1, 2] * py
    radius = math.hypot(x, y)
    theta = np.array(entry['field_angle_deg'])
    red, green, blue = (np.array(c['real_height_abs_mm']) for c in entry['channels'])
    corner = np.interp(radius, green, theta)
    gap = abs(float(np.interp(corner, theta, red - blue)))
    return gap * math.hypot(x / px, y / py) / radius


#: case2_bk7's largest red-blue separation, from optiland's traces (1.0140 px).
RB_SEPARATION_PX = rb_separation_from_optiland('case2_bk7')


def test_channels_differ_where_the_glass_disperses() -> None:
    traces = glass_model('case2_bk7').lateral_color()
    red, green, blue = (ch.height_at(np.radians([20.0]))[0] for ch in traces.channels)
    # N-BK7's index falls towards red: here the red image is the larger one.
    assert red > green > blue
    # Derived from optiland's traces, not from this code's output (issue 29).
    assert RB_SEPARATION_PX == pytest.approx(1.014, abs=0.001)
    assert traces.max_rb_separation_px == pytest.approx(RB_SEPARATION_PX, abs=0.002)
    assert traces.max_rb_separation_at_px == (0.0, 0.0)


def test_green_at_the_focus_wavelength_is_the_model() -> None:
    model = glass_model('case2_bk7')
    green = model.lateral_color().channels[1]
    assert green.wavelength_nm == model.values['lens.wavelength_nm']
    npt.assert_array_equal(green.curve.ideal_mm, model.curve.ideal_mm[:green.curve.ideal_mm.size])
    npt.assert_allclose(green.curve.real_mm, model.curve.real_mm, rtol=0.0, atol=1e-9)
    # The channel source itself, at the focus wavelength, traces the model's lens (the trace
    # above reuses the model's; this checks the source that the other channels use).
    field = model.field_curve
    source = lateral_color.ChannelSource(model.source, green.wavelength_nm, model.values)
    heights, _ = source.real_heights(field.field_angle_rad, 1000.0)
    npt.assert_allclose(heights, field.real_mm, rtol=0.0, atol=1e-12)


def test_switch_without_glass_names_is_refused_naming_it() -> None:
    values = load_params_file(REPO / 'config' / 'case2.yaml')
    values['output.lateral_color_correction'] = True
    with pytest.raises(ModelError, match='output.lateral_color_correction') as info:
        build_model(values)
    assert 'lens.glass' in str(info.value)
    values = load_params_file(REPO / 'config' / 'cooke_triplet.yaml')
    values['output.lateral_color_correction'] = True
    assert build_model(values).lateral_color().max_rb_separation_px < 0.1, 'its glasses named'
    values['lens.surfaces.glass'] = []
    with pytest.raises(ModelError, match='lens.surfaces.glass'):
        build_model(values)


def test_channel_wavelength_beyond_a_glass_formula_is_refused_naming_it() -> None:
    values = load_params_file(REPO / 'config' / 'cooke_triplet.yaml')
    values.update({'output.lateral_color_correction': True,
                   'lens.channel_wavelengths_nm': [750.0, 550.0, 465.0]})
    with pytest.raises(ModelError, match='lens.channel_wavelengths_nm') as info:
        build_model(values)
    assert 'SK16' in str(info.value)
    values['lens.channel_wavelengths_nm'] = [610.0, 550.0]
    with pytest.raises(ModelError, match='three wavelengths'):
        build_model(values)


def _maps(width: int, height: int, strengths: tuple[float, ...]) -> list[tuple[Any, Any]]:
    u, v = np.meshgrid(np.arange(width, dtype=np.float32), np.arange(height, dtype=np.float32))
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    r2 = ((u - cx) ** 2 + (v - cy) ** 2) / (cx * cx + cy * cy)
    return [(cx + (u - cx) * (1 - k * r2), cy + (v - cy) * (1 - k * r2)) for k in strengths]


@pytest.mark.parametrize(
    'interpolation', [cv2.INTER_NEAREST, cv2.INTER_LINEAR, cv2.INTER_CUBIC, cv2.INTER_LANCZOS4],
    ids=['nearest', 'linear', 'cubic', 'lanczos4'])
@pytest.mark.parametrize(
    ('order', 'dtype'), [((0, 1, 2), np.uint8), ((2, 1, 0), np.uint16),
                         ((0, 1, 2, 1), np.uint8), ((2, 1, 0), np.float32)],
    ids=['rgb8', 'bgr16', 'rgba8', 'bgr32f'])
def test_folded_remap_equals_each_channel_remapped_alone(
        interpolation: int, order: tuple[int, ...], dtype: Any) -> None:
    width, height = 97, 64
    # Strong maps (sources far outside) and one that pushes past the edges into the gaps.
    maps = _maps(width, height, (-0.3, 0.1, 0.4))
    rng = np.random.default_rng(0)
    src = (rng.uniform(0, 1000, (height, width, len(order))).astype(dtype))
    remap = ChannelRemap(maps, width, height)
    got = remap.remap(src, order, interpolation)
    for c, colour in enumerate(order):
        alone = cv2.remap(np.ascontiguousarray(src[..., c]), *maps[colour], interpolation,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        # Integer images: identical; float32: the same 1/32-px positions, summed in another
        # order (float32 rounding: 1e-4 of the data's range).
        npt.assert_allclose(got[..., c], alone, rtol=0,
                            atol=0.1 if dtype == np.float32 else 0, err_msg=f'channel {c}')


def test_too_wide_to_fold_falls_back_to_one_remap_per_channel(
        monkeypatch: pytest.MonkeyPatch) -> None:
    width, height = 40, 30
    maps = _maps(width, height, (-0.1, 0.0, 0.1))
    src = np.random.default_rng(0).integers(0, 255, (height, width, 3), dtype=np.uint8)
    folded = ChannelRemap(maps, width, height).remap(src, (0, 1, 2), cv2.INTER_LINEAR)
    monkeypatch.setattr(channel_remap, 'folds', lambda width, channels: False)
    split = ChannelRemap(maps, width, height).remap(src, (0, 1, 2), cv2.INTER_LINEAR)
    npt.assert_array_equal(split, folded)


def test_fold_limit_is_int16() -> None:
    assert channel_remap.folds(10900, 3) and not channel_remap.folds(10920, 3)
    assert channel_remap.folds(8000, 4) and not channel_remap.folds(8190, 4)


SPACING_PX = 40.0
SIGMA_PX = 2.5


def _dot_centres(model: LensModel) -> np.ndarray:
    """Return the dot centres of the chart on the corrected image (K_new), px."""
    xs = np.arange(SPACING_PX / 2, model.out_width - SPACING_PX / 2, SPACING_PX) + 0.3
    ys = np.arange(SPACING_PX / 2, model.out_height - SPACING_PX / 2, SPACING_PX) + 0.6
    return np.array([(x, y) for y in ys for x in xs])


def _render_raw(model: LensModel, curve: Any) -> np.ndarray:
    """
    Render the raw image of the dot chart through one channel's trace, exactly.

    Each raw pixel is mapped to the corrected image by the channel's radial map and the
    nearest Gaussian dot (sigma SIGMA_PX there) is evaluated at that point: no interpolation
    enters the rendering, only the correction's.
    """
    channel = replace(model, curve=curve, _summary_cache={}, _illumination_cache={},
                      _lateral_cache={})     # lateral_color.channel_model, given the curve
    u, v = np.meshgrid(np.arange(model.width, dtype=np.float64),
                       np.arange(model.height, dtype=np.float64))
    rect = channel.rect_from_raw(np.stack([u, v], axis=-1))
    # The nearest dot: centres at (SPACING/2 + 0.3 + i SPACING, SPACING/2 + 0.6 + j SPACING).
    cx = np.round((rect[..., 0] - SPACING_PX / 2 - 0.3) / SPACING_PX) * SPACING_PX + \
        SPACING_PX / 2 + 0.3
    cy = np.round((rect[..., 1] - SPACING_PX / 2 - 0.6) / SPACING_PX) * SPACING_PX + \
        SPACING_PX / 2 + 0.6
    d2 = (rect[..., 0] - cx) ** 2 + (rect[..., 1] - cy) ** 2
    with np.errstate(invalid='ignore'):
        out = np.exp(-d2 / (2.0 * SIGMA_PX ** 2))
    return np.nan_to_num(out).astype(np.float32)


def _centroids(image: np.ndarray, centres: np.ndarray, half: int = 9) -> np.ndarray:
    out = np.full(centres.shape, np.nan)
    for i, (x, y) in enumerate(centres):
        x0, y0 = int(round(x)) - half, int(round(y)) - half
        if x0 < 0 or y0 < 0 or x0 + 2 * half + 1 > image.shape[1] or \
                y0 + 2 * half + 1 > image.shape[0]:
            continue
        patch = image[y0:y0 + 2 * half + 1, x0:x0 + 2 * half + 1].astype(np.float64)
        total = patch.sum()
        if total < 0.5 or (patch[0].sum() + patch[-1].sum() + patch[:, 0].sum()
                           + patch[:, -1].sum()) > 0.05 * total:
            continue            # cut by the field's edge, or a neighbour's tail
        yy, xx = np.mgrid[0:patch.shape[0], 0:patch.shape[1]]
        out[i] = (x0 + (patch * xx).sum() / total, y0 + (patch * yy).sum() / total)
    return out


def test_rendered_chart_registers_after_the_correction() -> None:
    model = glass_model('case2_bk7', **{'output.lateral_color_correction': True})
    centres = _dot_centres(model)
    traces = model.lateral_color()
    raw = np.dstack([_render_raw(model, ch.curve) for ch in traces.channels])
    rectifier = Rectifier(model)
    corrected = rectifier.correct(raw, colours=(0, 1, 2))
    plain = Rectifier(model, lateral=False).correct(raw)
    found = [_centroids(corrected[..., c], centres) for c in range(3)]
    before = [_centroids(plain[..., c], centres) for c in range(3)]
    ok = np.all(np.isfinite(np.hstack(found + before)), axis=1)
    assert ok.sum() > 100, 'the chart must cover the field'
    radius = np.hypot(*(centres[ok] - model.K_new[:2, 2]).T)
    assert radius.max() > 0.8 * math.hypot(model.out_width, model.out_height) / 2
    for c in (0, 2):
        shift = np.hypot(*(found[c][ok] - found[1][ok]).T)
        assert shift.max() < REGISTRATION_TOLERANCE_PX, f'channel {c}: {shift.max():.4f} px'
    unregistered = np.hypot(*(before[0][ok] - before[2][ok]).T)
    assert unregistered.max() > 0.5, 'without the correction R and B must not register'


def test_mono_and_unknown_orders_take_the_single_map() -> None:
    model = glass_model('case2_bk7', 320, 240, **{'output.lateral_color_correction': True,
                                                  'sensor.width_px': 0,
                                                  'sensor.height_px': 0})
    rectifier = Rectifier(model)
    plain = Rectifier(model, lateral=False)
    rng = np.random.default_rng(0)
    mono = rng.integers(0, 255, (240, 320), dtype=np.uint8)
    colour = rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)
    npt.assert_array_equal(rectifier.correct(mono, colours=(0, 1, 2)), plain.correct(mono))
    npt.assert_array_equal(rectifier.correct(colour), plain.correct(colour))
    assert not np.array_equal(rectifier.correct(colour, colours=(0, 1, 2)),
                              plain.correct(colour))
    assert rectifier.lateral_color_ms > 0.0 and rectifier.colour is not None


def test_report_per_channel_heights_and_separation() -> None:
    model = glass_model('case2_bk7')
    report = model.report()['lateral_color']
    assert [ch['name'] for ch in report['channels']] == list(lateral_color.CHANNELS)
    assert [ch['wavelength_nm'] for ch in report['channels']] == [610.0, 550.0, 465.0]
    for ch in report['channels']:
        assert len(ch['field_angle_deg']) == len(ch['real_height_mm']) == 33
        assert ch['real_height_mm'][0] == pytest.approx(0.0, abs=1e-12)
    assert report['max_rb_separation_px'] == pytest.approx(RB_SEPARATION_PX, abs=0.002)
    assert report['trace_ms'] > 0.0
    json.dumps(report, allow_nan=False)


def test_no_glass_reports_none() -> None:
    assert build_model(load_params_file(REPO / 'config' / 'case2.yaml')).report()[
        'lateral_color'] is None


def test_cli_info_json_has_lateral_color(tmp_path: Path,
                                         capsys: pytest.CaptureFixture) -> None:
    params = tmp_path / 'bk7.yaml'
    params.write_text(to_params_yaml(glass_values('case2_bk7')))
    assert main(['info', '--params', str(params), '--json']) == 0
    report = json.loads(capsys.readouterr().out)['lateral_color']
    assert report['max_rb_separation_px'] == pytest.approx(RB_SEPARATION_PX, abs=0.002)


def test_cli_correct_applies_lateral_colour_to_bgr_files(tmp_path: Path) -> None:
    params = tmp_path / 'bk7.yaml'
    values = glass_values('case2_bk7', **{'output.lateral_color_correction': True})
    params.write_text(to_params_yaml(values))
    rng = np.random.default_rng(0)
    bgr = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / 'in.png'), bgr)
    assert main(['correct', '--params', str(params), str(tmp_path / 'in.png'),
                 str(tmp_path / 'out.png')]) == 0
    written = cv2.imread(str(tmp_path / 'out.png'), cv2.IMREAD_UNCHANGED)
    rectifier = Rectifier(build_model(values))
    npt.assert_array_equal(written, rectifier.correct(bgr, colours=(2, 1, 0)))
    assert not np.array_equal(written, rectifier.correct(bgr))
