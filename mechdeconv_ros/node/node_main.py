# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Run one node until SIGINT/SIGTERM and exit 0; exit 1 on invalid start-up parameters.

SIGINT and SIGTERM only set a flag that the spin loop checks between callbacks (at least every
:data:`STOP_POLL_S`; :mod:`~mechdeconv_ros.node.stop_signals` says why, and how a second and a
third signal are taken): rclpy's own handler raises KeyboardInterrupt wherever the interpreter
is, and while a received image is converted to Python rclpy turns that into a RuntimeError,
so Ctrl-C (or ``ros2 launch`` stopping the node) ended with a traceback and exit code 1.
correct_node's console script installs the same handlers before its imports
(:mod:`~mechdeconv_ros.node.entry`); :func:`run_node` takes those over, so a stop requested
before the node exists ends the process with exit code 0 without creating it. The signal path
touches nothing but the flag: the main thread then destroys the node.

The GIL switch interval is :data:`GIL_SWITCH_S` while the node runs (Python's default is
5 ms). The node's background threads (model rebuild, summary, check) run pure-Python optics
that hold the GIL; each time the frame path gives the GIL up (rcl take, cv2.remap, publish) it
waits up to one interval to get it back. Measured on a 2-vCPU machine with a summary thread
looping beside a 1280x960 remap: frame p50 2.8 ms alone, 12.7 ms (p99 28.8) at 5 ms, 7.8 ms
(p99 11.4) at 0.5 ms. With no background thread busy nothing changes.
"""

from __future__ import annotations

import sys
from typing import Callable

from mechdeconv_ros.node.process_env import keep_large_buffers
from mechdeconv_ros.node.stop_signals import StopSignals, take_early
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

#: Longest wait of the spin loop before it looks at the stop flag, s.
STOP_POLL_S = 0.1
#: The GIL switch interval while a node runs, s (see the module docstring).
GIL_SWITCH_S = 0.0005


def run_node(factory: Callable[[], Node], name: str, args: list[str] | None = None) -> None:
    """
    Create a node, spin it in a SingleThreadedExecutor until a stop signal, destroy it.

    :param factory: makes the node (after ``rclpy.init``); a ValueError means invalid
        start-up parameters: logged as fatal, exit code 1.
    :param name: the logger name for that message.
    :param args: command-line arguments for rclpy (``--ros-args ...``); default ``sys.argv``.
    """
    keep_large_buffers()
    signals = take_early() or StopSignals().install()
    stop = signals.event
    if stop.is_set():           # stopped while Python imported the node: nothing to undo
        signals.restore()
        return
    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(GIL_SWITCH_S)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node: Node | None = None
    failed = False
    try:
        if not stop.is_set():
            node = factory()
        executor = SingleThreadedExecutor()
        if node is not None:
            executor.add_node(node)
        while not stop.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=STOP_POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as err:           # invalid start-up parameters (incl. ModelError)
        rclpy.logging.get_logger(name).fatal(str(err))
        failed = True
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        signals.restore()
        sys.setswitchinterval(switch_interval)
    if failed:
        sys.exit(1)


def log_function(node: Node) -> Callable[[str, str], None]:
    """
    Return ``log(level, message)`` on a node's logger (``'info'``, ``'warning'``, ``'error'``).

    One call site per level: rclpy refuses a second severity from the same line ("Logger
    severity cannot be changed between calls"), which a single ``getattr(logger, level)``
    call would hit on the first warning after an info, in the thread that logs it.

    :param node: the node.
    :return: the function.
    """
    logger = node.get_logger()

    def log(level: str, message: str) -> None:
        if level == 'error':
            logger.error(message)
        elif level == 'warning':
            logger.warning(message)
        else:
            logger.info(message)
    return log
