# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Pairing left and right frames by stamp (stereo_node's ``sync.slop_s``).

Each side keeps its last :data:`QUEUE` frames. A frame that arrives looks for the frame of the
other side whose stamp is closest to its own; within ``slop`` seconds (inclusive) the two are a
pair, and every frame older than the pair's on either side is dropped as unpaired (a later
frame cannot pair with it: stamps grow). A frame pushed out of a full queue is unpaired too.
Unpaired frames are counted per side (``unpaired_left``, ``unpaired_right``) and never
published. A frame whose stamp is not newer than its side's last one is refused (a replayed or
reset clock), counted as unpaired. Executor thread only.
"""

from __future__ import annotations

from collections import deque
from typing import Any

#: Frames kept per side while waiting for a partner.
QUEUE = 4
#: The two sides.
SIDES = ('left', 'right')


class StampPairer:
    """Pairs frames of two streams by stamp within a slop (module docstring)."""

    def __init__(self) -> None:
        """Start with empty queues and zero counters."""
        self._queues: dict[str, deque[tuple[int, Any]]] = {s: deque() for s in SIDES}
        self._last: dict[str, int] = dict.fromkeys(SIDES, -1)
        self.unpaired = dict.fromkeys(SIDES, 0)
        self.pairs = 0

    def push(self, side: str, stamp: int, frame: Any, slop: int) -> tuple[Any, Any] | None:
        """
        Offer one frame; return ``(left, right)`` when it completes a pair.

        :param side: ``'left'`` or ``'right'``.
        :param stamp: the frame's header stamp, ns.
        :param frame: anything (the node's message and reader).
        :param slop: the largest stamp difference of a pair, ns.
        :return: the pair's two frames, or None.
        """
        if stamp <= self._last[side]:
            self.unpaired[side] += 1
            return None
        self._last[side] = stamp
        other = SIDES[1 - SIDES.index(side)]
        queue = self._queues[other]
        best = min(range(len(queue)), key=lambda i: abs(queue[i][0] - stamp), default=None)
        if best is None or abs(queue[best][0] - stamp) > slop:
            own = self._queues[side]
            own.append((stamp, frame))
            if len(own) > QUEUE:
                own.popleft()
                self.unpaired[side] += 1
            return None
        partner_stamp, partner = queue[best]
        for _ in range(best + 1):
            queue.popleft()
        self.unpaired[other] += best
        own = self._queues[side]
        while own and own[0][0] < stamp:
            own.popleft()
            self.unpaired[side] += 1
        self.pairs += 1
        return (frame, partner) if side == 'left' else (partner, frame)

    def pending(self) -> dict[str, int]:
        """
        Return how many frames each side holds while waiting for a partner.

        :return: side -> count.
        """
        return {s: len(q) for s, q in self._queues.items()}
