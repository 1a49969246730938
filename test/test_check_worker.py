# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The check's child process (runtime/check_worker.py), without ROS.

It must give the in-process check's result (the window pooled, a new current model judged),
receive a model once (only when it changes), run at nice 19 and SCHED_IDLE, ignore SIGINT,
exit when stopped and when its parent dies by SIGKILL (no orphan), and report its death as
WorkerGone.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
from typing import Iterator

from check_scenes import featureless, grid, Lens, PIXEL_MM
from mechdeconv_ros.imaging import plumb_check as pc
from mechdeconv_ros.imaging.remap import build_float_maps, Rectifier
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.runtime.check_worker import CheckWorker, portable, WorkerGone
from mechdeconv_ros.schema.params import defaults, load_params_file
import psutil
import pytest
from ros_helpers import REPO


def fisheye(offset_px: tuple[float, float] = (0.0, 0.0)) -> object:
    """Return the fisheye config's model with an axis offset in px."""
    values = defaults()
    values.update(load_params_file(REPO / 'config' / 'fisheye.yaml'))
    values['sensor.axis_offset_x_mm'] = offset_px[0] * PIXEL_MM
    values['sensor.axis_offset_y_mm'] = offset_px[1] * PIXEL_MM
    return build_model(values)


@pytest.fixture(scope='module')
def models() -> tuple[object, object]:
    """Return the fisheye's nominal model and the one with the axis 16, 12 px off."""
    return fisheye(), fisheye((16.0, 12.0))


@pytest.fixture()
def worker() -> Iterator[CheckWorker]:
    """Return a started worker; stop it after the test."""
    client = CheckWorker()
    client.start()
    yield client
    client.stop()
    client.close()


def test_the_child_gives_the_in_process_result_and_gets_each_model_once(
        worker: CheckWorker, models: tuple[object, object]) -> None:
    lens = Lens('fisheye')
    nominal, shifted = models
    frame = Rectifier(nominal).correct(grid(lens, (16.0, 12.0), 0.0, 0.0, 10.0))
    sent: list[object] = []
    send = worker._conn.send
    worker._conn.send = lambda obj: (sent.append(obj), send(obj))[1]
    first = worker.check(featureless(lens), nominal, nominal, 2, 0.3)
    second = worker.check(frame, nominal, shifted, 2, 0.3)    # a new current model
    assert [sorted(h['models']) for h in sent] == [[1], [2]]  # each model sent once
    assert first['frames'] == 1 and second['frames'] == 2     # the window pools
    assert first['result'].verdict == 'not_enough_edges'
    chains = pc.chains_from_corrected(frame, *build_float_maps(nominal))
    assert second['result'] == pc.check_chains(shifted, chains, 0.3)
    assert second['result'].verdict == 'ok'
    # What is pickled: no caches (filled by other threads), small (no maps).
    nominal._summary_cache['filled'] = True
    copy = portable(nominal)
    assert copy._summary_cache == {} and nominal._summary_cache
    del nominal._summary_cache['filled']
    assert len(pickle.dumps(copy)) < 1 << 20


def test_the_child_is_nice_ignores_sigint_and_its_death_is_reported(
        worker: CheckWorker, models: tuple[object, object]) -> None:
    model = models[0]
    blank = featureless(Lens('fisheye'))
    child = psutil.Process(worker.process.pid)
    assert worker.check(blank, model, model, 1, 0.3)['result'].verdict == 'not_enough_edges'
    assert child.nice() == 19 and os.sched_getscheduler(child.pid) == os.SCHED_IDLE
    child.send_signal(signal.SIGINT)
    reply = worker.check(blank, model, model, 1, 0.3)
    assert reply['result'].verdict == 'not_enough_edges' and child.is_running()
    child.kill()
    child.wait(5.0)
    with pytest.raises(WorkerGone):
        worker.check(blank, model, model, 1, 0.3)
    worker.stop()
    worker.start()      # a fresh child serves again
    assert worker.check(blank, model, model, 1, 0.3)['result'].verdict == 'not_enough_edges'


@pytest.mark.parametrize('paused', [False, True], ids=['running', 'paused'])
def test_no_orphan_when_the_parent_is_killed(paused: bool) -> None:
    # Running: its socket's EOF ends it. Paused (SIGSTOP, the node's CPU gate): it cannot
    # read, PR_SET_PDEATHSIG kills it.
    code = ('import sys, time\n'
            'from mechdeconv_ros.runtime.check_worker import CheckWorker\n'
            'w = CheckWorker()\nw.start()\nif len(sys.argv) > 1:\n'
            # Paused once it serves (its nice 19 is set after the death signal), as in a check.
            '    import psutil\n    child = psutil.Process(w.process.pid)\n'
            '    while child.nice() != 19:\n        time.sleep(0.05)\n    w.pause(True)\n'
            'print(w.process.pid, flush=True)\ntime.sleep(60)\n')
    parent = subprocess.Popen([sys.executable, '-c', code, *(['paused'] if paused else [])],
                              stdout=subprocess.PIPE, cwd=REPO)
    try:
        child = psutil.Process(int(parent.stdout.readline()))
        parent.kill()
        parent.wait(5.0)
        gone, alive = psutil.wait_procs([child], timeout=10.0)
        assert not alive, alive
    finally:
        parent.kill()
        parent.wait(5.0)
        parent.stdout.close()


def test_a_paused_child_waits_then_answers_and_stops_at_once(
        worker: CheckWorker, models: tuple[object, object]) -> None:
    """The node pauses a check (SIGSTOP) while the CPUs are busy (runtime/check_gate.py)."""
    model = models[0]
    blank = featureless(Lens('fisheye'))
    child = psutil.Process(worker.process.pid)
    stopped: list[bool] = []

    def waiting() -> None:
        # Called while no reply has come (the frame is sent): pause, look twice, continue.
        if not stopped:
            worker.pause(True)
        stopped.append(child.status() == psutil.STATUS_STOPPED)
        if len(stopped) == 3:
            worker.pause(False)

    reply = worker.check(blank, model, model, 1, 0.3, waiting=waiting, poll_s=0.05)
    assert reply['result'].verdict == 'not_enough_edges'
    # (SIGSTOP is delivered asynchronously: the first look may come before it.)
    assert stopped[1:3] == [True, True] and not worker.paused
    assert child.status() != psutil.STATUS_STOPPED
    worker.pause(True)
    process = worker.process
    worker.stop()       # a paused child ends by SIGTERM, not the SIGKILL after 2 s
    assert process.returncode == -signal.SIGTERM
