# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The lens model: a lens source turned into a camera (layer 3).

``build_model`` (values -> :class:`LensModel`: raw and corrected intrinsics, the radial map),
the equivalent camera_info fit, the summary of scene constraints and tolerances, lateral colour.
It may import :mod:`mechdeconv_ros.lenses` and the layers below; no ROS, no images.
"""
