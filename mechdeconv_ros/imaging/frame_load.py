# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The frame path's load, and the gate that keeps the self-check off a busy node (issue 26).

The load is the fraction of wall time the frame callback was busy, with an exponential
memory of ``tau`` seconds::

    load(t) = (1 / tau) * sum_i b_i * exp(-(t - t_i) / tau)

``b_i`` the busy seconds of frame ``i``, ended at ``t_i`` (seconds, a monotonic clock). A
steady stream of frames taking ``b`` every ``T`` seconds reads ``(b / tau) /
(1 - exp(-T / tau))``, which is ``b / T`` within 1 % for ``T <= tau / 50`` (30 Hz and
faster at the default ``tau`` of 1 s); no frames for ``tau`` seconds divides it by e. One
update is one ``exp``: cheap enough for every frame.

Why a gate at all: the check runs in a child process at the lowest CPU priority, but a
priority does not share the memory bus or the last-level cache. On 2 vCPUs, a node paced at
its serial bound (both cores busy with the remap and DDS) delivered 92-93 % of the frames
with the check on against 97 % with it off (docs/benchmarks.md, issue 26). :class:`LoadGate`
decides, from the load, whether a check may start and whether one already running should
be paused (SIGSTOP) until the load falls (SIGCONT); a check that waits is a check later,
never a frame lost. Pure Python, no ROS; the node's executor thread owns a gate.
"""

from __future__ import annotations

import math

#: Seconds of the load's exponential memory.
TAU_S = 1.0
#: A paused check resumes when the load is below this fraction of ``check.max_load``
#: (hysteresis: a load at the limit must not stop and continue the check every frame).
RESUME_FRACTION = 0.8


class FrameLoad:
    """The decaying busy fraction of the frame path (module docstring)."""

    def __init__(self, tau_s: float = TAU_S):
        """
        Create a load of 0.

        :param tau_s: seconds of memory (> 0).
        """
        if not tau_s > 0.0:
            raise ValueError(f'tau_s must be > 0, got {tau_s}')
        self.tau_s = float(tau_s)
        self._value = 0.0
        self._at: float | None = None

    def value(self, now: float) -> float:
        """
        Return the load at ``now`` (decayed since the last frame; not changed).

        :param now: seconds on the clock of :meth:`add`.
        :return: the busy fraction (0 before the first frame).
        """
        if self._at is None:
            return 0.0
        return self._value * math.exp(-max(0.0, now - self._at) / self.tau_s)

    def add(self, busy_s: float, now: float) -> float:
        """
        Add one frame's busy time, ended at ``now``, and return the load.

        :param busy_s: seconds the frame kept the callback busy (>= 0).
        :param now: seconds on a monotonic clock.
        :return: the load after the frame.
        """
        self._value = self.value(now) + max(0.0, float(busy_s)) / self.tau_s
        self._at = now
        return self._value


class LoadGate:
    """Whether the check may run, from the frame path's load and ``check.max_load``."""

    def __init__(self, tau_s: float = TAU_S):
        """
        Create a gate with a load of 0 (open).

        :param tau_s: seconds of the load's memory.
        """
        self.load = FrameLoad(tau_s)
        #: Checks not started because the frame path was busy (since the node started).
        self.deferred = 0

    def may_start(self, load: float, max_load: float) -> bool:
        """
        Return whether a check may start at this load; count a refusal.

        :param load: the frame path's load now.
        :param max_load: ``check.max_load`` (1 or more: always).
        :return: True when the check may start.
        """
        if max_load >= 1.0 or load <= max_load:
            return True
        self.deferred += 1
        return False

    @staticmethod
    def should_pause(load: float, max_load: float, paused: bool) -> bool:
        """
        Return whether a running check should be paused (True) or run (False) at this load.

        :param load: the frame path's load now.
        :param max_load: ``check.max_load`` (1 or more: never paused).
        :param paused: whether it is paused now (the hysteresis of :data:`RESUME_FRACTION`).
        :return: the new paused state.
        """
        if max_load >= 1.0:
            return False
        if paused:
            return load > RESUME_FRACTION * max_load
        return load > max_load
