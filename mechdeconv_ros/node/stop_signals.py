# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
SIGINT and SIGTERM as a stop request, from the first line of a node process (stdlib only).

A node process spends its first 0.5 to 1 s importing rclpy, numpy and OpenCV. Under Python's
own handler a Ctrl-C (or ``ros2 launch`` stopping the node) in that time raised
KeyboardInterrupt inside some import: a traceback and exit code -2. correct_node's entry
point (:mod:`mechdeconv_ros.node.entry`) therefore calls :func:`catch_early` before it
imports anything heavy, and :func:`mechdeconv_ros.node.node_main.run_node` takes over the
same :class:`StopSignals` (:func:`take_early`): a stop requested from then on (the
interpreter's own start-up, tens of ms, comes before) ends the process with exit code 0.

The handlers only set an Event (the main thread then stops and destroys the node). A second
SIGINT is ignored: Ctrl-C on ``ros2 launch`` reaches the node from the terminal and launch
forwards one more, which used to interrupt the shutdown. A third SIGINT, or a SIGTERM after
the first signal (launch sends one after its timeout), stops the process the default way, in
case shutdown hangs. Signal handlers run in the main thread only: from another thread
:meth:`StopSignals.install` installs nothing (the Event still works when set by hand).
"""

from __future__ import annotations

import signal
import threading
from typing import Any

#: The signals that request a stop.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopSignals:
    """A stop Event set by SIGINT or SIGTERM, and the handlers it replaced."""

    def __init__(self) -> None:
        """Create an unset Event; install nothing yet."""
        self.event = threading.Event()
        self._previous: dict[int, Any] = {}

    def install(self) -> StopSignals:
        """
        Install the handlers (main thread only; elsewhere nothing is installed).

        :return: self.
        """
        if threading.current_thread() is threading.main_thread():
            for sig in STOP_SIGNALS:
                self._previous.setdefault(sig, signal.signal(sig, self._request_stop))
        return self

    def restore(self) -> None:
        """Put back the handlers that :meth:`install` replaced."""
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def _request_stop(self, signum: int, frame: Any) -> None:
        self.event.set()
        signal.signal(signal.SIGINT, self._ignore_once)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)

    def _ignore_once(self, signum: int, frame: Any) -> None:
        signal.signal(signal.SIGINT, signal.default_int_handler)


_early: StopSignals | None = None


def catch_early() -> None:
    """Install the stop handlers now, before the heavy imports of a node process."""
    global _early
    if _early is None:
        _early = StopSignals().install()


def take_early() -> StopSignals | None:
    """
    Return the handlers :func:`catch_early` installed, once (None if it was not called).

    :return: the early :class:`StopSignals`, whose Event may already be set.
    """
    global _early
    early, _early = _early, None
    return early
