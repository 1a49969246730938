# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The straight-edge check in a child process (issue 26): its loop and the parent's client.

Pure Python, numpy and OpenCV, no ROS (docs/design.md section 2.17). One check of one frame is
seconds of Python; in the node's process it held the interpreter lock that the frame path
needs (p99 latency 33 -> 46 ms at 1280x960). Here it runs in a child process
(``python -P -c BOOTSTRAP FD``: :data:`BOOTSTRAP` runs :func:`main` of this module; started by
:class:`CheckWorker` with :class:`subprocess.Popen`, so it imports nothing of ROS and
inherits no ROS state, only the socket; the plumbing below is
:mod:`~mechdeconv_ros.runtime.child_process`, shared with the stereo check), which:

* imports the package the parent runs, never one in its current directory: ``-P`` keeps the
  current directory off ``sys.path`` (``python -c`` puts it first) and ``PYTHONPATH`` starts
  with the directory that holds the parent's ``mechdeconv_ros`` (issue 36 (i));

* runs at nice 19 and, on Linux, the SCHED_IDLE policy, set by the parent as soon as it
  exists (its imports are a second of CPU) and again by itself (it runs on a
  core no other thread wants, and a waking thread of the node takes the core at once: on 2
  cores it lowered the check's cost on the frames in most runs, docs/benchmarks.md), runs
  OpenCV on one thread, runs in a session of its own and ignores SIGINT (a node is stopped by
  SIGINT to its process group and must exit 0; its parent stops the child);
* exits when its end of the socket pair closes (the parent stopped, or died, even by
  SIGKILL: the kernel closes the parent's end), after the check it is in, if any; while
  paused (SIGSTOP: the node's CPU gate, :mod:`~mechdeconv_ros.runtime.check_gate`) it cannot
  read, so it also asks Linux to SIGKILL it when its parent dies (PR_SET_PDEATHSIG);
* is also stopped while the node's frame path holds it (:meth:`CheckWorker.hold`, a frame in
  flight, issue 36): stopped while ``paused or held``.

Protocol, over a :class:`multiprocessing.connection.Connection` on a Unix socket pair, one
request and one reply at a time:

* request: a pickled header ``{'shape', 'dtype', 'frame_model', 'current_model', 'models',
  'window', 'max_rms_px'}`` and then the frame's bytes (the array's buffer, not pickled),
  each framed as :class:`~multiprocessing.connection.Connection` frames them (a 4-byte
  big-endian length, then the bytes). The parent writes them without blocking, with a
  deadline (:data:`SEND_TIMEOUT_S`), after a SIGCONT: a child left stopped (SIGSTOP, the
  CPU gate) could not read, and a blocking multi-MB send would wait forever. Models are
  named by integer tokens; ``models`` carries only those the child does not hold (a model
  is sent once, when it changes: :func:`portable`, about 90 kB and 1 ms for the fisheye
  config). Both sides keep only the two tokens of the last request.
* reply: ``{'result': CheckResult | None, 'frames': n, 'ms': float}`` (None: the window was
  restarted because the frame's size is not the current model's) or ``{'error': repr}``.

The child keeps what the node's thread kept: the frame model's float maps (rebuilt when the
token changes) and the raw chains of the last ``window`` frames (raw pixels, so they stay
valid when the model changes). A frame of another raw size than the window's starts a new
window: raw pixels of two sizes are not one camera's (issue 36 (c)).

A child that does not answer is never waited for silently (issue 36 (a)): it is continued
(SIGCONT) before every send and after every reply, so a pause that lands after its reply
cannot leave it stopped; a send that cannot finish within :data:`SEND_TIMEOUT_S`, or a reply
that has not come after :data:`REPLY_TIMEOUT_S` of the child running (time paused by the
gate not counted), raises :class:`WorkerStuck`; the caller restarts the child and says so.
"""

from __future__ import annotations

from collections import deque
import copy
import dataclasses
import sys
import time
from typing import Any, Callable

import cv2
from mechdeconv_ros.imaging.plumb_check import chains_from_corrected, check_chains
from mechdeconv_ros.imaging.remap import build_float_maps
from mechdeconv_ros.runtime.child_process import (  # noqa: F401 - re-exported
    bootstrap, child_connection, ChildProcess, KILL_WAIT_S, lower_priority, NICE,
    PR_SET_PDEATHSIG, REPLY_TIMEOUT_S, SEND_TIMEOUT_S, STOP_WAIT_S, THREAD_ENV, WorkerGone,
    WorkerStuck)
import numpy as np

#: The child's command (:func:`~mechdeconv_ros.runtime.child_process.bootstrap`): SIGINT
#: ignored before anything else is imported, then :func:`main`.
MODULE = 'mechdeconv_ros.runtime.check_worker'
BOOTSTRAP = bootstrap(MODULE)


def portable(model: Any) -> Any:
    """
    Return a shallow copy of a model without its lazily filled caches, to pickle.

    The caches (``*_cache`` fields: summary, illumination, lateral colour) are filled by other
    threads of the node and not needed by the check; the copy does not share them.

    :param model: a LensModel.
    :return: the copy.
    """
    out = copy.copy(model)
    if dataclasses.is_dataclass(out):
        for item in dataclasses.fields(out):
            if item.name.endswith('_cache'):
                object.__setattr__(out, item.name, {})
    return out


class Worker:
    """The child's state: the models it holds, the frame model's maps, the chain window."""

    def __init__(self) -> None:
        """Create an empty worker."""
        self.models: dict[int, Any] = {}
        self._maps: tuple[int | None, Any, Any] = (None, None, None)
        self._window: deque[list[Any]] = deque()
        self._window_size: tuple[int, int] | None = None     # raw (width, height) pooled

    def handle(self, header: dict[str, Any], frame: np.ndarray) -> dict[str, Any]:
        """
        Check one frame (with the window before it) and return the reply.

        :param header: the request header (module docstring).
        :param frame: the corrected frame.
        :return: the reply.
        """
        start = time.perf_counter()
        self.models.update(header['models'])
        token, current_token = header['frame_model'], header['current_model']
        self.models = {k: v for k, v in self.models.items() if k in (token, current_token)}
        model, current = self.models[token], self.models[current_token]
        if self._maps[0] != token:
            self._maps = (None, None, None)      # free the old maps before the new ones
            self._maps = (token, *build_float_maps(model))
        _, map_x, map_y = self._maps
        size = (int(model.width), int(model.height))
        if size != self._window_size:       # a camera that changed resolution: a new window
            self._window.clear()
            self._window_size = size
        self._window.append(chains_from_corrected(frame, map_x, map_y))
        while len(self._window) > int(header['window']):
            self._window.popleft()
        if (current.width, current.height) != (model.width, model.height):
            self._window.clear()
            return {'result': None, 'frames': 0, 'ms': (time.perf_counter() - start) * 1e3}
        chains = [c for frame_chains in self._window for c in frame_chains]
        result = check_chains(current, chains, float(header['max_rms_px']))
        return {'result': result, 'frames': len(self._window),
                'ms': (time.perf_counter() - start) * 1e3}


def serve(conn: Any) -> int:
    """
    Answer requests on a connection until it closes (the child's loop).

    :param conn: the child's end.
    :return: the exit status (0).
    """
    worker = Worker()
    while True:
        try:
            header = conn.recv()
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return 0
        except Exception as err:    # noqa: B902 - a broken stream: the parent starts anew
            print(f'check worker: bad request: {err!r}', file=sys.stderr)
            return 1
        try:
            frame = np.frombuffer(data, dtype=header['dtype']).reshape(header['shape'])
            reply = worker.handle(header, frame)
        except Exception as err:    # noqa: B902 - one bad check must not end the worker
            reply = {'error': repr(err)}
        del data
        try:
            conn.send(reply)
        except OSError:
            return 0


class CheckWorker(ChildProcess):
    """The parent's client of one check child process (started on the first request)."""

    def __init__(self) -> None:
        """Create the client; no process yet."""
        super().__init__(MODULE, 'check process')
        self._held: dict[int, Any] = {}    # token -> model, as the child holds them
        self._next_token = 0

    def start(self) -> None:
        """Start the child process (a fresh one: no models, no window)."""
        super().start()
        self._held = {}

    def _token(self, model: Any, taken: int = 0) -> int:
        """Return the token of a model the child holds, else a new one (above ``taken``)."""
        for token, held in self._held.items():
            if held is model:
                return token
        self._next_token = max(self._next_token, taken) + 1
        return self._next_token

    def check(self, frame: np.ndarray, model: Any, current: Any, window: int,
              max_rms_px: float, waiting: Callable[[], None] | None = None,
              poll_s: float = 0.25, reply_timeout_s: float = REPLY_TIMEOUT_S,
              send_timeout_s: float = SEND_TIMEOUT_S) -> dict[str, Any]:
        """
        Check a frame in the child; block (the interpreter lock released) until it replies.

        The child is continued (SIGCONT) before the request is sent and after its reply has
        come, whatever ``waiting`` did: it is never left stopped between two checks
        (:meth:`~mechdeconv_ros.runtime.child_process.ChildProcess.request`).

        :param frame: the corrected frame (C-contiguous).
        :param model: the model that corrected it.
        :param current: the model to judge (the node's current one).
        :param window: how many frames' chains to pool.
        :param max_rms_px: ``check.max_rms_px``.
        :param waiting: called every ``poll_s`` seconds after the frame is sent, while the
            reply has not come: the node pauses and continues the child there.
        :param poll_s: seconds between calls of ``waiting``.
        :param reply_timeout_s: seconds of the child running (not paused) without a reply
            after which it is stuck.
        :param send_timeout_s: seconds the request's send may take.
        :return: the reply (module docstring).
        :raises WorkerStuck: if the send or the reply did not come in time (the child is
            still there: stop it).
        :raises WorkerGone: if the child exited or the pipe broke.
        """
        if self.process is None or self.process.poll() is not None:
            raise WorkerGone('the check process is not running')
        frame_token = self._token(model)
        current_token = frame_token if current is model else self._token(current, frame_token)
        tokens = {frame_token: model, current_token: current}
        new = {t: portable(m) for t, m in tokens.items() if t not in self._held}
        frame = np.ascontiguousarray(frame)
        header = {'shape': frame.shape, 'dtype': frame.dtype.str, 'models': new,
                  'frame_model': frame_token, 'current_model': current_token,
                  'window': int(window), 'max_rms_px': float(max_rms_px)}
        self._held = tokens
        try:
            reply = self.request(
                (header, frame.reshape(-1).view(np.uint8)),     # flat: bytes, not rows
                waiting, poll_s, reply_timeout_s, send_timeout_s)
        except WorkerGone:
            self._held = {}     # the child may not have taken them: send them again
            raise
        if 'error' in reply:
            self._held = {}
        return reply


def main(argv: list[str] | None = None) -> int:
    """
    Run the child: nice 19, SCHED_IDLE, SIGINT ignored; serve the socket until it closes.

    :param argv: ``[FD, PARENT_PID]``: the child's end of the socket pair and the pid of the
        process that started it; default ``sys.argv[1:]``.
    :return: the exit status.
    """
    conn = child_connection(argv)     # SIGINT ignored, PR_SET_PDEATHSIG, SCHED_IDLE
    if conn is None:
        return 0        # the parent died already
    cv2.setNumThreads(1)    # one core at most: the node's remap threads need the others
    return serve(conn)


if __name__ == '__main__':
    sys.exit(main())
