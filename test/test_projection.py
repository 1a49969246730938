# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The one public projection (model/projection.py): round trips, the old results, the signs.

- Round trips: ``directions_of(pixels_of(d)) = d`` and ``pixels_of(directions_of(p)) = p``
  within 1e-6 px for a sensor offset alone, a tilted sensor, a tilted flat port and a
  decentred dome. Before issue 37 an untilted sensor's inverse interpolated linearly (1.5e-3 px
  off its own forward on the wide angle) and a non-symmetric port's inverse ignored the port's
  tilt (27 px off at the corner).
- The old results: ``test/data/projection_regression.json`` is a REGRESSION reference written
  by ``tools/make_projection_regression.py`` from the code of commit 0a30dce (not an
  independent one: optiland's are test/test_reference_assembly.py and
  test/test_underwater_reference.py). On every shipped config, centred and with the sensor
  offset and tilted (and the flat port tilted), the forward, ``mechdeconv project``'s tangent
  path and the self-check's inverse are unchanged to 1e-9 px; the inverse is unchanged where it
  was exact (tilted) and moves only by the old interpolation error elsewhere.
- The signs by value: a positive ``sensor.tilt_x_deg`` brings the rows of larger v closer to
  the lens, where the converging chief rays have not spread as far (docs/design.md section
  1.1); the self-check's pose vector means the same rotation as the parameters.
"""

from __future__ import annotations

import json
from pathlib import Path

from mechdeconv_ros.imaging.plumb_lines import ChiefLines
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.model.projection import directions_of, pixels_of, project_points
from mechdeconv_ros.schema.params import load_params_file
import numpy as np
from numpy.testing import assert_allclose
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = json.loads((ROOT / 'test' / 'data' / 'projection_regression.json').read_text())
CASES = sorted(DATA['cases'])
#: The old untilted inverse interpolated theta linearly in the real height.
OLD_LINEAR_INVERSE_PX = 5e-3
SEA = {'scene.medium': 'seawater', 'scene.distance_mm': 1000.0}
FLAT = {**SEA, 'port.type': 'flat', 'port.glass': 'PMMA', 'port.distance_mm': 10.0,
        'port.thickness_mm': 5.0}
DOME = {**SEA, 'port.type': 'dome', 'port.glass': 'N-BK7', 'port.radius_mm': 40.0,
        'port.thickness_mm': 6.0}
ROUND_TRIPS = {
    'offset_wide': ('wide_angle', {'sensor.axis_offset_x_mm': 0.2,
                                   'sensor.axis_offset_y_mm': -0.15}),
    'tilt_fisheye': ('fisheye', {'sensor.axis_offset_x_mm': -0.1, 'sensor.tilt_x_deg': 1.0,
                                 'sensor.tilt_y_deg': -0.7}),
    'tilt_triplet': ('cooke_triplet', {'sensor.tilt_x_deg': -0.6, 'sensor.tilt_y_deg': 1.0}),
    'flat_port_tilted': ('cooke_triplet', {**FLAT, 'port.tilt_x_deg': 1.0,
                                           'port.tilt_y_deg': -0.5}),
    'dome_decentred': ('cooke_triplet', {**DOME, 'port.decenter_x_mm': 1.0,
                                         'port.decenter_y_mm': -1.0}),
}


def _array(values: list, columns: int) -> np.ndarray:
    return np.array([np.nan if x is None else x for x in values], dtype=float).reshape(
        -1, columns)


def _config(name: str) -> dict:
    return load_params_file(ROOT / 'config' / f'{name}.yaml')


@pytest.fixture(scope='module')
def models():
    cache: dict = {}

    def get(key: str, config: str, values: dict):
        if key not in cache:
            cache[key] = build_model({**_config(config), **values})
        return cache[key]
    return get


def _case_model(models, key: str):
    case = DATA['cases'][key]
    config = Path(case['config']).stem
    return case, models(key, config, case['values'])


def _grid(model, count: int = 9) -> np.ndarray:
    us = np.linspace(-0.5, model.width - 0.5, count)
    vs = np.linspace(-0.5, model.height - 0.5, count)
    return np.stack(np.meshgrid(us, vs), axis=-1).reshape(-1, 2)


@pytest.mark.parametrize('key', list(ROUND_TRIPS), ids=list(ROUND_TRIPS))
def test_round_trips(models, key) -> None:
    config, values = ROUND_TRIPS[key]
    model = models(key, config, values)
    pixels = _grid(model, 7)
    dirs = directions_of(model, pixels)
    seen = np.all(np.isfinite(dirs), axis=1)
    assert seen.sum() >= 20
    assert_allclose(np.linalg.norm(dirs[seen], axis=1), 1.0, rtol=1e-12)
    assert_allclose(pixels_of(model, dirs[seen]), pixels[seen], rtol=0, atol=1e-6)
    # And from directions: those the lens images, back to themselves.
    back = directions_of(model, pixels_of(model, dirs[seen]))
    assert_allclose(back, dirs[seen], rtol=0, atol=1e-9)


def test_the_regression_reference_covers_the_shipped_configs() -> None:
    configs = {Path(DATA['cases'][key]['config']).name for key in CASES}
    # stereo_node's params files hold two cameras of the shipped lenses (test_stereo.py).
    shipped = {p.name for p in (ROOT / 'config').glob('*.yaml')
               if not p.name.startswith('stereo')}
    assert configs == shipped
    assert DATA['commit'] == '0a30dce'
    assert any(DATA['cases'][key]['values'].get('sensor.tilt_x_deg') for key in CASES)


@pytest.mark.parametrize('key', CASES, ids=CASES)
def test_forward_and_check_unchanged(models, key) -> None:
    case, model = _case_model(models, key)
    old = _array(case['forward_pixels'], 2)
    assert_allclose(pixels_of(model, _array(case['forward_directions'], 3)), old, rtol=0,
                    atol=1e-9)
    tangents = _array(case['tangents'], 2)
    u, v = project_points(model, tangents[:, 0], tangents[:, 1])
    assert_allclose(np.stack([u, v], axis=1), _array(case['tangent_pixels'], 2), rtol=0,
                    atol=1e-9)
    pixels = _array(case['pixels'], 2)
    dirs, radial, tangential = ChiefLines.from_model(model).directions_and_scales(
        pixels, np.array(case['check_pose']))
    assert_allclose(dirs, _array(case['check_directions'], 3), rtol=0, atol=1e-12)
    assert_allclose(radial, _array(case['check_radial'], 1).ravel(), rtol=1e-12)
    assert_allclose(tangential, _array(case['check_tangential'], 1).ravel(), rtol=1e-12)


@pytest.mark.parametrize('key', CASES, ids=CASES)
def test_inverse_unchanged_where_it_was_exact(models, key) -> None:
    case, model = _case_model(models, key)
    pixels = _array(case['pixels'], 2)
    old = _array(case['directions'], 3)
    new = directions_of(model, pixels)
    assert np.array_equal(np.isnan(new[:, 0]), np.isnan(old[:, 0]))
    f_px = float(np.sqrt(model.K[0, 0] * model.K[1, 1]))
    moved_px = np.nanmax(np.linalg.norm(new - old, axis=1)) * f_px
    if key.endswith('port_tilt_y'):
        # The old inverse ignored the port's tilt: its own forward put it 27 px away.
        assert moved_px > 1.0
    elif case['values'].get('sensor.tilt_x_deg'):
        assert moved_px < 1e-9
    else:
        assert moved_px < OLD_LINEAR_INVERSE_PX


def test_sensor_tilt_x_brings_rows_of_larger_v_closer(models) -> None:
    # Closer to the lens the converging chief rays have spread less: the part of the image at
    # larger v comes towards the axis pixel, the part at smaller v moves away from it.
    base = models('triplet', 'cooke_triplet', {})
    tilted = models('triplet_tilt_x', 'cooke_triplet', {'sensor.tilt_x_deg': 1.0})
    dirs = np.array([[0.0, 0.2, 1.0], [0.0, -0.2, 1.0], [0.2, 0.0, 1.0]])
    p0, p1 = pixels_of(base, dirs), pixels_of(tilted, dirs)
    c = tilted.K[:2, 2]
    assert abs(p1[0, 1] - c[1]) < abs(p0[0, 1] - c[1])       # below the axis: inward
    assert abs(p1[1, 1] - c[1]) > abs(p0[1, 1] - c[1])       # above: outward
    # A direction on the row line through the axis: the plane there did not move (first
    # order), so the column through the axis keeps it.
    assert abs(p1[2, 0] - p0[2, 0]) < 1e-3 * abs(p0[2, 0] - c[0])


def test_check_pose_vector_is_the_parameters_rotation(models) -> None:
    # The self-check's (dx, dy, alpha, beta, dz) with dz = 0 sees what the model with those
    # sensor.* values sees: one convention, one rotation.
    values = {'sensor.axis_offset_x_mm': 0.1, 'sensor.axis_offset_y_mm': -0.05,
              'sensor.tilt_x_deg': 0.8, 'sensor.tilt_y_deg': -0.4}
    base = models('triplet', 'cooke_triplet', {})
    tilted = models('triplet_pose', 'cooke_triplet', values)
    pixels = _grid(tilted, 5)
    lines = ChiefLines.from_model(base)
    dirs = lines.directions(pixels, np.array([0.1, -0.05, 0.8, -0.4, 0.0]))
    assert_allclose(dirs, directions_of(tilted, pixels), rtol=0, atol=1e-7)
