# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The checks' shared child-process plumbing (runtime/child_process.py), without ROS.

A trivial child that echoes (written to a temporary directory) stands in for a check: a
request's objects and bytes arrive in order and the reply comes back; a child that takes no
request, or does not answer, is WorkerStuck (not an endless wait); a child that ignores
SIGTERM is killed by :meth:`ChildProcess.stop`; ``paused or held`` stops it. Both checks'
clients are this plumbing: the stereo check's child now starts with ``python -P`` at nice 19
and SCHED_IDLE from the parent, and imports the parent's package, not a ``mechdeconv_ros/``
in its current directory (it used ``python -c``, which put the current directory first).
"""

from __future__ import annotations

import os
from pathlib import Path
import signal
import time
from typing import Any, Callable, Iterator

from mechdeconv_ros.runtime import check_worker, stereo_check_worker
from mechdeconv_ros.runtime.child_process import ChildProcess, WorkerGone, WorkerStuck
import numpy as np
import psutil
import pytest

ECHO = """
import os, signal, sys, time
from mechdeconv_ros.runtime.child_process import child_connection


def main():
    conn = child_connection()
    if conn is None:
        return 0
    while True:
        try:
            message = conn.recv()
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return 0
        if message == 'nap':
            time.sleep(60.0)
        if message == 'no_term':
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        conn.send({'message': message, 'bytes': bytes(data), 'pid': os.getpid()})
"""


def wait_for(predicate: Callable[[], bool], timeout: float = 15.0) -> bool:
    """Poll until ``predicate()`` or the timeout; return the predicate."""
    deadline = time.monotonic() + timeout
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.02)
    return bool(predicate())


@pytest.fixture(scope='module')
def echo_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return a directory holding the echo child's module ``echo_child``."""
    path = tmp_path_factory.mktemp('echo')
    (path / 'echo_child.py').write_text(ECHO)
    return path


@pytest.fixture()
def echo(echo_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[ChildProcess]:
    """Return a started echo child (its module on PYTHONPATH); stop it after the test."""
    monkeypatch.setenv('PYTHONPATH', os.pathsep.join(
        p for p in (str(echo_dir), os.environ.get('PYTHONPATH', '')) if p))
    child = ChildProcess('echo_child', 'echo process')
    child.start()
    yield child
    child.stop()
    child.close()


def test_a_request_is_sent_in_order_and_answered(echo: ChildProcess) -> None:
    frame = np.arange(12, dtype=np.uint16).reshape(3, 4)
    reply = echo.request(({'a': 1}, frame.reshape(-1).view(np.uint8)))
    assert reply['message'] == {'a': 1} and reply['bytes'] == frame.tobytes()
    assert echo.request(('again', b'xy'))['bytes'] == b'xy'
    child = psutil.Process(echo.process.pid)
    assert child.nice() == 19 and os.sched_getscheduler(child.pid) == os.SCHED_IDLE
    command = child.cmdline()
    assert command[1] == '-P' and 'echo_child' in ' '.join(command)


def test_a_child_that_does_not_answer_or_read_is_stuck_then_gone(echo: ChildProcess) -> None:
    with pytest.raises(WorkerStuck, match='did not answer'):
        echo.request(('nap', b''), poll_s=0.02, reply_timeout_s=0.2)
    with pytest.raises(WorkerStuck, match='took no request'):     # it sleeps: a full pipe
        echo.request(('big', bytes(16 << 20)), send_timeout_s=0.2)
    echo.stop()
    with pytest.raises(WorkerGone, match='echo process is not running'):
        echo.request(('late', b''))


def test_stopped_while_paused_or_held_and_continued_for_a_request(echo: ChildProcess) -> None:
    child = psutil.Process(echo.process.pid)

    def stopped() -> bool:
        return child.status() == psutil.STATUS_STOPPED

    echo.hold(True)
    assert wait_for(stopped)
    echo.pause(True)
    echo.hold(False)        # still paused
    assert echo.paused and stopped()
    looks: list[bool] = []
    # The request continues it; ``waiting`` sees it run (a pause after the reply: resumed).
    reply = echo.request(('x', b''), waiting=lambda: looks.append(stopped()), poll_s=0.001)
    assert reply['message'] == 'x' and not echo.paused and not any(looks)
    assert wait_for(lambda: not stopped())


def test_a_child_that_ignores_sigterm_is_killed_by_stop(echo: ChildProcess) -> None:
    echo.request(('no_term', b''))
    echo.pause(True)
    process = echo.process
    echo.stop()
    assert process.returncode == -signal.SIGKILL and echo.process is None


@pytest.mark.parametrize('client', [check_worker.CheckWorker,
                                    stereo_check_worker.StereoCheckWorker],
                         ids=['check', 'stereo'])
def test_both_checks_import_the_parents_package_at_idle_priority(
        client: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """
    A decoy ``mechdeconv_ros/`` in the child's current directory is not imported.

    Caught (stereo): ``python -c`` put the current directory first on ``sys.path``: the decoy
    ended the child (exit 3) and the request was WorkerGone.
    """
    decoy = tmp_path / 'mechdeconv_ros'
    decoy.mkdir()
    (decoy / '__init__.py').write_text('raise SystemExit(3)\n')
    monkeypatch.chdir(tmp_path)
    worker = client()
    worker.start()
    try:
        child = psutil.Process(worker.process.pid)
        assert child.nice() == 19 and os.sched_getscheduler(child.pid) == os.SCHED_IDLE
        # A request the child cannot check: its error comes back, from the real package.
        reply = worker.request(({}, b''))
        assert 'error' in reply and 'KeyError' in reply['error'], reply
        # (Its command line is read once it serves: just after the exec it can be empty.)
        command = child.cmdline()
        assert command[1] == '-P' and client.__module__.rsplit('.', 1)[1] in ' '.join(command)
    finally:
        worker.stop()
        worker.close()
    assert isinstance(worker, ChildProcess) and worker.process is None
