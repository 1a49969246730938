# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
When the self-check may use the CPU: the machine's load, and the gate on it (issue 26).

The check runs in a child process at the lowest CPU priority (nice 19, SCHED_IDLE), but a
priority does not share the memory bus or the last-level cache: on 2 vCPUs, a node paced at
its serial bound delivered 92-93 % of the frames with the check running against 97 % with it
off (docs/benchmarks.md, issue 26). So the check is idle-time work: it starts only while the
machine has idle CPU, and a check in progress is paused (SIGSTOP) while it has none.

The load is the busy fraction of all CPUs over the last :data:`PERIOD_S` (or more) seconds,
from the kernel's cumulative counters (Linux ``/proc/stat``, first line, clock ticks)::

    load = d(user + system + irq + softirq + steal) / d(user + nice + system + idle + iowait
                                                        + irq + softirq + steal)

``nice`` is counted as idle: it is the time of processes at a positive nice value, the check's
own child among them (a check must not count itself busy) and any other background work that
yields to the frame path as the check does. The frame path itself (the node's executor, its
remap threads, DDS), the camera driver and the node's subscribers are all in ``user`` and
``system``. ``guest`` time is already inside ``user``. In a container ``/proc/stat`` is the
host's: the gate then sees the host's load, which is what shares the caches. Where
``/proc/stat`` cannot be read (not Linux) the load reads 0: the check is never held back.

:class:`LoadGate` holds the latest load (written by the check's coordinator thread only, read
by the frame path as one float) and decides from it and ``check.max_load``: no check starts
above the limit; a running one is paused above it and continued below
:data:`RESUME_FRACTION` of it (hysteresis: a load at the limit must not stop and continue
the check every poll).

While a check runs, the load it reads can lie low: a node near its throughput limit that
shares its cores with the check delivers fewer frames and so uses less CPU. Measured at
1080p paced at 56 Hz on 2 vCPUs: the gate read 0.58 to 0.74 (under the 0.75 limit) while
the node delivered 37 and 39 fps, against 46 and 56 fps with the check off. So every
:data:`PROBE_EVERY_S` of running the check is stopped for one load period (a probe), and
the load read over that period, with the check stopped, decides: above the limit it stays
paused (until below :data:`RESUME_FRACTION` of it), else it continues. A probe costs the
check a quarter of its speed and the frames nothing. Pure Python, no ROS.
"""

from __future__ import annotations

from typing import Sequence

#: Seconds between two readings of the counters (and the shortest span a load covers);
#: 0.5 s is 100 ticks on 2 CPUs at the usual 100 Hz: a 1 % resolution.
PERIOD_S = 0.5
#: A paused check continues when the load is below this fraction of ``check.max_load``.
RESUME_FRACTION = 0.8
#: Seconds of running after which a check is stopped for one period to read the load without
#: it (a probe; module docstring).
PROBE_EVERY_S = 2.0
#: The counters file (Linux).
PROC_STAT = '/proc/stat'
#: Indexes in the ``cpu`` line: user nice system idle iowait irq softirq steal.
BUSY = (0, 2, 5, 6, 7)
ALL = (0, 1, 2, 3, 4, 5, 6, 7)


def read_counters(path: str = PROC_STAT) -> tuple[int, int] | None:
    """
    Return the machine's cumulative busy and total CPU ticks (niced time counted idle).

    :param path: the counters file (``/proc/stat`` format).
    :return: ``(busy, total)``, or None if it cannot be read or parsed.
    """
    try:
        with open(path, 'rb') as stream:
            line = stream.readline().split()
    except OSError:
        return None
    if len(line) < 9 or line[0] != b'cpu':
        return None
    try:
        ticks: Sequence[int] = [int(v) for v in line[1:9]]
    except ValueError:
        return None
    return sum(ticks[i] for i in BUSY), sum(ticks[i] for i in ALL)


def busy_fraction(before: tuple[int, int], after: tuple[int, int]) -> float | None:
    """
    Return the busy fraction between two readings (module docstring's equation).

    :param before: ``(busy, total)`` ticks.
    :param after: the later ``(busy, total)``.
    :return: in [0, 1], or None when no tick passed.
    """
    total = after[1] - before[1]
    if total <= 0:
        return None
    return min(1.0, max(0.0, (after[0] - before[0]) / total))


class LoadGate:
    """The machine's load and whether the check may run at it (module docstring)."""

    def __init__(self, path: str = PROC_STAT, period_s: float = PERIOD_S):
        """
        Create a gate with a load of 0 (open) and take the first reading.

        :param path: the counters file.
        :param period_s: seconds between readings.
        """
        self._path, self._period_s = path, float(period_s)
        self._reading = read_counters(path)
        self._at = -1e18
        #: The latest load (0 until two readings are ``period_s`` apart).
        self.load = 0.0
        #: Checks not started because the machine was busy (since the gate was created).
        self.deferred = 0
        #: Times a running check was paused because the machine was busy (probes that let
        #: it continue not counted).
        self.busy_pauses = 0
        #: Probes taken (a running check stopped for one period to read the load without it).
        self.probes = 0
        self._running_since: float | None = None     # the check runs (not paused) since
        self._probe_until: float | None = None       # a probe's reading is due then
        self._probe_read = False                     # that reading was taken

    def sample(self, now: float) -> float:
        """
        Read the counters if ``period_s`` has passed since the last reading; return the load.

        :param now: seconds on a monotonic clock.
        :return: the latest load.
        """
        if now - self._at < self._period_s:
            return self.load
        reading = read_counters(self._path)
        if reading is not None and self._reading is not None:
            load = busy_fraction(self._reading, reading)
            if load is not None:
                self.load = load
        self._reading, self._at = reading, now
        if self._probe_until is not None and now >= self._probe_until:
            self._probe_read = True
        return self.load

    def may_start(self, max_load: float) -> bool:
        """
        Return whether a check may start at the latest load; count a refusal.

        :param max_load: ``check.max_load`` (1 or more: always).
        :return: True when the check may start.
        """
        if max_load >= 1.0 or self.load <= max_load:
            return True
        self.deferred += 1
        return False

    def should_pause(self, max_load: float, paused: bool, now: float | None = None) -> bool:
        """
        Return whether a running check should be paused (True) or run (False) now.

        With ``now`` (the coordinator's calls) a check that has run :data:`PROBE_EVERY_S`
        is paused for a probe: the counters are read again at once, and the reading one
        period later, taken with the check stopped, decides whether it continues.

        :param max_load: ``check.max_load`` (1 or more: never paused).
        :param paused: whether it is paused now (the hysteresis of :data:`RESUME_FRACTION`).
        :param now: seconds on the clock of :meth:`sample` (None: no probes).
        :return: the new paused state.
        """
        if max_load >= 1.0:
            self._probe_until = None
            return False
        if paused:
            if self._probe_until is not None:
                if not self._probe_read:
                    return True
                self._probe_until = None
                stay = self.load > max_load     # what the others need, the check stopped
                self.busy_pauses += stay
            else:
                stay = self.load > RESUME_FRACTION * max_load
            if not stay:
                self._running_since = now
            return stay
        if self.load > max_load:
            self.busy_pauses += 1
            return True
        if now is None:
            return False
        if self._running_since is None:
            self._running_since = now
        elif now - self._running_since >= PROBE_EVERY_S:
            self.probes += 1
            self._reading, self._at = read_counters(self._path), now
            self._probe_until, self._probe_read = now + self._period_s, False
            return True
        return False

    def check_ended(self) -> None:
        """Forget the running check (its running time and any probe in progress)."""
        self._running_since = self._probe_until = None
