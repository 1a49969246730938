# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The stereo check in a child process at SCHED_IDLE: its loop and the parent's client.

No ROS. The check of one pair (two SIFT detections, matching, the epipolar fit:
:mod:`~mechdeconv_ros.imaging.stereo_check`) is about a second of CPU at 720p; in the node's
process it would hold the interpreter lock the frame path needs. The child and the parent's
end are the straight-edge check's (:mod:`~mechdeconv_ros.runtime.child_process`, issue 36):
``python -P -c`` :data:`BOOTSTRAP` ``FD PARENT_PID`` (the parent's package, never one in the
current directory), nice 19 and SCHED_IDLE from the parent at once, OpenCV on one thread,
SIGINT ignored, a session of its own, exit when its socket closes, PR_SET_PDEATHSIG; the
parent continues it (SIGCONT) before every send and after every reply, sends without blocking
past a deadline, raises :class:`WorkerStuck` (a :class:`WorkerGone`) when no reply comes after
:data:`~mechdeconv_ros.runtime.child_process.REPLY_TIMEOUT_S` of running, and stops it within
1.5 s. While the node rectifies and publishes a pair it stops the child
(:meth:`StereoCheckWorker.pause`, SIGSTOP/SIGCONT: two system calls per pair, only while a
check is in progress), so the check runs only in the time between pairs: SCHED_IDLE alone
left it the memory bandwidth and cache the remap needs.

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
import sys
import time
from typing import Any

import cv2
from mechdeconv_ros.imaging.stereo_check import check_pairs, match_pixels
from mechdeconv_ros.model.stereo import build_stereo
from mechdeconv_ros.runtime.child_process import (  # noqa: F401 - re-exported
    bootstrap, child_connection, ChildProcess, WorkerGone, WorkerStuck)
import numpy as np

#: The child's module; its command (:func:`~mechdeconv_ros.runtime.child_process.bootstrap`):
#: SIGINT ignored before anything else is imported, then :func:`main`.
MODULE = 'mechdeconv_ros.runtime.stereo_check_worker'
BOOTSTRAP = bootstrap(MODULE)


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


class StereoCheckWorker(ChildProcess):
    """The parent's client of one stereo check child process."""

    def __init__(self) -> None:
        """Create the client; no process yet."""
        super().__init__(MODULE, 'stereo check process')
        self._generation: int | None = None

    def start(self) -> None:
        """Start a fresh child (no models, no window; the pipe of an earlier one closed)."""
        super().start()
        self._generation = None

    def check(self, left: np.ndarray, right: np.ndarray, values: dict[str, Any],
              sizes: tuple[tuple[int, int], tuple[int, int]], generation: int,
              window: int, **request: Any) -> dict[str, Any]:
        """
        Check one grey raw pair in the child; block (interpreter lock released) for the reply.

        :param left: the left 8-bit grey raw frame.
        :param right: the right one.
        :param values: the pair's values the pair in use was built from (``StereoModel.values``).
        :param sizes: the raw ``(width, height)`` of the left and the right camera.
        :param generation: their generation (values are sent when it changes).
        :param window: pairs to pool.
        :param request: ``waiting``, ``poll_s``, ``reply_timeout_s``, ``send_timeout_s`` of
            :meth:`~mechdeconv_ros.runtime.child_process.ChildProcess.request`.
        :return: the reply (module docstring).
        :raises WorkerStuck: if the send or the reply did not come in time (stop the child).
        :raises WorkerGone: if the child exited or the pipe broke.
        """
        if self.process is None or self.process.poll() is not None:
            raise WorkerGone('the stereo check process is not running')
        new = None if generation == self._generation else dict(values)
        header = {'shapes': (left.shape[:2], right.shape[:2]), 'values': new, 'sizes': sizes,
                  'generation': generation, 'window': int(window)}
        data = np.concatenate([np.ascontiguousarray(left).reshape(-1),
                               np.ascontiguousarray(right).reshape(-1)])
        self._generation = generation
        try:
            reply = self.request((header, data), **request)
        except WorkerGone:
            self._generation = None     # the child may not have taken them: send them again
            raise
        if 'error' in reply:
            self._generation = None
        return reply


def main(argv: list[str] | None = None) -> int:
    """
    Run the child: nice 19, SCHED_IDLE, SIGINT ignored; serve the socket until it closes.

    :param argv: ``[FD, PARENT_PID]``; default ``sys.argv[1:]``.
    :return: the exit status.
    """
    conn = child_connection(argv)     # SIGINT ignored, PR_SET_PDEATHSIG, SCHED_IDLE
    if conn is None:
        return 0        # the parent died already
    cv2.setNumThreads(1)
    return serve(conn)


if __name__ == '__main__':
    sys.exit(main())
