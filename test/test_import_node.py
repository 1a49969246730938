# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A params file written by ``mechdeconv import`` runs correct_node as it is.

A real vendor file (the Edmund 55278 achromat pair, UTF-16, obsolete glass names) is imported
by the CLI in this process; correct_node is started on it with ``--ros-args --params-file``
(real rclpy, own process group, pid-derived ROS_DOMAIN_ID, stopped by SIGINT, exit 0). Its
parameters read back as written, and its ``camera_info`` for a frame carries the K and D that
``build_model`` computes in-process from the same file.
"""

from __future__ import annotations

from pathlib import Path
import signal

from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import load_params_file
from mechdeconv_ros.tools.cli import main
import numpy as np
import numpy.testing as npt
import pytest
from ros_helpers import (
    BEST_EFFORT, make_image, next_domain_id, node_command, NodeProcess, ros_env, RosClient)
from sensor_msgs.msg import CameraInfo, Image

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[1]


def test_imported_params_file_runs_the_node(tmp_path: Path, capsys) -> None:
    params = tmp_path / 'edmund_55278.yaml'
    assert main(['import', str(ROOT / 'test' / 'data' / 'zmx' / 'edmund_55278.zmx'),
                 '-o', str(params)]) == 0
    capsys.readouterr()
    values = load_params_file(params)
    width, height = 320, 240
    expected = build_model(values, width, height)
    domain = next_domain_id()
    with NodeProcess(node_command(params), ros_env(domain), tmp_path) as proc:
        with RosClient(domain) as client:
            client.wait_until_answering()
            got = client.get_parameters('lens.surfaces.radius_mm', 'lens.stop_surface',
                                        'lens.surfaces.refractive_index',
                                        'lens.surfaces.glass', 'lens.wavelength_nm',
                                        'lens.image_distance_mm')
            assert list(got['lens.surfaces.glass']) == values['lens.surfaces.glass']
            assert 'SCHOTT:N-BK7' in values['lens.surfaces.glass']
            assert got['lens.wavelength_nm'] == values['lens.wavelength_nm'] == 587.6
            assert got['lens.image_distance_mm'] == values['lens.image_distance_mm'] > 40.0
            npt.assert_array_equal(got['lens.surfaces.radius_mm'],
                                   values['lens.surfaces.radius_mm'])
            npt.assert_array_equal(got['lens.surfaces.refractive_index'],
                                   values['lens.surfaces.refractive_index'])
            assert got['lens.stop_surface'] == values['lens.stop_surface']
            infos: list[CameraInfo] = []
            client.node.create_subscription(CameraInfo, 'camera_info', infos.append,
                                            BEST_EFFORT)
            pub = client.node.create_publisher(Image, 'image_raw', BEST_EFFORT)
            frame = make_image(np.full((height, width), 128, np.uint8), 'mono8')

            def sent() -> bool:
                pub.publish(frame)
                client.spin_for(0.1)
                return bool(infos)

            assert client.spin_until(sent, 30.0), 'no camera_info from the imported lens'
            npt.assert_allclose(infos[-1].k, expected.K.ravel(), rtol=1e-9)
            npt.assert_allclose(infos[-1].d, expected.D, rtol=1e-7, atol=1e-12)
        code = proc.stop(signal.SIGINT)
        log = proc.output()
    assert code == 0, log[-3000:]
    assert 'Traceback' not in log, log[-3000:]
