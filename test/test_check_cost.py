# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
What keeps the self-check off the frame path (issue 36).

The child's scheduling, its hold while a frame is in flight, and the duty cycle; no timing
here (benchmarks/check_ab.py measures it).
"""

from __future__ import annotations

import os
from pathlib import Path
import sys
import time
from typing import Any, Iterator

from mechdeconv_ros.runtime.check_session import CheckSession, STABLE_REPEATS
from mechdeconv_ros.runtime.check_worker import CheckWorker
from mechdeconv_ros.schema.params import defaults
import pytest

LINUX = sys.platform.startswith('linux')


def state(pid: int) -> str:
    """Return a process's state letter from /proc (T: stopped)."""
    return Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]


def wait_for(predicate: Any, timeout: float = 15.0) -> bool:
    """Poll until ``predicate()`` or the timeout; return the predicate."""
    deadline = time.monotonic() + timeout
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.05)
    return bool(predicate())


@pytest.fixture(scope='module')
def worker() -> Iterator[CheckWorker]:
    """Start a check child (no check sent); stop it after the module."""
    client = CheckWorker()
    client.start()
    yield client
    client.stop()
    client.close()


@pytest.mark.skipif(not LINUX, reason='SCHED_IDLE and /proc are Linux')
def test_the_child_runs_in_the_idle_scheduling_class(worker: CheckWorker) -> None:
    """The child takes a core only when no other thread wants it (SCHED_IDLE, nice 19)."""
    pid = worker.process.pid
    assert wait_for(lambda: os.sched_getscheduler(pid) == os.SCHED_IDLE)
    assert os.getpriority(os.PRIO_PROCESS, pid) == 19


@pytest.mark.skipif(not LINUX, reason='SCHED_IDLE is Linux')
def test_the_child_imports_at_idle_priority_already() -> None:
    """Its priority is set as it starts, not after its second of imports (numpy, OpenCV)."""
    client = CheckWorker()
    client.start()
    try:
        pid = client.process.pid
        assert os.sched_getscheduler(pid) == os.SCHED_IDLE
        assert os.getpriority(os.PRIO_PROCESS, pid) == 19
    finally:
        client.stop()
        client.close()


@pytest.mark.skipif(not LINUX, reason='/proc states are Linux')
@pytest.mark.parametrize('order', ['hold_first', 'pause_first'], ids=['hold-first', 'pause-first'])
def test_the_child_is_stopped_while_held_or_paused(worker: CheckWorker, order: str) -> None:
    """Stopped while a frame holds it OR the gate pauses it; running only when neither does."""
    pid = worker.process.pid
    assert wait_for(lambda: state(pid) != 'T')
    first, second = ((worker.hold, worker.pause) if order == 'hold_first'
                     else (worker.pause, worker.hold))
    first(True)
    assert wait_for(lambda: state(pid) == 'T')
    second(True)
    first(False)        # the other still holds it: it must stay stopped
    time.sleep(0.2)
    assert state(pid) == 'T'
    assert worker.paused == (order == 'hold_first')
    second(False)
    assert wait_for(lambda: state(pid) != 'T')
    assert not worker.paused


def test_hold_before_a_child_exists_does_nothing() -> None:
    """The frame path may hold before the check's process is started: no signal, no error."""
    client = CheckWorker()
    client.hold(True)
    client.hold(False)
    assert client.process is None and not client.paused


def _thread(values: dict[str, Any]) -> CheckSession:
    """Return a check session (not started: no thread, no child) reading ``values``."""
    return CheckSession(values.__getitem__, lambda: None, {}, lambda level, message: None,
                        lambda: None)


def test_the_duty_cycle_slows_down_once_stable_and_not_for_a_new_model() -> None:
    """Checks at 1 / rate until STABLE_REPEATS same verdicts of one model, then the long period."""
    values = defaults()
    values.update({'check.rate_hz': 0.2, 'check.stable_period_s': 60.0})
    thread = _thread(values)
    model, other = object(), object()
    assert thread._period(0.2, model) == pytest.approx(5.0)
    for k in range(STABLE_REPEATS):
        assert thread._period(0.2, model) == pytest.approx(5.0), k
        thread._record(model, 'ok')
    assert thread._period(0.2, model) == pytest.approx(60.0)
    # A new model (a parameter set, a new size) is checked at the rate again.
    assert thread._period(0.2, other) == pytest.approx(5.0)
    # Another verdict of the same model starts the count again.
    thread._record(model, 'description_off')
    assert thread._period(0.2, model) == pytest.approx(5.0)
    # 0 = always at the rate; a period shorter than 1 / rate never speeds it up.
    for _ in range(STABLE_REPEATS):
        thread._record(model, 'description_off')
    values['check.stable_period_s'] = 0.0
    assert thread._period(0.2, model) == pytest.approx(5.0)
    values['check.stable_period_s'] = 1.0
    assert thread._period(0.2, model) == pytest.approx(5.0)


@pytest.mark.skipif(not LINUX, reason='/proc states are Linux')
def test_a_held_child_stops_and_a_late_hold_does_nothing() -> None:
    """Stopping a child a frame holds ends it; a frame that ends after the stop signals nobody."""
    client = CheckWorker()
    client.start()
    process = client.process
    client.hold(True)
    assert wait_for(lambda: state(process.pid) == 'T')
    client.stop()
    client.close()
    assert process.poll() is not None
    client.hold(False)
    client.hold(True)
    assert client.process is None and not client.paused


@pytest.mark.skipif(not LINUX, reason='/proc states are Linux')
@pytest.mark.parametrize('busy', [True, False], ids=['check-running', 'no-check'])
def test_the_frame_callback_holds_a_running_check(busy: bool) -> None:
    """While a check runs, a frame's callback runs with the child stopped, even if it raises."""
    values = defaults()
    thread = _thread(values)
    thread._worker.start()
    try:
        pid = thread._worker.process.pid
        assert wait_for(lambda: state(pid) != 'T')
        thread._busy = busy
        seen = []

        def frame(msg: Any, read: Any) -> None:
            seen.append((msg, read, wait_for(lambda: state(pid) == 'T', 0.5 if busy else 0.2)))
            raise RuntimeError('a bad frame')

        with pytest.raises(RuntimeError):
            thread.holding(frame)('msg', 'read')
        assert seen == [('msg', 'read', busy)]
        assert wait_for(lambda: state(pid) != 'T')
        # Not while check.pause_during_frames is false.
        values['check.pause_during_frames'] = False
        thread.holding(lambda *args: seen.append(state(pid)))('msg', 'read')
        assert seen[-1] != 'T'
    finally:
        thread._worker.stop()
        thread._worker.close()
