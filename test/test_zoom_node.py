# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
correct_node following a moving lens (issue 19), with real rclpy: the node in its own process.

The lens is config/zoom.yaml's first three zoom rows on a small sensor of the same size in mm
(a grid of five states builds in about a second). The client publishes ``lens_state``
(sensor_msgs/JointState) and frames with chosen stamps and checks that each frame's
CameraInfos carry the model of the state AT ITS STAMP (interpolated between the two states
around it, the newest for a newer frame), that image_rect is that state's correction, and
that ignored states are counted in /diagnostics. The node runs on sim time (``use_sim_time``,
the client publishes ``/clock``): one start-up serves every test, in file order, and the last
ones send the clock back (a bag loop, a simulator restart) and an unstamped frame.
"""

from __future__ import annotations

import math
from pathlib import Path
import time
from typing import Any, Iterator

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from mechdeconv_ros.imaging.moving_maps import build_moving_maps
from mechdeconv_ros.lenses import lens_table
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import load_params_file, to_params_yaml
import numpy as np
import numpy.testing as npt
import psutil
import pytest
from ros_helpers import (
    BEST_EFFORT, make_image, next_domain_id, node_command, REPO, RosClient, running_node,
    stamp_of)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState

pytestmark = pytest.mark.ros

W, H = 240, 136


def small_zoom(tmp: Path) -> tuple[Path, dict[str, Any]]:
    values = dict(load_params_file(REPO / 'config' / 'zoom.yaml'))
    values['lens.zoom.positions'] = values['lens.zoom.positions'][:3]
    values['lens.zoom.thickness_mm'] = values['lens.zoom.thickness_mm'][:9]
    values.update({'sensor.pixel_size_x_um': 100.0, 'sensor.pixel_size_y_um': 100.0,
                   'sensor.width_px': W, 'sensor.height_px': H})
    names = [n for n in values if n.startswith(('lens.', 'sensor.', 'scene.'))]
    path = tmp / 'zoom_small.yaml'
    path.write_text(to_params_yaml(values, names=names))
    return path, load_params_file(path)


class Client:
    """The client's publishers (frames, lens_state) and the node's outputs by stamp."""

    def __init__(self, client: RosClient) -> None:
        node = client.node
        self.client = client
        self.frames = node.create_publisher(Image, 'image_raw', BEST_EFFORT)
        self.states = node.create_publisher(JointState, 'lens_state', 10)
        # Sim time ticks in wall time (the node's timers, /diagnostics, run on it) from 100 s.
        self.clock = node.create_publisher(Clock, '/clock', 10)
        self.sim_ns = 100 * 1_000_000_000
        node.create_timer(0.05, self._tick)
        self.by_stamp: dict[tuple[int, int], dict[str, Any]] = {}
        self.diagnostics: list[Any] = []
        node.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, 10)
        for kind, msg_type, topic in (('image', Image, 'image_rect'),
                                      ('info', CameraInfo, 'camera_info'),
                                      ('info_rect', CameraInfo, 'camera_info_rect')):
            node.create_subscription(msg_type, topic, self._store(kind), BEST_EFFORT)

    def _store(self, kind: str) -> Any:
        def store(msg: Any) -> None:
            self.by_stamp.setdefault(stamp_of(msg), {})[kind] = msg
        return store

    def state(self, sec: int, nanosec: int, names: list[str], positions: list[float]) -> None:
        msg = JointState(name=names, position=positions)
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        self.states.publish(msg)

    def _tick(self) -> None:
        self.sim_ns += 50_000_000
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(self.sim_ns, 1_000_000_000)
        self.clock.publish(msg)

    def set_clock(self, sec: int) -> None:
        self.sim_ns = sec * 1_000_000_000
        self._tick()
        self.client.spin_for(0.3)

    def diagnostics_entries(self) -> dict[str, str]:
        if not self.diagnostics:
            return {}
        return {kv.key: kv.value for kv in self.diagnostics[-1].status[0].values}

    def frame(self, msg: Image, sec: int, nanosec: int, timeout: float = 8.0) -> dict[str, Any]:
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        stamp = (sec, nanosec)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.frames.publish(msg)
            if self.client.spin_until(lambda: len(self.by_stamp.get(stamp, {})) == 3, 0.3):
                return self.by_stamp[stamp]
        raise AssertionError(f'no output for the frame {stamp}')


@pytest.fixture(scope='module')
def running(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Client, dict, Any]]:
    tmp = tmp_path_factory.mktemp('zoom_node')
    path, values = small_zoom(tmp)
    domain = next_domain_id()
    with running_node(node_command(path, 'use_sim_time:=true'), domain, tmp,
                      answer_timeout=60.0) as (proc, client):
        yield Client(client), values, proc


def _exact(values: dict, p: float):
    return build_model(lens_table.values_at(values, {'zoom': p}), W, H)


def test_before_any_state_a_frame_gets_the_first_row_and_a_warning(running) -> None:
    # Runs first (file order): no lens_state has been published yet.
    client, values, proc = running
    msg = make_image(np.zeros((H, W), np.uint8), 'mono8')
    result = client.frame(msg, 99, 0)
    npt.assert_allclose(result['info'].k, _exact(values, 0.0).K.ravel(), rtol=1e-6)
    joint = values['lens.zoom.joint']
    assert client.client.spin_until(
        lambda: f"no lens_state of joint '{joint}' yet" in proc.output(), 5.0), \
        proc.output()[-2000:]
    assert client.client.spin_until(lambda: int(client.diagnostics_entries().get(
        'lens_state_missing_frames', '0')) >= 1, 5.0), client.diagnostics_entries()
    # Issue 36 (h): the self-check cannot judge a lens whose groups move: no check process
    # (140-190 MiB) is started for it (check.rate_hz is its default, 0.2), and /diagnostics
    # says why. Caught: every node started one.
    assert client.diagnostics_entries().get('check_state', '').startswith(
        'not checked: lens.zoom.joint'), client.diagnostics_entries()
    assert not [c for c in psutil.Process(proc.pid).children()
                if 'check_worker' in ' '.join(c.cmdline())]


def test_each_frame_gets_the_model_of_its_stamp(running) -> None:
    client, values, proc = running
    rng = np.random.default_rng(0)
    msg = make_image(rng.integers(0, 255, (H, W), np.uint8), 'mono8')
    assert client.client.spin_until(lambda: client.states.get_subscription_count() > 0, 10.0)
    client.state(100, 0, ['pan', 'zoom'], [0.3, 0.0])
    client.state(100, 200_000_000, ['zoom'], [0.125])
    client.client.spin_for(0.5)
    # Half-way between the two states: the model at zoom 0.0625 (a table row).
    result = client.frame(msg, 100, 100_000_000)
    exact = _exact(values, 0.0625)
    npt.assert_allclose(result['info'].k, exact.K.ravel(), rtol=1e-6)
    npt.assert_allclose(result['info_rect'].k, exact.K_new.ravel(), rtol=1e-6)
    npt.assert_allclose(np.reshape(result['info'].p, (3, 4))[:, :3], exact.K_new, rtol=1e-6)
    npt.assert_allclose(result['info'].d, exact.D, rtol=1e-6, atol=1e-9)
    # image_rect is the correction of that state (the same grid built here).
    grid = build_moving_maps(values, lens_table.mechanisms(values),
                             lambda v: build_model(v, W, H))
    _, full = grid.at({'zoom': 0.0625})
    expected = cv2.remap(np.frombuffer(bytes(msg.data), np.uint8).reshape(H, W), full, None,
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    got = np.frombuffer(bytes(result['image'].data), np.uint8).reshape(H, W)
    npt.assert_array_equal(got, expected)
    # A frame newer than every state: the newest (the long end of the small table).
    result = client.frame(msg, 101, 0)
    npt.assert_allclose(result['info'].k, _exact(values, 0.125).K.ravel(), rtol=1e-6)
    # At a quarter: interpolated state 0.03125, between grid states.
    result = client.frame(msg, 100, 50_000_000)
    npt.assert_allclose(result['info'].k, _exact(values, 0.03125).K.ravel(), rtol=1e-5)


def test_ignored_states_are_counted_in_diagnostics(running) -> None:
    client, values, proc = running
    client.state(102, 0, ['pan', 'tilt'], [0.1, 0.2])
    client.state(102, 10, ['zoom'], [math.nan])
    msg = make_image(np.zeros((H, W), np.uint8), 'mono8')
    client.frame(msg, 103, 0)

    def entries() -> dict[str, str]:
        if not client.diagnostics:
            return {}
        status = client.diagnostics[-1].status[0]
        return {kv.key: kv.value for kv in status.values}

    assert client.client.spin_until(lambda: entries().get('lens_states_ignored') == '2', 5.0), \
        entries()
    diag = entries()
    assert 'zoom is nan' in diag['lens_states_last_ignored']
    assert float(diag['lens_state.zoom']) == pytest.approx(0.125)
    assert float(diag['lens_state_lag_ms']) == pytest.approx(2800.0)
    assert int(diag['lens_grid_states']) == 5


def test_a_state_outside_the_table_is_clamped_and_warned(running) -> None:
    client, values, proc = running
    client.state(104, 0, ['zoom'], [5.0])
    client.client.spin_for(0.3)
    msg = make_image(np.zeros((H, W), np.uint8), 'mono8')
    result = client.frame(msg, 104, 0)
    npt.assert_allclose(result['info'].k, _exact(values, 0.125).K.ravel(), rtol=1e-6)
    assert client.client.spin_until(
        lambda: 'is outside lens.zoom.positions' in proc.output(), 5.0), proc.output()[-2000:]


def test_a_clock_jump_back_clears_the_history(running) -> None:
    # A simulator restart: /clock and the joint stamps start again from 10 s. Pruned on
    # insert, the new state would leave the old (zoom 0.125 at 200 s) newest.
    client, values, proc = running
    client.set_clock(200)
    client.state(200, 0, ['zoom'], [0.125])
    client.client.spin_for(0.3)
    client.set_clock(10)
    client.state(10, 0, ['zoom'], [0.0])
    client.client.spin_for(0.3)
    msg = make_image(np.zeros((H, W), np.uint8), 'mono8')
    result = client.frame(msg, 10, 0)
    npt.assert_allclose(result['info'].k, _exact(values, 0.0).K.ravel(), rtol=1e-6)
    assert client.client.spin_until(
        lambda: client.diagnostics_entries().get('lens_state_time_jumps') == '1', 5.0), \
        client.diagnostics_entries()
    assert proc.output().count('the lens state history was cleared') == 1, proc.output()[-2000:]


def test_an_unstamped_frame_gets_the_newest_state(running) -> None:
    client, values, proc = running
    # After the jump: zoom 0.0 at 10 s (the oldest), now 0.0625 (the newest).
    client.state(10, 500_000_000, ['zoom'], [0.0625])
    client.client.spin_for(0.3)
    msg = make_image(np.zeros((H, W), np.uint8), 'mono8')
    result = client.frame(msg, 0, 0)
    npt.assert_allclose(result['info'].k, _exact(values, 0.0625).K.ravel(), rtol=1e-6)
