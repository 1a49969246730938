# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The lens-state history (issue 19): interpolation at a stamp, holding, ignoring, lag."""

from __future__ import annotations

import math

from mechdeconv_ros.imaging.lens_state import KEEP_NS, LensStateHistory, MAX_SAMPLES
import pytest

MS = 1_000_000


def test_interpolates_between_the_two_states_around_the_stamp():
    history = LensStateHistory({'zoom': 'zoom_joint'})
    assert history.add(100 * MS, ['zoom_joint'], [0.0])
    assert history.add(200 * MS, ['pan', 'zoom_joint'], [9.0, 1.0])
    state = history.at(150 * MS)
    assert state.positions == {'zoom': pytest.approx(0.5)}
    assert state.held == () and state.lag_s == pytest.approx(-0.05)
    assert history.at(125 * MS).positions['zoom'] == pytest.approx(0.25)
    # At a sample exactly: that sample.
    assert history.at(200 * MS).positions['zoom'] == 1.0


def test_newer_frame_holds_the_newest_and_reports_the_lag():
    history = LensStateHistory({'zoom': 'z'})
    history.add(100 * MS, ['z'], [0.2])
    history.add(200 * MS, ['z'], [0.4])
    state = history.at(230 * MS)
    assert state.positions['zoom'] == 0.4
    assert state.held == ('zoom',)
    assert state.lag_s == pytest.approx(0.03)
    # Older than every sample kept: the oldest.
    assert history.at(50 * MS).positions['zoom'] == 0.2


def test_out_of_order_states_are_sorted():
    history = LensStateHistory({'zoom': 'z'})
    for stamp, value in ((300, 3.0), (100, 1.0), (200, 2.0)):
        history.add(stamp * MS, ['z'], [value])
    assert history.at(250 * MS).positions['zoom'] == pytest.approx(2.5)
    assert history.newest() == {'zoom': 3.0}


@pytest.mark.parametrize('names, positions, why', [
    (['pan', 'tilt'], [0.1, 0.2], 'no position of z'),
    (['z'], [math.nan], 'z is nan'),
    (['z'], [math.inf], 'z is inf'),
    ([], [], 'no position of z'),
], ids=['other-joints', 'nan', 'inf', 'empty'])
def test_ignored_states_are_counted_and_change_nothing(names, positions, why):
    history = LensStateHistory({'zoom': 'z'})
    history.add(100 * MS, ['z'], [0.5])
    assert not history.add(200 * MS, names, positions)
    assert history.ignored == 1 and history.received == 2
    assert history.last_ignored == why
    assert history.at(300 * MS).positions['zoom'] == 0.5


def test_two_joints_from_two_drivers():
    history = LensStateHistory({'zoom': 'z', 'focus': 'f'})
    history.add(100 * MS, ['z'], [0.0])
    state = history.at(150 * MS)
    assert state.positions == {'zoom': 0.0} and state.missing == ('focus',)
    history.add(120 * MS, ['f'], [4.0])
    history.add(200 * MS, ['z', 'f'], [1.0, math.nan])   # the NaN focus is skipped
    state = history.at(150 * MS)
    assert state.positions == {'zoom': pytest.approx(0.5), 'focus': 4.0}
    assert state.held == ('focus',)
    assert history.ignored == 0


def test_unstamped_states_take_the_arrival_time():
    history = LensStateHistory({'zoom': 'z'})
    history.add(0, ['z'], [0.0], received_ns=100 * MS)
    history.add(0, ['z'], [1.0], received_ns=200 * MS)
    assert history.at(150 * MS).positions['zoom'] == pytest.approx(0.5)


def test_before_any_state_nothing_is_known():
    state = LensStateHistory({'zoom': 'z'}).at(5 * MS)
    assert state.positions == {} and state.missing == ('zoom',) and math.isnan(state.lag_s)


def test_old_states_are_dropped():
    history = LensStateHistory({'zoom': 'z'})
    for k in range(3 * MAX_SAMPLES):
        history.add(k * MS, ['z'], [float(k)])
    joint = history._by_joint['z']
    assert len(joint.stamps) <= MAX_SAMPLES
    assert joint.stamps[-1] - joint.stamps[0] <= KEEP_NS
    # A long pause keeps the last two states.
    history.add(10 ** 13, ['z'], [5.0])
    assert len(joint.stamps) == 2


def test_a_state_long_before_the_newest_is_a_jump_back_and_clears_the_history():
    # A bag played in a loop: the stamps start again 60 s earlier. Pruning on insert would
    # drop every new sample and keep the stale "future" ones newest.
    history = LensStateHistory({'zoom': 'z', 'focus': 'f'})
    history.add(60_000 * MS, ['z', 'f'], [1.0, 3.0])
    history.add(60_100 * MS, ['z'], [0.9])
    history.add(100 * MS, ['z'], [0.2])
    assert history.time_jumps == 1 and 'before the newest' in history.last_jump
    state = history.at(150 * MS)
    assert state.positions == {'zoom': 0.2} and state.missing == ('focus',)
    history.add(200 * MS, ['z'], [0.4])
    assert history.at(150 * MS).positions['zoom'] == pytest.approx(0.3)
    # A late message within KEEP_NS is not a jump: it is sorted in.
    history.add(200 * MS - KEEP_NS + MS, ['z'], [0.0])
    assert history.time_jumps == 1


def test_a_clock_jump_back_clears_only_a_history_from_the_future():
    history = LensStateHistory({'zoom': 'z'})
    history.add(5_000 * MS, ['z'], [1.0])
    assert not history.time_jumped_back(5_000 * MS)     # nothing newer than the clock
    assert history.time_jumped_back(1_000 * MS)
    assert history.time_jumps == 1 and history.newest() == {}
    assert 'clock went back' in history.last_jump


def test_an_unstamped_frame_gets_the_newest_state():
    history = LensStateHistory({'zoom': 'z'})
    history.add(100 * MS, ['z'], [0.0])
    history.add(1_900 * MS, ['z'], [1.0])
    state = history.at(0)
    assert state.positions == {'zoom': 1.0} and math.isnan(state.lag_s)
