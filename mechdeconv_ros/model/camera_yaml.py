# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A model's raw camera as camera_calibration_parsers YAML (what camera_info_manager loads).

``mechdeconv camera-info`` prints it: ``image_width``, ``image_height``, ``camera_name``,
``camera_matrix`` K (3x3), ``distortion_model`` and ``distortion_coefficients`` D (the
equivalent fit, :mod:`mechdeconv_ros.model.camera_info_fit`), ``rectification_matrix`` R = I
and ``projection_matrix`` P = ``[K_new | 0]`` (3x4): the same content the node publishes on
``camera_info``. :func:`info_yaml` writes any CameraInfo contents (a stereo pair's, with its
R and P). Pure Python, no ROS.
"""

from __future__ import annotations

from typing import Any, Mapping

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
    return info_yaml({'width': model.width, 'height': model.height,
                      'distortion_model': model.distortion_model, 'D': model.D, 'K': model.K,
                      'R': np.eye(3), 'P': model.P}, camera_name)


def info_yaml(info: Mapping[str, Any], camera_name: str) -> str:
    """
    Write CameraInfo contents as camera_calibration_parsers YAML.

    :param info: ``width``, ``height``, ``distortion_model``, ``D``, ``K`` (9), ``R`` (9) and
        ``P`` (12), as :func:`mechdeconv_ros.model.stereo.stereo_camera_infos` gives them.
    :param camera_name: the ``camera_name`` field.
    :return: YAML text.
    """
    def matrix(rows: int, cols: int, data: Any) -> dict[str, Any]:
        return {'rows': rows, 'cols': cols,
                'data': [float(x) for x in np.asarray(data, dtype=np.float64).ravel()]}

    document = {
        'image_width': int(info['width']),
        'image_height': int(info['height']),
        'camera_name': camera_name,
        'camera_matrix': matrix(3, 3, info['K']),
        'distortion_model': str(info['distortion_model']),
        'distortion_coefficients': matrix(1, len(info['D']), info['D']),
        'rectification_matrix': matrix(3, 3, info['R']),
        'projection_matrix': matrix(3, 4, info['P']),
    }
    return yaml.safe_dump(document, sort_keys=False, default_flow_style=None)
