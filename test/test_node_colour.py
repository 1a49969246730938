# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
End-to-end tests of correct_node with colour input, real rclpy (issue #20).

Bayer frames (``bayer_*8`` / ``bayer_*16``) published on ``image_raw`` come out on
``image_rect`` as ``rgb8`` / ``rgb16``, pixel for pixel what ``demosaic`` + ``Rectifier`` give
in-process; the ``debayer`` parameter is set as ``ros2 param set`` does; odd-sized and short
mosaics are refused and counted as malformed frames. Lateral colour: switched on with the
glass set in one atomic request, rgb8, bgr8 and demosaiced Bayer frames are corrected per
channel (each channel with its colour's map, the same camera_info), mono frames with the one
map (logged once); the switch without glass names is refused naming it. The node runs in its
own process, as in test_node.py, and must exit 0 on SIGINT.
"""

from __future__ import annotations

import time
from typing import Any, Iterator

from mechdeconv_ros.imaging.debayer import demosaic
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.node.image_msgs import image_to_array
from mechdeconv_ros.schema.params import load_params_file
import numpy as np
import numpy.testing as npt
import pytest
from rclpy.parameter import Parameter
from ros_helpers import make_image, next_domain_id, node_command, running_node
from test_node import (
    assert_camera_infos, case2_params, expected_model, FOLLOW_IMAGES, Harness, Outputs)

pytestmark = pytest.mark.ros

SIZE = (320, 240)


def mosaic(height: int, width: int, dtype: type) -> np.ndarray:
    """Return a seeded smooth Bayer frame with noise, so the three methods differ."""
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:height, 0:width]
    top = np.iinfo(dtype).max
    base = 0.5 + 0.3 * np.sin(x / 13.0) * np.cos(y / 9.0) + rng.uniform(-0.1, 0.1, (height, width))
    return np.round(np.clip(base, 0.0, 1.0) * top).astype(dtype)


@pytest.fixture(scope='module')
def harness(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Harness]:
    tmp = tmp_path_factory.mktemp('colour')
    params = case2_params(tmp)
    domain = next_domain_id()
    values = load_params_file(params)
    values.update({'sensor.width_px': 0, 'sensor.height_px': 0})
    with running_node(node_command(params, *FOLLOW_IMAGES), domain, tmp) as (proc, client):
        yield Harness(proc, client, values)


@pytest.fixture
def outputs(harness: Harness) -> Iterator[Outputs]:
    out = Outputs(harness.client)
    harness.wait_subscribed()
    try:
        yield out
    finally:
        out.close()


def _set_debayer(harness: Harness, method: str) -> None:
    result = harness.client.set_parameters(Parameter('debayer', Parameter.Type.STRING, method))
    assert result[0].successful, result[0].reason


@pytest.mark.parametrize(('encoding', 'method', 'pad'), [
    ('bayer_rggb8', 'vng', 0),
    ('bayer_bggr8', 'bilinear', 4),
    ('bayer_gbrg8', 'edge_aware', 0),
    ('bayer_grbg16', 'bilinear', 6),
    ('bayer_rggb16', 'edge_aware', 0),
])
def test_bayer_frames_are_demosaiced_and_corrected(harness: Harness, outputs: Outputs,
                                                   encoding: str, method: str, pad: int) -> None:
    width, height = SIZE
    sixteen = encoding.endswith('16')
    raw = mosaic(height, width, np.uint16 if sixteen else np.uint8)
    _set_debayer(harness, method)
    try:
        result = harness.exchange(outputs, make_image(raw, encoding, pad=pad))
    finally:
        _set_debayer(harness, 'vng')
    image = result['image']
    assert image.encoding == ('rgb16' if sixteen else 'rgb8')
    got, _ = image_to_array(image)
    model = expected_model(harness.values, width, height)
    expected = Rectifier(model).correct(demosaic(raw, encoding[6:10], method))
    npt.assert_array_equal(got, expected)
    assert result['info'].width == width


def test_sixteen_bit_vng_is_edge_aware_and_logged_once(
        harness: Harness, outputs: Outputs) -> None:
    width, height = SIZE
    raw = mosaic(height, width, np.uint16)
    for _ in range(2):
        result = harness.exchange(outputs, make_image(raw, 'bayer_bggr16'))
    got, _ = image_to_array(result['image'])
    model = expected_model(harness.values, width, height)
    npt.assert_array_equal(got, Rectifier(model).correct(demosaic(raw, 'bggr', 'edge_aware')))
    log = harness.proc.output()
    assert log.count("debayer: OpenCV's VNG demosaics 8-bit mosaics only") == 1, log[-2000:]


def test_odd_and_short_mosaics_are_refused_and_counted(harness: Harness,
                                                       outputs: Outputs) -> None:
    width, height = SIZE
    before = harness.diag()
    odd = make_image(mosaic(height, width - 1, np.uint8), 'bayer_rggb8')
    harness.expect_no_output(outputs, odd)
    short = make_image(mosaic(height, width, np.uint8), 'bayer_grbg8')
    del short.data[-width:]
    harness.expect_no_output(outputs, short)
    harness.exchange(outputs, make_image(mosaic(height, width, np.uint8), 'bayer_grbg8'))
    after = harness.diag()
    assert int(after['frames_failed']) >= int(before['frames_failed']) + 2
    assert int(after['rejected_encodings']) == int(before['rejected_encodings'])
    log = harness.proc.output()
    assert 'a Bayer mosaic needs an even width and height' in log
    assert harness.proc.running()


def test_debayer_parameter_refuses_unknown_methods(harness: Harness) -> None:
    result = harness.client.set_parameters(Parameter('debayer', Parameter.Type.STRING, 'ahd'))
    assert not result[0].successful
    assert 'debayer' in result[0].reason


#: Case 2 in N-BK7, focused at 550 nm: about 1 px of lateral colour at the raw corner.
GLASS = {'lens.glass': 'SCHOTT:N-BK7', 'lens.wavelength_nm': 550.0}


def _lateral(harness: Harness, on: bool) -> None:
    params = [Parameter('lens.glass', Parameter.Type.STRING, GLASS['lens.glass'] if on else ''),
              Parameter('lens.wavelength_nm', Parameter.Type.DOUBLE,
                        GLASS['lens.wavelength_nm'] if on else 587.56),
              Parameter('output.lateral_color_correction', Parameter.Type.BOOL, on)]
    result = harness.client.set_parameters_atomically(*params)
    assert result.successful, result.reason
    harness.values.update({p.name: p.value for p in params})


def _until_lateral(harness: Harness, outputs: Outputs, msg: Any, expected: np.ndarray,
                   timeout: float = 8.0) -> dict[str, Any]:
    """Exchange frames until the node's output is the expected one (the rebuild is async)."""
    deadline = time.monotonic() + timeout
    while True:
        result = harness.exchange(outputs, msg)
        got, _ = image_to_array(result['image'])
        if np.array_equal(got, expected) or time.monotonic() > deadline:
            npt.assert_array_equal(got, expected)
            return result


def test_lateral_colour_corrects_each_channel_with_its_own_map(
        harness: Harness, outputs: Outputs) -> None:
    width, height = SIZE
    rng = np.random.default_rng(1)
    src = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
    try:
        _lateral(harness, True)
        model = expected_model(harness.values, width, height)
        lateral = Rectifier(model)
        assert lateral.colour is not None
        plain = Rectifier(model, lateral=False)
        rgb = lateral.correct(src, colours=(0, 1, 2))
        assert not np.array_equal(rgb, plain.correct(src)), 'the lens must show lateral colour'
        result = _until_lateral(harness, outputs, make_image(src, 'rgb8'), rgb)
        assert_camera_infos(result, model)
        # bgr8: the same pixels in the other order get each its colour's map.
        bgr = src[..., ::-1].copy()
        result = harness.exchange(outputs, make_image(bgr, 'bgr8'))
        got, _ = image_to_array(result['image'])
        npt.assert_array_equal(got, lateral.correct(bgr, colours=(2, 1, 0)))
        npt.assert_array_equal(got[..., ::-1], rgb)
        # A Bayer frame: demosaiced, then per channel.
        raw = mosaic(height, width, np.uint8)
        result = harness.exchange(outputs, make_image(raw, 'bayer_rggb8'))
        got, _ = image_to_array(result['image'])
        npt.assert_array_equal(got, lateral.correct(demosaic(raw, 'rggb', 'vng'),
                                                    colours=(0, 1, 2)))
        # mono8 ignores the switch: the one map, and one log line however many frames.
        mono = src[..., 1].copy()
        for _ in range(2):
            result = harness.exchange(outputs, make_image(mono, 'mono8'))
        got, _ = image_to_array(result['image'])
        npt.assert_array_equal(got, plain.correct(mono))
        log = harness.proc.output()
        assert log.count('mono8 has no known colour channels') == 1, log[-2000:]
        assert 'largest R-B separation on the raw image' in log
    finally:
        _lateral(harness, False)


def test_lateral_colour_without_glass_is_refused_naming_it(harness: Harness) -> None:
    result = harness.client.set_parameters(
        Parameter('output.lateral_color_correction', Parameter.Type.BOOL, True))[0]
    assert not result.successful
    assert 'output.lateral_color_correction' in result.reason
    assert 'lens.glass' in result.reason
