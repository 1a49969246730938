# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The stereo check in a child process at SCHED_IDLE: its loop and the parent's client.

No ROS. The check of one pair (two SIFT detections, matching, the epipolar fit:
:mod:`~mechdeconv_ros.imaging.stereo_check`) is about a second of CPU at 720p; in the node's
process it would hold the interpreter lock the frame path needs. The child (``python -c``
:data:`BOOTSTRAP` ``FD PARENT_PID``, started by :class:`StereoCheckWorker` with
:class:`subprocess.Popen`, so it inherits no ROS state, only its socket) lowers itself to nice
19 and the SCHED_IDLE policy (a core only when no thread of the node wants one), runs OpenCV
on one thread, ignores SIGINT, lives in a session of its own, exits when its socket closes
and asks Linux to kill it when its parent dies (PR_SET_PDEATHSIG). While the node rectifies
and publishes a pair it stops the child (:meth:`StereoCheckWorker.pause`, SIGSTOP/SIGCONT:
two system calls per pair, only while a check is in progress), so the check runs only in the
time between pairs: SCHED_IDLE alone left it the memory bandwidth and cache the remap needs.

Protocol (a :class:`multiprocessing.connection.Connection` on a Unix socket pair, one request
and one reply at a time): a pickled header ``{'shapes', 'values', 'sizes', 'generation',
'window'}`` and then the two 8-bit grey frames' bytes (``send_bytes``, not pickled).
``values`` are the pair's parameter values the pair in use was built from, sent only when
the generation changed: the child builds the pair's model itself
(:func:`~mechdeconv_ros.model.stereo.build_stereo` at the raw ``sizes``, at its idle
priority). Pickling the two lens models instead held the node's interpreter lock for tens of
milliseconds: a frame's worth. The child keeps the matched RAW pixels of the last ``window``
pairs (raw pixels stay valid when the lenses' description changes: they are mapped to
directions again by the current models at each check; a new raw size clears them). Reply:
``{'result': StereoCheckResult.as_dict(), 'pairs': n, 'ms': float}`` or ``{'error': repr}``.
"""

from __future__ import annotations

from collections import deque
import ctypes
import os
from pathlib import Path
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import Any

import cv2
from mechdeconv_ros.imaging.stereo_check import check_pairs, match_pixels
from mechdeconv_ros.model.stereo import build_stereo
import numpy as np

#: Linux prctl option: the signal a child gets when its parent (thread) dies.
PR_SET_PDEATHSIG = 1
#: Seconds the parent waits for the child to exit after SIGTERM before SIGKILL.
STOP_WAIT_S = 2.0
#: One thread for numpy's BLAS and OpenMP in the child.
THREAD_ENV = {'OMP_NUM_THREADS': '1', 'OPENBLAS_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1'}
#: The child's command: SIGINT ignored before anything else is imported.
BOOTSTRAP = ('import signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); '
             'from mechdeconv_ros.runtime.stereo_check_worker import main; sys.exit(main())')


class WorkerGone(RuntimeError):
    """The stereo check's child process exited or its pipe broke."""


class PairWindow:
    """The child's state: the pair's model and the matched pixels of recent pairs."""

    def __init__(self) -> None:
        """Start empty."""
        self.stereo: Any = None
        self._window: deque[tuple[np.ndarray, np.ndarray]] = deque()
        self._shapes: Any = None

    def handle(self, header: dict[str, Any], left: np.ndarray,
               right: np.ndarray) -> dict[str, Any]:
        """
        Match one pair, pool it with the window and check the rig.

        :param header: the request header (module docstring).
        :param left: the left grey raw frame.
        :param right: the right grey raw frame.
        :return: the reply.
        """
        start = time.perf_counter()
        if header['values'] is not None:
            self.stereo = None      # free the old model first
            sizes = header['sizes']
            self.stereo = build_stereo(header['values'], tuple(sizes[0]), tuple(sizes[1]))
        if header['shapes'] != self._shapes:
            self._window.clear()
            self._shapes = header['shapes']
        self._window.append(match_pixels(left, right))
        while len(self._window) > int(header['window']):
            self._window.popleft()
        stereo = self.stereo
        rig = {k: float(v) for k, v in stereo.values.items() if k.startswith('rig.')}
        result = check_pairs(stereo.left, stereo.right, rig, list(self._window),
                             float(stereo.K_rect[1, 1]), matched=True)
        return {'result': result.as_dict(), 'pairs': len(self._window),
                'ms': (time.perf_counter() - start) * 1e3}


def serve(conn: Any) -> int:
    """
    Answer requests on a connection until it closes (the child's loop).

    :param conn: the child's end.
    :return: the exit status (0).
    """
    state = PairWindow()
    while True:
        try:
            header = conn.recv()
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return 0
        except Exception as err:    # noqa: B902 - a broken stream: the parent starts anew
            print(f'stereo check worker: bad request: {err!r}', file=sys.stderr)
            return 1
        try:
            (hl, wl), (hr, wr) = header['shapes']
            flat = np.frombuffer(data, np.uint8)
            reply = state.handle(header, flat[:hl * wl].reshape(hl, wl),
                                 flat[hl * wl:].reshape(hr, wr))
        except Exception as err:    # noqa: B902 - one bad check must not end the worker
            reply = {'error': repr(err)}
        del data
        try:
            conn.send(reply)
        except OSError:
            return 0


class StereoCheckWorker:
    """The parent's client of one stereo check child process."""

    def __init__(self) -> None:
        """Create the client; no process yet."""
        self.process: subprocess.Popen | None = None
        self._conn: Any = None
        self._generation: int | None = None
        #: Whether the child is stopped (SIGSTOP) by :meth:`pause`.
        self.paused = False
        self._signal_lock = threading.Lock()

    def pause(self, paused: bool) -> None:
        """
        Stop (SIGSTOP) or continue (SIGCONT) the child; nothing if it is already so or gone.

        A stopped child uses no CPU, no memory bandwidth and no cache: what its SCHED_IDLE
        priority alone cannot give the frame path (a 720p SIFT evicts the remap's maps).
        Safe from any thread.

        :param paused: True to stop it, False to continue it.
        """
        with self._signal_lock:
            process = self.process
            if process is None or paused == self.paused or process.poll() is not None:
                self.paused = paused and process is not None and process.poll() is None
                return
            try:
                process.send_signal(signal.SIGSTOP if paused else signal.SIGCONT)
            except OSError:
                return
            self.paused = paused

    def start(self) -> None:
        """Start a fresh child (no models, no window)."""
        from multiprocessing.connection import Connection
        parent, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[2])
        env['PYTHONPATH'] = os.pathsep.join(p for p in (root, env.get('PYTHONPATH', '')) if p)
        env.update(THREAD_ENV)
        try:
            # Its own session: SIGINT to the node's process group must not reach it.
            self.process = subprocess.Popen(
                [sys.executable, '-c', BOOTSTRAP, str(child.fileno()), str(os.getpid())],
                pass_fds=(child.fileno(),), env=env, stdin=subprocess.DEVNULL,
                start_new_session=True)
        finally:
            child.close()
        self._conn = Connection(parent.detach())
        self._generation = None

    def check(self, left: np.ndarray, right: np.ndarray, values: dict[str, Any],
              sizes: tuple[tuple[int, int], tuple[int, int]], generation: int,
              window: int) -> dict[str, Any]:
        """
        Check one grey raw pair in the child; block (interpreter lock released) for the reply.

        :param left: the left 8-bit grey raw frame.
        :param right: the right one.
        :param values: the pair's values the pair in use was built from (``StereoModel.values``).
        :param sizes: the raw ``(width, height)`` of the left and the right camera.
        :param generation: their generation (values are sent when it changes).
        :param window: pairs to pool.
        :return: the reply (module docstring).
        :raises WorkerGone: if the child exited or the pipe broke.
        """
        if self.process is None or self.process.poll() is not None:
            raise WorkerGone('the stereo check process is not running')
        new = None if generation == self._generation else dict(values)
        header = {'shapes': (left.shape[:2], right.shape[:2]), 'values': new, 'sizes': sizes,
                  'generation': generation, 'window': int(window)}
        data = np.concatenate([np.ascontiguousarray(left).reshape(-1),
                               np.ascontiguousarray(right).reshape(-1)])
        try:
            self._conn.send(header)
            self._conn.send_bytes(data)
            self._generation = generation
            reply = self._conn.recv()
        except (EOFError, OSError) as err:
            raise WorkerGone(f'the stereo check process stopped ({err!r})') from err
        if 'error' in reply:
            self._generation = None
        return reply

    def stop(self) -> None:
        """Stop the child (SIGCONT if paused, SIGTERM, then SIGKILL) and close the pipe."""
        self.pause(False)
        with self._signal_lock:
            process, self.process = self.process, None
            self.paused = False
        if process is not None and process.poll() is None:
            process.terminate()
            try:
                process.wait(STOP_WAIT_S)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(STOP_WAIT_S)
        if self._conn is not None:
            self._conn.close()
            self._conn = None


def main(argv: list[str] | None = None) -> int:
    """
    Run the child: nice 19, SCHED_IDLE, SIGINT ignored; serve the socket until it closes.

    :param argv: ``[FD, PARENT_PID]``; default ``sys.argv[1:]``.
    :return: the exit status.
    """
    from multiprocessing.connection import Connection
    args = sys.argv[1:] if argv is None else argv
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        pass
    if len(args) > 1 and os.getppid() != int(args[1]):
        return 0
    try:
        os.setpriority(os.PRIO_PROCESS, 0, 19)
    except (AttributeError, OSError):
        pass
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        pass
    cv2.setNumThreads(1)
    return serve(Connection(int(args[0])))


if __name__ == '__main__':
    sys.exit(main())
