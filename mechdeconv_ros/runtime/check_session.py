# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The node's live self-check without ROS: its thread, its child, its /diagnostics, its apply.

A :class:`CheckSession` is what ``node/check_thread.py`` wires to a node (issue 26; moved
here and hardened by issue 36 so that it is tested without ROS in milliseconds). It is given
the node's parameter values (``value(name)``), the record frames use now (``current()``: an
:class:`~mechdeconv_ros.runtime.live_model.ActiveModel`, or None before the first frame),
a log function, and two hooks: ``request_apply()`` (ask the thread that owns parameter sets,
the node's executor, to call :meth:`CheckSession.take_apply`) and ``checkable()`` (None, or
why the node's lens cannot be checked).

When a frame is checked. At most ``check.rate_hz`` times a second, counted from the end of
the last check (0 = off), the frame callback hands over a COPY of a corrected frame with the
model that made it (:meth:`CheckSession.offer`: one ``np.copy``), only while no check is
running and the CPU gate (:mod:`~mechdeconv_ros.runtime.check_gate`) lets it start. The
session's thread (nice 19) sends it to the child (:mod:`~mechdeconv_ros.runtime.check_worker`)
and waits with the interpreter lock released, pausing and continuing the child from the
gate's load while it waits.

The child. Started with the thread when ``check.rate_hz`` > 0 and the lens can be checked
(else at the first check): never for a lens the check cannot judge (:func:`not_checkable`: a
zoom or focus whose groups move, a tilted or decentred port), which saves its 140 to 190 MiB.
A child that dies, or is stuck (:class:`~mechdeconv_ros.runtime.check_worker.WorkerStuck`:
it took no request or gave no reply in time), is stopped, logged and restarted with a fresh
window at most :data:`MAX_RESTARTS` times; then the check gives up until ``check.rate_hz``
is set to 0 and back. ``check.rate_hz`` 0 or a lens that cannot be checked stops the child
within :data:`WAIT_S`.

/diagnostics (:meth:`CheckSession.entries`, read by the diagnostics timer): ``check_state``
always says what the check is doing (``on``, ``off (check.rate_hz 0)``, ``not checked: ...``,
``restarting: ...``, ``gave up: ...``), ``checks`` and ``check_applied`` count; the last result
(the keys of :func:`diagnostics_entries`, ``check_frames``, ``check_ms_last``) comes with its
age ``check_age_s`` (s, at the time of the message) and the model it judged
(``check_model_revision``, ``check_values_generation``: compare with ``model_revision``), and
goes away when the check is off, gave up or cannot check the lens (its WARN with it).

``check.apply``. With the verdict ``description_off``, the parameters whose sigma is within
their tolerance (:func:`~mechdeconv_ros.imaging.plumb_check.to_apply`) are set, bounded by
``BOUND_SIGMAS`` tolerances about the reference: the start-up values, moved by every set that
is not the check's own (:meth:`CheckSession.user_set`: a user's set wins and moves the
bounds). The session never sets a parameter itself: it keeps the changes with the values
generation of the model it judged and calls ``request_apply``; the executor calls
:meth:`CheckSession.take_apply` with the current generation and makes the set through the
node's own parameter path (validation, commit, the atomic swap), serialised with the user's
sets. A set made since the model judged (a newer generation) drops the apply: the next check
judges the new values. :meth:`CheckSession.applied` counts and logs the outcome.

Stop (:meth:`CheckSession.stop`): bounded, for ``ros2 launch`` (SIGTERM 5 s after SIGINT):
the child is ended (SIGTERM, SIGKILL after ``STOP_WAIT_S``; its pipe's EOF or a broken send
wakes the thread), the thread joined for at most :data:`JOIN_S`; nothing waits without bound.
"""

from __future__ import annotations

import math
import os
import threading
import time
from typing import Any, Callable, Mapping

from mechdeconv_ros.imaging.plumb_check import CheckResult, ESTIMATED, to_apply
from mechdeconv_ros.model.underwater import is_exact_3d
from mechdeconv_ros.runtime.check_gate import LoadGate
from mechdeconv_ros.runtime.check_worker import (
    CheckWorker, REPLY_TIMEOUT_S, SEND_TIMEOUT_S, WorkerGone, WorkerStuck)
from mechdeconv_ros.schema.params import MECHANISMS
import numpy as np

#: Seconds the thread waits for a frame before it looks at its stop flag, the rate and
#: whether the lens can be checked again.
WAIT_S = 0.5
#: Seconds between two looks at the machine's load while a check runs (pause / continue).
LOAD_POLL_S = 0.05
#: Checks in a row of one model with one verdict after which the next waits
#: ``check.stable_period_s`` (issue 36's duty cycle).
STABLE_REPEATS = 2
#: Restarts of a check process that died or got stuck before the check gives up.
MAX_RESTARTS = 3
#: Seconds the thread waits, after its check process ended, for the node's stop (a stop in
#: progress ends the child first) before it counts a death.
STOP_GRACE_S = 1.0
#: Longest join of the thread on stop, s (the child is already ended then).
JOIN_S = 1.0
#: Longest wait for the thread's hold on the child on stop, s.
LOCK_WAIT_S = 0.25
#: Seconds between two log lines of the same kind (a failing check, a description_off).
LOG_THROTTLE_S = 60.0
#: ``check_state`` while the check runs as it should.
STATE_ON = 'on'


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


def not_checkable(values: Mapping[str, Any], model: Any = None) -> str | None:
    """
    Return why the check cannot judge this lens, or None when it can.

    A lens whose groups move (``lens.zoom.joint`` / ``lens.focus.joint`` set) has a map per
    frame, which the child does not have; a tilted or decentred port bends rays in 3-D,
    which the check's chief-ray lines (the symmetric port's) do not describe.

    :param values: the node's parameter values.
    :param model: the model in use (None: judge from the values only).
    :return: the reason, as /diagnostics shows it, or None.
    """
    for mechanism in MECHANISMS:
        if values.get(f'lens.{mechanism}.joint'):
            return (f'not checked: lens.{mechanism}.joint moves lens groups (each frame has '
                    'its own map)')
    if model is not None and is_exact_3d(model):
        return ("not checked: the port is tilted or decentred (the check's lines are a "
                "symmetric port's)")
    return None


class CheckSession:
    """The low-priority straight-edge check of a node, without ROS (module docstring)."""

    def __init__(self, value: Callable[[str], Any], current: Callable[[], Any],
                 counters: dict[str, Any], log: Callable[[str, str], None],
                 request_apply: Callable[[], Any],
                 checkable: Callable[[], str | None] = lambda: None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        """
        Create the session (its thread not started).

        :param value: the node's current parameter value by name.
        :param current: the record frames use now (``.model``, ``.revision``,
            ``.values_generation``), or None before the first frame.
        :param counters: /diagnostics entries updated here (``check_deferred`` by the frame
            path, ``check_pauses`` and ``check_cpu_load`` by the thread); the keys are set
            now, so the diagnostics timer never sees the dict change size.
        :param log: ``log(level, message)``, level ``'info'``, ``'warning'`` or ``'error'``.
        :param request_apply: asks the owner of parameter sets to call :meth:`take_apply`.
        :param checkable: None, or why the lens cannot be checked (:func:`not_checkable`).
        :param clock: seconds, monotonic (the results' age).
        """
        self._value, self._current, self._log = value, current, log
        self._request_apply, self._checkable, self._clock = request_apply, checkable, clock
        self._counters = counters
        counters.update(check_deferred=0, check_pauses=0, check_cpu_load=0.0)
        # The machine's load: read and written by this thread, read by the frame path
        # (offer: one float, no lock needed).
        self._gate = LoadGate()
        self._lock = threading.Lock()      # pending frame, result, state, apply, reference
        self._pending: tuple[np.ndarray, Any] | None = None
        self._wake = threading.Event()
        self._stop = False
        self._last_offer = -1e9
        self._busy = False
        self._blocked = False              # the lens cannot be checked: offer does nothing
        self._worker = CheckWorker()
        self._worker_lock = threading.Lock()    # start (thread) vs stop (node) of the child
        self._stopping = threading.Event()
        self.restarts = 0
        self._state = STATE_ON
        self._result: dict[str, Any] | None = None
        self._result_at = 0.0
        self._apply: tuple[dict[str, float], int] | None = None
        self._reference = {name: float(value(name)) for name, _ in ESTIMATED}
        self._logged: dict[str, float] = {}
        self.checks = 0
        # The duty cycle (issue 36): the model last judged, its verdict, how many checks in a
        # row gave it (STABLE_REPEATS of them: the next waits check.stable_period_s).
        self._stable: tuple[Any, str | None, int] = (None, None, 0)
        self.applied_sets = 0
        #: Seconds of the child running without a reply, and of a request's send, after
        #: which it is stuck.
        self.reply_timeout_s, self.send_timeout_s = REPLY_TIMEOUT_S, SEND_TIMEOUT_S
        self._thread = threading.Thread(target=self._run, name='check', daemon=True)

    # -- the node's side -----------------------------------------------------------------------

    def start(self) -> None:
        """Start the thread."""
        self._thread.start()

    def stop(self) -> None:
        """End the child and the thread: bounded (module docstring, "Stop")."""
        self._stopping.set()
        held = self._worker_lock.acquire(timeout=LOCK_WAIT_S)
        try:
            self._stop = True
            self._wake.set()
            self._worker.stop()     # the thread's recv() or send sees the pipe break
        finally:
            if held:
                self._worker_lock.release()
        if self._thread.is_alive():
            self._thread.join(timeout=JOIN_S)
        if not self._thread.is_alive():
            self._worker.close()

    @property
    def worker_pid(self) -> int | None:
        """Return the check process's pid (None when there is none)."""
        process = self._worker.process
        return None if process is None else process.pid

    @property
    def reference(self) -> dict[str, float]:
        """Return the values ``check.apply`` is bounded about (a copy)."""
        with self._lock:
            return dict(self._reference)

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
        if self._blocked:
            return
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

    def _record(self, current: Any, verdict: str) -> None:
        """Count the checks in a row of one model with one verdict (:meth:`_period`)."""
        judged, last, repeats = self._stable
        same = judged is current and last == verdict
        self._stable = (current, verdict, repeats + 1 if same else 1)

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

    def entries(self) -> dict[str, Any]:
        """
        Return the check's /diagnostics entries now (module docstring; any thread).

        :return: key -> value.
        """
        with self._lock:
            state, result, at = self._state, self._result, self._result_at
        if float(self._value('check.rate_hz')) <= 0.0:
            state, result = 'off (check.rate_hz 0)', None
        out: dict[str, Any] = {'check_state': state, 'checks': self.checks,
                               'check_applied': self.applied_sets}
        if result is not None:
            out.update(result)
            out['check_age_s'] = round(max(0.0, self._clock() - at), 1)
        return out

    def user_set(self, changes: Mapping[str, Any]) -> None:
        """
        Move the apply's bounds to the values of a set that is not the check's own.

        :param changes: name -> value of an accepted set (executor: the post-set callback).
        """
        with self._lock:
            for name in self._reference:
                if name in changes:
                    self._reference[name] = float(changes[name])

    def take_apply(self, generation: int) -> dict[str, float] | None:
        """
        Return the parameters to set now for ``check.apply``, or None (executor).

        :param generation: the live model's values generation now.
        :return: name -> value, or None when nothing is pending or a set came after the
            model the check judged (that set wins; logged).
        """
        with self._lock:
            pending, self._apply = self._apply, None
        if pending is None or not bool(self._value('check.apply')):
            return None
        changes, judged = pending
        if generation != judged:
            self._log('info', 'check.apply: not applied: the parameters were set after the '
                              'check judged them; the next check judges the new ones')
            return None
        return changes

    def applied(self, changes: Mapping[str, float], successful: bool, reason: str) -> None:
        """
        Count and log the outcome of an apply's set (executor).

        :param changes: what was set.
        :param successful: whether the node accepted it.
        :param reason: the refusal's reason.
        """
        if successful:
            self.applied_sets += 1
            # The chains stay (raw points); the next check judges the new description.
            self._log('info', 'check.apply: set ' + ', '.join(
                f'{n} = {v:.6g}' for n, v in changes.items()))
        else:
            self._log('warning', f'check.apply refused: {reason}')

    # -- the thread ----------------------------------------------------------------------------

    def _throttled(self, kind: str, level: str, message: str) -> None:
        """Log at most every :data:`LOG_THROTTLE_S` per kind (this thread)."""
        now = time.monotonic()
        if now - self._logged.get(kind, -math.inf) >= LOG_THROTTLE_S:
            self._logged[kind] = now
            self._log(level, message)

    def _set_state(self, state: str, keep_result: bool = False) -> None:
        with self._lock:
            self._state = state
            if not keep_result:
                self._result = None

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
        if self._idle_look():
            self._start_worker()     # now, not at the first check: its imports take a second
        while not self._stop:
            woke = self._wake.wait(WAIT_S)
            # Every WAIT_S at least: the gate's load stays fresh.
            self._sample_load(time.monotonic())
            if not woke:
                self._idle_look()
                continue
            self._wake.clear()
            with self._lock:
                pending, self._pending = self._pending, None
            if pending is None or not self._idle_look():    # a set may have changed either
                self._busy = False
                continue
            try:
                self._check(*pending)
            except Exception as err:    # noqa: B902 - the check must never stop the node
                self._throttled('failed', 'error', f'check failed: {err!r}')
            finally:
                # The period runs from the end of a check: the thread idles at least
                # 1 / check.rate_hz between checks, however long one takes.
                self._gate.check_ended()
                self._last_offer = time.monotonic()
                self._busy = False

    def _idle_look(self) -> bool:
        """
        Stop the child when the check is off or the lens cannot be checked (this thread).

        :return: whether the check may run (rate above 0, the lens checkable).
        """
        reason = None if self._stop else self._checkable()
        self._blocked = reason is not None
        rate = float(self._value('check.rate_hz'))
        if reason is None and rate > 0.0:
            with self._lock:
                if self._state.startswith(('off', 'not checked')):
                    self._state = STATE_ON
            return True
        if reason is not None:
            self._set_state(reason)
        else:       # off: a later rate above 0 starts afresh (also after giving up)
            self._set_state('off (check.rate_hz 0)')
            self.restarts = 0
        with self._worker_lock:
            if self._stop or self._worker.process is None:
                return False
        self._worker.stop()     # continues a paused one first
        self._worker.close()
        self._stable = (None, None, 0)      # a fresh window: checked at the rate again
        self._log('info', f'check: {reason or "off (check.rate_hz 0)"}: its process stopped')
        return False

    def _start_worker(self) -> bool:
        """Start the child process if it is not running; False if stopping or given up."""
        with self._worker_lock:
            if self._stop or self.restarts > MAX_RESTARTS:
                return False
            if self._worker.process is None:
                self._worker.start()
                with self._lock:
                    if not self._state.startswith('restarting'):
                        self._state = STATE_ON
            return True

    def _in_worker(self, frame: np.ndarray, model: Any, current: Any) -> dict[str, Any] | None:
        """Check in the child process; None if it died or got stuck (restarted) or stopping."""
        if not self._start_worker():
            return None
        try:
            return self._worker.check(frame, model, current, int(self._value('check.window')),
                                      float(self._value('check.max_rms_px')),
                                      waiting=self._pause_for_load, poll_s=LOAD_POLL_S,
                                      reply_timeout_s=self.reply_timeout_s,
                                      send_timeout_s=self.send_timeout_s)
        except WorkerGone as err:
            # A child ended during the node's stop (or by a signal to its session) is not
            # a death to log; a stuck one is.
            if not isinstance(err, WorkerStuck) and self._stopping.wait(STOP_GRACE_S):
                return None
            with self._worker_lock:
                if self._stop:
                    return None
            self._worker.stop()
            self._worker.close()
            self.restarts += 1
            self._stable = (None, None, 0)      # a fresh window: checked at the rate again
            if self.restarts > MAX_RESTARTS:
                self._set_state(f'gave up: {err} (restarted {MAX_RESTARTS} times; set '
                                'check.rate_hz to 0 and back to try again)')
                self._log('error', f'check: {err}; the check stays off (restarted '
                                   f'{MAX_RESTARTS} times)')
            else:
                self._set_state(f'restarting: {err} ({self.restarts} of {MAX_RESTARTS})',
                                keep_result=True)
                self._log('error', f'check: {err}; restarting it ({self.restarts} of '
                                   f'{MAX_RESTARTS})')
                self._start_worker()    # now: its imports overlap the wait for the next check
            return None

    def _check(self, frame: np.ndarray, model: Any) -> None:
        start = time.perf_counter()
        record = self._current()
        current = model if record is None else record.model
        reply = self._in_worker(frame, model, current)
        if reply is None:
            return
        if 'error' in reply:
            raise RuntimeError(reply['error'])
        result = reply['result']
        if result is None:      # the frame's size is not the current model's: a new window
            return
        self.checks += 1
        self._record(current, result.verdict)
        entries = diagnostics_entries(result)
        entries['check_frames'] = reply['frames']
        entries['check_ms_last'] = (time.perf_counter() - start) * 1e3
        entries['check_model_revision'] = getattr(record, 'revision', -1)
        generation = getattr(record, 'values_generation', -1)
        entries['check_values_generation'] = generation
        with self._lock:
            self._result, self._result_at, self._state = entries, self._clock(), STATE_ON
        if result.verdict == 'description_off':
            self._throttled('off', 'warning', (
                f'check: description_off (straightness {result.straightness_rms_px:.3f} px '
                f'rms over {result.edges} edges; after the estimate '
                f'{result.straightness_rms_px_after or float("nan"):.3f} px)'))
        if record is not None and bool(self._value('check.apply')):
            self.plan_apply(result, current, generation)

    def plan_apply(self, result: CheckResult, judged: Any, generation: int) -> None:
        """
        Keep what ``check.apply`` may set and ask the executor to set it (this thread).

        :param result: the check (its verdict and estimate).
        :param judged: the model it judged (its ``values``).
        :param generation: that model's values generation.
        """
        changes = to_apply(result, judged.values, self.reference)
        if not changes:
            return
        with self._lock:
            self._apply = (changes, generation)
        self._request_apply()
