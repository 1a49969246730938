# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``project`` through ports and water against optiland's real chief rays (issue 27).

The reference is ``test/data/optiland_ports.json``, written by tools/make_optiland_ports.py
with optiland 0.6.3 (requirements-reference.txt, not installed by ``make test``): for each
case (Cooke triplet, wide-angle and fisheye configs; flat ports at 3 distances, 2 thicknesses,
PMMA and N-BK7, 1 deg of tilt about x and about y, 3 scene distances; domes centred on the
entrance pupil, 2 mm off it, 1 mm decentred in x and in y; fresh water and seawater; 486, 588
and 656 nm) a 21 x 21 grid of scene directions (11 x 11 of it for most cases: see the JSON's
``keep``), optiland's chief ray on our sensor plane as a raw pixel.

The grid is traced whole (the generator drops no direction): optiland's null means it has no
chief ray to the sensor there.

Asserted: ``mechdeconv_ros.model.underwater.project_points`` (what ``mechdeconv project``
prints) has a pixel exactly where optiland has one (no nan where optiland traces a ray, none
where it traces none: the ends of the field agree) and lands within 0.01 px of it; and the
reference tells the signs apart: the model with a port tilt or decentring of the opposite
sign misses it by far more than the tolerance (the signs tested by value, against optiland's
independently checked geometry).
"""

from __future__ import annotations

import json
from pathlib import Path

from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.model.underwater import project_points
from mechdeconv_ros.schema.params import load_params_file
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = json.loads((ROOT / 'test' / 'data' / 'optiland_ports.json').read_text())
CASES = DATA['cases']
CONFIGS = {'cooke': 'config/cooke_triplet.yaml', 'wide': 'config/wide_angle.yaml',
           'fisheye': 'config/fisheye.yaml'}
TOLERANCE_PX = 0.01


def case_values(case: dict) -> dict:
    """Return the parameter values of a case, as the generator made them."""
    values = load_params_file(ROOT / CONFIGS[case['lens']])
    values.update(case['overrides'])
    if case['lens'] == 'cooke':
        values['sensor.pixel_size_x_um'] = values['sensor.pixel_size_y_um'] = 5.0
    return values


def directions(case: dict) -> tuple[np.ndarray, np.ndarray]:
    """Return the grid of directions of a case, row-major (ty outer)."""
    grid = case['grid']
    tx, ty = np.meshgrid(
        np.linspace(-grid['half_tx'], grid['half_tx'], grid['n'])[::grid['step']],
        np.linspace(-grid['half_ty'], grid['half_ty'], grid['n'])[::grid['step']])
    return tx.ravel(), ty.ravel()


def errors(case: dict, flip: str = '') -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return our distances from optiland's pixels (px, where both have one) and the masks."""
    values = case_values(case)
    if flip:
        values[flip] = -float(values[flip])
    model = build_model(values)
    u_ref = np.array([np.nan if u is None else u for u in case['u']])
    v_ref = np.array([np.nan if v is None else v for v in case['v']])
    tx, ty = directions(case)
    u, v = project_points(model, tx, ty)
    ref, ours = np.isfinite(u_ref), np.isfinite(u)
    return np.hypot(u - u_ref, v - v_ref)[ref & ours], ref, ours


def test_the_reference_covers_the_issue() -> None:
    keys = set(CASES)
    for lens in CONFIGS:
        for suffix in ('flat_d5', 'flat_d10', 'flat_d20', 'flat_t3_bk7_fresh',
                       'flat_t12_bk7_fresh', 'flat_tilt_x1', 'flat_tilt_y1', 'dome_centred',
                       'dome_off2', 'dome_dx1', 'dome_dy1', 'flat_sea_486.13nm',
                       'flat_fresh_656.27nm', 'dome_fresh_486.13nm'):
            assert f'{lens}_{suffix}' in keys
    assert all(c['max_stop_residual_mm'] < 1e-8 for c in CASES.values())


@pytest.mark.parametrize('key', sorted(CASES))
def test_project_matches_optiland(key: str) -> None:
    err, ref, ours = errors(CASES[key])
    assert ref.sum() >= 5, f'{key}: optiland traced only {ref.sum()} rays'
    assert not np.any(ref & ~ours), f'{key}: nan for {np.sum(ref & ~ours)} rays optiland traces'
    assert not np.any(ours & ~ref), f'{key}: {np.sum(ours & ~ref)} pixels optiland has no ray for'
    assert np.max(err) < TOLERANCE_PX, f'{key}: {np.max(err):.3g} px'


def test_the_reference_is_the_whole_grid() -> None:
    # Every case stores every direction of its grid (null included): none was left out
    # because our model did not see it.
    for key, case in CASES.items():
        grid = case['grid']
        side = len(range(0, grid['n'], grid['step']))
        assert len(case['u']) == side * side, key


@pytest.mark.parametrize('key,flip', [
    ('cooke_flat_tilt_x1', 'port.tilt_x_deg'), ('cooke_flat_tilt_y1', 'port.tilt_y_deg'),
    ('cooke_dome_dx1', 'port.decenter_x_mm'), ('cooke_dome_dy1', 'port.decenter_y_mm'),
    ('fisheye_flat_tilt_x1', 'port.tilt_x_deg'), ('fisheye_dome_dy1', 'port.decenter_y_mm'),
], ids=['cooke-tilt-x', 'cooke-tilt-y', 'cooke-dx', 'cooke-dy', 'fisheye-tilt-x',
        'fisheye-dy'])
def test_the_opposite_sign_misses_optiland(key: str, flip: str) -> None:
    # The right sign lands within TOLERANCE_PX (test_project_matches_optiland); the opposite
    # one is off by far more, so the reference fixes each sign by value.
    err, _, _ = errors(CASES[key], flip)
    assert np.max(err) > 100.0 * TOLERANCE_PX, f'{key}: {np.max(err):.3g} px with {flip} flipped'
