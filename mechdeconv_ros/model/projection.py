# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The one public projection: scene direction <-> raw pixel, for any lens, pose and port.

Frames and signs (docs/design.md section 1): the camera's optical frame is REP-103's, X right,
Y down, Z ahead along the lens axis; a scene direction is a unit vector ``d = (x, y, z)`` in
it (``z <= 0`` is behind the lens plane: a fisheye sees past 90 deg). A raw pixel is
``(u, v)``, u along the rows (right), v down the columns, the centre of the top-left pixel at
(0, 0). The scene is at ``scene.distance_mm`` (0: at infinity, directions).

- :func:`pixels_of` (forward): the pixel where the chief ray of each direction meets the
  sensor, through the lens, the sensor's pose and any port; NaN where no chief ray passes.
- :func:`directions_of` (inverse): the unit direction each raw pixel sees; NaN outside the
  traced field.

Both are what ``mechdeconv project``, the remap and the self-check compute; nothing else in
the package should solve the chief-ray lines for a pose itself.
"""

from __future__ import annotations

from typing import Any

from mechdeconv_ros.lenses.lens_errors import FloatArray
from mechdeconv_ros.model.assembly import project_angles, unproject_angles
from mechdeconv_ros.model.underwater import exact_pixels, is_exact_3d
import numpy as np


def pixels_of(model: Any, directions: FloatArray) -> FloatArray:
    """
    Return the raw pixel of each scene direction.

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param directions: ``(..., 3)`` directions in the optical frame (need not be unit).
    :return: ``(..., 2)`` raw pixels ``(u, v)``; NaN where no chief ray passes.
    """
    d = np.asarray(directions, dtype=np.float64)
    norm = np.linalg.norm(d, axis=-1)
    with np.errstate(invalid='ignore', divide='ignore'):
        z = np.clip(d[..., 2] / norm, -1.0, 1.0)
        theta = np.arccos(z)
        phi = np.arctan2(d[..., 1], d[..., 0])
    if is_exact_3d(model):
        # Traced exactly in 3-D through the port, scene at scene.distance_mm (0: infinity,
        # any angle; a finite scene plane has no point at z <= 0: NaN).
        u, v = exact_pixels(model, d)
    else:
        u, v = project_angles(model, theta, phi)
    return np.stack([np.asarray(u, float), np.asarray(v, float)], axis=-1)


def directions_of(model: Any, pixels: FloatArray) -> FloatArray:
    """
    Return the unit scene direction each raw pixel sees.

    :param model: a :class:`~mechdeconv_ros.model.model.LensModel`.
    :param pixels: ``(..., 2)`` raw pixels ``(u, v)``.
    :return: ``(..., 3)`` unit directions in the optical frame; NaN outside the traced field.
    """
    p = np.asarray(pixels, dtype=np.float64)
    theta, phi = unproject_angles(model, p[..., 0], p[..., 1])
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)
