# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The node's live self-check: a coordinator thread here, the work in a child process (issue 26).

At most ``check.rate_hz`` times a second, counted from the end of the last check (0 = off),
and only while the machine's CPU load (its busy fraction over the last second, niced work
such as the check's own not counted: :mod:`~mechdeconv_ros.runtime.check_gate`) is at most
``check.max_load``, the frame callback hands over a COPY of a corrected frame with the model
that made it (:meth:`CheckThread.offer`: a dict swap and one ``np.copy``). A check in progress
when the load rises above ``check.max_load`` is paused (SIGSTOP to its process) until the load
is below 0.8 of it: an idle-priority process still shares the memory bus and the cache (in
two runs a node paced at its serial bound delivered 4-5 % fewer frames with the check on).
Every 2 s of running the check is stopped for one load period, so that the load is also read
without it (a node the check slows uses less CPU: the gate's probes).
``check_deferred``, ``check_pauses`` and ``check_cpu_load`` in ``/diagnostics`` show what the
gate did.

Issue 36, the frame path does not pay for the check: while a check is in progress, the
node's frame callback (wrapped by :meth:`CheckThread.holding`) stops the child for the
frame's time and lets it run after (``check.pause_during_frames``; one state with the gate's
pause in :class:`~mechdeconv_ros.runtime.check_worker.CheckWorker`); and once
:data:`STABLE_REPEATS` checks in a row of the model in use gave the same verdict, the next
waits ``check.stable_period_s`` instead of ``1 / check.rate_hz`` (a new model is checked at
the rate again). docs/design.md section 2.17, "What runs when".

The thread (nice 19 on Linux) sends the frame to the check's child process
(:mod:`~mechdeconv_ros.runtime.check_worker`: nice 19, no ROS in it; started with the
thread when ``check.rate_hz`` > 0, else at the first check) and waits for the reply with the
interpreter lock released: the seconds of Python of a check no longer share the frame path's
lock (a model is pickled, about 1 ms, only when it changes). The child detects
the edge chains of that frame, carries them to raw pixels through the same model's float
maps (so the raw points do not depend on any later model), keeps the chains of the last
``check.window`` frames, and runs :func:`~mechdeconv_ros.imaging.plumb_check.check_chains`
with the node's current model. The result goes to ``/diagnostics`` under the keys of
:meth:`~mechdeconv_ros.imaging.plumb_check.CheckResult.as_dict` (``estimate.<name>.value``
and ``.sigma``), with ``check_ms_last`` (the thread's time: send, check, reply),
``check_frames`` (in the window), ``checks`` (done since start) and ``check_applied`` (sets
made). A child that dies is logged and restarted (a fresh window) at most
``MAX_RESTARTS`` times; after that the check stays off; the node never stops for it. On
stop, and within ``WAIT_S`` of ``check.rate_hz`` set to 0, the child is terminated (SIGTERM,
SIGKILL after 2 s) and waited for; a later rate above 0 starts a new one.

``check.apply``: when the verdict is ``description_off`` and a parameter's sigma is within
its tolerance, the thread sets the estimated parameters on the node in ONE
``set_parameters_atomically`` call (the node's own parameter API: its validation, its atomic
rebuild, visible in ``ros2 param get``), logged; never farther than ``BOUND_SIGMAS``
tolerances from the values the node started with. The rebuild swaps the whole model at
once, so no frame mixes two models.
"""

from __future__ import annotations

import os
import threading
import time
from typing import Any, Callable

from mechdeconv_ros.imaging.plumb_check import CheckResult, ESTIMATED, to_apply
from mechdeconv_ros.runtime.check_gate import LoadGate
from mechdeconv_ros.runtime.check_worker import CheckWorker, WorkerGone
import numpy as np
from rclpy.parameter import Parameter

#: Seconds the thread waits for a frame before it looks at its stop flag again.
WAIT_S = 0.5
#: Seconds between two looks at the machine's load while a check runs (pause / continue).
LOAD_POLL_S = 0.05
#: Checks in a row of one model with one verdict after which the next waits
#: ``check.stable_period_s`` (issue 36's duty cycle).
STABLE_REPEATS = 2
#: Restarts of a check process that died before the check stays off.
MAX_RESTARTS = 3
#: Seconds the thread waits, after its check process ended, for the node's stop (a stop in
#: progress ends the child first) before it counts a death.
STOP_GRACE_S = 1.0


def diagnostics_entries(result: CheckResult) -> dict[str, Any]:
    """
    Return a check result as flat /diagnostics entries (the issue's key names).

    :param result: the check.
    :return: key -> value; the estimate as ``estimate.<parameter>.value`` / ``.sigma``.
    """
    out = {key: value for key, value in result.as_dict().items() if key != 'estimate'}
    for name, est in result.estimate.items():
        out[f'estimate.{name}.value'] = est['value']
        out[f'estimate.{name}.sigma'] = est['sigma']
    return out


class CheckThread:
    """The low-priority straight-edge check of a node."""

    def __init__(self, node: Any, value: Callable[[str], Any], current_model: Callable[[], Any],
                 publish: Callable[[dict[str, Any]], None], counters: dict[str, Any]):
        """
        Create the thread (not started).

        :param node: the rclpy node (its logger and ``set_parameters_atomically``).
        :param value: the node's current parameter value by name.
        :param current_model: returns the node's active model (None before the first frame).
        :param publish: receives the /diagnostics entries after each check.
        :param counters: /diagnostics entries updated here (``check_deferred`` by the frame
            path, ``check_pauses`` and ``check_cpu_load`` by this thread); the keys are set
            now, so the diagnostics timer never sees the dict change size.
        """
        self._node, self._value, self._current_model = node, value, current_model
        self._publish = publish
        self._counters = counters
        counters.update(check_deferred=0, check_pauses=0, check_cpu_load=0.0)
        # The machine's load: read and written by this thread, read by the frame path
        # (offer: one float, no lock needed).
        self._gate = LoadGate()
        self._lock = threading.Lock()
        self._pending: tuple[np.ndarray, Any] | None = None
        self._wake = threading.Event()
        self._stop = False
        self._last_offer = -1e9
        self._busy = False
        self._worker = CheckWorker()
        self._worker_lock = threading.Lock()    # start (thread) vs stop (node) of the child
        self._stopping = threading.Event()
        self.restarts = 0
        self._reference = {name: float(value(name)) for name, _ in ESTIMATED}
        self.checks = 0
        # The duty cycle (issue 36): the model last judged, its verdict, how many checks in a
        # row gave it (STABLE_REPEATS of them: the next waits check.stable_period_s).
        self._stable: tuple[Any, str | None, int] = (None, None, 0)
        self.applied = 0
        self._thread = threading.Thread(target=self._run, name='check', daemon=True)

    def start(self) -> None:
        """Start the thread."""
        self._thread.start()

    def stop(self) -> None:
        """Stop the child process (bounded: SIGTERM, then SIGKILL) and the thread."""
        self._stopping.set()
        with self._worker_lock:
            self._stop = True
            self._wake.set()
            self._worker.stop()     # the thread's recv() sees the pipe close
        if self._thread.is_alive():
            self._thread.join(timeout=10.0)
        self._worker.close()

    @property
    def worker_pid(self) -> int | None:
        """Return the check process's pid (None before the first check or after stop)."""
        process = self._worker.process
        return None if process is None else process.pid

    def offer(self, corrected: np.ndarray, model: Any) -> None:
        """
        Hand over a corrected frame, if the rate, the load and the thread allow (frame path).

        Every frame of a static model comes here (executor thread). Above ``check.max_load``
        (the machine's load, :mod:`~mechdeconv_ros.runtime.check_gate`, read by this
        object's thread) no check starts: the next chance is a period later. A check in
        progress is paused by the thread (:meth:`_pause_for_load`).

        :param corrected: the corrected frame (copied here when taken).
        :param model: the model that corrected it.
        """
        rate = float(self._value('check.rate_hz'))
        now = time.monotonic()
        if rate <= 0.0 or self._busy or now - self._last_offer < self._period(rate, model):
            return
        self._last_offer = now
        if not self._gate.may_start(float(self._value('check.max_load'))):
            self._counters['check_deferred'] = self._gate.deferred
            return
        with self._lock:
            self._pending = (np.copy(corrected), model)
            self._busy = True
        self._wake.set()

    def _period(self, rate: float, model: Any) -> float:
        """
        Return the seconds from the end of the last check to the next (the duty cycle).

        ``1 / check.rate_hz``; once :data:`STABLE_REPEATS` checks in a row of the model that
        corrects the frames gave the same verdict, ``check.stable_period_s`` (if longer; 0:
        never): a new model (a parameter set, another frame size) is checked at the rate again.
        """
        judged, _, repeats = self._stable
        stable_s = float(self._value('check.stable_period_s'))
        if model is judged and repeats >= STABLE_REPEATS and stable_s > 0.0:
            return max(1.0 / rate, stable_s)
        return 1.0 / rate

    def _record(self, current: Any, result: Any) -> None:
        """Count the checks in a row of one model with one verdict (:meth:`_period`)."""
        judged, verdict, repeats = self._stable
        same = judged is current and verdict == result.verdict
        self._stable = (current, result.verdict, repeats + 1 if same else 1)

    def holding(self, callback: Callable[..., None]) -> Callable[..., None]:
        """
        Return the frame callback wrapped in :meth:`frame_started` / :meth:`frame_ended`.

        :param callback: the node's frame callback.
        :return: the same callback, the check's process stopped while it runs.
        """
        def held(*args: Any) -> None:
            self.frame_started()
            try:
                callback(*args)
            finally:
                self.frame_ended()
        return held

    def frame_started(self) -> None:
        """
        Stop the check's process: a frame enters the frame path (issue 36).

        Only while a check is in progress and ``check.pause_during_frames`` is true; a
        signal (about 5 us) at most. :meth:`frame_ended` must follow (try / finally).
        """
        if self._busy and bool(self._value('check.pause_during_frames')):
            self._worker.hold(True)

    def frame_ended(self) -> None:
        """Let the check's process run again: the frame is out (published or dropped)."""
        self._worker.hold(False)

    def _sample_load(self, now: float) -> None:
        """Read the machine's load if its period has passed (this thread only)."""
        self._counters['check_cpu_load'] = self._gate.sample(now)

    def _pause_for_load(self) -> None:
        """
        Pause or continue the check's process from the machine's load (this thread).

        Called every :data:`LOAD_POLL_S` while a check's reply has not come (never while a
        frame is being sent: a stopped process would stop the send). Never waits for the stop
        lock: a stop in progress continues the process itself.
        """
        now = time.monotonic()
        self._sample_load(now)
        worker = self._worker
        paused = self._gate.should_pause(float(self._value('check.max_load')), worker.paused,
                                         now)
        self._counters['check_pauses'] = self._gate.busy_pauses
        if paused == worker.paused or not self._worker_lock.acquire(blocking=False):
            return
        try:
            if not self._stop:
                worker.pause(paused)
        finally:
            self._worker_lock.release()

    def _run(self) -> None:
        try:        # the lowest CPU priority for this thread only (Linux: a thread id)
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
        except (AttributeError, OSError):
            pass
        if float(self._value('check.rate_hz')) > 0.0:
            self._start_worker()     # now, not at the first check: its imports take a second
        while not self._stop:
            woke = self._wake.wait(WAIT_S)
            # Every WAIT_S at least: the gate's load stays fresh.
            self._sample_load(time.monotonic())
            if not woke:
                self._stop_worker_if_off()
                continue
            self._wake.clear()
            with self._lock:
                pending, self._pending = self._pending, None
            if pending is None:
                continue
            try:
                self._check(*pending)
            except Exception as err:    # noqa: B902 - the check must never stop the node
                self._node.get_logger().error(f'check failed: {err!r}',
                                              throttle_duration_sec=60.0)
            finally:
                # The period runs from the end of a check: the thread idles at least
                # 1 / check.rate_hz between checks, however long one takes.
                self._gate.check_ended()
                self._last_offer = time.monotonic()
                self._busy = False

    def _stop_worker_if_off(self) -> None:
        """Stop the child when ``check.rate_hz`` was set to 0 (its memory back; the window too)."""
        if float(self._value('check.rate_hz')) > 0.0:
            return
        with self._worker_lock:
            if self._stop or self._worker.process is None:
                return
            self._worker.stop()     # continues a paused one first
            self._worker.close()
            self._stable = (None, None, 0)      # a fresh window: checked at the rate again
        self._node.get_logger().info('check: off (check.rate_hz 0): its process stopped')

    def _start_worker(self) -> bool:
        """Start the child process if it is not running; False if stopping or given up."""
        with self._worker_lock:
            if self._stop or self.restarts > MAX_RESTARTS:
                return False
            if self._worker.process is None:
                self._worker.start()
            return True

    def _in_worker(self, frame: np.ndarray, model: Any, current: Any) -> dict[str, Any] | None:
        """Check in the child process; None if it died (restarted next time) or stopping."""
        if not self._start_worker():
            return None
        try:
            return self._worker.check(frame, model, current, int(self._value('check.window')),
                                      float(self._value('check.max_rms_px')),
                                      waiting=self._pause_for_load, poll_s=LOAD_POLL_S)
        except WorkerGone as err:
            # A child ended during the node's stop (or by a signal to its session) is not
            # a death to log.
            if self._stopping.wait(STOP_GRACE_S):
                return None
            with self._worker_lock:
                if self._stop:
                    return None
                self._worker.stop()
                self._worker.close()
                self.restarts += 1
                self._stable = (None, None, 0)      # a fresh window: checked at the rate again
            logger = self._node.get_logger()
            if self.restarts > MAX_RESTARTS:
                logger.error(f'check: {err}; the check stays off (restarted {MAX_RESTARTS} '
                             'times)')
            else:
                logger.error(f'check: {err}; restarting it ({self.restarts} of '
                             f'{MAX_RESTARTS})')
                self._start_worker()    # now: its imports overlap the wait for the next check
            return None

    def _check(self, frame: np.ndarray, model: Any) -> None:
        start = time.perf_counter()
        current = self._current_model() or model
        reply = self._in_worker(frame, model, current)
        if reply is None:
            return
        if 'error' in reply:
            raise RuntimeError(reply['error'])
        result = reply['result']
        if result is None:      # the frame's size is not the current model's: a new window
            return
        self.checks += 1
        self._record(current, result)
        entries = diagnostics_entries(result)
        entries['check_frames'] = reply['frames']
        entries['checks'] = self.checks
        entries['check_ms_last'] = (time.perf_counter() - start) * 1e3
        entries['check_applied'] = self.applied
        self._publish(entries)
        if result.verdict == 'description_off':
            self._node.get_logger().warning(
                f'check: description_off (straightness {result.straightness_rms_px:.3f} px '
                f'rms over {result.edges} edges; after the estimate '
                f'{result.straightness_rms_px_after or float("nan"):.3f} px)',
                throttle_duration_sec=60.0)
        if bool(self._value('check.apply')):
            self._apply(result)

    def _apply(self, result: CheckResult) -> None:
        values = {name: self._value(name) for name, _ in ESTIMATED}
        changes = to_apply(result, values, self._reference)
        if not changes:
            return
        outcome = self._node.set_parameters_atomically(
            [Parameter(name, Parameter.Type.DOUBLE, value) for name, value in changes.items()])
        if outcome.successful:
            self.applied += 1
            # The chains stay (raw points); the next check judges the new description.
            self._node.get_logger().info(
                'check.apply: set ' + ', '.join(f'{n} = {v:.6g}' for n, v in changes.items()))
        else:
            self._node.get_logger().warning(f'check.apply refused: {outcome.reason}')
