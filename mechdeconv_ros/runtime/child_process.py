# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A check's child process and the parent's end of it: the plumbing both checks share.

No ROS, no numpy, no OpenCV. The straight-edge check (:mod:`~mechdeconv_ros.runtime.check_worker`)
and the stereo check (:mod:`~mechdeconv_ros.runtime.stereo_check_worker`) each run in a child
process so that seconds of Python do not hold the interpreter lock the node's frame path needs.
:class:`ChildProcess` is the parent's end; :func:`child_connection` the child's start. The
child (``python -P -c BOOTSTRAP FD PARENT_PID``, its module named in ``BOOTSTRAP``, so a
process list shows which check it is):

* imports the package the parent runs, never one in its current directory: ``-P`` keeps the
  current directory off ``sys.path`` (``python -c`` puts it first) and ``PYTHONPATH`` starts
  with the directory that holds the parent's ``mechdeconv_ros`` (issue 36 (i));
* runs at nice 19 and, on Linux, the SCHED_IDLE policy, set by the parent as soon as it
  exists (:func:`lower_priority`: its imports are a second of CPU) and again by itself;
  numpy's BLAS and OpenMP on one thread (:data:`THREAD_ENV`);
* runs in a session of its own and ignores SIGINT (a node is stopped by SIGINT to its process
  group and must exit 0; its parent stops the child);
* exits when its end of the socket pair closes (the parent stopped, or died, even by
  SIGKILL); while stopped (SIGSTOP) it cannot read, so it also asks Linux to SIGKILL it when
  its parent dies (PR_SET_PDEATHSIG).

The parent stops the child (SIGSTOP) while ``paused or held`` (:meth:`ChildProcess.pause`:
the node's CPU gate; :meth:`ChildProcess.hold`: a frame in flight), under one lock. One
request and one reply at a time (:meth:`ChildProcess.request`), each message framed as
:class:`multiprocessing.connection.Connection` frames it (a 4-byte big-endian length, then
the bytes). A child that does not answer is never waited for silently (issue 36 (a)): it is
continued (SIGCONT) before every send and after every reply, so a pause that lands after its
reply cannot leave it stopped; a send that cannot finish within :data:`SEND_TIMEOUT_S`, or a
reply that has not come after :data:`REPLY_TIMEOUT_S` of the child running (time stopped not
counted), raises :class:`WorkerStuck`; the caller restarts the child and says so.
:meth:`ChildProcess.stop` takes at most :data:`STOP_WAIT_S` + :data:`KILL_WAIT_S`.
"""

from __future__ import annotations

import ctypes
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
from typing import Any, Callable, Iterable

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
#: Seconds of running (not stopped) after which a child that has not replied is stuck (a
#: check takes 0.5 to 7 s; 20 x that).
REPLY_TIMEOUT_S = 120.0
#: The CPU priority (nice) of the child.
NICE = 19
#: One thread for numpy's BLAS and OpenMP in the child (set before it imports numpy).
THREAD_ENV = {'OMP_NUM_THREADS': '1', 'OPENBLAS_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1'}


def bootstrap(module: str) -> str:
    """
    Return the child's ``-c`` program: SIGINT ignored first, then ``module.main()``.

    SIGINT is ignored before anything else is imported: a node stopped while its child still
    imports numpy must not leave a KeyboardInterrupt traceback.

    :param module: the dotted name of a module with ``main() -> int``.
    :return: the program.
    """
    return ('import signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); '
            f'from {module} import main; sys.exit(main())')


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
    """A check's child process exited or its pipe broke."""


class WorkerStuck(WorkerGone):
    """A check's child process did not take a request or did not answer in time."""


def child_connection(argv: list[str] | None = None) -> Any:
    """
    Start the child's side: SIGINT ignored, PR_SET_PDEATHSIG, nice 19, SCHED_IDLE.

    :param argv: ``[FD, PARENT_PID]``: the child's end of the socket pair and the pid of the
        process that started it; default ``sys.argv[1:]``.
    :return: the child's :class:`~multiprocessing.connection.Connection`, or None when the
        parent died already (the child should exit 0).
    """
    from multiprocessing.connection import Connection
    args = sys.argv[1:] if argv is None else argv
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # A stopped child (SIGSTOP) cannot see its socket close: if the node dies then, Linux
    # kills it (PR_SET_PDEATHSIG, SIGKILL: it acts on a stopped process). It fires when the
    # parent's THREAD that started it ends: the node's check thread, which lives as long as
    # the node.
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        pass
    if len(args) > 1 and os.getppid() != int(args[1]):
        return None        # the parent died before the request above
    lower_priority(0)
    return Connection(int(args[0]))


class ChildProcess:
    """The parent's end of one child process (started by :meth:`start`)."""

    def __init__(self, module: str, name: str = 'child process') -> None:
        """
        Create the client; no process yet.

        :param module: the dotted name of the child's module (its ``main()`` serves).
        :param name: what messages call it (``'the <name> ...'``).
        """
        self.module = module
        self.name = name
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

    def start(self) -> None:
        """Start a fresh child process (the pipe of an earlier one is closed)."""
        from multiprocessing.connection import Connection
        self.close()
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
            # `site`, before the bootstrap can ignore SIGINT. The parent stops it; its
            # socket's EOF ends it if the parent dies.
            self.process = subprocess.Popen(
                [sys.executable, '-P', '-c', bootstrap(self.module), str(child.fileno()),
                 str(os.getpid())],
                pass_fds=(child.fileno(),), env=env, stdin=subprocess.DEVNULL,
                start_new_session=True)
        finally:
            child.close()
        # At once, from here: its imports (about a second of CPU) must not run at the node's
        # priority either (issue 36); the child sets it again.
        lower_priority(self.process.pid)
        self._sock = parent
        self._conn = Connection(os.dup(parent.fileno()))
        self.paused = self._frame_hold = self._stopped = False

    def request(self, messages: Iterable[Any], waiting: Callable[[], None] | None = None,
                poll_s: float = 0.25, reply_timeout_s: float = REPLY_TIMEOUT_S,
                send_timeout_s: float = SEND_TIMEOUT_S) -> Any:
        """
        Send one request's messages and block (interpreter lock released) for the reply.

        The child is continued (SIGCONT) before the request is sent and after its reply has
        come, whatever ``waiting`` did: it is never left stopped between two requests.

        :param messages: byte buffers (sent as they are) or objects (pickled), in order.
        :param waiting: called every ``poll_s`` seconds after the request is sent, while the
            reply has not come (the node pauses and continues the child there).
        :param poll_s: seconds between calls of ``waiting``.
        :param reply_timeout_s: seconds of the child running (not stopped) without a reply
            after which it is stuck.
        :param send_timeout_s: seconds the request's send may take.
        :return: the unpickled reply.
        :raises WorkerStuck: if the send or the reply did not come in time (the child is
            still there: stop it).
        :raises WorkerGone: if the child exited or the pipe broke.
        """
        if self.process is None or self.process.poll() is not None:
            raise WorkerGone(f'the {self.name} is not running')
        try:
            self.resume()
            deadline = time.monotonic() + send_timeout_s
            for message in messages:
                self.send(message, deadline)
            self.wait_for_reply(waiting, poll_s, reply_timeout_s)
            return self._conn.recv()
        except WorkerStuck:
            raise
        except (EOFError, OSError) as err:
            raise WorkerGone(f'the {self.name} stopped ({err!r})') from err
        finally:
            if self.process is not None:
                self.resume()       # a pause that came after the reply must not stay

    def send(self, message: Any, deadline: float) -> None:
        """
        Send one object (pickled) or byte buffer (as it is) without blocking past ``deadline``.

        :param message: bytes, a buffer (e.g. a numpy array's flat uint8 view) or an object.
        :param deadline: ``time.monotonic()`` by which it must be sent.
        :raises WorkerStuck: when the child does not take it in time.
        """
        if not isinstance(message, (bytes, bytearray, memoryview)) and not hasattr(
                message, '__array_interface__'):
            message = pickle.dumps(message, pickle.HIGHEST_PROTOCOL)
        self._send(message, deadline)

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
                        raise WorkerStuck(f'the {self.name} took no request in time'
                                          ) from None

    def wait_for_reply(self, waiting: Callable[[], None] | None, poll_s: float,
                       timeout_s: float) -> None:
        """
        Poll for the reply, calling ``waiting``, counting only the child's running time.

        :param waiting: called every ``poll_s`` seconds while no reply has come, or None.
        :param poll_s: seconds between polls.
        :param timeout_s: seconds of running without a reply after which it is stuck.
        :raises WorkerStuck: after ``timeout_s`` of running without a reply.
        """
        running_s, last = 0.0, time.monotonic()
        while not self._conn.poll(poll_s):
            now = time.monotonic()
            if not self._stopped:       # time stopped (gate, frames) is not the child's fault
                running_s += now - last
            last = now
            if running_s > timeout_s:
                raise WorkerStuck(f'the {self.name} did not answer in {timeout_s:.0f} s '
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

        A stopped child holds its memory and its place in a request; it uses no CPU, no
        memory bandwidth, no cache (what its priority alone could not give the frame path).
        It stays stopped while :meth:`hold` holds it. Safe from any thread.

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
        except OSError:     # it ended meanwhile: its reply (EOF) tells the caller
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
