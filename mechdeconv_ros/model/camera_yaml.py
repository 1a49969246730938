# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A model's raw camera as camera_calibration_parsers YAML (what camera_info_manager loads).

``mechdeconv camera-info`` prints it: ``image_width``, ``image_height``, ``camera_name``,
``camera_matrix`` K (3x3), ``distortion_model`` and ``distortion_coefficients`` D (the
equivalent fit, :mod:`mechdeconv_ros.model.camera_info_fit`), ``rectification_matrix`` R = I
and ``projection_matrix`` P = ``[K_new | 0]`` (3x4): the same content the node publishes on
``camera_info``. Pure Python, no ROS.
"""

from __future__ import annotations

from typing import Any

from mechdeconv_ros.model.model import LensModel
import numpy as np
import yaml


def camera_info_yaml(model: LensModel, camera_name: str = 'mechdeconv') -> str:
    """
    Write the raw camera as camera_calibration_parsers YAML (what camera_info_manager loads).

    K and D describe the raw camera (D = the equivalent coefficients), R is the identity and
    P = ``[K_new | 0]``: the same content the node publishes on ``camera_info``.

    :param model: the lens model.
    :param camera_name: the ``camera_name`` field.
    :return: YAML text.
    """
    def matrix(rows: int, cols: int, data: Any) -> dict[str, Any]:
        return {'rows': rows, 'cols': cols,
                'data': [float(x) for x in np.asarray(data, dtype=np.float64).ravel()]}

    document = {
        'image_width': model.width,
        'image_height': model.height,
        'camera_name': camera_name,
        'camera_matrix': matrix(3, 3, model.K),
        'distortion_model': model.distortion_model,
        'distortion_coefficients': matrix(1, len(model.D), model.D),
        'rectification_matrix': matrix(3, 3, np.eye(3)),
        'projection_matrix': matrix(3, 4, model.P),
    }
    return yaml.safe_dump(document, sort_keys=False, default_flow_style=None)
