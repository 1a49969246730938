# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The node's check without ROS (runtime/check_session.py, issue 36).

What ``check.apply`` sets is bounded about the values the user set last and never
overrides a set made after the model the check judged; /diagnostics shows a result's age
and the model it judged, and drops it (saying why) when the check is off or gave up; no
child process is started for a lens the check cannot judge; stop is bounded.
"""

from __future__ import annotations

import os
import signal
import time
from types import SimpleNamespace
from typing import Any, Callable

from mechdeconv_ros.imaging.plumb_check import CheckResult
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.runtime import check_session
from mechdeconv_ros.runtime.check_session import CheckSession, not_checkable
from mechdeconv_ros.schema.params import defaults, load_params_file
import numpy as np
import psutil
import pytest
from ros_helpers import REPO

X = 'sensor.axis_offset_x_mm'


def config(name: str, **checks: Any) -> dict[str, Any]:
    """Return a config's values with the check's parameters overridden (dots as __)."""
    values = defaults()
    values.update(load_params_file(REPO / 'config' / name))
    values.update({key.replace('__', '.'): value for key, value in checks.items()})
    return values


@pytest.fixture(scope='module')
def fisheye() -> Any:
    """Return the fisheye config's model."""
    return build_model(config('fisheye.yaml'))


def wait_for(predicate: Callable[[], bool], timeout: float = 60.0, every: Any = None) -> bool:
    """Poll a predicate (calling ``every`` between looks) until it holds or time is up."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        if every is not None:
            every()
        time.sleep(0.05)
    return True


def off_result(value: float, tol: float) -> CheckResult:
    """Return a description_off check that estimates the x offset at ``value``."""
    return CheckResult(verdict='description_off', edges=20, estimate={
        X: {'value': value, 'sigma': tol / 10.0, 'tolerance': tol}})


def test_a_user_set_moves_the_apply_bounds_and_wins_over_an_older_judgement() -> None:
    """
    Issue 36 (d) and (b): the apply was bounded about the start-up values.

    Caught: after a deliberate user set, every apply dragged the value back within 3
    tolerances of the start-up value; and an apply judged on the values before a user's set
    was made after it (the user's set, reported successful, was lost).
    """
    values = config('fisheye.yaml', check__apply=True)
    start, tol = float(values[X]), float(values['sensor.tolerance.axis_offset_x_mm'])
    logs: list[str] = []
    requests: list[int] = []
    session = CheckSession(values.__getitem__, lambda: None, {},
                           lambda level, message: logs.append(message),
                           lambda: requests.append(1))
    far = start + 10.0 * tol        # the estimate: beyond every bound below
    session.plan_apply(off_result(far, tol), SimpleNamespace(values=dict(values)), 3)
    assert requests == [1]
    np.testing.assert_allclose(session.take_apply(3)[X], start + 3.0 * tol)
    assert session.take_apply(3) is None        # taken once

    user = start + 5.0 * tol        # the user sets it: the bounds move with it
    values[X] = user
    session.user_set({X: user, 'check.rate_hz': 1.0})
    assert session.reference[X] == user
    session.plan_apply(off_result(far, tol), SimpleNamespace(values=dict(values)), 4)
    np.testing.assert_allclose(session.take_apply(4)[X], user + 3.0 * tol)

    # Judged at generation 4, a set came since (5): the user's set wins, nothing is applied.
    session.plan_apply(off_result(far, tol), SimpleNamespace(values=dict(values)), 4)
    assert session.take_apply(5) is None
    assert 'not applied' in logs[-1]
    session.plan_apply(off_result(far, tol), SimpleNamespace(values=dict(values)), 5)
    values['check.apply'] = False       # switched off since: nothing is set
    assert session.take_apply(5) is None
    session.applied({X: user}, False, 'refused for a reason')
    assert session.applied_sets == 0 and 'refused for a reason' in logs[-1]


def test_a_result_has_an_age_and_its_model_and_goes_when_off_or_given_up(
        fisheye: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """
    Issue 36 (g): a result's age and model; gone when the check is off or gave up.

    Caught: /diagnostics kept the last verdict (and its WARN) after check.rate_hz 0 or a
    child that gave up, with no age and no word of the model it judged.
    """
    monkeypatch.setattr(check_session, 'MAX_RESTARTS', 0)      # the first death gives up
    values = config('fisheye.yaml', check__rate_hz=20.0, check__max_load=1.0,
                    check__window=1, check__apply=False)
    record = SimpleNamespace(model=fisheye, revision=7, values_generation=3)
    now = [100.0]
    session = CheckSession(values.__getitem__, lambda: record, {}, lambda *a: None,
                           lambda: None, clock=lambda: now[0])
    frame = np.zeros((fisheye.out_height, fisheye.out_width), np.uint8)
    session.start()
    try:
        assert wait_for(lambda: session.entries()['checks'] >= 1,
                        every=lambda: session.offer(frame, fisheye))
        now[0] += 12.5
        entries = session.entries()
        assert entries['check_state'] == 'on' and entries['verdict'] == 'not_enough_edges'
        assert entries['check_age_s'] == 12.5
        assert (entries['check_model_revision'], entries['check_values_generation']) == (7, 3)

        values['check.rate_hz'] = 0.0       # off: the result goes at once, the child soon
        entries = session.entries()
        assert 'verdict' not in entries and 'check_age_s' not in entries
        assert entries['check_state'] == 'off (check.rate_hz 0)'
        assert wait_for(lambda: session.worker_pid is None, 10.0)

        values['check.rate_hz'] = 20.0      # on again: a child that dies gives up (0 restarts)
        checks = session.entries()['checks']
        assert wait_for(lambda: session.entries()['checks'] > checks,
                        every=lambda: session.offer(frame, fisheye))
        os.kill(session.worker_pid, signal.SIGKILL)
        assert wait_for(lambda: session.entries()['check_state'].startswith('gave up'),
                        every=lambda: session.offer(frame, fisheye))
        entries = session.entries()
        assert 'verdict' not in entries and 'the check process' in entries['check_state']
    finally:
        session.stop()


def test_no_child_for_a_lens_the_check_cannot_judge() -> None:
    """
    Issue 36 (h): every node spawned the 140-190 MiB child, also for a zoom lens.

    Caught: the child was started with the thread whenever check.rate_hz > 0.
    """
    values = config('zoom.yaml', check__rate_hz=20.0, check__max_load=1.0)
    reason = not_checkable(values)
    assert reason is not None and 'lens.zoom.joint' in reason
    assert not_checkable(config('fisheye.yaml')) is None
    session = CheckSession(values.__getitem__, lambda: None, {}, lambda *a: None,
                           lambda: None, checkable=lambda: not_checkable(values))
    children = psutil.Process().children()
    session.start()
    try:
        assert wait_for(lambda: session.entries()['check_state'] == reason, 10.0)
        session.offer(np.zeros((4, 4), np.uint8), None)
        assert session._pending is None and session.worker_pid is None
        assert psutil.Process().children() == children
        values['lens.zoom.joint'] = ''      # no longer moving: the check is on again
        assert wait_for(lambda: session.entries()['check_state'] == 'on', 10.0)
    finally:
        session.stop()


def test_a_child_stopped_by_another_hand_is_continued_and_stop_is_prompt(fisheye: Any) -> None:
    """
    Issues 36 (a), (j): a child stopped (SIGSTOP) not by the gate, then a check, then stop.

    Caught: only a pause the client had made itself was undone, so the check's multi-MB send
    waited forever on a stopped reader (no check completed); now the child is continued
    before every send. Stop then ends the stopped child and joins the thread (bounded).
    """
    values = config('fisheye.yaml', check__rate_hz=20.0, check__max_load=1.0,
                    check__window=1, check__apply=False)
    record = SimpleNamespace(model=fisheye, revision=1, values_generation=0)
    session = CheckSession(values.__getitem__, lambda: record, {}, lambda *a: None,
                           lambda: None)
    frame = np.zeros((fisheye.out_height, fisheye.out_width), np.uint8)
    session.start()
    try:
        assert wait_for(lambda: session.worker_pid is not None, 30.0)
        os.kill(session.worker_pid, signal.SIGSTOP)
        assert wait_for(lambda: session.entries()['checks'] >= 1,
                        every=lambda: session.offer(frame, fisheye))
        process = session._worker.process
        os.kill(process.pid, signal.SIGSTOP)
    finally:
        session.stop()
    assert not session._thread.is_alive()
    assert process.returncode is not None      # ended and reaped


def test_a_stuck_child_is_reported_and_restarted(fisheye: Any) -> None:
    """
    Issue 36 (a): a child that never answers (kept stopped by another hand).

    Caught: the check's thread waited for its reply forever and /diagnostics kept saying
    nothing; now it is stopped, ``check_state`` says why, and a new child checks.
    """
    values = config('fisheye.yaml', check__rate_hz=20.0, check__max_load=1.0,
                    check__window=1, check__apply=False)
    record = SimpleNamespace(model=fisheye, revision=1, values_generation=0)
    session = CheckSession(values.__getitem__, lambda: record, {}, lambda *a: None,
                           lambda: None)
    session.reply_timeout_s = session.send_timeout_s = 0.5
    frame = np.zeros((fisheye.out_height, fisheye.out_width), np.uint8)
    session.start()
    try:
        assert wait_for(lambda: session.worker_pid is not None, 30.0)
        stuck = session.worker_pid

        def hold() -> None:        # keeps stopping it, as a debugger or a frozen cgroup would
            try:
                os.kill(stuck, signal.SIGSTOP)
            except ProcessLookupError:
                pass
        assert wait_for(lambda: session.entries()['check_state'].startswith('restarting'),
                        every=lambda: (hold(), session.offer(frame, fisheye)))
        session.reply_timeout_s = session.send_timeout_s = 60.0    # a new child imports first
        state = session.entries()['check_state']
        assert 'did not answer' in state or 'took no request' in state, state
        assert session.restarts == 1
        assert wait_for(lambda: session.worker_pid not in (None, stuck), 30.0)
        checks = session.entries()['checks']
        assert wait_for(lambda: session.entries()['checks'] > checks,
                        every=lambda: session.offer(frame, fisheye))
        assert session.entries()['check_state'] == 'on'
    finally:
        session.stop()
