# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The stop signals of a node process (:mod:`mechdeconv_ros.node.stop_signals`), in process."""

from __future__ import annotations

import os
import signal
import threading

from mechdeconv_ros.node import stop_signals
from mechdeconv_ros.node.stop_signals import StopSignals
import pytest


def test_first_signal_sets_the_event_second_is_ignored_third_interrupts() -> None:
    before = signal.getsignal(signal.SIGINT)
    signals = StopSignals().install()
    try:
        os.kill(os.getpid(), signal.SIGINT)
        assert signals.event.is_set()
        os.kill(os.getpid(), signal.SIGINT)         # launch's forwarded copy: ignored
        with pytest.raises(KeyboardInterrupt):      # a third: shutdown hangs, stop for real
            os.kill(os.getpid(), signal.SIGINT)
        # After the first signal SIGTERM is the default one again (launch's escalation).
        assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    finally:
        signals.restore()
    assert signal.getsignal(signal.SIGINT) is before


def test_sigterm_requests_a_stop_too() -> None:
    before = signal.getsignal(signal.SIGTERM)
    signals = StopSignals().install()
    try:
        os.kill(os.getpid(), signal.SIGTERM)
        assert signals.event.is_set()
    finally:
        signals.restore()
    assert signal.getsignal(signal.SIGTERM) is before


def test_early_handlers_are_taken_once() -> None:
    before = signal.getsignal(signal.SIGINT)
    stop_signals.catch_early()
    try:
        early = stop_signals.take_early()
        assert early is not None and signal.getsignal(signal.SIGINT) == early._request_stop
        assert stop_signals.take_early() is None
    finally:
        early.restore()
    assert signal.getsignal(signal.SIGINT) is before


def test_outside_the_main_thread_nothing_is_installed() -> None:
    before = signal.getsignal(signal.SIGINT)
    result: list[StopSignals] = []
    thread = threading.Thread(target=lambda: result.append(StopSignals().install()))
    thread.start()
    thread.join()
    assert signal.getsignal(signal.SIGINT) is before
    assert not result[0].event.is_set()
