# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The frame path without ROS: remap tables and the per-frame correction (layer 4).

Remap and channel remap, the moving lens's maps, demosaicing, the lens state at a frame's
stamp and the self-check's frame mathematics (edges, plumb lines, the estimate). It may
import :mod:`mechdeconv_ros.model` and the layers below, OpenCV and numpy; never rclpy or ROS
message types, so all of it is tested without a ROS graph.
"""
