# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Run-time machinery without ROS: the live model, the check's process and its CPU gate (layer 5).

What runs beside the frame path rather than in it: the live model the node swaps atomically
(values, generations, validation, background rebuilds), the self-check's child process and
its client, and the gate that decides when the check may use the CPU. It may import
:mod:`mechdeconv_ros.imaging` and the layers below, the standard library, OpenCV and numpy;
never rclpy or ROS message types. :mod:`mechdeconv_ros.imaging` keeps the pure frame
computations (remap tables, edges, the check's mathematics).
"""
