# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
correct_node with the sensor as assembled: axis offset and tilt set by ``ros2 param set``.

Real rclpy, the node in its own process (the harness of test_node.py, started once for this
module). An offset and a tilt set through the real /correct_node/set_parameters service
rebuild the model: camera_info carries K with the principal point at the traced axis, and
image_rect equals what ``mechdeconv correct`` writes for the same parameters (the CLI run
in-process). An offset that puts the axis off the sensor is refused naming the parameter, and
the model stays.
"""

from __future__ import annotations

from pathlib import Path

import cv2
from mechdeconv_ros.node.image_msgs import image_to_array
from mechdeconv_ros.schema.params import to_params_yaml
from mechdeconv_ros.tools.cli import main
import numpy as np
import pytest
from ros_helpers import make_image
from test_node import (  # noqa: F401 - harness, outputs: fixtures of this module too
    _exchange_until_model, assert_camera_infos, double, expected_model, Harness, harness,
    Outputs, outputs, SMALL, test_pattern)

pytestmark = pytest.mark.ros

POSE = {'sensor.axis_offset_x_mm': 0.04, 'sensor.axis_offset_y_mm': -0.025,
        'sensor.tilt_x_deg': 0.8, 'sensor.tilt_y_deg': -0.5}


def test_offset_and_tilt_rebuild_as_the_cli_corrects(
        harness: Harness, outputs: Outputs, tmp_path: Path) -> None:  # noqa: F811
    width, height = SMALL
    src = test_pattern(width, height)
    msg = make_image(src, 'mono8')
    try:
        for name, value in POSE.items():
            results = harness.client.set_parameters(double(name, value))     # ros2 param set
            assert [r.successful for r in results] == [True], results[0].reason
        harness.values.update(POSE)
        model = expected_model(harness.values, width, height)
        got = _exchange_until_model(harness, outputs, msg, model)
        assert_camera_infos(got, model)
        px, py = model.pixel_mm
        assert got['info'].k[2] == pytest.approx((width - 1) / 2 + 0.04 / px)
        assert got['info'].k[5] == pytest.approx((height - 1) / 2 - 0.025 / py)
        image, _ = image_to_array(got['image'])

        # mechdeconv correct, same parameters, same frame.
        params = tmp_path / 'params.yaml'
        params.write_text(to_params_yaml(harness.values))
        raw, corrected = tmp_path / 'raw.png', tmp_path / 'corrected.png'
        assert cv2.imwrite(str(raw), src)
        assert main(['correct', '--params', str(params), str(raw), str(corrected)]) == 0
        cli = cv2.imread(str(corrected), cv2.IMREAD_UNCHANGED)
        assert cli.shape == image.shape
        assert float(np.mean(np.abs(cli.astype(float) - image.astype(float)))) <= 1.0
        assert not np.array_equal(image, src)

        # Off the sensor: refused naming the parameter; the model stays.
        revision = harness.revision()
        results = harness.client.set_parameters(double('sensor.axis_offset_x_mm', 5.0))
        assert not results[0].successful
        assert 'sensor.axis_offset_x_mm' in results[0].reason
        assert 'off the sensor' in results[0].reason
        assert harness.client.get_parameters('sensor.axis_offset_x_mm') == {
            'sensor.axis_offset_x_mm': 0.04}
        assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)
        assert harness.revision() == revision
    finally:
        restore = harness.client.set_parameters_atomically(
            *(double(name, 0.0) for name in POSE))
        assert restore.successful, restore.reason
        harness.values.update(dict.fromkeys(POSE, 0.0))
    model = expected_model(harness.values, width, height)
    assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)
