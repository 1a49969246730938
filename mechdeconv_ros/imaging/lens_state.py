# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The recent positions of the lens joints, and the lens state at a frame's stamp.

A motorised lens reports its joints in ``sensor_msgs/JointState`` messages (``lens_state``),
stamped when the positions were read; a frame is stamped when it was exposed. The state a
frame is corrected with is the one AT ITS STAMP t:

    p(t) = p_a + (p_b - p_a) (t - t_a) / (t_b - t_a)     for the two samples t_a <= t <= t_b,
    p(t) = the newest sample                              for t after every sample,
    p(t) = the oldest sample kept                         for t before every sample kept,

per joint (two mechanisms may come from two drivers at two rates). Times are integer
nanoseconds (ROS ``builtin_interfaces/Time``); a message stamped 0 (a driver that does not
stamp) is taken at its arrival time (the caller passes rmw's received time, not the time it got
round to the message: messages queued under load keep their own times). A FRAME stamped 0 has
no time: it gets the newest sample of each joint (``lag_s`` NaN). Samples older than
:data:`KEEP_NS` behind the newest are dropped (at least two are kept), and at most
:data:`MAX_SAMPLES` per joint.

Time going back (a ``/clock`` reset, a rosbag played in a loop, a simulator restart) is a jump,
not a late message: a sample more than :data:`KEEP_NS` older than the newest kept (it would be
pruned on insert, leaving the stale "future" samples newest), or the node's clock jumping back
before the newest sample (:meth:`LensStateHistory.time_jumped_back`), clears every joint's
history, as tf2's buffer does on a jump back; :attr:`LensStateHistory.time_jumps` counts them
(``/diagnostics``: ``lens_state_time_jumps``) and :attr:`LensStateHistory.last_jump` says which.

A message that carries none of the joints, or only NaN / infinite positions for them, changes
nothing and is counted in :attr:`LensStateHistory.ignored` (``/diagnostics``:
``lens_states_ignored``, with :attr:`LensStateHistory.last_ignored` saying why). The lag of a
frame, ``t_frame - t_newest`` (s; > 0: the frame is newer than every state, which was then
held), is what :meth:`LensStateHistory.at` reports with the state.

No ROS import; not thread-safe (the node calls it from its executor thread only).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass
import math
from typing import Mapping, Sequence

#: How far back samples are kept behind the newest, ns (frames are rarely older than that).
KEEP_NS = 2_000_000_000
#: Most samples kept per joint (a 1 kHz driver over :data:`KEEP_NS`).
MAX_SAMPLES = 2000


@dataclass(frozen=True)
class StateAt:
    """The lens state at a stamp: positions by mechanism, and how it was found."""

    positions: dict[str, float]
    #: ``t_frame - t_newest`` over the joints, s (the largest); NaN before any sample.
    lag_s: float
    #: Mechanisms whose frame stamp lies after every sample (held at the newest).
    held: tuple[str, ...] = ()
    #: Mechanisms with no sample yet (left out of ``positions``).
    missing: tuple[str, ...] = ()


class _Joint:
    """The samples of one joint, sorted by stamp."""

    def __init__(self) -> None:
        self.stamps: list[int] = []
        self.positions: list[float] = []

    def add(self, stamp_ns: int, position: float) -> None:
        if not self.stamps or stamp_ns > self.stamps[-1]:
            self.stamps.append(stamp_ns)
            self.positions.append(position)
        else:
            i = bisect.bisect_left(self.stamps, stamp_ns)
            if i < len(self.stamps) and self.stamps[i] == stamp_ns:
                self.positions[i] = position        # the same instant again: the newer word
            else:
                self.stamps.insert(i, stamp_ns)
                self.positions.insert(i, position)
        newest = self.stamps[-1]
        drop = bisect.bisect_left(self.stamps, newest - KEEP_NS)
        drop = max(drop, len(self.stamps) - MAX_SAMPLES)
        drop = min(drop, len(self.stamps) - 2)
        if drop > 0:
            del self.stamps[:drop]
            del self.positions[:drop]

    def at(self, stamp_ns: int) -> tuple[float, bool]:
        stamps, positions = self.stamps, self.positions
        if stamp_ns >= stamps[-1]:
            return positions[-1], stamp_ns > stamps[-1]
        if stamp_ns <= stamps[0]:
            return positions[0], False
        i = bisect.bisect_right(stamps, stamp_ns)
        t_a, t_b = stamps[i - 1], stamps[i]
        p_a, p_b = positions[i - 1], positions[i]
        return p_a + (p_b - p_a) * ((stamp_ns - t_a) / (t_b - t_a)), False


class LensStateHistory:
    """Recent stamped positions of the lens joints (see the module doc)."""

    def __init__(self, joints: Mapping[str, str]) -> None:
        """
        Follow some joints.

        :param joints: mechanism name -> joint name, e.g. ``{'zoom': 'zoom_joint'}``.
        """
        self.joints = dict(joints)
        self._by_joint = {joint: _Joint() for joint in self.joints.values()}
        self.received = 0
        self.ignored = 0
        self.last_ignored = ''
        self.time_jumps = 0
        self.last_jump = ''

    def _newest_stamp(self) -> int | None:
        stamps = [joint.stamps[-1] for joint in self._by_joint.values() if joint.stamps]
        return max(stamps) if stamps else None

    def _clear(self, why: str) -> None:
        self._by_joint = {joint: _Joint() for joint in self.joints.values()}
        self.time_jumps += 1
        self.last_jump = why

    def time_jumped_back(self, now_ns: int) -> bool:
        """
        Clear the history when the clock went back before its newest sample (tf2's rule).

        :param now_ns: the clock's new time, ns.
        :return: True when samples from the "future" were cleared (and counted).
        """
        newest = self._newest_stamp()
        if newest is None or newest <= int(now_ns):
            return False
        self._clear(f'clock went back to {now_ns * 1e-9:.3f} s, '
                    f'{(newest - int(now_ns)) * 1e-9:.3f} s before the newest state')
        return True

    def add(self, stamp_ns: int, names: Sequence[str], positions: Sequence[float],
            received_ns: int = 0) -> bool:
        """
        Add one JointState's positions of the followed joints.

        :param stamp_ns: the message's header stamp, ns (0: use ``received_ns``).
        :param names: ``JointState.name``.
        :param positions: ``JointState.position`` (same length, else only the common prefix).
        :param received_ns: the arrival time, ns, for a message stamped 0.
        :return: True when a followed joint was updated, False when the message was ignored
            (and counted).
        """
        self.received += 1
        stamp = int(stamp_ns) if stamp_ns else int(received_ns)
        newest = self._newest_stamp()
        if newest is not None and stamp < newest - KEEP_NS and any(
                name in self._by_joint for name in names):
            self._clear(f'a state stamped {stamp * 1e-9:.3f} s, '
                        f'{(newest - stamp) * 1e-9:.3f} s before the newest')
        used = False
        reasons = []
        for name, position in zip(names, positions):
            joint = self._by_joint.get(name)
            if joint is None:
                continue
            value = float(position)
            if not math.isfinite(value):
                reasons.append(f'{name} is {value}')
                continue
            joint.add(stamp, value)
            used = True
        if not used:
            self.ignored += 1
            self.last_ignored = ('; '.join(reasons) if reasons else
                                 'no position of ' + ', '.join(sorted(self._by_joint)))
        return used

    def newest(self) -> dict[str, float]:
        """Return the newest position of each mechanism that has one."""
        return {mech: self._by_joint[joint].positions[-1]
                for mech, joint in self.joints.items() if self._by_joint[joint].stamps}

    def at(self, stamp_ns: int) -> StateAt:
        """
        Return the lens state at a frame's stamp (interpolated, held after the newest).

        :param stamp_ns: the frame's header stamp, ns (0: unstamped, the newest state).
        :return: the state; mechanisms without any sample are in ``missing``.
        """
        positions: dict[str, float] = {}
        held, missing = [], []
        lag = -math.inf
        for mech, name in self.joints.items():
            joint = self._by_joint[name]
            if not joint.stamps:
                missing.append(mech)
                continue
            if not stamp_ns:
                # No time to look up: the newest, and no lag to report.
                positions[mech], lag = joint.positions[-1], math.nan
                continue
            positions[mech], after = joint.at(int(stamp_ns))
            if after:
                held.append(mech)
            lag = max(lag, (int(stamp_ns) - joint.stamps[-1]) * 1e-9)
        return StateAt(positions, lag if positions else math.nan, tuple(held), tuple(missing))
