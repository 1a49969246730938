# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Per-frame stage timestamps of the frame path, for the stage benchmark (off by default).

With the environment variable ``MECHDECONV_STAGE_TIMES`` set to a file path, ``correct_node``
(and the benchmark's relays, :mod:`benchmarks.stage_relay`) time every frame stage by stage
and write the samples there as JSON when the node is destroyed. Unset (the default),
:func:`stage_clock_from_env` returns None and the frame path pays one ``is None`` test per
stage boundary (about 30 ns each, under 1 us per frame).

Per frame, in ms: ``receive`` = callback entry (wall clock) - ``header.stamp`` (the publisher's
wall clock: publish, transport, the executor's wait and take, rclpy's conversion to a Python
message; only meaningful when the stamp is the wall clock at publish, as in the benchmarks),
then each named stage = ``time.perf_counter`` between two marks, and ``image_out_ns`` = wall
clock when the image publish returned (to time the output hop against a subscriber's receive
time). Stage names are the callers' (``correct_node``: ``read``, ``model``, ``remap``,
``publish_image``, ``publish_info``, ``publish_info_rect``, ``bookkeeping``). One thread
(the frame callback's) writes; :meth:`StageClock.dump` runs after the executor stopped.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import time
from typing import Any

#: The environment variable that turns the stage clock on (its value: the output file).
ENV = 'MECHDECONV_STAGE_TIMES'
#: Most frames kept (11 minutes at 30 Hz); later ones are not recorded.
CAPACITY = 20000


class StageClock:
    """Stage timestamps of each frame; see the module docstring."""

    def __init__(self, path: Path, capacity: int = CAPACITY) -> None:
        """
        Start with no frames.

        :param path: where :meth:`dump` writes the JSON.
        :param capacity: most frames kept.
        """
        self.path = Path(path)
        self.capacity = capacity
        self.frames: list[dict[str, Any]] = []
        self._current: dict[str, Any] | None = None
        self._last = 0.0

    def start(self, stamp: Any) -> None:
        """
        Open a frame at callback entry.

        :param stamp: the frame's ``header.stamp`` (``sec``, ``nanosec``).
        """
        now_ns = time.time_ns()
        self._last = time.perf_counter()
        stamp_ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
        self._current = {'stamp_ns': stamp_ns, 'receive': (now_ns - stamp_ns) * 1e-6}

    def mark(self, stage: str) -> None:
        """
        Close a stage: the time since the previous mark, or since the start, goes to ``stage``.

        :param stage: the stage's name (a repeated name adds up).
        """
        now = time.perf_counter()
        if self._current is not None:
            self._current[stage] = self._current.get(stage, 0.0) + (now - self._last) * 1e3
            if stage == 'publish_image':
                self._current['image_out_ns'] = time.time_ns()
        self._last = now

    def end(self) -> None:
        """Close the frame (a frame that never reaches ``end`` is not kept)."""
        if self._current is not None and len(self.frames) < self.capacity:
            self.frames.append(self._current)
        self._current = None

    def dump(self) -> None:
        """Write the frames to the file (errors are ignored: it is a measurement aid)."""
        try:
            self.path.write_text(json.dumps({'pid': os.getpid(), 'frames': self.frames}))
        except OSError:
            pass


def stage_clock_from_env() -> StageClock | None:
    """Return a StageClock when ``MECHDECONV_STAGE_TIMES`` names a file, else None."""
    path = os.environ.get(ENV, '')
    return StageClock(Path(path)) if path else None
