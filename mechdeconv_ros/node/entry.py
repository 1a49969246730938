# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The console scripts of the nodes (``ros2 run mechdeconv_ros correct_node``, ``stereo_node``).

It catches SIGINT and SIGTERM (:mod:`mechdeconv_ros.node.stop_signals`) before it imports
the node, whose imports (rclpy, numpy, OpenCV) take 0.5 to 1 s: a stop requested meanwhile
ends the process with exit code 0, as one requested later does. This module imports nothing
else at module level, and neither do the packages above it.
"""

from __future__ import annotations

from mechdeconv_ros.node.stop_signals import catch_early


def correct_node() -> None:
    """Run ``correct_node`` until SIGINT/SIGTERM (exit 0; exit 1 on invalid parameters)."""
    catch_early()
    from mechdeconv_ros.node.correct_node import main
    main()


def stereo_node() -> None:
    """Run ``stereo_node`` until SIGINT/SIGTERM (exit 0; exit 1 on invalid parameters)."""
    catch_early()
    from mechdeconv_ros.node.stereo_node import main
    main()


if __name__ == '__main__':
    correct_node()
