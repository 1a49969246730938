# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The straight-edge check in a child process (issue 26): its loop and the parent's client.

Pure Python, numpy and OpenCV, no ROS (docs/design.md section 2.17). One check of one frame is
seconds of Python; in the node's process it held the interpreter lock that the frame path
needs (p99 latency 33 -> 46 ms at 1280x960). Here it runs in a child process
(``python -P -c BOOTSTRAP FD``: :data:`BOOTSTRAP` runs :func:`main` of this module; started by
:class:`CheckWorker` with :class:`subprocess.Popen`, so it imports nothing of ROS and
inherits no ROS state, only the socket), which:

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
import ctypes
import dataclasses
import os
from pathlib import Path
import pickle
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from typing import Any, Callable

import cv2
from mechdeconv_ros.imaging.plumb_check import chains_from_corrected, check_chains
from mechdeconv_ros.imaging.remap import build_float_maps
import numpy as np

#: Linux prctl option: the signal a child gets when its parent (thread) dies.
PR_SET_PDEATHSIG = 1
#: Seconds the parent waits for the child to exit after SIGTERM before SIGKILL: a node
#: stopped by ``ros2 launch`` must be gone before its SIGTERM escalation (5 s after SIGINT
#: by default). A child at SCHED_IDLE on a busy machine may need more to run its exit.
STOP_WAIT_S = 1.0
#: Seconds the parent then waits after SIGKILL (a child still not reaped is reparented and
#: reaped by init when the node exits).
KILL_WAIT_S = 0.5
#: Seconds a request's send may take (a few MB into a running child: milliseconds).
SEND_TIMEOUT_S = 30.0
#: Seconds of running (not paused) after which a child that has not replied is stuck (a
#: check takes 0.5 to 7 s; 20 x that).
REPLY_TIMEOUT_S = 120.0
#: The CPU priority (nice) of the child.
NICE = 19
#: One thread for numpy's BLAS and OpenMP in the child (set before it imports numpy).
THREAD_ENV = {'OMP_NUM_THREADS': '1', 'OPENBLAS_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1'}
#: The child's command: SIGINT ignored before anything else is imported (a node stopped while
#: its child still imports numpy must not leave a KeyboardInterrupt traceback), then main().
BOOTSTRAP = ('import signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); '
             'from mechdeconv_ros.runtime.check_worker import main; sys.exit(main())')


def lower_priority(pid: int) -> None:
    """
    Give a process nice 19 and (Linux) the SCHED_IDLE policy; nothing where not allowed.

    SCHED_IDLE: a core only when no other thread wants it, and a waking one preempts it at
    once.

    :param pid: the process (0: this one).
    """
    try:
        os.setpriority(os.PRIO_PROCESS, pid, NICE)
    except (AttributeError, OSError):
        pass
    try:
        os.sched_setscheduler(pid, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        pass


class WorkerGone(RuntimeError):
    """The check's child process exited or its pipe broke."""


class WorkerStuck(WorkerGone):
    """The check's child process did not take a request or did not answer in time."""


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


class CheckWorker:
    """The parent's client of one check child process (started on the first request)."""

    def __init__(self) -> None:
        """Create the client; no process yet."""
        self.process: subprocess.Popen | None = None
        #: Whether the child is stopped by :meth:`pause` (SIGSTOP) and not yet resumed.
        self.paused = False
        # Issue 36: the child is stopped while the gate pauses it OR a frame is in flight
        # (:meth:`hold`, from the frame path); one lock orders the callers' signals.
        self._frame_hold = False
        self._stopped = False
        self._signal_lock = threading.Lock()
        self._conn: Any = None
        self._sock: socket.socket | None = None    # the same socket, for non-blocking sends
        self._held: dict[int, Any] = {}    # token -> model, as the child holds them
        self._next_token = 0

    def start(self) -> None:
        """Start the child process (a fresh one: no models, no window)."""
        from multiprocessing.connection import Connection
        parent, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        # The directory holding THIS mechdeconv_ros goes first on the child's path, and -P
        # keeps the current directory off it: a `mechdeconv_ros/` there must not shadow it.
        package_root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ)
        env['PYTHONPATH'] = os.pathsep.join(
            p for p in (package_root, *env.get('PYTHONPATH', '').split(os.pathsep)) if p)
        env.update(THREAD_ENV)
        try:
            # Its own session (and process group): SIGINT to the node's group (Ctrl-C, a
            # test, launch) must not reach it, not even while its interpreter still imports
            # `site`, before BOOTSTRAP can ignore SIGINT (a "Fatal Python error" traceback in
            # the node's log). The parent stops it; its socket's EOF ends it if the parent dies.
            self.process = subprocess.Popen(
                [sys.executable, '-P', '-c', BOOTSTRAP, str(child.fileno()), str(os.getpid())],
                pass_fds=(child.fileno(),), env=env, stdin=subprocess.DEVNULL,
                start_new_session=True)
        finally:
            child.close()
        # At once, from here: its imports (about a second of CPU) must not run at the node's
        # priority either (issue 36); main() sets it again.
        lower_priority(self.process.pid)
        self._sock = parent
        self._conn = Connection(os.dup(parent.fileno()))
        self._held = {}
        self.paused = self._frame_hold = self._stopped = False

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
        come, whatever ``waiting`` did: it is never left stopped between two checks.

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
        try:
            self.resume()
            deadline = time.monotonic() + send_timeout_s
            self._send(pickle.dumps(header, pickle.HIGHEST_PROTOCOL), deadline)
            self._send(frame.reshape(-1).view(np.uint8), deadline)     # flat: bytes, not rows
            self._held = tokens
            self._wait_for_reply(waiting, poll_s, reply_timeout_s)
            reply = self._conn.recv()
        except WorkerStuck:
            self._held = {}
            raise
        except (EOFError, OSError) as err:
            raise WorkerGone(f'the check process stopped ({err!r})') from err
        finally:
            if self.process is not None:
                self.resume()       # a pause that came after the reply must not stay
        if 'error' in reply:
            self._held = {}     # the child may not have taken them: send them again
        return reply

    def _send(self, data: Any, deadline: float) -> None:
        """
        Send one message framed as Connection frames it, without blocking past ``deadline``.

        :param data: bytes or a byte buffer.
        :param deadline: ``time.monotonic()`` by which it must be sent.
        :raises WorkerStuck: when the child does not take it in time.
        """
        view = memoryview(data).cast('B')
        size = len(view)
        head = struct.pack('!i', size) if size <= 0x7fffffff else struct.pack('!iQ', -1, size)
        for part in (memoryview(head), view):
            while len(part):
                try:
                    part = part[self._sock.send(part, socket.MSG_DONTWAIT):]
                except BlockingIOError:
                    left = deadline - time.monotonic()
                    if left <= 0.0 or not select.select([], [self._sock], [], left)[1]:
                        raise WorkerStuck('the check process took no request in time'
                                          ) from None

    def _wait_for_reply(self, waiting: Callable[[], None] | None, poll_s: float,
                        timeout_s: float) -> None:
        """Poll for the reply, calling ``waiting``; raise WorkerStuck after ``timeout_s``."""
        running_s, last = 0.0, time.monotonic()
        while not self._conn.poll(poll_s):
            now = time.monotonic()
            if not self._stopped:       # time stopped (gate, frames) is not the child's fault
                running_s += now - last
            last = now
            if running_s > timeout_s:
                raise WorkerStuck(f'the check process did not answer in {timeout_s:.0f} s '
                                  'of running')
            if waiting is not None:
                waiting()

    def resume(self) -> None:
        """
        Continue the child (SIGCONT), whatever :attr:`paused` says; nothing if it is gone.

        A frame's hold (:meth:`hold`) is not lifted: its end sends nothing (the child runs).
        """
        with self._signal_lock:
            process = self.process
            if process is not None:
                try:
                    process.send_signal(signal.SIGCONT)
                except OSError:
                    pass
            self.paused = self._stopped = False

    def pause(self, paused: bool) -> None:
        """
        Stop (SIGSTOP) or continue (SIGCONT) the child; nothing if it is already so or gone.

        A stopped child holds its memory and its place in a check; it uses no CPU, no memory
        bandwidth, no cache (what its priority alone could not give the frame path). It stays
        stopped while :meth:`hold` holds it.

        :param paused: True to stop it, False to continue it.
        """
        with self._signal_lock:
            if self.process is None or paused == self.paused:
                return
            self.paused = paused
            self._signal()

    def hold(self, held: bool) -> None:
        """
        Stop the child while a frame is in flight (True), let it run again after (False).

        Called by the node's frame path (issue 36): a signal per change, about 5 us; the
        child's state is ``paused or held``. The frame path always releases what it held, so
        a held child never waits longer than one frame.

        :param held: True at a frame's start, False at its end.
        """
        with self._signal_lock:
            if self.process is None or held == self._frame_hold:
                return
            self._frame_hold = held
            self._signal()

    def _signal(self) -> None:
        """Send SIGSTOP / SIGCONT when ``paused or held`` differs from the child's state."""
        stop = self.paused or self._frame_hold
        process = self.process
        if process is None or stop == self._stopped:
            return
        try:
            process.send_signal(signal.SIGSTOP if stop else signal.SIGCONT)
        except OSError:     # it ended meanwhile: its reply (EOF) tells the thread
            return
        self._stopped = stop

    def stop(self) -> None:
        """
        Stop the child (SIGTERM, then SIGKILL after STOP_WAIT_S); at most 1.5 s.

        The pipe stays open until :meth:`close` (the caller's thread may still read it).
        """
        with self._signal_lock:     # no frame's hold can stop it again after this
            process, self.process = self.process, None
            if process is not None:
                try:    # not needed for SIGTERM (fatal: it wakes a stopped one); tidy
                    process.send_signal(signal.SIGCONT)
                except OSError:
                    pass
            self.paused = self._frame_hold = self._stopped = False
        if process is not None and process.poll() is None:
            try:    # SCHED_IDLE on a busy machine may not run its exit for seconds
                os.sched_setscheduler(process.pid, os.SCHED_OTHER, os.sched_param(0))
            except (AttributeError, OSError):   # not Linux, or RLIMIT_NICE forbids it
                pass
            process.terminate()
            try:
                process.wait(STOP_WAIT_S)
            except subprocess.TimeoutExpired:
                process.kill()
                try:
                    process.wait(KILL_WAIT_S)
                except subprocess.TimeoutExpired:   # not yet scheduled to die: not our wait
                    pass

    def close(self) -> None:
        """Close the parent's end of the pipe (after :meth:`stop` and the caller's join)."""
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def main(argv: list[str] | None = None) -> int:
    """
    Run the child: nice 19, SCHED_IDLE, SIGINT ignored; serve the socket until it closes.

    :param argv: ``[FD, PARENT_PID]``: the child's end of the socket pair and the pid of the
        process that started it; default ``sys.argv[1:]``.
    :return: the exit status.
    """
    from multiprocessing.connection import Connection
    args = sys.argv[1:] if argv is None else argv
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # A paused child (SIGSTOP, the node's CPU gate) cannot see its socket close: if the node
    # dies then, Linux kills it (PR_SET_PDEATHSIG, SIGKILL: it acts on a stopped process). It
    # fires when the parent's THREAD that started it ends: the node's check thread, which
    # lives as long as the node.
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        pass
    if len(args) > 1 and os.getppid() != int(args[1]):
        return 0        # the parent died before the request above

    lower_priority(0)
    cv2.setNumThreads(1)    # one core at most: the node's remap threads need the others
    return serve(Connection(int(args[0])))


if __name__ == '__main__':
    sys.exit(main())
