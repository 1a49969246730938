# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""Calibration-free lens distortion correction: a ROS-free core and a thin ROS 2 node."""
