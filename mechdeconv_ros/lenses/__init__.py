# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Where a lens comes from: the lens-source seam and every source (layer 2).

Parameters to a prescription (thick lens or surfaces), the physical refusals of a parameter set,
the sensor plane, the traced sources, datasheet tables, moving zoom/focus groups and the
``.zmx``/CSV importers. It may import :mod:`mechdeconv_ros.optics` and
:mod:`mechdeconv_ros.schema`, never the model built from it; no ROS.
"""
