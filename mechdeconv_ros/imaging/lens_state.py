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
stamp) is taken at its arrival time. Samples older than :data:`KEEP_NS` behind the newest are
dropped (at least two are kept), and at most :data:`MAX_SAMPLES` per joint.

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

        :param stamp_ns: the frame's header stamp, ns.
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
            positions[mech], after = joint.at(int(stamp_ns))
            if after:
                held.append(mech)
            lag = max(lag, (int(stamp_ns) - joint.stamps[-1]) * 1e-9)
        return StateAt(positions, lag if positions else math.nan, tuple(held), tuple(missing))
