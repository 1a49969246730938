# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The straight-edge self-check (issue 26) on frames rendered through an independent route.

Frames: test/check_scenes.py (optiland's chief-ray heights of config/wide_angle.yaml and
config/fisheye.yaml, a spline of the test's own, analytic anti-aliasing; no package code) of
planar grids at several angles and a box room, seen by a sensor whose axis is off by
``OFFSET_PX``. The description is checked with the true offset (the rendering floor) and
with the nominal (centred) one. A box room seen by a sensor both off the axis and tilted by
``TILT_DEG`` (optiland's chief-ray lines: test/data/optiland_chief_slopes.json) is checked
the same way; the renderer's tilted sensor is tied to the package's ``project`` first.

Measured (docs/design.md section 2.17): the floor of whole lines is 0.077 px RMS (wide-angle,
pinhole output) and 0.100 px (fisheye, equidistant output, px at its centre scale); the
renders are deterministic (fixed noise seed) and ``FLOOR_PX`` bounds both.
"""

from __future__ import annotations

import json
from pathlib import Path

from check_scenes import box_room, discs, featureless, grid, Lens, PIXEL_MM
import cv2
from mechdeconv_ros.imaging import plumb_check as pc
from mechdeconv_ros.imaging.plumb_check import check_chains, CheckResult, to_apply
from mechdeconv_ros.imaging.remap import build_float_maps, Rectifier
from mechdeconv_ros.model.assembly import project_angles
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import defaults, load_params_file
from mechdeconv_ros.tools.cli import main
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
CONFIGS = {'wide': 'config/wide_angle.yaml', 'fisheye': 'config/fisheye.yaml'}
OFFSET_PX = {'wide': (20.0, -15.0), 'fisheye': (16.0, 12.0)}
#: The rendering floor of the straightness, px (whole lines, issue 36: measured 0.076 and
#: 0.100 on these frames; edge by edge it was 0.054 and 0.086).
FLOOR_PX = 0.12
MAX_RMS_PX = 0.3


def values(name: str, offset_px: tuple[float, float] = (0.0, 0.0)) -> dict:
    """Return the lens's parameter values with an axis offset in px."""
    vals = defaults()
    vals.update(load_params_file(REPO / CONFIGS[name]))
    vals['sensor.axis_offset_x_mm'] = offset_px[0] * PIXEL_MM
    vals['sensor.axis_offset_y_mm'] = offset_px[1] * PIXEL_MM
    return vals


@pytest.fixture(scope='module', params=['wide', 'fisheye'])
def scene(request: pytest.FixtureRequest) -> dict:
    """Render the frames of one lens, detect their chains, build both descriptions."""
    name = request.param
    lens = Lens(name)
    off = OFFSET_PX[name]
    frames = [grid(lens, off, 0.0, 0.0, 10.0), grid(lens, off, 35.0, -10.0, -25.0),
              box_room(lens, off)]
    return {'name': name, 'lens': lens, 'frames': frames, 'chains': pc.raw_chains(frames),
            'true': build_model(values(name, off)), 'nominal': build_model(values(name))}


def test_the_true_description_is_ok_at_the_floor(scene: dict) -> None:
    result = check_chains(scene['true'], scene['chains'], MAX_RMS_PX)
    assert result.verdict == 'ok'
    assert result.edges >= 30
    assert result.field_coverage > 0.5
    assert result.straightness_rms_px < FLOOR_PX
    # Each estimate agrees with the truth within one tolerance (no false alarm); the truth
    # of the image distance is the description's own sensor plane.
    for name, est in result.estimate.items():
        truth = (scene['true'].values[name] if name.startswith('sensor.')
                 else pc.image_distance_base(scene['true']))
        assert abs(est['value'] - truth) <= max(3.0 * est['sigma'], est['tolerance']), name
    distance = result.estimate['lens.image_distance_mm']
    assert distance['sigma'] <= distance['tolerance']
    assert abs(distance['value'] - pc.image_distance_base(scene['true'])) < 0.5 * distance[
        'tolerance']


def test_the_nominal_description_is_off_and_the_offset_is_found(scene: dict) -> None:
    result = check_chains(scene['nominal'], scene['chains'], MAX_RMS_PX)
    assert result.verdict == 'description_off', result.as_dict()
    for axis, name in enumerate(('sensor.axis_offset_x_mm', 'sensor.axis_offset_y_mm')):
        truth_px = OFFSET_PX[scene['name']][axis]
        error_px = abs(result.estimate[name]['value'] / PIXEL_MM - truth_px)
        assert error_px <= max(abs(truth_px) / 4.0, 2.0), (name, error_px)
        assert result.estimate[name]['sigma'] < result.estimate[name]['tolerance']
    assert result.straightness_rms_px_after <= 1.5 * FLOOR_PX
    assert result.straightness_rms_px_after < result.straightness_rms_px


def test_the_tilts_are_judged_and_apply_sets_what_is_seen(scene: dict) -> None:
    # Whole lines across the field see a 0.2 deg tilt (issue 36; edge by edge they did not):
    # each tilt is seen and consistent with the truth (0), or held at the description with
    # a sigma the edges measured (not the cap of pc.SIGMA_CAP tolerances) and never applied.
    result = check_chains(scene['nominal'], scene['chains'], MAX_RMS_PX)
    applied = to_apply(result, scene['nominal'].values)
    for name in ('sensor.tilt_x_deg', 'sensor.tilt_y_deg'):
        est = result.estimate[name]
        assert_seen_or_held(est, 0.0, scene['nominal'].values[name], name)
        assert (name in applied) == (est['sigma'] <= est['tolerance'])
    # What apply sets: the offsets, which the edges see, at the truth within 2 px.
    assert {'sensor.axis_offset_x_mm', 'sensor.axis_offset_y_mm'} <= set(applied)
    for axis, name in enumerate(('sensor.axis_offset_x_mm', 'sensor.axis_offset_y_mm')):
        assert abs(applied[name] / PIXEL_MM - OFFSET_PX[scene['name']][axis]) <= 2.0, name


def test_circles_do_not_move_the_estimate(scene: dict) -> None:
    base = check_chains(scene['nominal'], scene['chains'], MAX_RMS_PX)
    off = OFFSET_PX[scene['name']]
    extra = pc.raw_chains([discs(scene['lens'], off)])
    assert len(extra) >= 5
    mixed = check_chains(scene['nominal'], scene['chains'] + extra, MAX_RMS_PX)
    for name in ('sensor.axis_offset_x_mm', 'sensor.axis_offset_y_mm'):
        moved = abs(mixed.estimate[name]['value'] - base.estimate[name]['value'])
        assert moved <= base.estimate[name]['sigma'], name


@pytest.mark.parametrize('noise', [0.0, 6.0, 25.0])
def test_featureless_frames_give_no_estimate(noise: float) -> None:
    lens = Lens('fisheye')
    result = pc.check_images(build_model(values('fisheye')), [featureless(lens, noise)],
                             MAX_RMS_PX)
    assert result.verdict == 'not_enough_edges'
    assert result.estimate == {}
    assert to_apply(result, {}) == {}


def test_the_corrected_frame_route_agrees(scene: dict) -> None:
    # The node's route: edges found in the corrected frame, carried back through its maps.
    model = scene['true']
    rect = Rectifier(model)
    map_x, map_y = build_float_maps(model)
    chains = []
    for frame in scene['frames']:
        chains += pc.chains_from_corrected(rect.correct(frame), map_x, map_y)
    result = check_chains(model, chains, MAX_RMS_PX)
    assert result.straightness_rms_px < FLOOR_PX, result.as_dict()
    nominal = check_chains(scene['nominal'], chains, MAX_RMS_PX)
    assert nominal.verdict == 'description_off'
    # A pinhole image_rect of the 160 deg lens crops the periphery, where the offset shows
    # most: this route finds fewer edges (docs/design.md section 2.17) and is held to a third
    # of the offset (measured: 1.0 px of 20 for the wide-angle, 1.9 px of 16 for the fisheye).
    for axis, name in enumerate(('sensor.axis_offset_x_mm', 'sensor.axis_offset_y_mm')):
        truth_px = OFFSET_PX[scene['name']][axis]
        error_px = abs(nominal.estimate[name]['value'] / PIXEL_MM - truth_px)
        assert error_px <= max(abs(truth_px) / 3.0, 2.0), (name, error_px)
    assert nominal.edges < check_chains(scene['nominal'], scene['chains'], MAX_RMS_PX).edges


@pytest.mark.parametrize('value, expected', [(0.5, 0.06), (-0.5, -0.06), (0.013, 0.013)],
                         ids=['clipped-high', 'clipped-low', 'inside'])
def test_to_apply_stays_within_the_tolerances(value: float, expected: float) -> None:
    # Literal cases, not the rule restated: 3 tolerances of 0.02 mm about 0 are 0.06 mm; a
    # tilt the edges do not see (sigma 3 of 0.2) and an automatic image distance (0) stay.
    result = CheckResult(verdict='description_off', estimate={
        'sensor.axis_offset_x_mm': {'value': value, 'sigma': 0.001, 'tolerance': 0.02},
        'sensor.tilt_x_deg': {'value': 0.1, 'sigma': 3.0, 'tolerance': 0.2},
        'lens.image_distance_mm': {'value': 4.2, 'sigma': 0.001, 'tolerance': 0.01}})
    current = {'sensor.axis_offset_x_mm': 0.0, 'sensor.tilt_x_deg': 0.0,
               'lens.image_distance_mm': 0.0}
    assert to_apply(result, current) == {'sensor.axis_offset_x_mm': pytest.approx(expected)}
    # A set image distance is applied (within its bounds: 4.17 +- 0.03 mm).
    out = to_apply(result, {**current, 'lens.image_distance_mm': 4.17})
    assert out['lens.image_distance_mm'] == pytest.approx(4.2)
    out = to_apply(result, {**current, 'lens.image_distance_mm': 4.0})
    assert out['lens.image_distance_mm'] == pytest.approx(4.03)
    # Bounds about the start-up values, not the current ones.
    out = to_apply(result, {**current, 'sensor.axis_offset_x_mm': 0.06},
                   {'sensor.axis_offset_x_mm': 0.0})
    assert out == {'sensor.axis_offset_x_mm': pytest.approx(expected)}
    assert to_apply(CheckResult(verdict='ok', estimate=result.estimate), current) == {}


def test_cli_check_json(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    lens = Lens('fisheye')
    off = OFFSET_PX['fisheye']
    paths = []
    for k, frame in enumerate([grid(lens, off, 0.0, 0.0, 10.0), box_room(lens, off)]):
        paths.append(str(tmp_path / f'f{k}.png'))
        cv2.imwrite(paths[-1], frame)
    assert main(['check', '--params', str(REPO / 'config/fisheye.yaml'), '--json',
                 *paths]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ('straightness_rms_px', 'straightness_max_px', 'edges', 'field_coverage',
                'estimate', 'straightness_rms_px_after', 'verdict'):
        assert key in out
    assert out['verdict'] == 'description_off'
    assert abs(out['estimate']['sensor.axis_offset_x_mm']['value'] / PIXEL_MM - off[0]) <= 4.0
    assert main(['check', '--params', str(REPO / 'config/fisheye.yaml'), *paths]) == 0
    assert 'verdict: description_off' in capsys.readouterr().out
    blank = tmp_path / 'blank.png'
    cv2.imwrite(str(blank), featureless(lens))
    assert main(['check', '--params', str(REPO / 'config/fisheye.yaml'), '--json',
                 str(blank)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['verdict'] == 'not_enough_edges' and out['estimate'] == {}


#: A sensor both off the axis and tilted (issue 26): the offsets above with tilts of 0.5 deg
#: about x and y (2.5 tolerances; the bound of the estimate is 3). The scene is one box room:
#: its long wall edges see the tilt best of these scenes (docs/design.md section 2.17) and its
#: rendering floor is lower than the bar grids' (measured 0.033 and 0.054 px).
TILT_DEG = {'wide': (0.5, -0.5), 'fisheye': (-0.5, 0.5)}
BOX_FLOOR_PX = 0.07


def tilted_values(name: str, offset_px: tuple[float, float],
                  tilt_deg: tuple[float, float]) -> dict:
    """Return the lens's parameter values with an axis offset and a sensor tilt."""
    vals = values(name, offset_px)
    vals['sensor.tilt_x_deg'], vals['sensor.tilt_y_deg'] = tilt_deg
    return vals


def assert_seen_or_held(est: dict, truth: float, description: float, key: str) -> None:
    """
    Assert an estimate is seen and right, or held at the description with a measured sigma.

    Seen (sigma within the tolerance): within 3 sigma of the truth. Held (sigma above it):
    the description's value exactly, and a sigma under 20 tolerances, far below the cap of
    ``SIGMA_CAP`` (100): a large sigma alone does not pass (measured: 1 to 5 tolerances).
    """
    if est['sigma'] <= est['tolerance']:
        assert abs(est['value'] - truth) <= 3.0 * est['sigma'], (key, est, truth)
    else:
        assert est['value'] == description, (key, est)
        assert est['sigma'] < 20.0 * est['tolerance'], (key, est)


def test_the_chief_slopes_reference_is_the_curves_lines() -> None:
    # test/data/optiland_chief_slopes.json: the same rays as the height curve, and lines
    # (optiland's own intersections 0.05 mm before and after the image plane lie on them).
    lines = json.loads((REPO / 'test/data/optiland_chief_slopes.json').read_text())['lenses']
    curves = json.loads((REPO / 'test/data/optiland_wide_reference.json').read_text())['lenses']
    for key in ('wide_angle_160', 'fisheye_170'):
        line, curve = lines[key], curves[key]['curve']
        h, s = np.array(line['height_mm']), np.array(line['slope'])
        assert np.allclose(line['field_angle_deg'], curve['field_angle_deg'], rtol=0, atol=1e-12)
        assert np.allclose(h, curve['real_height_abs_mm'], rtol=0, atol=1e-12)
        step = line['plane_step_mm']
        assert np.allclose(h - s * step, line['height_minus_mm'], rtol=0, atol=1e-12)
        assert np.allclose(h + s * step, line['height_plus_mm'], rtol=0, atol=1e-12)
        # The rays leave the axis as they travel on (s > 0 off axis): a tilt moves them.
        assert s[0] == 0.0 and np.all(s[1:] > 0.0)


@pytest.fixture(scope='module', params=['wide', 'fisheye'])
def tilted(request: pytest.FixtureRequest) -> dict:
    """Check a tilted, decentred sensor's frame with the true and the nominal descriptions."""
    name = request.param
    lens = Lens(name)
    chains = pc.raw_chains([box_room(lens, OFFSET_PX[name], tilt_deg=TILT_DEG[name])])
    true = build_model(tilted_values(name, OFFSET_PX[name], TILT_DEG[name]))
    return {'name': name, 'lens': lens, 'model': true,
            'true': check_chains(true, chains, MAX_RMS_PX),
            'nominal': check_chains(build_model(values(name)), chains, MAX_RMS_PX)}


def test_the_tilted_renderer_meets_project(tilted: dict) -> None:
    # The renderer's sensor (built from the words of design.md 2.16, optiland's lines) and
    # the package's project agree for the same pose: the conventions (signs, the order of the
    # turns, the pivot) are the same, while the renderer uses no package code.
    lens, name = tilted['lens'], tilted['name']
    off = OFFSET_PX[name]
    u, v = np.meshgrid(np.linspace(0, lens.width - 1, 41), np.linspace(0, lens.height - 1, 31))
    errors = []
    for tilt in (TILT_DEG[name], (0.0, 0.0)):
        d = lens.directions(u, v, off, tilt)
        theta, phi = np.arccos(np.clip(d[..., 2], -1.0, 1.0)), np.arctan2(d[..., 1], d[..., 0])
        inside = np.isfinite(theta)
        assert inside.sum() > 0.6 * u.size
        pu, pv = project_angles(tilted['model'], theta, phi)
        errors.append(np.hypot(pu - u, pv - v)[inside])
        # Every direction of the design field projects (the package's field of the fisheye
        # ends at 87.8 deg, optiland's curve at 102 deg).
        assert np.all(np.isfinite(errors[-1][theta[inside] < np.radians(85.0)]))
    assert np.nanmax(errors[0]) < 0.01       # measured 3e-4 px (wide), 7e-6 px (fisheye)
    # Rendered untilted, the same pixels are off by more than a pixel: the test sees the tilt.
    assert np.nanmax(errors[1]) > 1.0


def test_a_tilted_sensor_with_the_true_description_is_ok(tilted: dict) -> None:
    result = tilted['true']
    name = tilted['name']
    assert result.verdict == 'ok', result.as_dict()
    assert result.edges >= 10
    assert result.straightness_rms_px < BOX_FLOOR_PX
    truth = {**dict(zip(('sensor.tilt_x_deg', 'sensor.tilt_y_deg'), TILT_DEG[name])),
             'sensor.axis_offset_x_mm': OFFSET_PX[name][0] * PIXEL_MM,
             'sensor.axis_offset_y_mm': OFFSET_PX[name][1] * PIXEL_MM}
    for key, value in truth.items():
        est = result.estimate[key]
        assert_seen_or_held(est, value, value, key)


def test_a_tilted_sensor_with_the_nominal_description(tilted: dict) -> None:
    result = tilted['nominal']
    name = tilted['name']
    assert result.verdict == 'description_off', result.as_dict()
    for axis, key in enumerate(('sensor.axis_offset_x_mm', 'sensor.axis_offset_y_mm')):
        truth_px = OFFSET_PX[name][axis]
        error_px = abs(result.estimate[key]['value'] / PIXEL_MM - truth_px)
        # The tilt (estimated, or held at 0 where unseen) does not drag the offset out of
        # the untilted case's bound: measured 0.4 px (wide) and 1.7 px (fisheye) at most.
        assert error_px <= max(abs(truth_px) / 4.0, 2.0), (key, error_px)
    for axis, key in enumerate(('sensor.tilt_x_deg', 'sensor.tilt_y_deg')):
        est = result.estimate[key]
        # Seen: within 3 sigma of the truth; not seen: held at the description's 0 with a
        # sigma the edges measured, and never applied.
        assert_seen_or_held(est, TILT_DEG[name][axis], 0.0, key)
        if est['sigma'] > est['tolerance']:
            assert key not in to_apply(result, values(name))
    # Within 1.5 x this scene's floor (the true description's straightness, measured here):
    # measured 0.030 of 0.033 px (wide-angle) and 0.055 of 0.054 px (fisheye).
    assert result.straightness_rms_px_after <= 1.5 * tilted['true'].straightness_rms_px
    assert result.straightness_rms_px_after < result.straightness_rms_px


def test_the_false_alarm_of_wide_bars_is_gone() -> None:
    # The render that gave a false description_off (docs/design.md section 2.17): the wide
    # angle, the true description, two grids of bars of half-width 0.12 (of the 0.55 period)
    # and the box room, the sensor off the axis and tilted by 0.5 deg about y. Before: the
    # image distance +0.0129 mm (sigma 0.0040) from the truth. Measured now: -0.0047 (0.0039).
    lens = Lens('wide')
    off, tilt = OFFSET_PX['wide'], (0.0, 0.5)
    frames = [grid(lens, off, 0.0, 0.0, 10.0, tilt_deg=tilt, half_width=0.12),
              grid(lens, off, 35.0, -10.0, -25.0, tilt_deg=tilt, half_width=0.12),
              box_room(lens, off, tilt_deg=tilt)]
    model = build_model(tilted_values('wide', off, tilt))
    result = pc.check_images(model, frames, MAX_RMS_PX)
    assert result.verdict == 'ok', result.as_dict()
    est = result.estimate['lens.image_distance_mm']
    error = est['value'] - pc.image_distance_base(model)
    assert abs(error) < 0.75 * est['tolerance'], est
    assert abs(error) <= 3.0 * est['sigma'], est


def synthetic_lines(model: object, noise_px: float, seed: int, count: int = 60) -> list:
    """Return raw points of scene lines through the package's project, with white noise."""
    rng = np.random.default_rng(seed)
    chains = []
    while len(chains) < count:
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        e1 = np.cross(normal, [0.0, 0.0, 1.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(normal, e1)
        angle = rng.uniform(-np.pi, np.pi) + np.linspace(0.0, 0.5, 400)
        d = np.cos(angle)[:, None] * e1 + np.sin(angle)[:, None] * e2
        d = d[d[:, 2] > 0.25]
        u, v = project_angles(model, np.arccos(d[:, 2]), np.arctan2(d[:, 1], d[:, 0]))
        inside = np.isfinite(u) & np.isfinite(v) & (u > 10) & (v > 10) & (
            u < model.width - 11) & (v < model.height - 11)
        if inside.sum() >= 100:
            points = np.stack([u[inside], v[inside]], axis=1)
            chains.append(points + rng.normal(0.0, noise_px, points.shape))
    return chains


def test_white_edge_noise_does_not_move_the_image_distance() -> None:
    # The estimator's own bias: with residuals weighted at the description's pose, raw noise
    # looked smaller in angle at a larger image distance and pulled it there (measured +0.015
    # mm mean over these four seeds at 0.3 px, +0.005 over sixteen at 0.15 px); with each
    # point's raw px distance at the pose being judged: -0.003 and -0.0007 mm.
    model = build_model(values('wide', OFFSET_PX['wide']))
    errors = []
    for seed in range(4):
        result = check_chains(model, synthetic_lines(model, 0.3, seed), MAX_RMS_PX)
        est = result.estimate['lens.image_distance_mm']
        errors.append(est['value'] - pc.image_distance_base(model))
    assert abs(np.mean(errors)) < 0.0075, errors
    noiseless = check_chains(model, synthetic_lines(model, 0.0, 0), MAX_RMS_PX)
    assert noiseless.verdict == 'ok'
    assert abs(noiseless.estimate['lens.image_distance_mm']['value']
               - pc.image_distance_base(model)) < 1e-4


@pytest.mark.parametrize('before, after, off', [
    (0.03, 0.025, False), (0.06, 0.049, False), (0.12, 0.09, True), (0.3, 0.1, True),
    (0.5, 0.45, False)], ids=['floor-gain', 'small-bend', 'bend', 'large', 'no-ratio'])
def test_the_ratio_rule_has_an_absolute_floor(before: float, after: float, off: bool) -> None:
    # Item (e): 0.005 px gained on 0.03 px edges (a ratio of 1.2) is no bend anyone could
    # see; the rule wants the ratio and a removed bend (in quadrature) over 0.05 px.
    assert pc.straightens(before, after) is off
