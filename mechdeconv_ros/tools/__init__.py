# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The programs people run: the ``mechdeconv`` CLI, the demo and its camera, the plots (layer 7).

The top layer: it may import every layer below and nothing imports it (but the tests and
benchmarks).
"""
