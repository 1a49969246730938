# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
correct_node in a robot's graph: two cameras in two namespaces, and compressed input.

Two cameras: two correct_node processes, ``--ros-args -r __ns:=/left`` with config/case2.yaml
and ``-r __ns:=/right`` with config/cooke_triplet.yaml, on one domain. Each must correct its
own stream (``/left/image_raw`` -> ``/left/image_rect``) with its own lens (compared with the
core's Rectifier for that lens), a parameter set on ``/left/correct_node`` must change only
the left node, and the /diagnostics statuses must be named by the fully qualified node names.

Compressed input: ``image_transport:=compressed`` with ``-r image_raw:=/cam/image_raw``
subscribes ``/cam/image_raw/compressed`` (the resolved name plus ``/compressed``, as
image_transport names it); a JPEG and a 16-bit PNG frame are corrected exactly as the core
corrects the decoded pixels; a frame that does not decode, or names an encoding the node
cannot produce, is counted and the next good frame is corrected; the diagnostics carry the
decode time. ``image_rect/compressed`` carries the corrected frame as image_transport would
(JPEG by default, PNG after ``image_rect.compressed.format`` is set to png).
"""

from __future__ import annotations

from pathlib import Path
import signal
import time
from typing import Any, Iterator

from diagnostic_msgs.msg import DiagnosticArray
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model, LensModel
from mechdeconv_ros.node.compressed import decode, encode
from mechdeconv_ros.node.image_msgs import image_to_array
from mechdeconv_ros.schema.params import load_params_file
import numpy as np
import numpy.testing as npt
import pytest
from rclpy.parameter import Parameter
from ros_helpers import (
    BEST_EFFORT, make_image, next_domain_id, node_command, NodeProcess, REPO, ros_env,
    RosClient, stamp_of)
from sensor_msgs.msg import CompressedImage, Image

pytestmark = pytest.mark.ros

FOLLOW_IMAGES = ('sensor.width_px:=0', 'sensor.height_px:=0')
SIZE = (320, 240)
LENSES = {'left': REPO / 'config' / 'case2.yaml', 'right': REPO / 'config' / 'cooke_triplet.yaml'}


def lens_values(params_file: Path, **changes: Any) -> dict[str, Any]:
    """Return the values a node started with ``params_file`` and FOLLOW_IMAGES holds."""
    values = load_params_file(params_file)
    values.update({'sensor.width_px': 0, 'sensor.height_px': 0}, **changes)
    return values


def pattern(channels: int = 3, dtype: Any = np.uint8, seed: int = 0) -> np.ndarray:
    """Return a smooth seeded test image of SIZE (JPEG-friendly, so decoding stays close)."""
    width, height = SIZE
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width]
    base = (np.sin(x / 9.0 + rng.uniform(0, 6)) + np.cos(y / 7.0)) * 0.25 + 0.5
    top = np.iinfo(dtype).max
    img = (base * top).astype(dtype)
    if channels == 0:
        return img
    return np.dstack([np.roll(img, 11 * c, axis=1) for c in range(channels)])


def stop_all(procs: dict[str, NodeProcess]) -> None:
    """SIGINT every node; each must exit 0 without a traceback."""
    for name, proc in procs.items():
        code = proc.stop(signal.SIGINT)
        log = proc.output()
        assert code == 0, f'{name} exited with {code}:\n{log[-3000:]}'
        assert 'Traceback' not in log, log[-3000:]


class Collector:
    """Subscriptions of a client node: outputs by (topic, stamp), /diagnostics statuses."""

    def __init__(self, client: RosClient, topics: tuple[str, ...]) -> None:
        """Subscribe to each image_rect topic and to /diagnostics."""
        self.client = client
        self.images: dict[tuple[str, tuple[int, int]], Image] = {}
        self.statuses: dict[str, dict[str, str]] = {}
        for topic in topics:
            client.node.create_subscription(
                Image, topic, lambda m, t=topic: self.images.__setitem__((t, stamp_of(m)), m),
                BEST_EFFORT)
        client.node.create_subscription(DiagnosticArray, '/diagnostics', self._diag, 50)

    def _diag(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            self.statuses[status.name] = {kv.key: kv.value for kv in status.values}

    def exchange(self, pub: Any, msg: Any, topic: str, proc: NodeProcess,
                 timeout: float = 8.0) -> Image:
        """Publish ``msg`` (again every 0.3 s: best effort) until ``topic`` carries its stamp."""
        stamp = self.client.next_stamp(msg)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            pub.publish(msg)
            if self.client.spin_until(lambda: (topic, stamp) in self.images, 0.3):
                return self.images[(topic, stamp)]
        raise AssertionError(f'no {topic} for {stamp}; node log:\n' + proc.output()[-3000:])

    def status(self, name: str, predicate: Any = None, timeout: float = 5.0) -> dict[str, str]:
        """Return the latest values of the status ``name`` (that satisfy ``predicate``)."""
        self.statuses.pop(name, None)
        ok = self.client.spin_until(
            lambda: name in self.statuses and (predicate is None
                                               or predicate(self.statuses[name])), timeout)
        assert ok, f'no diagnostics status {name!r} (seen: {sorted(self.statuses)})'
        return self.statuses[name]


def rectified(image: Image) -> np.ndarray:
    """Return the pixels of an output Image."""
    pixels, _ = image_to_array(image)
    return pixels


def expected(model: LensModel, src: np.ndarray, depth: bool = False) -> np.ndarray:
    """Return what the core's Rectifier makes of ``src``."""
    return Rectifier(model).correct(src, nearest=depth)


# ---------------------------------------------------------------------------------------------
# Two cameras, two namespaces, two lenses
# ---------------------------------------------------------------------------------------------

def test_two_cameras_each_correct_their_own_stream_with_their_own_lens(tmp_path: Path) -> None:
    domain = next_domain_id()
    env = ros_env(domain)
    procs: dict[str, NodeProcess] = {}
    try:
        for side, params in LENSES.items():
            argv = node_command(params, *FOLLOW_IMAGES) + ['-r', f'__ns:=/{side}']
            procs[side] = NodeProcess(argv, env, tmp_path, name=side)
        with RosClient(domain, node_name='left/correct_node') as left, \
                RosClient(domain, name='right_client', node_name='right/correct_node') as right:
            left.wait_until_answering()
            right.wait_until_answering()
            out = Collector(left, ('/left/image_rect', '/right/image_rect'))
            pubs = {side: left.node.create_publisher(Image, f'/{side}/image_raw', BEST_EFFORT)
                    for side in LENSES}
            assert left.spin_until(lambda: all(p.get_subscription_count() > 0
                                               for p in pubs.values()), 15.0), \
                'the nodes did not subscribe to /left/image_raw and /right/image_raw'
            src = pattern()
            got = {}
            for side, params in LENSES.items():
                image = out.exchange(pubs[side], make_image(src, 'rgb8'), f'/{side}/image_rect',
                                     procs[side])
                got[side] = rectified(image)
                model = build_model(lens_values(params), *SIZE)
                npt.assert_array_equal(got[side], expected(model, src), err_msg=side)
            assert not np.array_equal(got['left'], got['right']), 'the two lenses must differ'

            # A set on /left/correct_node changes the left node only.
            before_right = right.get_parameters('scene.distance_mm')
            result = left.set_parameters(Parameter('scene.distance_mm', value=250.0))
            assert result[0].successful, result[0].reason
            assert left.get_parameters('scene.distance_mm') == {'scene.distance_mm': 250.0}
            assert right.get_parameters('scene.distance_mm') == before_right
            new_left = build_model(lens_values(LENSES['left'], **{'scene.distance_mm': 250.0}),
                                   *SIZE)
            deadline = time.monotonic() + 10.0
            while True:     # the rebuild runs after the reply: the next frames show it
                image = out.exchange(pubs['left'], make_image(src, 'rgb8'), '/left/image_rect',
                                     procs['left'])
                if np.array_equal(rectified(image), expected(new_left, src)):
                    break
                assert time.monotonic() < deadline, 'the left node never used its new lens'
            image = out.exchange(pubs['right'], make_image(src, 'rgb8'), '/right/image_rect',
                                 procs['right'])
            npt.assert_array_equal(rectified(image), got['right'])

            # Diagnostics: one status per node, named by its fully qualified name.
            for side in LENSES:
                values = out.status(f'/{side}/correct_node: lens correction',
                                    lambda v: int(v.get('frames_out', 0)) > 0)
                assert values['input_topic'] == f'/{side}/image_raw'
    finally:
        stop_all(procs)


# ---------------------------------------------------------------------------------------------
# Compressed input
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope='module')
def compressed_node(tmp_path_factory: pytest.TempPathFactory) -> Iterator[
        tuple[NodeProcess, RosClient, Collector, Any]]:
    """Run a node with image_transport:=compressed and image_raw remapped to /cam/image_raw."""
    tmp = tmp_path_factory.mktemp('compressed')
    domain = next_domain_id()
    argv = node_command(LENSES['left'], *FOLLOW_IMAGES, 'image_transport:=compressed') + [
        '-r', 'image_raw:=/cam/image_raw']
    proc = NodeProcess(argv, ros_env(domain), tmp, name='compressed')
    try:
        with RosClient(domain) as client:
            client.wait_until_answering()
            out = Collector(client, ('/image_rect',))
            pub = client.node.create_publisher(CompressedImage, '/cam/image_raw/compressed',
                                               BEST_EFFORT)
            assert client.spin_until(lambda: pub.get_subscription_count() > 0, 15.0), \
                'no subscription on /cam/image_raw/compressed:\n' + proc.output()[-3000:]
            raw = client.node.create_publisher(Image, '/cam/image_raw', BEST_EFFORT)
            assert raw.get_subscription_count() == 0, 'compressed mode must not take raw'
            yield proc, client, out, pub
    finally:
        stop_all({'compressed': proc})


def compressed_msg(fmt: str, data: bytes) -> CompressedImage:
    """Return a CompressedImage with this format and payload."""
    msg = CompressedImage()
    msg.header.frame_id = 'cam_optical'
    msg.format = fmt
    msg.data = data
    return msg


STATUS = '/correct_node: lens correction'


@pytest.mark.parametrize('encoding, codec, channels, dtype', [
    ('rgb8', 'jpeg', 3, np.uint8),
    ('bgr8', 'png', 3, np.uint8),
    ('mono16', 'png', 0, np.uint16),
    ('mono8', 'jpeg', 0, np.uint8),
], ids=['rgb8-jpeg', 'bgr8-png', 'mono16-png', 'mono8-jpeg'])
def test_compressed_frames_are_decoded_and_corrected(
        compressed_node: Any, encoding: str, codec: str, channels: int, dtype: Any) -> None:
    proc, client, out, pub = compressed_node
    src = pattern(channels, dtype)
    fmt, data = encode(src, encoding, codec, jpeg_quality=90)
    image = out.exchange(pub, compressed_msg(fmt, data), '/image_rect', proc)
    assert image.encoding == encoding and image.header.frame_id == 'cam_optical'
    decoded = decode(fmt, data)
    model = build_model(lens_values(LENSES['left']), *SIZE)
    npt.assert_array_equal(rectified(image), expected(model, decoded.pixels))
    values = out.status(STATUS, lambda v: v.get('decode_time_ms_last', 'nan') != 'nan')
    assert values['image_transport'] == 'compressed'
    assert values['input_topic'] == '/cam/image_raw/compressed'
    assert float(values['decode_time_ms_last']) > 0.0


def test_bad_compressed_frames_are_counted_and_the_next_good_one_is_corrected(
        compressed_node: Any) -> None:
    proc, client, out, pub = compressed_node
    before = out.status(STATUS)
    bad = [compressed_msg('bgr8; jpeg compressed bgr8', bytes(range(200))),
           compressed_msg('bgr16; png compressed bgr16', encode(pattern(), 'bgr8', 'png')[1])]
    for msg in bad:
        client.next_stamp(msg)
        pub.publish(msg)
        client.spin_for(0.2)
    values = out.status(STATUS, lambda v: (
        int(v['frames_undecodable']) > int(before['frames_undecodable'])
        and int(v['rejected_encodings']) > int(before['rejected_encodings'])))
    assert 'neither JPEG nor PNG' in values['last_error'] or 'bgr16' in values['last_error']
    assert values['last_rejected_encoding'] == 'bgr16'
    src = pattern(seed=3)
    fmt, data = encode(src, 'bgr8', 'jpeg')
    image = out.exchange(pub, compressed_msg(fmt, data), '/image_rect', proc)
    model = build_model(lens_values(LENSES['left']), *SIZE)
    npt.assert_array_equal(rectified(image), expected(model, decode(fmt, data).pixels))
    assert 'Traceback' not in proc.output()


def test_image_rect_compressed_follows_its_parameters(compressed_node: Any) -> None:
    proc, client, out, pub = compressed_node
    received: dict[tuple[int, int], CompressedImage] = {}
    client.node.create_subscription(
        CompressedImage, '/image_rect/compressed',
        lambda m: received.__setitem__(stamp_of(m), m), BEST_EFFORT)
    model = build_model(lens_values(LENSES['left']), *SIZE)
    src = pattern(seed=5)
    fmt, data = encode(src, 'bgr8', 'png')
    want = expected(model, decode(fmt, data).pixels)
    try:
        for codec in ('jpeg', 'png'):
            if codec == 'png':
                result = client.set_parameters(
                    Parameter('image_rect.compressed.format', value='png'))
                assert result[0].successful, result[0].reason
            deadline = time.monotonic() + 8.0
            while True:
                msg = compressed_msg(fmt, data)
                stamp = client.next_stamp(msg)
                pub.publish(msg)
                client.spin_until(lambda: stamp in received, 0.5)
                if stamp in received and codec in received[stamp].format:
                    break
                assert time.monotonic() < deadline, f'no {codec} image_rect/compressed'
            got = received[stamp]
            assert got.format == f'bgr8; {codec} compressed bgr8'
            assert got.header.frame_id == 'cam_optical'
            pixels = decode(got.format, got.data).pixels
            if codec == 'png':
                npt.assert_array_equal(pixels, want)
            else:
                assert np.abs(pixels.astype(float) - want).mean() < 3.0     # quality 95
    finally:
        client.set_parameters(Parameter('image_rect.compressed.format', value='jpeg'))
    values = out.status(STATUS, lambda v: int(v['frames_out_compressed']) >= 2)
    assert int(values['frames_out_compressed']) >= 2
