# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
End-to-end tests of correct_node with real rclpy: the node runs as its own process.

The node under test is started once per module (``python -m mechdeconv_ros.node.correct_node
--ros-args --params-file config/case2.yaml -p ...``) in its own process group, on a
pid-derived ROS_DOMAIN_ID, with discovery limited to localhost and the package's Fast DDS
profile; it is always stopped by SIGINT to its PID and must exit with code 0. A client node in
this process publishes frames on ``image_raw``, collects ``image_rect``, ``camera_info`` and
``camera_info_rect`` by stamp, reads ``/diagnostics`` and calls the node's parameter services
exactly as ``ros2 param set`` does. Expected K, D, P and pixels are computed in-process with
``build_model`` and ``Rectifier`` from the same values.
"""

from __future__ import annotations

from pathlib import Path
import signal
import statistics
import subprocess
import sys
import textwrap
import time
from typing import Any, Iterator
import xml.etree.ElementTree as ElementTree

from diagnostic_msgs.msg import DiagnosticArray
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model, LensModel
from mechdeconv_ros.node.image_msgs import image_to_array
from mechdeconv_ros.schema.params import defaults, load_params_file, to_params_yaml
import numpy as np
import numpy.testing as npt
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_helpers import (
    BEST_EFFORT, FASTDDS_PROFILE, make_image, next_domain_id, node_command, NodeProcess, REPO,
    ros_env, RosClient, running_node, stamp_of)
from sensor_msgs.msg import CameraInfo, Image

pytestmark = pytest.mark.ros

#: Follow the image size (case2.yaml fixes 640x480) so each test can pick its frame size.
FOLLOW_IMAGES = ('sensor.width_px:=0', 'sensor.height_px:=0')
SMALL = (320, 240)


def case2_params(tmp_dir: Path) -> Path:
    """Return config/case2.yaml, or an equivalent written to ``tmp_dir`` if it is absent."""
    path = REPO / 'config' / 'case2.yaml'
    if path.exists():
        return path
    fallback = tmp_dir / 'case2.yaml'
    fallback.write_text(to_params_yaml(defaults()))
    return fallback


def double(name: str, value: float) -> Parameter:
    """Return a DOUBLE parameter."""
    return Parameter(name, Parameter.Type.DOUBLE, float(value))


def expected_model(values: dict[str, Any], width: int, height: int) -> LensModel:
    """Build the model the node should be using, in-process."""
    return build_model(values, width, height)


def test_pattern(width: int, height: int, channels: int = 0,
                 dtype: Any = np.uint8) -> np.ndarray:
    """Return a seeded random image with smooth structure (so interpolation matters)."""
    rng = np.random.default_rng(0)
    shape = (height, width) if channels == 0 else (height, width, channels)
    if np.dtype(dtype) == np.float32:
        return rng.choice(np.array([0.5, 1.25, 2.0, 3.5, 7.0], np.float32), size=shape)
    top = np.iinfo(dtype).max
    return rng.integers(0, top, size=shape, endpoint=True).astype(dtype)


test_pattern.__test__ = False       # type: ignore[attr-defined] - a helper, not a test


class Outputs:
    """Subscriptions to the node's three outputs, collected by stamp; plus /diagnostics."""

    def __init__(self, client: RosClient) -> None:
        """Subscribe (which makes a lazy node subscribe to image_raw)."""
        self.client = client
        self.by_stamp: dict[tuple[int, int], dict[str, Any]] = {}
        self.arrivals: list[tuple[float, str, Any]] = []
        node = client.node
        self._subs = [
            node.create_subscription(Image, 'image_rect', self._collector('image'),
                                     BEST_EFFORT),
            node.create_subscription(CameraInfo, 'camera_info', self._collector('info'),
                                     BEST_EFFORT),
            node.create_subscription(CameraInfo, 'camera_info_rect',
                                     self._collector('info_rect'), BEST_EFFORT),
        ]

    def _collector(self, kind: str) -> Any:
        def store(msg: Any) -> None:
            self.by_stamp.setdefault(stamp_of(msg), {})[kind] = msg
            self.arrivals.append((time.monotonic(), kind, msg))
        return store

    def close(self) -> None:
        """Unsubscribe."""
        for sub in self._subs:
            self.client.node.destroy_subscription(sub)
        self._subs = []

    def complete(self, stamp: tuple[int, int]) -> bool:
        """Return True when all three outputs of a stamp arrived."""
        return len(self.by_stamp.get(stamp, {})) == 3


class Harness:
    """The node process, the client, its image_raw publisher and a diagnostics reader."""

    def __init__(self, proc: NodeProcess, client: RosClient, values: dict[str, Any]) -> None:
        """Create the image publisher and the diagnostics subscription."""
        self.proc = proc
        self.client = client
        self.values = values                # what the node's parameters are now
        self.pub = client.node.create_publisher(Image, 'image_raw', BEST_EFFORT)
        self.diagnostics: list[DiagnosticArray] = []
        client.node.create_subscription(DiagnosticArray, '/diagnostics',
                                        self.diagnostics.append, 10)

    def wait_subscribed(self, timeout: float = 10.0) -> None:
        """Wait until the node subscribes to image_raw (after an output subscriber appears)."""
        assert self.client.spin_until(lambda: self.pub.get_subscription_count() > 0, timeout), \
            'the node did not subscribe to image_raw'

    def exchange(self, outputs: Outputs, msg: Image, timeout: float = 6.0) -> dict[str, Any]:
        """Publish a frame (again every 0.3 s: best effort) until its three outputs arrive."""
        stamp = self.client.next_stamp(msg)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.pub.publish(msg)
            if self.client.spin_until(lambda: outputs.complete(stamp), 0.3):
                return outputs.by_stamp[stamp]
        raise AssertionError(f'no output for the frame {stamp} within {timeout} s; node log:\n'
                             + self.proc.output()[-3000:])

    def expect_no_output(self, outputs: Outputs, msg: Image, seconds: float = 1.0) -> None:
        """Publish a frame a few times and check that nothing comes out for it."""
        stamp = self.client.next_stamp(msg)
        for _ in range(3):
            self.pub.publish(msg)
            self.client.spin_for(seconds / 3)
        assert stamp not in outputs.by_stamp

    def diag(self, timeout: float = 3.0) -> dict[str, str]:
        """Return the key/values of the next diagnostics message."""
        return self.client.next_diagnostics(self.diagnostics, timeout)

    def revision(self) -> int:
        """Return the model revision the node reports (fresh diagnostics)."""
        return int(self.diag()['model_revision'])


@pytest.fixture(scope='module')
def harness(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Harness]:
    tmp = tmp_path_factory.mktemp('node')
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


def assert_camera_infos(result: dict[str, Any], model: LensModel) -> None:
    """Check both CameraInfos against a model computed in-process."""
    info, rect = result['info'], result['info_rect']
    assert (info.width, info.height) == (model.width, model.height)
    assert info.distortion_model == model.distortion_model
    npt.assert_allclose(info.k, model.K.ravel(), rtol=1e-9)
    npt.assert_allclose(info.d, model.D, rtol=1e-7, atol=1e-12)
    npt.assert_allclose(info.r, np.eye(3).ravel())
    npt.assert_allclose(info.p, model.P.ravel(), rtol=1e-9)
    assert (rect.width, rect.height) == (model.out_width, model.out_height)
    assert rect.distortion_model == 'plumb_bob'
    npt.assert_array_equal(rect.d, np.zeros(5))
    npt.assert_allclose(rect.k, model.K_new.ravel(), rtol=1e-9)
    npt.assert_allclose(np.reshape(rect.p, (3, 4))[:, :3], np.reshape(rect.k, (3, 3)))
    npt.assert_allclose(rect.r, np.eye(3).ravel())


def _exchange_until_model(harness: Harness, outputs: Outputs, msg: Image,
                          model: LensModel, timeout: float = 5.0,
                          check: Any = None) -> dict[str, Any]:
    """Exchange frames until the node's camera_info carries ``model``'s D (and ``check``)."""
    deadline = time.monotonic() + timeout
    while True:
        result = harness.exchange(outputs, msg)
        done = np.allclose(result['info'].d, model.D, rtol=1e-7, atol=1e-12)
        if (done and (check is None or check(result))) or time.monotonic() > deadline:
            return result


# ---------------------------------------------------------------------------------------------
# Frames in, three outputs out
# ---------------------------------------------------------------------------------------------

def test_frame_gives_image_rect_and_both_camera_infos(harness: Harness,
                                                      outputs: Outputs) -> None:
    width, height = SMALL
    src = test_pattern(width, height, 3)
    msg = make_image(src, 'rgb8', frame_id='cam_optical')
    result = harness.exchange(outputs, msg)
    model = expected_model(harness.values, width, height)
    for kind in ('image', 'info', 'info_rect'):
        assert stamp_of(result[kind]) == stamp_of(msg)
        assert result[kind].header.frame_id == 'cam_optical'
    image = result['image']
    assert image.encoding == 'rgb8'
    assert (image.width, image.height) == (model.out_width, model.out_height)
    got, _ = image_to_array(image)
    npt.assert_array_equal(got, Rectifier(model).correct(src))
    assert not np.array_equal(got, src), 'the correction must move pixels'
    assert_camera_infos(result, model)


@pytest.mark.parametrize(('encoding', 'channels', 'dtype', 'pad', 'bigendian'), [
    ('mono8', 0, np.uint8, 0, False),
    ('bgra8', 4, np.uint8, 8, False),
    ('16UC1', 0, np.uint16, 6, False),
    ('mono16', 0, np.uint16, 2, True),
    ('32FC1', 0, np.float32, 0, False),
    ('32FC1', 0, np.float32, 4, True),
], ids=['mono8', 'bgra8-padded', '16UC1-padded', 'mono16-bigendian', '32FC1',
        '32FC1-bigendian-padded'])
def test_encodings_are_corrected(harness: Harness, outputs: Outputs, encoding: str,
                                 channels: int, dtype: Any, pad: int, bigendian: bool) -> None:
    width, height = SMALL
    src = test_pattern(width, height, channels, dtype)
    msg = make_image(src, encoding, pad=pad, bigendian=bigendian)
    result = harness.exchange(outputs, msg)
    image = result['image']
    assert image.encoding == encoding
    got, enc = image_to_array(image)
    model = expected_model(harness.values, width, height)
    depth = encoding in ('16UC1', '32FC1')
    npt.assert_array_equal(got, Rectifier(model).correct(src, nearest=depth))
    if depth:
        # Nearest neighbour: every output value is an input value (or 0 outside the field).
        assert set(np.unique(got)) <= set(np.unique(src)) | {0}
        assert enc.depth


def test_refused_frames_are_counted_and_the_next_good_one_is_corrected(
        harness: Harness, outputs: Outputs) -> None:
    width, height = SMALL
    before = harness.diag()
    bayer = make_image(test_pattern(width, height), 'bayer_rgbg8')
    harness.expect_no_output(outputs, bayer)
    good = make_image(test_pattern(width, height), 'mono8')
    harness.exchange(outputs, good)
    short = make_image(test_pattern(width, height), 'mono8')
    del short.data[-width:]
    harness.expect_no_output(outputs, short)
    harness.exchange(outputs, make_image(test_pattern(width, height), 'mono8'))
    after = harness.diag()
    assert int(after['rejected_encodings']) > int(before['rejected_encodings'])
    assert after['last_rejected_encoding'] == 'bayer_rgbg8'
    assert int(after['frames_failed']) > int(before['frames_failed'])
    log = harness.proc.output()
    assert "unsupported image encoding 'bayer_rgbg8'" in log and 'debayer' in log
    assert 'less than step' in log
    assert harness.proc.running()


def test_frame_of_other_size_than_fixed_sensor_is_dropped(
        harness: Harness, outputs: Outputs) -> None:
    harness.exchange(outputs, make_image(test_pattern(*SMALL), 'mono8'))
    revision = harness.revision()
    fixed = harness.client.set_parameters_atomically(
        Parameter('sensor.width_px', Parameter.Type.INTEGER, 640),
        Parameter('sensor.height_px', Parameter.Type.INTEGER, 480))
    assert fixed.successful, fixed.reason
    try:
        # The rebuild runs in the background: frames are corrected by the old model until the
        # new one (fixed at 640x480) is swapped in.
        harness.client.spin_until(lambda: harness.revision() > revision, 5.0)
        harness.expect_no_output(outputs, make_image(test_pattern(*SMALL), 'mono8'))
        assert 'sensor.width_px x sensor.height_px is 640x480' in harness.proc.output()
    finally:
        reset = harness.client.set_parameters_atomically(
            Parameter('sensor.width_px', Parameter.Type.INTEGER, 0),
            Parameter('sensor.height_px', Parameter.Type.INTEGER, 0))
        assert reset.successful, reset.reason
    harness.exchange(outputs, make_image(test_pattern(*SMALL), 'mono8'))


def test_new_input_size_and_output_size(harness: Harness, outputs: Outputs) -> None:
    harness.exchange(outputs, make_image(test_pattern(*SMALL), 'mono8'))
    dropped = int(harness.diag()['frames_dropped'])
    # A new input resolution: the frame that brings it is corrected by a model of its size.
    src = test_pattern(200, 150)
    result = harness.exchange(outputs, make_image(src, 'mono8'))
    model = expected_model(harness.values, 200, 150)
    assert_camera_infos(result, model)
    got, _ = image_to_array(result['image'])
    npt.assert_array_equal(got, Rectifier(model).correct(src))
    # An output size of its own: image_rect and camera_info_rect follow it, camera_info
    # keeps describing the raw camera.
    sized = harness.client.set_parameters_atomically(
        Parameter('output.width_px', Parameter.Type.INTEGER, 400),
        Parameter('output.height_px', Parameter.Type.INTEGER, 300))
    assert sized.successful, sized.reason
    try:
        values = dict(harness.values, **{'output.width_px': 400, 'output.height_px': 300})
        model = expected_model(values, 200, 150)
        result = _exchange_until_model(harness, outputs, make_image(src, 'mono8'), model,
                                       check=lambda r: r['image'].width == 400)
        assert (result['image'].width, result['image'].height) == (400, 300)
        assert_camera_infos(result, model)
        got, _ = image_to_array(result['image'])
        npt.assert_array_equal(got, Rectifier(model).correct(src))
    finally:
        reset = harness.client.set_parameters_atomically(
            Parameter('output.width_px', Parameter.Type.INTEGER, 0),
            Parameter('output.height_px', Parameter.Type.INTEGER, 0))
        assert reset.successful, reset.reason
    harness.exchange(outputs, make_image(test_pattern(*SMALL), 'mono8'))
    assert int(harness.diag()['frames_dropped']) == dropped


# ---------------------------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------------------------

def test_parameter_sets_rebuild_the_model(harness: Harness, outputs: Outputs) -> None:
    width, height = SMALL
    src = test_pattern(width, height)
    msg = make_image(src, 'mono8')
    old = harness.exchange(outputs, msg)
    revision = harness.revision()
    original = {k: harness.values[k] for k in ('lens.stop_offset_mm', 'lens.thickness_mm')}
    try:
        for name, value in (('lens.stop_offset_mm', 0.45), ('lens.thickness_mm', 2.5)):
            results = harness.client.set_parameters(double(name, value))   # ros2 param set
            assert [r.successful for r in results] == [True], results[0].reason
            harness.values[name] = value
            model = expected_model(harness.values, width, height)
            new = _exchange_until_model(harness, outputs, msg, model)
            assert not np.allclose(new['info'].d, old['info'].d), f'{name}: D did not change'
            assert_camera_infos(new, model)
            got, _ = image_to_array(new['image'])
            npt.assert_array_equal(got, Rectifier(model).correct(src))
            revision += 1
            assert harness.revision() == revision
            old = new

        # Two parameters together: exactly one rebuild.
        result = harness.client.set_parameters_atomically(
            double('lens.stop_offset_mm', 0.1), double('lens.thickness_mm', 3.5))
        assert result.successful, result.reason
        harness.values.update({'lens.stop_offset_mm': 0.1, 'lens.thickness_mm': 3.5})
        model = expected_model(harness.values, width, height)
        assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)
        harness.client.spin_for(0.5)
        assert harness.revision() == revision + 1
        revision += 1

        # `ros2 param load` sends ONE set_parameters request with several parameters, which
        # rclpy applies one at a time: still one rebuild.
        results = harness.client.set_parameters(
            double('lens.stop_offset_mm', 0.3), double('lens.thickness_mm', 3.2))
        assert [r.successful for r in results] == [True, True], [r.reason for r in results]
        harness.values.update({'lens.stop_offset_mm': 0.3, 'lens.thickness_mm': 3.2})
        model = expected_model(harness.values, width, height)
        assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)
        harness.client.spin_for(0.5)
        assert harness.revision() == revision + 1
        revision += 1
    finally:
        restore = harness.client.set_parameters_atomically(
            *(double(k, v) for k, v in original.items()))
        assert restore.successful, restore.reason
        harness.values.update(original)
    model = expected_model(harness.values, width, height)
    assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)
    # Setting a parameter to the value it has, or a node parameter, rebuilds nothing.
    revision = harness.revision()
    results = harness.client.set_parameters(
        double('lens.stop_offset_mm', harness.values['lens.stop_offset_mm']),
        Parameter('remap_threads', Parameter.Type.INTEGER, 2),
        Parameter('remap_threads', Parameter.Type.INTEGER, 1))
    assert all(r.successful for r in results), [r.reason for r in results]
    harness.exchange(outputs, msg)
    assert harness.revision() == revision


AFOCAL = (double('lens.refractive_index', 1.5), double('lens.r1_mm', 10.0),
          double('lens.r2_mm', 5.0), double('lens.thickness_mm', 15.0))

#: Refused sets: (id, parameters, text the reason must contain). One parameter goes through
#: set_parameters (as ``ros2 param set``), several through set_parameters_atomically.
BAD_SETS = [
    ('n-0.9', (double('lens.refractive_index', 0.9),), 'lens.refractive_index'),
    ('t-negative', (double('lens.thickness_mm', -1.0),), 'lens.thickness_mm'),
    # n r2 - n r1 + t (n - 1) = 7.5 - 15 + 7.5 = 0: eq. 8 has no finite focal length.
    ('afocal', AFOCAL, 'afocal'),
    ('scene-inside-f', (double('scene.distance_mm', 3.0),), 'inside the focal length'),
    ('interpolation-bogus', (Parameter('output.interpolation', Parameter.Type.STRING,
                                       'bogus'),), 'bogus'),
    ('nan', (double('lens.stop_offset_mm', float('nan')),), 'nan'),
    ('inf', (double('lens.aperture_diameter_mm', float('inf')),), 'lens.aperture_diameter_mm'),
    ('integer-for-double', (Parameter('lens.r1_mm', Parameter.Type.INTEGER, 4),), 'type'),
    ('array-lengths', (
        Parameter('lens.surfaces.radius_mm', Parameter.Type.DOUBLE_ARRAY, [4.0, -4.0]),
        Parameter('lens.surfaces.thickness_mm', Parameter.Type.DOUBLE_ARRAY, [3.0]),
        Parameter('lens.surfaces.refractive_index', Parameter.Type.DOUBLE_ARRAY, [1.5, 1.0])),
     'one per surface'),
    ('output-too-big', (Parameter('output.width_px', Parameter.Type.INTEGER, 16384),
                        Parameter('output.height_px', Parameter.Type.INTEGER, 16384)), 'Mpx'),
    ('projection-bogus', (Parameter('output.projection', Parameter.Type.STRING,
                                    'stereographic'),), 'output.projection'),
    ('asphere-length', (
        Parameter('lens.surfaces.radius_mm', Parameter.Type.DOUBLE_ARRAY, [4.0, -4.0]),
        Parameter('lens.surfaces.thickness_mm', Parameter.Type.DOUBLE_ARRAY, [3.0, 0.0]),
        Parameter('lens.surfaces.refractive_index', Parameter.Type.DOUBLE_ARRAY, [1.5, 1.0]),
        Parameter('lens.surfaces.asphere_a4', Parameter.Type.DOUBLE_ARRAY, [1e-4] * 3)),
     'lens.surfaces.asphere_a4'),
    # k = 5 on r = 4 mm: the sag is defined only to r = 1.63 mm, inside the 3 mm semi-diameter.
    ('conic-undefined', (
        Parameter('lens.surfaces.radius_mm', Parameter.Type.DOUBLE_ARRAY, [4.0, -4.0]),
        Parameter('lens.surfaces.thickness_mm', Parameter.Type.DOUBLE_ARRAY, [3.0, 0.0]),
        Parameter('lens.surfaces.refractive_index', Parameter.Type.DOUBLE_ARRAY, [1.5, 1.0]),
        Parameter('lens.surfaces.semi_diameter_mm', Parameter.Type.DOUBLE_ARRAY, [3.0, 3.0]),
        Parameter('lens.surfaces.conic', Parameter.Type.DOUBLE_ARRAY, [5.0, 0.0])),
     'lens.surfaces.conic'),
    # Issue 14: a gain limit below 1 (or not finite), through both set services.
    ('max-gain-0.5', (double('output.max_vignetting_gain', 0.5),),
     'output.max_vignetting_gain'),
    ('max-gain-0.5-atomic', (double('output.max_vignetting_gain', 0.5),
                             Parameter('output.vignetting_correction', Parameter.Type.BOOL,
                                       True)), 'output.max_vignetting_gain'),
    ('max-gain-nan', (double('output.max_vignetting_gain', float('nan')),),
     'output.max_vignetting_gain'),
]


@pytest.fixture(scope='module')
def refused(harness: Harness) -> dict[str, Any]:
    """
    Try every bad set once against the running node; record what happened.

    After each refusal a frame is exchanged and compared with the one before; the model
    revision is read before the first and after the last (diagnostics come at 1 Hz).
    """
    out = Outputs(harness.client)
    harness.wait_subscribed()
    try:
        msg = make_image(test_pattern(*SMALL), 'mono8')
        before = harness.exchange(out, msg)
        record: dict[str, Any] = {'revision_before': harness.revision()}
        for case_id, params, _ in BAD_SETS:
            names = [p.name for p in params]
            current = harness.client.get_parameters(*names)
            if len(params) == 1:
                results = harness.client.set_parameters(*params)
                assert len(results) == 1
                result = results[0]
            else:
                result = harness.client.set_parameters_atomically(*params)
            after = harness.exchange(out, msg)
            record[case_id] = {
                'successful': result.successful, 'reason': result.reason,
                'parameters_kept': harness.client.get_parameters(*names) == current,
                'same_d': np.array_equal(after['info'].d, before['info'].d),
                'same_k_new': np.array_equal(after['info_rect'].k, before['info_rect'].k),
                'same_image': np.array_equal(np.frombuffer(after['image'].data, np.uint8),
                                             np.frombuffer(before['image'].data, np.uint8)),
            }
        record['revision_after'] = harness.revision()
        record['running'] = harness.proc.running()
        return record
    finally:
        out.close()


@pytest.mark.parametrize(('case_id', 'reason'), [(c, r) for c, _, r in BAD_SETS],
                         ids=[c for c, _, _ in BAD_SETS])
def test_bad_values_are_refused_with_their_reason(refused: dict[str, Any], case_id: str,
                                                  reason: str) -> None:
    case = refused[case_id]
    assert not case['successful']
    assert reason.lower() in case['reason'].lower(), case['reason']
    assert case['parameters_kept'], 'a refused set must not change any parameter'
    assert case['same_d'] and case['same_k_new'], 'a refused set must not change the model'
    assert case['same_image'], 'a refused set must not change the output'


def test_refused_sets_do_not_rebuild(refused: dict[str, Any]) -> None:
    assert refused['revision_after'] == refused['revision_before']
    assert refused['running']


def test_double_array_parameters_can_be_set_and_cleared(harness: Harness,
                                                        outputs: Outputs) -> None:
    width, height = SMALL
    msg = make_image(test_pattern(width, height), 'mono8')
    assert harness.client.get_parameters('lens.surfaces.radius_mm') == {
        'lens.surfaces.radius_mm': array_of()}
    prescription = {
        'lens.surfaces.radius_mm': [4.0, -4.0],
        'lens.surfaces.thickness_mm': [3.0, 0.0],
        'lens.surfaces.refractive_index': [1.5168, 1.0],
    }
    result = harness.client.set_parameters_atomically(
        *(Parameter(k, Parameter.Type.DOUBLE_ARRAY, v) for k, v in prescription.items()))
    assert result.successful, result.reason
    try:
        values = dict(harness.values, **prescription)
        model = expected_model(values, width, height)
        assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)
    finally:
        cleared = harness.client.set_parameters_atomically(
            *(Parameter(k, Parameter.Type.DOUBLE_ARRAY, []) for k in prescription))
        assert cleared.successful, cleared.reason
    model = expected_model(harness.values, width, height)
    assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)


def test_aspheric_prescription_and_equidistant_output_rebuild(
        harness: Harness, outputs: Outputs) -> None:
    width, height = SMALL
    src = test_pattern(width, height)
    msg = make_image(src, 'mono8')
    change = {
        'lens.surfaces.radius_mm': [4.0, -4.0],
        'lens.surfaces.thickness_mm': [3.0, 0.0],
        'lens.surfaces.refractive_index': [1.5168, 1.0],
        'lens.surfaces.conic': [-0.5, 0.0],
        'lens.surfaces.asphere_a4': [0.0, 2e-3],
    }
    params = [Parameter(k, Parameter.Type.DOUBLE_ARRAY, v) for k, v in change.items()]
    params.append(Parameter('output.projection', Parameter.Type.STRING, 'equidistant'))
    result = harness.client.set_parameters_atomically(*params)
    assert result.successful, result.reason
    try:
        values = dict(harness.values, **change, **{'output.projection': 'equidistant'})
        model = expected_model(values, width, height)
        assert model.prescription.surfaces[1].asphere[0] == 2e-3
        got = _exchange_until_model(
            harness, outputs, msg, model,
            check=lambda r: r['info_rect'].distortion_model == 'equidistant')
        rect = got['info_rect']
        assert rect.distortion_model == 'equidistant'
        npt.assert_array_equal(rect.d, np.zeros(4))
        npt.assert_allclose(rect.k, model.K_new.ravel(), rtol=1e-9)
        assert got['info'].distortion_model == model.distortion_model
        image, _ = image_to_array(got['image'])
        npt.assert_array_equal(image, Rectifier(model).correct(src))
        # The covered field and the equivalent calibration's error reach /diagnostics.
        deadline = time.monotonic() + 5.0
        diag = harness.diag()
        while diag.get('projection') != 'equidistant' and time.monotonic() < deadline:
            diag = harness.diag()
        report = model.report()
        npt.assert_allclose(float(diag['max_field_angle_deg']), report['max_field_angle_deg'],
                            rtol=1e-5)
        npt.assert_allclose(float(diag['equivalent_max_error_px']),
                            report['equivalent_max_error_px'], rtol=1e-4, atol=1e-9)
        assert diag['projection'] == 'equidistant'
        assert 'covered_field.image_circle_radius_mm' in diag
    finally:
        restore = [Parameter(k, Parameter.Type.DOUBLE_ARRAY, []) for k in change]
        restore.append(Parameter('output.projection', Parameter.Type.STRING, 'pinhole'))
        cleared = harness.client.set_parameters_atomically(*restore)
        assert cleared.successful, cleared.reason
    model = expected_model(harness.values, width, height)
    assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)


def test_vignetting_correction_brightens_the_corners(harness: Harness,
                                                     outputs: Outputs) -> None:
    width, height = SMALL
    flat = np.full((height, width, 3), 100, np.uint8)
    msg = make_image(flat, 'rgb8')
    plain = harness.exchange(outputs, msg)
    before, _ = image_to_array(plain['image'])
    on = Parameter('output.vignetting_correction', Parameter.Type.BOOL, True)
    result = harness.client.set_parameters(on)[0]
    assert result.successful, result.reason
    try:
        values = dict(harness.values, **{'output.vignetting_correction': True})
        model = expected_model(values, width, height)
        expected = Rectifier(model).correct(flat)
        deadline = time.monotonic() + 5.0
        while True:
            got, _ = image_to_array(harness.exchange(outputs, msg)['image'])
            if np.array_equal(got, expected) or time.monotonic() > deadline:
                break
        npt.assert_array_equal(got, expected)
        centre = got[height // 2, width // 2]
        corner = got[2, 2]
        npt.assert_array_equal(centre, before[height // 2, width // 2])
        # The corner is divided by RI < 1: brighter than without the correction.
        assert corner.min() > before[2, 2].max(), (corner, before[2, 2])
        ri = model.illumination().at(np.hypot(*(np.subtract(
            model.raw_from_rect(np.array([2.0, 2.0])), model.K[:2, 2]) * model.pixel_mm)))
        npt.assert_allclose(corner.astype(float), before[2, 2] / ri, atol=1.0)
        diag = harness.diag()
        deadline = time.monotonic() + 5.0
        while diag.get('vignetting_correction') != 'true' and time.monotonic() < deadline:
            diag = harness.diag()
        assert diag['vignetting_correction'] == 'true'
        npt.assert_allclose(float(diag['relative_illumination.corner_ri']),
                            model.illumination().corner_ri, rtol=1e-5)
    finally:
        off = Parameter('output.vignetting_correction', Parameter.Type.BOOL, False)
        assert harness.client.set_parameters(off)[0].successful
    model = expected_model(harness.values, width, height)
    _exchange_until_model(harness, outputs, msg, model)


def array_of(*values: float) -> Any:
    """Return what a DOUBLE_ARRAY parameter reads back as."""
    import array
    return array.array('d', values)


def test_diagnostics_carry_the_model_summary_and_counters(
        harness: Harness, outputs: Outputs) -> None:
    harness.exchange(outputs, make_image(test_pattern(*SMALL), 'mono8'))
    diag = harness.diag()
    model = expected_model(harness.values, *SMALL)
    report = model.report()
    for key in ('focal_length_mm', 'focal_length_sigma_mm', 'fov_deg.horizontal',
                'fov_deg.diagonal', 'footprint_mm.x', 'feature_resolution_mm.y', 'f_number',
                'hyperfocal_mm', 'hyperfocal_sigma_mm', 'depth_of_field_mm.near',
                'max_displacement_px', 'fit_rms_px', 'model_revision', 'last_rebuild_ms',
                'frames_in', 'frames_out', 'frames_dropped', 'frames_failed',
                'rejected_encodings', 'frame_time_ms_mean'):
        assert key in diag, key
    npt.assert_allclose(float(diag['focal_length_mm']), report['focal_length_mm'], rtol=1e-5)
    npt.assert_allclose(float(diag['fov_deg.horizontal']), report['fov_deg']['horizontal'],
                        rtol=1e-5)
    assert int(diag['frames_out']) >= 1
    assert float(diag['last_rebuild_ms']) > 0.0
    # The status is named after the fully qualified node name (two cameras, two statuses).
    assert harness.diagnostics[-1].status[0].name == '/correct_node: lens correction'


# ---------------------------------------------------------------------------------------------
# Lazy subscription
# ---------------------------------------------------------------------------------------------

def test_lazy_subscription(harness: Harness) -> None:
    client = harness.client
    # No output subscriber (every test closes its own): the node must not be subscribed.
    assert client.spin_until(lambda: harness.pub.get_subscription_count() == 0, 3.0)
    client.spin_for(1.2)                            # > two polls of the node
    assert harness.pub.get_subscription_count() == 0
    out = Outputs(client)
    try:
        assert client.spin_until(lambda: harness.pub.get_subscription_count() == 1, 5.0), \
            'the node did not subscribe when an output got a subscriber'
    finally:
        out.close()
    assert client.spin_until(lambda: harness.pub.get_subscription_count() == 0, 5.0), \
        'the node did not unsubscribe when the last output subscriber left'


# ---------------------------------------------------------------------------------------------
# Process behaviour: SIGTERM, start-up errors, params-file arrays
# ---------------------------------------------------------------------------------------------

def test_params_file_arrays_load_and_sigterm_exits_cleanly(tmp_path: Path) -> None:
    values = load_params_file(case2_params(tmp_path))
    values.update({'lens.surfaces.radius_mm': [4.0, -4.0], 'lens.surfaces.thickness_mm':
                   [3.0, 0.0], 'lens.surfaces.refractive_index': [1.5168, 1.0],
                   'lazy_subscription': False})
    # The standard QoS override parameters, as a user matching a reliable driver would write.
    values.update({'qos_overrides./image_raw.subscription.reliability': 'reliable',
                   'qos_overrides./image_rect.publisher.reliability': 'reliable',
                   'qos_overrides./image_rect.publisher.depth': 3})
    params = tmp_path / 'prescription.yaml'
    params.write_text(to_params_yaml(values, node_name='correct_node'))
    domain = next_domain_id()
    with NodeProcess(node_command(params), ros_env(domain), tmp_path) as proc, \
            RosClient(domain) as client:
        client.wait_until_answering()
        got = client.get_parameters('lens.surfaces.radius_mm', 'lens.surfaces.thickness_mm',
                                    'lazy_subscription')
        assert list(got['lens.surfaces.radius_mm']) == [4.0, -4.0]
        assert list(got['lens.surfaces.thickness_mm']) == [3.0, 0.0]
        assert got['lazy_subscription'] is False
        reliable = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
        pub = client.node.create_publisher(Image, 'image_raw', reliable)
        assert client.spin_until(lambda: pub.get_subscription_count() == 1, 5.0), \
            'lazy_subscription false: the node must subscribe without output subscribers'
        (sub_info,) = client.node.get_subscriptions_info_by_topic('/image_raw')
        assert sub_info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
        (pub_info,) = client.node.get_publishers_info_by_topic('/image_rect')
        assert pub_info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
        (info_pub,) = client.node.get_publishers_info_by_topic('/camera_info')
        assert info_pub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
        code = proc.stop(signal.SIGTERM)
        log = proc.output()
    assert code == 0, log[-3000:]
    assert 'Traceback' not in log, log[-3000:]


@pytest.mark.parametrize(('override', 'expected'), [
    ('lens.r1_mm:=4', 'decimal point'),
    ('scene.distance_mm:=2.0', 'inside the focal length'),
    ('scene.focus_distance_mm:=3.0', 'scene.focus_distance_mm: 3 mm is inside the focal length'),
    ('lens.stop_offset_mm:=-10.0', 'lens.stop_offset_mm: -10 mm puts the stop'),
    ('lens.aperture_diameter_mm:=1000.0', 'lens.aperture_diameter_mm: 1000 mm'),
], ids=['integer-for-double', 'scene-inside-f', 'focus-inside-f', 'stop-behind-sensor',
        'aperture-1000'])
def test_invalid_start_up_parameters_exit_with_a_reason(tmp_path: Path, override: str,
                                                        expected: str) -> None:
    argv = node_command(case2_params(tmp_path), override)
    run = subprocess.run(argv, env=ros_env(next_domain_id()), capture_output=True, text=True,
                         timeout=30, start_new_session=True)
    assert run.returncode == 1, run.stdout + run.stderr
    assert expected in run.stderr, run.stderr
    assert 'Traceback' not in run.stderr


def test_params_file_of_a_lens_that_cannot_exist_exits_with_the_reason(tmp_path: Path) -> None:
    """The params file itself (not a -p override) describes no camera: exit 1, the reason."""
    values = load_params_file(case2_params(tmp_path))
    values['scene.circle_of_confusion_mm'] = 5.0
    params = tmp_path / 'bad.yaml'
    params.write_text(to_params_yaml(values, node_name='correct_node'))
    run = subprocess.run(node_command(params), env=ros_env(next_domain_id()),
                         capture_output=True, text=True, timeout=30, start_new_session=True)
    assert run.returncode == 1, run.stdout + run.stderr
    assert 'scene.circle_of_confusion_mm: 5 mm is larger than the 3.361 mm diagonal' in \
        run.stderr, run.stderr
    assert 'Traceback' not in run.stderr


# ---------------------------------------------------------------------------------------------
# Fast DDS profile
# ---------------------------------------------------------------------------------------------

def test_fastdds_profile_has_the_big_shared_memory_segment() -> None:
    ns = {'d': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    root = ElementTree.parse(FASTDDS_PROFILE).getroot()
    transports = {t.findtext('d:transport_id', namespaces=ns): t
                  for t in root.iterfind('.//d:transport_descriptor', ns)}
    types = {t.findtext('d:type', namespaces=ns): t for t in transports.values()}
    assert set(types) == {'SHM', 'UDPv4'}
    assert int(types['SHM'].findtext('d:segment_size', namespaces=ns)) == 128 * 2 ** 20
    assert int(types['SHM'].findtext('d:maxMessageSize', namespaces=ns)) == 64 * 2 ** 20
    participant = root.find('.//d:participant', ns)
    assert participant is not None and participant.get('is_default_profile') == 'true'
    used = [t.text for t in participant.iterfind('.//d:userTransports/d:transport_id', ns)]
    assert sorted(used) == sorted(transports)
    assert participant.findtext('.//d:useBuiltinTransports', namespaces=ns) == 'false'


_TRANSPORT_SCRIPT = textwrap.dedent("""
    import array, sys, time
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image
    role, seconds = sys.argv[1], float(sys.argv[2])
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    rclpy.init()
    node = Node('transport_' + role)
    if role == 'pub':
        pub = node.create_publisher(Image, 'transport_test', qos)
        msg = Image(width=1280, height=720, encoding='rgb8', step=1280 * 3)
        msg.data = array.array('B', bytes(1280 * 720 * 3))
        deadline = time.monotonic() + 20
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)
        start, sent = time.monotonic(), 0
        while time.monotonic() - start < seconds:
            pub.publish(msg)
            sent += 1
            time.sleep(max(0.0, start + sent / 30.0 - time.monotonic()))
        print(sent, flush=True)
    else:
        got = []
        node.create_subscription(Image, 'transport_test',
                                 lambda m: got.append(time.monotonic()), qos)
        deadline = time.monotonic() + seconds
        # Until the stream has been quiet for 1 s (or the deadline).
        while time.monotonic() < deadline and not (got and time.monotonic() - got[-1] > 1.0):
            rclpy.spin_once(node, timeout_sec=0.05)
        print(len(got), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
""")


def test_fastdds_profile_loads_and_carries_720p_rgb8_at_30hz_best_effort(
        tmp_path: Path) -> None:
    env = ros_env(next_domain_id())
    script = tmp_path / 'transport.py'
    script.write_text(_TRANSPORT_SCRIPT)
    sub = subprocess.Popen([sys.executable, str(script), 'sub', '20'], env=env,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           start_new_session=True)
    try:
        pub = subprocess.run([sys.executable, str(script), 'pub', '3'], env=env,
                             capture_output=True, text=True, timeout=40,
                             start_new_session=True)
        out, err = sub.communicate(timeout=30)
    finally:
        if sub.poll() is None:
            sub.kill()
            sub.wait()
    for stream in (pub.stderr, err):
        assert 'XMLPARSER' not in stream and 'Error' not in stream, stream
    sent, received = int(pub.stdout.split()[-1]), int(out.split()[-1])
    print(f'\n1280x720 rgb8, 30 Hz best effort, fastdds_shm.xml: {received}/{sent} delivered')
    # The builtin transports deliver ~2 of 30 fps here; the profile delivers all of them.
    assert sent >= 80
    assert received >= 0.9 * sent


# ---------------------------------------------------------------------------------------------
# Measured (printed) numbers: parameter set -> first frame of the new model
# ---------------------------------------------------------------------------------------------

def _measure_one_set(harness: Harness, out: Outputs, msg: Image, value: float
                     ) -> tuple[float, float, float, int]:
    """
    Stream frames at 30 Hz, set lens.stop_offset_mm mid-stream, time the switch.

    :return: ``(ms from the set_parameters reply to the first output of the new model
        (negative if it came first), ms from the request to it, the largest gap between two
        output images while streaming, ms, output images that arrived between the reply and
        the first image of the new model)``.
    """
    client, period = harness.client, 1.0 / 30.0
    start = len(out.arrivals)
    next_send = time.monotonic()
    future: Any = None
    sent_at = reply_at = new_at = None
    old_d: np.ndarray | None = None
    frames_after = 0
    deadline = time.monotonic() + 8.0
    while time.monotonic() < deadline:
        now = time.monotonic()
        if now >= next_send:
            client.next_stamp(msg)
            harness.pub.publish(msg)
            next_send += period
            frames_after += sent_at is not None
        infos = [(when, m) for when, kind, m in out.arrivals[start:] if kind == 'info']
        if future is None and len(infos) >= 8:
            old_d = np.array(infos[-1][1].d)
            sent_at = time.monotonic()
            future = client.set_parameters_async(double('lens.stop_offset_mm', value))
        if future is not None and reply_at is None and future.done():
            reply_at = time.monotonic()
            assert future.result().results[0].successful
        if sent_at is not None and new_at is None:
            new_at = next((when for when, m in infos
                           if when >= sent_at and not np.allclose(np.array(m.d), old_d)), None)
        if reply_at is not None and new_at is not None and frames_after >= 12:
            break
        client.executor.spin_once(timeout_sec=max(0.0, min(0.005, next_send - now)))
    assert reply_at is not None and new_at is not None, 'no frame of the new model within 8 s'
    images = [when for when, kind, _ in out.arrivals[start:] if kind == 'image']
    old_during = sum(1 for when in images if reply_at <= when < new_at)
    return ((new_at - reply_at) * 1e3, (new_at - sent_at) * 1e3,
            float(np.max(np.diff(images))) * 1e3, old_during)


@pytest.mark.parametrize('size', [(640, 480), (1920, 1080)], ids=['640x480', '1920x1080'])
def test_param_set_to_first_new_frame_at_30fps(harness: Harness, size: tuple[int, int]
                                               ) -> None:
    width, height = size
    out = Outputs(harness.client)
    harness.wait_subscribed()
    msg = make_image(test_pattern(width, height, 3), 'rgb8')
    try:
        # Warm up: the first frame of this size builds its model synchronously.
        harness.exchange(out, msg, timeout=10.0)
        latencies, from_request, rebuilds, gaps, old_during = [], [], [], [], []
        # 1080p: two sets (each costs a 1080p rebuild; the timing itself is benchmarked in
        # benchmarks/node_latency.py, median of many).
        for value in (0.3, 0.2, 0.35, 0.2) if width < 1920 else (0.3, 0.2):
            latency, total, gap, during = _measure_one_set(harness, out, msg, value)
            latencies.append(latency)
            from_request.append(total)
            gaps.append(gap)
            old_during.append(during)
            rebuilds.append(float(harness.diag()['last_rebuild_ms']))
        harness.values['lens.stop_offset_mm'] = 0.2

        def listing(values: list[float]) -> str:
            return f'{statistics.median(values):.1f} ms median (' + ', '.join(
                f'{v:.1f}' for v in values) + ')'

        print(f'\n{width}x{height} rgb8 at 30 fps: set_parameters reply -> first frame of the '
              f'new model {listing(latencies)}, from the request {listing(from_request)}; '
              f'rebuild (model + maps) {listing(rebuilds)}; '
              f'largest gap between output frames {max(gaps):.1f} ms; frames of the old '
              f'model after the reply {old_during}')
        # No wall-clock bound here (the number is a benchmark's, measured as a ratio): every
        # set reached the frames (within _measure_one_set's deadline), and the rebuild does
        # not block the frame path. A rebuild in the executor would hold the reply until the
        # maps are done, then the next output would already be the new model's; rebuilt
        # aside, the old model's frames keep arriving after the reply. So whenever the rebuild
        # (as the node times it) lasted more than two frame periods, frames of the old model
        # arrived between the reply and the first frame of the new one.
        period_ms = 1e3 / 30.0
        slow = [during for rebuild_ms, during in zip(rebuilds, old_during)
                if rebuild_ms > 2.0 * period_ms]
        assert all(during >= 1 for during in slow), (rebuilds, old_during)
    finally:
        out.close()
