# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The ROS 2 side: messages, parameters, services, diagnostics and ``correct_node`` (layer 6).

Everything that knows rclpy or a ROS message type lives here (image and CameraInfo conversion,
compressed transport, the hardened parameter services, ``/diagnostics``, the lens-state
subscription, running a node until SIGINT) together with the environment of the processes of a
graph we start. It may import every layer below; the logic it wires stays in those layers.
"""
