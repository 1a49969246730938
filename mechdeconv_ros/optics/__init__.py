# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Geometric optics of rotationally symmetric lenses, knowing nothing of cameras (layer 1).

Surfaces (sag, intersection, refraction), prescriptions and their paraxial data, the chief-ray
trace and the skew-ray trace, glass by name, the paper's thick lens, its scene constraints and
the relative illumination a traced lens gives. Pure numpy; it imports only its own modules and
:mod:`mechdeconv_ros.schema`.
"""
