# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""Per-frame maps of a moving lens (issue 19) against the exact model of each state."""

from __future__ import annotations

from pathlib import Path

import cv2
from mechdeconv_ros.imaging.moving_maps import (
    build_moving_maps, grid_axis, lagrange_weights, node_positions)
from mechdeconv_ros.imaging.remap import build_float_maps
from mechdeconv_ros.lenses import lens_table
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import check_values, load_params_file
import numpy as np
from numpy.testing import assert_allclose
import pytest

CONFIG = Path(__file__).resolve().parents[1] / 'config'
# The shipped zoom's first three rows, on a small sensor of the same size in mm (fast), with
# nodes as far apart in mm as 16 px at 1920x1080.
W, H = 240, 136


@pytest.fixture(scope='module')
def lens():
    values = dict(load_params_file(CONFIG / 'zoom.yaml'))
    values['lens.zoom.positions'] = values['lens.zoom.positions'][:3]
    values['lens.zoom.thickness_mm'] = values['lens.zoom.thickness_mm'][:9]
    values.update({'sensor.pixel_size_x_um': 100.0, 'sensor.pixel_size_y_um': 100.0,
                   'sensor.width_px': 0, 'sensor.height_px': 0})
    values = check_values(values)
    moving = lens_table.mechanisms(values)
    grid = build_moving_maps(values, moving, lambda v: build_model(v, W, H), step=2)
    return values, moving, grid


def _exact(values, p):
    return build_model(lens_table.values_at(values, {'zoom': p}), W, H)


def test_grid_holds_the_rows_and_mid_rows(lens):
    _, moving, grid = lens
    assert_allclose(grid.axes[0], [0.0, 0.03125, 0.0625, 0.09375, 0.125])
    assert len(grid.cameras) == 5
    nodes = (W // 2 + 2) * (H // 2 + 2) * 2 * 4
    assert 5 * nodes <= grid.memory_bytes < 5 * (nodes + 1000)
    assert grid.frame_map_bytes == (W + 4) * (H + 4) * 8


@pytest.mark.parametrize('p', [0.0, 0.03125, 0.02, 0.07, 0.11], ids=str)
def test_map_k_and_d_match_the_exact_model_of_the_state(lens, p):
    values, _, grid = lens
    exact = _exact(values, p)
    camera, full = grid.at({'zoom': p})
    map_x, map_y = build_float_maps(exact)
    error = np.hypot(full[..., 0] - map_x, full[..., 1] - map_y)
    assert full.shape == (H, W, 2) and full.dtype == np.float32
    assert float(error.max()) < 0.02
    assert_allclose(camera.K, exact.K, rtol=1e-4)
    assert_allclose(camera.K_new, exact.K_new, rtol=1e-4)
    assert camera.distortion_model == exact.distortion_model
    # D as a distortion curve: the blend's r_d within 0.01 % of the exact fit's.
    t = np.linspace(0.0, 0.2, 50)
    r = [t * (1 + d[0] * t ** 2 + d[1] * t ** 4 + d[4] * t ** 6) for d in (camera.D, exact.D)]
    assert_allclose(r[0], r[1], rtol=1e-4, atol=1e-7)


def test_the_map_corrects_a_frame_like_the_exact_model(lens):
    values, _, grid = lens
    rng = np.random.default_rng(0)
    src = cv2.GaussianBlur(rng.integers(0, 255, (H, W), np.uint8), (0, 0), 2.0)
    exact = _exact(values, 0.05)
    _, full = grid.at({'zoom': 0.05})
    mine = cv2.remap(src, full, None, cv2.INTER_LINEAR)
    theirs = cv2.remap(src, *build_float_maps(exact), cv2.INTER_LINEAR)
    assert np.abs(mine.astype(int) - theirs.astype(int)).max() <= 2


def test_clamped_outside_the_table(lens):
    _, _, grid = lens
    state, clamped = grid.clamp({'zoom': 3.0})
    assert state == {'zoom': 0.125} and clamped == ('zoom',)
    assert_allclose(grid.at({'zoom': 3.0})[0].K, grid.at({'zoom': 0.125})[0].K)
    assert grid.clamp({'zoom': 0.1})[1] == ()


def test_same_state_reuses_the_map(lens):
    _, _, grid = lens
    first = grid.at({'zoom': 0.06})
    assert grid.at({'zoom': 0.06})[1] is first[1]
    assert grid.at({'zoom': 0.061})[1] is not first[1]


def test_lagrange_weights_stay_inside_a_table_interval():
    axis = np.array([0.0, 0.5, 1.0, 1.5, 2.0])       # rows 0, 1, 2 with refine 2
    weights = dict(lagrange_weights(axis, 0.7, refine=2))
    assert set(weights) == {0, 1, 2}
    assert sum(weights.values()) == pytest.approx(1.0)
    weights = dict(lagrange_weights(axis, 1.2, refine=2))
    assert set(weights) == {2, 3, 4}
    assert lagrange_weights(axis, 1.5, refine=2) == [(3, 1.0)]
    # A quadratic is reproduced exactly.
    x = 1.3
    assert sum(w * axis[i] ** 2 for i, w in lagrange_weights(axis, x, 2)) == pytest.approx(x * x)
    weights = lagrange_weights(axis, 0.2, refine=1)
    assert dict(weights) == pytest.approx({0: 0.6, 1: 0.4})


def test_node_grid_matches_cv2_resize():
    # A linear function sampled at the nodes comes back exactly at every pixel.
    xs, big = node_positions(100, 8)
    nodes = np.tile(xs.astype(np.float32), (3, 1))
    resized = cv2.resize(nodes, (big, 3), interpolation=cv2.INTER_LINEAR)[:, 8:108]
    assert_allclose(resized[1], np.arange(100), atol=1e-4)


def test_grid_axis_refines_each_interval():
    mech = lens_table.Mechanism('zoom', 'z', np.array([0.0, 1.0, 3.0]), (1,),
                                np.zeros((3, 1)))
    assert_allclose(grid_axis(mech, 2), [0.0, 0.5, 1.0, 2.0, 3.0])
    assert_allclose(grid_axis(mech, 1), [0.0, 1.0, 3.0])


def test_a_moving_lens_reuses_two_map_buffers(lens):
    # Issue 29: a new lens state wrote a new full-size map (17 MB at 1080p) per frame while
    # the lens moved. Two buffers alternate: the previous frame's map stays valid while the
    # next is written.
    _, _, grid = lens
    positions = (0.01, 0.04, 0.07, 0.1, 0.11)
    maps = []
    for p in positions:
        _, full = grid.at({'zoom': p})
        maps.append((full, full.copy()))
    for k, (full, _) in enumerate(maps[2:], start=2):
        assert np.shares_memory(full, maps[k - 2][0])
        assert not np.shares_memory(full, maps[k - 1][0])
    # The previous map is intact, the newest is the state's own map.
    np.testing.assert_array_equal(maps[-2][0], maps[-2][1])
    fresh = grid.full_map(grid.camera_at({'zoom': positions[-1]}))
    np.testing.assert_array_equal(maps[-1][0], fresh)
