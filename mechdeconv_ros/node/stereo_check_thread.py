# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
stereo_node's check coordinator: raw pairs at ``stereo_check.rate_hz`` to the idle-time child.

The frame path calls :meth:`StereoCheckThread.offer` with the pair's raw pixels and the pair
record it used: at most ``stereo_check.rate_hz`` times a second it keeps REFERENCES (no copy,
no conversion: one comparison and two assignments on the frame path) and wakes the thread
(``mechdeconv-stereo-check``). The thread turns them into 8-bit grey (OpenCV, interpreter lock
released) and hands them to the child process
(:class:`~mechdeconv_ros.runtime.stereo_check_worker.StereoCheckWorker`, nice 19, SCHED_IDLE),
waiting for the reply with the lock released. While a check is in the child the frame path
stops it for the time it rectifies and publishes a pair (:meth:`StereoCheckThread.hold` and
:meth:`~StereoCheckThread.release`: SIGSTOP, SIGCONT), so it runs between pairs only. The
child matches the pair, pools the last
``stereo_check.window`` pairs and fits the rig. A child that dies, or is stuck (no request
taken, or no reply after two minutes of running: ``WorkerStuck``, the plumbing of
:mod:`~mechdeconv_ros.runtime.child_process` it shares with the straight-edge check), is
restarted up to :data:`MAX_RESTARTS` times.

The result's keys (the JSON of ``mechdeconv stereo-check``: ``verdict``, ``matches``,
``vertical_disparity_rms_px``, ``vertical_disparity_rms_px_after``, ``estimate.<name>.value``
/ ``.sigma`` / ``.tolerance``) and ``stereo_checks``, ``stereo_check_pairs``,
``stereo_check_ms_last``, ``stereo_check_applied``, ``stereo_check_state``,
``stereo_check_model_generation`` (the pair the result judged) and its age go to /diagnostics
(one dict rebound whole). With ``stereo_check.rate_hz`` 0, or after the child gave up, the
result is dropped and ``stereo_check_state`` says why.

``stereo_check.apply``: with the verdict ``rig_off``, the measured parameters (sigma within
the tolerance), each within the tolerance about the USER's value
(:func:`~mechdeconv_ros.imaging.stereo_check.apply_values`), are handed to the executor
thread (a guard condition), which sets them in ONE ``set_parameters_atomically`` call: the
node's validation, its background rebuild and swap, as a user's set. The user's values are
those of the start-up and of every set that was not the check's own.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable

from mechdeconv_ros.imaging.stereo_check import apply_values, StereoCheckResult, to_grey
from mechdeconv_ros.node.stereo_io import CHECK_DONE_KEY
from mechdeconv_ros.runtime.stereo_check_worker import StereoCheckWorker, WorkerGone
from mechdeconv_ros.schema.stereo_params import RIG_PARAMS
from rclpy.parameter import Parameter

#: Restarts of a dead child before the check stays off.
MAX_RESTARTS = 3
#: ``stereo_check_state`` while ``stereo_check.rate_hz`` is 0.
OFF_BY_RATE = 'off (stereo_check.rate_hz 0)'
#: The rig's values and tolerances the check reads.
RIG_NAMES = (*RIG_PARAMS, *(f'rig.tolerance.{n[len("rig."):]}' for n in RIG_PARAMS))


def diagnostics_entries(result: dict[str, Any]) -> dict[str, Any]:
    """
    Return a check result (``as_dict``) as flat /diagnostics entries.

    :param result: the result dict.
    :return: key -> value, the estimate as ``estimate.<name>.value`` / ``.sigma`` /
        ``.tolerance``.
    """
    out = {k: v for k, v in result.items() if k != 'estimate'}
    for name, est in (result.get('estimate') or {}).items():
        for key in ('value', 'sigma', 'tolerance'):
            out[f'estimate.{name}.{key}'] = est[key]
    return out


class StereoCheckThread:
    """The low-priority stereo check of stereo_node (module docstring)."""

    def __init__(self, node: Any, value: Callable[[str], Any],
                 publish: Callable[[dict[str, Any]], None]) -> None:
        """
        Create the thread (not started) and the guard condition of ``stereo_check.apply``.

        :param node: the rclpy node (logger, guard condition, ``set_parameters_atomically``).
        :param value: the node's current parameter values by name.
        :param publish: receives the diagnostics entries after each check.
        """
        self._node, self._value, self._publish = node, value, publish
        self._cond = threading.Condition()
        self._pending: tuple[Any, Any, Any] | None = None
        self._stopping = False
        self._last_offer = -math.inf
        self._worker = StereoCheckWorker()
        self._restarts = 0
        self._busy = False      # a check is in the child (the frame path holds it meanwhile)
        self.checks = 0
        self.applied = 0
        self._to_apply: dict[str, float] = {}
        self._applying = False
        self.user: dict[str, Any] = {k: value(k) for k in RIG_NAMES}
        self._rate = float(value('stereo_check.rate_hz'))
        self._publish(self._state_entries('on' if self._rate > 0.0 else OFF_BY_RATE))
        self._apply_trigger = node.create_guard_condition(self._apply_now)
        self._thread = threading.Thread(target=self._run, name='mechdeconv-stereo-check',
                                        daemon=True)

    def start(self) -> None:
        """Start the coordinator thread (the child starts with the first check)."""
        self._thread.start()

    def offer(self, left: Any, right: Any, active: Any,
              copy: tuple[bool, bool] = (False, False)) -> None:
        """
        Keep a raw pair for the next check, at most ``stereo_check.rate_hz`` (frame path).

        :param left: the left raw pixels (kept by reference).
        :param right: the right raw pixels.
        :param active: the pair record that rectified them.
        :param copy: per side, whether its buffer is reused by the next frame (a demosaiced
            one): that side is copied (a Bayer camera's check costs one copy per check).
        """
        rate = self._rate
        now = time.monotonic()
        if rate <= 0.0 or now - self._last_offer < 1.0 / rate:
            return
        self._last_offer = now
        left, right = (p.copy() if c else p for p, c in zip((left, right), copy))
        with self._cond:
            self._pending = (left, right, active)
            self._cond.notify()

    def hold(self) -> None:
        """Stop the child while the frame path rectifies a pair (only during a check)."""
        if self._busy:
            self._worker.pause(True)

    def release(self) -> None:
        """Let the child go on after the pair is published."""
        if self._worker.paused:
            self._worker.pause(False)

    def settings_changed(self) -> None:
        """
        Read ``stereo_check.rate_hz`` again (executor thread, after a set).

        Off (0) drops the last result from /diagnostics at once (a verdict the node no longer
        refreshes is not shown as current) and any pair waiting for the thread.
        """
        with self._cond:
            was = self._rate
            self._rate = float(self._value('stereo_check.rate_hz'))
            if self._rate <= 0.0:
                self._pending = None
                self._publish(self._state_entries(OFF_BY_RATE))
            elif was <= 0.0:
                self._publish(self._state_entries('on'))

    def _state_entries(self, state: str) -> dict[str, Any]:
        """Return the /diagnostics entries of a check without a current result."""
        return {'stereo_check_state': state, 'stereo_checks': self.checks,
                'stereo_check_applied': self.applied}

    def user_set(self, changes: dict[str, Any]) -> None:
        """
        Note a set of rig values (executor thread): a user's unless it is the check's own.

        :param changes: name -> value of the set.
        """
        if not self._applying:
            self.user.update({k: v for k, v in changes.items() if k.startswith('rig.')})

    def stop(self) -> None:
        """Stop the thread and the child."""
        with self._cond:
            self._stopping = True
            self._cond.notify()
        self._worker.stop()     # at most 1.5 s; the thread's read then ends (EOF)
        if self._thread.is_alive():
            self._thread.join(timeout=10.0)
        if not self._thread.is_alive():
            self._worker.close()    # after the join: the thread may still read the pipe

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._stopping:
                    self._cond.wait()
                if self._stopping:
                    return
                (left, right, active), self._pending = self._pending, None
            try:
                self._check(left, right, active)
            except Exception as err:    # noqa: B902 - the check must not end the thread
                self._node.get_logger().error(f'stereo check failed: {err!r}',
                                              throttle_duration_sec=30.0)

    def _check(self, left: Any, right: Any, active: Any) -> None:
        start = time.perf_counter()
        if self._worker.process is None:
            self._worker.start()
        stereo = active.stereo
        sizes = ((stereo.left.width, stereo.left.height),
                 (stereo.right.width, stereo.right.height))
        grey = (to_grey(left), to_grey(right))
        self._busy = True
        try:
            reply = self._worker.check(*grey, dict(stereo.values), sizes, active.generation,
                                       int(self._value('stereo_check.window')))
        except WorkerGone as err:
            self._worker.stop()
            self._restarts += 1
            if self._restarts > MAX_RESTARTS:
                with self._cond:
                    self._rate = 0.0
                    self._publish(self._state_entries(
                        f'off: its process died {self._restarts} times'))
            self._node.get_logger().error(f'stereo check: {err}; restarts {self._restarts}')
            return
        finally:
            self._busy = False
            self._worker.pause(False)
        if 'error' in reply:
            self._node.get_logger().error(f"stereo check: {reply['error']}",
                                          throttle_duration_sec=30.0)
            return
        self.checks += 1
        entries = diagnostics_entries(reply['result'])
        entries.update({'stereo_check_state': 'on', 'stereo_checks': self.checks,
                        'stereo_check_pairs': reply['pairs'],
                        'stereo_check_ms_last': (time.perf_counter() - start) * 1e3,
                        'stereo_check_applied': self.applied,
                        'stereo_check_model_generation': active.generation,
                        CHECK_DONE_KEY: time.monotonic()})
        with self._cond:
            if self._rate <= 0.0:       # turned off while this check ran: not shown, not applied
                return
            self._publish(entries)
        result = StereoCheckResult(**reply['result'])
        if result.verdict == 'rig_off' and bool(self._value('stereo_check.apply')):
            changes = apply_values(result, self.user)
            if changes:
                with self._cond:
                    self._to_apply = changes
                self._apply_trigger.trigger()

    def _apply_now(self) -> None:
        """Set the check's estimate in one atomic set (executor thread)."""
        with self._cond:
            changes, self._to_apply = self._to_apply, {}
        if not changes:
            return
        self._applying = True
        try:
            outcome = self._node.set_parameters_atomically(
                [Parameter(n, Parameter.Type.DOUBLE, float(v)) for n, v in changes.items()])
        finally:
            self._applying = False
        if outcome.successful:
            self.applied += 1
            self._node.get_logger().info('stereo_check.apply: set ' + ', '.join(
                f'{n} = {v:.6g}' for n, v in changes.items()))
        else:
            self._node.get_logger().warning(f'stereo_check.apply refused: {outcome.reason}')
