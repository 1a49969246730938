# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The straightness measures whole scene lines (issue 36, item 2).

Fisheye frames of test/check_scenes.py (a grid and the box room, the axis 16 px right and
12 px down). The truth: every detected edge point is given its known scene line by the
renderer's own geometry (:func:`check_scenes.assign_to_lines`), and the RMS distance from
the whole lines is computed from that grouping (:func:`check_scenes.whole_line_rms`). The
check must read the same number from the edges alone: within 25 % where a wrong
description bends the lines by 1 px or more, within 2 x the truth's floor with the true
description (docs/design.md section 2.17 has the measured table).
"""

from __future__ import annotations

from check_scenes import assign_to_lines, box_room, grid, grid_lines, Lens, room_lines
from check_scenes import whole_line_rms
from mechdeconv_ros.imaging.plumb_check import check_chains
from mechdeconv_ros.imaging.straight_edges import detect_chains, frame_of, tagged
from mechdeconv_ros.model.model import build_model
import numpy as np
import pytest
from test_check import MAX_RMS_PX, OFFSET_PX, values

OFF = OFFSET_PX['fisheye']
#: Descriptions: the truth, the axis centred (nominal) and as far again on the other side.
DESCRIPTIONS = {'true': OFF, 'nominal': (0.0, 0.0), 'far': (-OFF[0] / 2, -OFF[1] / 2)}


@pytest.fixture(scope='module', params=['grid', 'room'])
def scene(request: pytest.FixtureRequest) -> dict:
    """Render one scene, detect its chains and give every point its known line."""
    lens = Lens('fisheye')
    if request.param == 'grid':
        frame, lines = grid(lens, OFF, 0.0, 0.0, 10.0), grid_lines(0.0, 0.0, 10.0)
    else:
        frame, lines = box_room(lens, OFF), room_lines()
    chains = detect_chains(frame)
    points = np.concatenate(chains)
    label = assign_to_lines(lens, OFF, points, lines)
    out = {'kind': request.param, 'chains': chains, 'points': points, 'label': label}
    for name, off in DESCRIPTIONS.items():
        model = build_model(values('fisheye', off))
        out[name] = (whole_line_rms(model, points, label),
                     check_chains(model, chains, MAX_RMS_PX))
    return out


def test_the_truth_knows_most_points(scene: dict) -> None:
    # The ground truth is about the edges found: nine in ten points lie on a known line.
    assert np.mean(scene['label'] >= 0) > 0.9


@pytest.mark.parametrize('name', ['nominal', 'far'])
def test_a_wrong_description_reads_the_whole_lines_bend(scene: dict, name: str) -> None:
    # Within 25 % of the truth (item 2 asks it from 1 px of bend; the room's smaller bends,
    # 0.3 to 0.5 px, are read as well).
    truth, result = scene[name]
    assert 0.75 * truth <= result.straightness_rms_px <= 1.25 * truth, (truth, result.as_dict())
    assert result.verdict == 'description_off'


def test_the_grid_bends_by_more_than_a_pixel(scene: dict) -> None:
    # The test above covers the regime of item 2: on the grid both wrong descriptions bend
    # the lines by 1 px or more (measured 1.65 and 2.5 px), on the room less.
    if scene['kind'] == 'grid':
        assert min(scene['nominal'][0], scene['far'][0]) >= 1.0
    else:
        assert scene['nominal'][0] < 1.0


def test_the_true_description_reads_the_floor(scene: dict) -> None:
    floor, result = scene['true']
    assert floor < 0.1
    assert result.straightness_rms_px <= 2.0 * floor, (floor, result.as_dict())
    assert result.verdict == 'ok', result.as_dict()
    # Each line is one group: as many lines as the truth has lines with points.
    known = len(np.unique(scene['label'][scene['label'] >= 0]))
    assert 0.75 * known <= result.lines <= known


def test_lines_are_grouped_within_a_frame(scene: dict) -> None:
    # Every chain of its own frame (the node's window of a moving camera): only pieces of
    # one chain join, so the same edges make more lines than with the frame known.
    model = build_model(values('fisheye', OFF))
    alone = [tagged(np.asarray(c), 1000 + k) for k, c in enumerate(scene['chains'])]
    assert all(frame_of(c) == 1000 + k for k, c in enumerate(alone))
    apart = check_chains(model, alone, MAX_RMS_PX)
    together = scene['true'][1]
    assert apart.edges == together.edges
    if scene['kind'] == 'grid':     # bars crossed by bars: a line of several chains
        assert apart.lines > together.lines
    else:                           # the room's lines: one chain each
        assert apart.lines == together.lines
