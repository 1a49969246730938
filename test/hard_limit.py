# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
pytest plugin: end the test process when one test runs past a hard limit, with every stack.

Once in CI a test client's ``Node.destroy_node`` spun at 100 % CPU inside rclpy, holding the
GIL, until the run was killed by hand: no Python-level timeout (pytest-timeout's thread or
signal methods) can run while a C call holds the GIL. faulthandler's watchdog is a C thread:
after ``MECHDECONV_TEST_HARD_LIMIT_S`` seconds (default :data:`DEFAULT_S`, far above the
slowest test's 25 s) it writes the traceback of every thread to stderr and exits the process
with status 1. Under pytest-xdist the controller then reports that worker's test as failed
and starts a new worker, so the rest of the suite still runs. The stacks go to a copy of
the process's stderr taken at configure time, when pytest's own capture is suspended (as
pytest's faulthandler plugin does): the descriptor 2 of a running test is a capture file,
lost with the process.
"""

from __future__ import annotations

import faulthandler
import os
import sys
from typing import Iterator

import pytest

#: The variable that sets the limit, in seconds.
ENV = 'MECHDECONV_TEST_HARD_LIMIT_S'
#: The default limit, s.
DEFAULT_S = 600.0

_stderr_copy: list[int] = []        # the real stderr's duplicate, from pytest_configure


def pytest_configure(config: pytest.Config) -> None:
    """Keep a duplicate of the real stderr (pytest's capture is suspended here)."""
    _stderr_copy.append(os.dup(sys.__stderr__.fileno()))


def pytest_unconfigure(config: pytest.Config) -> None:
    """Close the duplicate."""
    while _stderr_copy:
        os.close(_stderr_copy.pop())


@pytest.fixture(autouse=True)
def hard_time_limit() -> Iterator[None]:
    """Arm the watchdog for this test; disarm it when the test ends."""
    limit = float(os.environ.get(ENV, DEFAULT_S))
    target = _stderr_copy[0] if _stderr_copy else sys.__stderr__.fileno()
    faulthandler.dump_traceback_later(limit, exit=True, file=target)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
