# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The demo camera publishes ``image_raw/compressed`` as image_transport's compressed plugin does.

Runs the camera in this process (its own rclpy Context on a private domain): the topic is the
RESOLVED ``image_raw`` plus ``/compressed`` (so a remapping of ``image_raw`` moves it), the
format string is the plugin's, and the payload decodes to the chart the raw transport sends.
The demo's ``--transport compressed`` runs the whole compressed path end to end.
"""

from __future__ import annotations

from pathlib import Path
import re
import subprocess
import sys
import time
from typing import Any, Iterator

from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.node.compressed import decode
from mechdeconv_ros.schema.params import load_params_file
from mechdeconv_ros.tools.demo_camera import Chart, convert_rgb, DemoCamera
from numpy.testing import assert_array_equal
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from ros_helpers import next_domain_id, REPO
from sensor_msgs.msg import CompressedImage

pytestmark = pytest.mark.ros

CASE2 = REPO / 'config' / 'case2.yaml'


@pytest.fixture
def context() -> Iterator[Context]:
    """Give each test its own rclpy Context on a private domain."""
    ctx = Context()
    rclpy.init(context=ctx, domain_id=next_domain_id())
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


def camera_overrides(**extra: object) -> list[Parameter]:
    """Return the Case 2 lens/sensor/scene parameters plus ``extra`` (dots in names: '__')."""
    values = load_params_file(CASE2)
    # (Empty arrays would be BYTE_ARRAY overrides: the arrays keep their declared [].)
    params = [Parameter(n, value=values[n]) for n in values
              if n.startswith(('lens.', 'sensor.', 'scene.'))
              and not isinstance(values[n], list)]     # rclpy infers no type from []
    return params + [Parameter(k.replace('__', '.'), value=v) for k, v in extra.items()]


def receive(context: Context, camera: DemoCamera, topic: str, count: int = 2,
            timeout: float = 10.0) -> list[CompressedImage]:
    """Spin the camera and a client until ``count`` messages arrived on ``topic``."""
    client = Node('compressed_camera_client', context=context)
    received: list[CompressedImage] = []
    client.create_subscription(CompressedImage, topic, received.append, qos_profile_sensor_data)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(camera)
    executor.add_node(client)
    try:
        deadline = time.monotonic() + timeout
        while len(received) < count and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()
        client.destroy_node()
    assert len(received) >= count, f'no CompressedImage on {topic}'
    return received


def expected_chart(encoding: str) -> Any:
    """Return the pixels the raw transport sends for the Case 2 lens."""
    model = build_model(load_params_file(CASE2), 640, 480)
    return convert_rgb(Chart(model).render(model), encoding)


def test_jpeg_follows_a_remapped_image_raw_and_decodes_to_the_chart(context: Context) -> None:
    camera = DemoCamera(context=context, cli_args=['--ros-args', '-r',
                                                   'image_raw:=/cam/image_raw'],
                        parameter_overrides=camera_overrides(
                            transport='compressed', rate_hz=50.0, encoding='rgb8'))
    try:
        msg = receive(context, camera, '/cam/image_raw/compressed')[-1]
    finally:
        camera.destroy_node()
    assert msg.format == 'rgb8; jpeg compressed bgr8'
    assert msg.header.frame_id == 'camera_optical_frame'
    assert msg.header.stamp.sec > 0
    decoded = decode(msg.format, msg.data)
    assert decoded.encoding.name == 'rgb8'
    expected = expected_chart('rgb8')
    assert decoded.pixels.shape == expected.shape
    assert abs(decoded.pixels.astype(float) - expected).mean() < 4.0   # quality 95


def test_png_is_lossless_and_mono16_stays_16_bit(context: Context) -> None:
    camera = DemoCamera(context=context, parameter_overrides=camera_overrides(
        transport='compressed', rate_hz=50.0, encoding='mono16',
        image_raw__compressed__format='png'))
    try:
        msg = receive(context, camera, 'image_raw/compressed')[-1]
    finally:
        camera.destroy_node()
    assert msg.format == 'mono16; png compressed '
    decoded = decode(msg.format, msg.data)
    assert_array_equal(decoded.pixels, expected_chart('mono16'))


def test_bad_transport_or_codec_is_refused(context: Context) -> None:
    with pytest.raises(ValueError, match='transport'):
        DemoCamera(context=context, parameter_overrides=camera_overrides(transport='h264'))
    camera = DemoCamera(context=context,
                        parameter_overrides=camera_overrides(transport='compressed'))
    try:
        result = camera.set_parameters_atomically(
            [Parameter('image_raw.compressed.format', value='tiff')])
        assert not result.successful and 'image_raw.compressed.format' in result.reason
        result = camera.set_parameters_atomically(
            [Parameter('image_raw.compressed.format', value='png')])
        assert result.successful
        assert camera._compressed is not None and camera._compressed.format.endswith('bgr8')
        assert 'png' in camera._compressed.format
    finally:
        camera.destroy_node()


def test_demo_with_compressed_transport_corrects_the_jpeg_stream(tmp_path: Path) -> None:
    from test_demo import blurred_difference, CHANGE, demo_env, read_rgb
    result = subprocess.run(
        [sys.executable, '-m', 'mechdeconv_ros.tools.demo', '--seconds', '1', '--transport',
         'compressed', '--out', str(tmp_path)],
        cwd=REPO, env=demo_env(), stdin=subprocess.DEVNULL, capture_output=True, text=True,
        timeout=120)
    log = result.stdout + result.stderr
    assert result.returncode == 0, log
    assert 'Traceback' not in log, log
    assert 'image_raw/compressed (JPEG)' in log, log
    decode_ms = [float(v) for v in re.findall(r'decode_time_ms_mean ([0-9.]+)', log)]
    assert decode_ms and all(v > 0.0 for v in decode_ms), log
    assert re.search(r'frames_undecodable 0\b', log), log
    for node in ('demo_camera', 'correct_node'):
        assert f'{node} exited with status 0' in log, log
    values = load_params_file(CASE2)
    before = build_model(values, 640, 480)
    after = build_model({**values, **CHANGE}, 640, 480)
    chart = Chart(before)
    raw, corrected, corrected_after = (read_rgb(tmp_path / n) for n in (
        'raw.png', 'corrected.png', 'corrected_after_change.png'))
    assert (blurred_difference(corrected, chart.texture)
            < 0.5 * blurred_difference(raw, chart.texture))
    expected_after = Rectifier(after).correct(chart.render(after))
    assert blurred_difference(corrected_after, expected_after) < 2.0     # JPEG quality 95
