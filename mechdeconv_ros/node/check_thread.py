# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The node's live self-check: the ROS-free check session wired to rclpy (issues 26, 36).

Everything that needs no ROS (when a frame is checked, the child process, the CPU gate's
calls, /diagnostics entries, what ``check.apply`` may set and about which values) is the
:class:`~mechdeconv_ros.runtime.check_session.CheckSession`'s, tested without ROS. What is
left here is what only the node can do:

* ``check.apply``'s set runs on the node's executor, never in the check's thread: the
  session calls ``request_apply`` (a guard condition's trigger, thread-safe); the guard
  condition's callback, in the node's default callback group (the parameter services'
  group: mutually exclusive, so serialised with every user's set even in a multi-threaded
  executor), takes the pending changes (:meth:`CheckSession.take_apply`: dropped if a set
  came after the model the check judged) and sets them with ``set_parameters_atomically``:
  the on-set (validation) and post-set (commit) callbacks a user's set goes through, then
  the rebuild a service request starts.
* every other accepted set moves the apply's bounds (:meth:`CheckThread.user_set`, from the
  post-set callback): the check's own set is told apart by a flag that only the executor
  reads and writes.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping

from mechdeconv_ros.runtime.check_session import CheckSession, not_checkable
from rclpy.node import Node
from rclpy.parameter import Parameter


class CheckThread:
    """The straight-edge check of a node (module docstring)."""

    def __init__(self, node: Node, live: Any, counters: dict[str, Any],
                 log: Callable[[str, str], None]) -> None:
        """
        Create the check (its thread not started).

        :param node: the node (its ``set_parameters_atomically``, its guard conditions).
        :param live: the node's :class:`~mechdeconv_ros.runtime.live_model.LiveModel`.
        :param counters: the gate's /diagnostics counters (the session's docstring).
        :param log: ``log(level, message)`` on the node's logger.
        """
        self._node, self._live = node, live
        self._applying = False      # executor only: the set in progress is the check's own
        self._trigger = node.create_guard_condition(self._apply_on_executor)
        self.session = CheckSession(
            live.value, lambda: live.active, counters, log, self._trigger.trigger,
            lambda: not_checkable(live.values(), getattr(live.active, 'model', None)
                                  or live.startup_model))

    def start(self) -> None:
        """Start the check's thread."""
        self.session.start()

    def stop(self) -> None:
        """End the child and the thread (bounded)."""
        self.session.stop()

    @property
    def worker_pid(self) -> int | None:
        """Return the check process's pid (None when there is none)."""
        return self.session.worker_pid

    def offer(self, corrected: Any, model: Any) -> None:
        """
        Hand over a corrected frame (frame path; :meth:`CheckSession.offer`).

        :param corrected: the corrected frame.
        :param model: the model that corrected it.
        """
        self.session.offer(corrected, model)

    def holding(self, callback: Any) -> Any:
        """
        Return the frame callback with the check's process stopped while it runs (issue 36).

        :param callback: the node's frame callback.
        :return: :meth:`CheckSession.holding` of it.
        """
        return self.session.holding(callback)

    def entries(self) -> dict[str, Any]:
        """Return the check's /diagnostics entries now."""
        return self.session.entries()

    def user_set(self, changes: Mapping[str, Any]) -> None:
        """
        Move the apply's bounds after an accepted set that is not the check's (post-set).

        :param changes: name -> value of the set.
        """
        if not self._applying:
            self.session.user_set(changes)

    def _apply_on_executor(self) -> None:
        """Make ``check.apply``'s pending set through the node's parameter path (executor)."""
        changes = self.session.take_apply(self._live.values_generation)
        if not changes:
            return
        self._applying = True
        try:
            outcome = self._node.set_parameters_atomically(
                [Parameter(name, Parameter.Type.DOUBLE, v) for name, v in changes.items()])
            successful, reason = outcome.successful, outcome.reason
        except Exception as err:    # noqa: B902 - an executor callback must never raise
            successful, reason = False, repr(err)
        finally:
            self._applying = False
        self._live.start_requested_rebuild()    # what the services do after a request
        self.session.applied(changes, successful, reason)
