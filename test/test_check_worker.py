# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The check's child process (runtime/check_worker.py), without ROS.

It must give the in-process check's result (the window pooled, a new current model judged),
receive a model once (only when it changes), run at nice 19 and SCHED_IDLE, ignore SIGINT,
exit when stopped and when its parent dies by SIGKILL (no orphan), and report its death as
WorkerGone. Issue 36: never left stopped by a pause that lands after its reply, a child that
does not answer is WorkerStuck (not an endless wait), a new frame size starts a new window,
and the child imports the parent's package, not a ``mechdeconv_ros/`` in its current
directory.
"""

from __future__ import annotations

import os
from pathlib import Path
import pickle
import signal
import subprocess
import sys
import threading
from typing import Any, Iterator

from check_scenes import featureless, grid, Lens, PIXEL_MM
from mechdeconv_ros.imaging import plumb_check as pc
from mechdeconv_ros.imaging.remap import build_float_maps, Rectifier
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.runtime.check_worker import (
    CheckWorker, portable, Worker, WorkerGone, WorkerStuck)
from mechdeconv_ros.schema.params import defaults, load_params_file
import numpy as np
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
    send = worker._send
    worker._send = lambda data, deadline: (sent.append(data), send(data, deadline))[1]
    first = worker.check(featureless(lens), nominal, nominal, 2, 0.3)
    second = worker.check(frame, nominal, shifted, 2, 0.3)    # a new current model
    headers = [pickle.loads(data) for data in sent[::2]]      # then each frame's bytes
    assert [sorted(h['models']) for h in headers] == [[1], [2]]  # each model sent once
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
            # Paused once it serves (blocked reading its socket: after the death signal), as
            # in a check (the parent sets its nice 19 at once: no sign of that any more).
            '    wchan = f"/proc/{w.process.pid}/wchan"\n'
            '    while "unix_stream" not in open(wchan).read():\n        time.sleep(0.05)\n'
            '    w.pause(True)\n'
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


def test_a_pause_after_the_reply_does_not_leave_the_child_stopped(
        worker: CheckWorker, models: tuple[object, object]) -> None:
    """
    The reply lands between the poll's timeout and the gate's pause (issue 36 (a)).

    Caught: the child stayed SIGSTOPped after the first check, and the second check's
    multi-MB send (1280 x 960 bytes, more than the socket's buffer) blocked forever.
    """
    model = models[0]
    blank = featureless(Lens('fisheye'))
    assert blank.nbytes > 1 << 20
    child = psutil.Process(worker.process.pid)

    def waiting() -> None:
        if not worker.paused:
            assert worker._conn.poll(60.0)      # the reply is there, not yet taken
            worker.pause(True)

    first = worker.check(blank, model, model, 1, 0.3, waiting=waiting, poll_s=0.001)
    assert first['result'].verdict == 'not_enough_edges'
    second: list[Any] = []
    sender = threading.Thread(target=lambda: second.append(
        worker.check(blank, model, model, 1, 0.3)), daemon=True)
    sender.start()
    sender.join(60.0)       # generous: a hang, not a speed, is what this catches
    if sender.is_alive():
        child.resume()      # let the hung send finish before the fixture stops the child
        sender.join(60.0)
        pytest.fail('the second check hung: the child was left stopped')
    assert second[0]['result'].verdict == 'not_enough_edges'
    assert not worker.paused and child.status() != psutil.STATUS_STOPPED


def test_a_child_that_does_not_answer_is_stuck_not_waited_for(
        worker: CheckWorker, models: tuple[object, object]) -> None:
    """
    A child stopped by something else than the gate never answers (issue 36 (a)).

    Caught: ``check`` waited for its reply forever (no watchdog); now WorkerStuck after the
    reply timeout of running time, and the child can be stopped and a fresh one started.
    """
    model = models[0]
    blank = featureless(Lens('fisheye'))
    pid = worker.process.pid

    def waiting() -> None:
        os.kill(pid, signal.SIGSTOP)    # not worker.pause: the client believes it runs

    with pytest.raises(WorkerStuck):
        worker.check(blank, model, model, 1, 0.3, waiting=waiting, poll_s=0.05,
                     reply_timeout_s=0.5)
    process = worker.process
    worker.stop()
    assert process.returncode == -signal.SIGTERM
    worker.close()
    worker.start()
    assert worker.check(blank, model, model, 1, 0.3)['result'].verdict == 'not_enough_edges'


def test_a_new_frame_size_starts_a_new_window(models: tuple[object, object]) -> None:
    """
    A camera that changes resolution (issue 36 (c)): no result pools edges of two sizes.

    Caught: the first frame of the new size was pooled with the old size's chains
    (``frames`` 2), when the model judged was the new size's.
    """
    values = defaults()
    values.update(load_params_file(REPO / 'config' / 'fisheye.yaml'))
    values['sensor.width_px'], values['sensor.height_px'] = 640, 480
    small = build_model(values)
    large = models[0]
    worker = Worker()
    blank = [np.zeros((m.out_height, m.out_width), np.uint8) for m in (large, small)]
    header = {'models': {1: large, 2: small}, 'window': 3, 'max_rms_px': 0.3}
    for expected in (1, 2):
        reply = worker.handle(dict(header, frame_model=1, current_model=1), blank[0])
        assert reply['frames'] == expected
    reply = worker.handle(dict(header, frame_model=2, current_model=2), blank[1])
    assert reply['frames'] == 1 and reply['result'] is not None
    reply = worker.handle(dict(header, frame_model=2, current_model=2), blank[1])
    assert reply['frames'] == 2


def test_the_child_imports_the_installed_package_not_a_decoy_in_its_directory(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, models: tuple[object, object]) -> None:
    """
    Started from a directory holding a ``mechdeconv_ros/`` package (issue 36 (i)).

    Caught: the child ran ``python -c``, which puts the current directory first on its path,
    so it imported the decoy (which here records itself and exits) and the check failed.
    """
    marker = tmp_path / 'decoy_imported'
    decoy = tmp_path / 'mechdeconv_ros'
    decoy.mkdir()
    (decoy / '__init__.py').write_text(
        f'open({str(marker)!r}, "w").close()\nraise SystemExit(3)\n')
    monkeypatch.chdir(tmp_path)
    model = models[0]
    client = CheckWorker()
    client.start()
    try:
        reply = client.check(featureless(Lens('fisheye')), model, model, 1, 0.3)
    finally:
        client.stop()
        client.close()
    assert reply['result'].verdict == 'not_enough_edges'
    assert not marker.exists()
