# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
End-to-end test of ``python -m mechdeconv_ros.tools.demo`` (what ``make demo`` runs).

The demo starts the real ``correct_node`` and ``demo_camera`` processes. The pictures it saves
are checked against the lens model: the corrected frame must show the camera's chart
undistorted (much closer to the chart than the raw frame is), and after the lens change the
corrected frame must be the chart as the NEW lens sees it, corrected by the new model.
Another test interrupts the demo as Ctrl-C would and checks that nothing is left running.
The camera node itself is also tested in this process (its own rclpy Context): what it
publishes, and how it takes and refuses lens changes.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

from typing import Iterator

import cv2
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model, LensModel
from mechdeconv_ros.node.image_msgs import image_to_array
from mechdeconv_ros.schema.params import load_params_file
from mechdeconv_ros.tools.demo_camera import Chart, convert_rgb, DemoCamera
import numpy as np
from numpy.testing import assert_array_equal
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from ros_helpers import next_domain_id
from sensor_msgs.msg import Image

REPO = Path(__file__).resolve().parents[1]
DemoRun = tuple[subprocess.CompletedProcess, Path, float]
CASE2 = REPO / 'config' / 'case2.yaml'
#: The demo's default lens change.
CHANGE = {'lens.stop_offset_mm': 0.6, 'lens.thickness_mm': 4.0}


def demo_env() -> dict[str, str]:
    """Return the environment of a demo run: the repo importable, unbuffered output."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(
        [str(REPO)] + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p])
    env['PYTHONUNBUFFERED'] = '1'
    return env


def read_rgb(path: Path) -> np.ndarray:
    """Read a PNG the demo wrote, as RGB (the encoding the demo camera publishes)."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert image is not None, f'{path} is not a readable image'
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def blurred_difference(a: np.ndarray, b: np.ndarray) -> float:
    """
    Return the mean absolute difference of two images after a small Gaussian blur.

    The blur (sigma 2 px) forgives the interpolation softening of the 2 px grid lines, so what
    remains measures where the lines and cells are, i.e. the geometry.
    """
    assert a.shape == b.shape
    blur_a = cv2.GaussianBlur(a, (0, 0), 2.0).astype(np.float64)
    blur_b = cv2.GaussianBlur(b, (0, 0), 2.0).astype(np.float64)
    return float(np.mean(np.abs(blur_a - blur_b)))


def expected_corrected(chart: Chart, model: LensModel) -> np.ndarray:
    """Return what correct_node should publish for the demo camera behind ``model``'s lens."""
    return Rectifier(model).correct(chart.render(model))


@pytest.fixture(scope='module')
def demo_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, DemoRun]:
    """
    Run the default demo and the fisheye demo side by side, 1 s measuring windows each.

    Return ``{'default': (result, out folder, seconds), 'fisheye': ...}``. The default demo
    (640x480) mostly waits (start-up, windows, replies), so the fisheye demo (1280x960) runs in
    its waits; the fisheye one gets a domain of this test run, the default one picks its own.
    """
    extra = {'default': [],
             'fisheye': ['--params', 'config/fisheye.yaml', '--domain-id', str(next_domain_id())]}
    started = {}
    for name, args in extra.items():
        out = tmp_path_factory.mktemp(f'demo_{name}')
        # Files, not pipes: a full pipe of the run not being read would stall it.
        with open(out / 'stdout.txt', 'w') as stdout, open(out / 'stderr.txt', 'w') as stderr:
            proc = subprocess.Popen(
                [sys.executable, '-m', 'mechdeconv_ros.tools.demo', '--seconds', '1', '--out',
                 str(out), *args], cwd=REPO, env=demo_env(), stdin=subprocess.DEVNULL,
                stdout=stdout, stderr=stderr, text=True)
        started[name] = (proc, out, time.monotonic())
    runs = {}
    for name, (proc, out, start) in started.items():
        try:
            proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        seconds = time.monotonic() - start
        result = subprocess.CompletedProcess(proc.args, proc.returncode,
                                             (out / 'stdout.txt').read_text(),
                                             (out / 'stderr.txt').read_text())
        runs[name] = (result, out, seconds)
    return runs


@pytest.fixture(scope='module')
def demo_run(demo_runs: dict[str, DemoRun]) -> DemoRun:
    """Return the default demo's run."""
    return demo_runs['default']


@pytest.mark.ros
def test_demo_exits_0_in_time_and_both_nodes_accept_the_lens(
        demo_run: DemoRun) -> None:
    result, _, seconds = demo_run
    log = result.stdout + result.stderr
    assert result.returncode == 0, log
    assert 'Traceback' not in log, log
    assert seconds < 40.0, f'the short demo took {seconds:.1f} s\n{log}'
    for node in ('demo_camera', 'correct_node'):
        assert re.search(rf'/{node}/set_parameters_atomically -> successful=True', log), log
        assert f'{node} exited with status 0' in log, log
    assert re.search(r'first frame from the new model -?[0-9.]+ ms after the reply', log), log
    assert re.search(r'throughput [0-9.]+ fps', log), log


@pytest.mark.ros
def test_demo_pictures_show_the_correction_before_and_after_the_change(
        demo_run: DemoRun) -> None:
    result, out, _ = demo_run
    assert result.returncode == 0, result.stdout + result.stderr
    names = ('raw.png', 'corrected.png', 'raw_after_change.png', 'corrected_after_change.png',
             'summary.png')
    for name in names:
        assert (out / name).is_file(), f'{name} missing; wrote {sorted(os.listdir(out))}'
    raw, corrected, corrected_after = (read_rgb(out / n) for n in (
        'raw.png', 'corrected.png', 'corrected_after_change.png'))
    assert raw.shape == corrected.shape == corrected_after.shape == (480, 640, 3)

    values = load_params_file(CASE2)
    before = build_model(values, 640, 480)
    after = build_model({**values, **CHANGE}, 640, 480)
    chart = Chart(before)

    # Before: the corrected frame is the chart itself (the camera draws it in the corrected
    # frame of the first model); the raw frame is visibly distorted away from it.
    to_chart_raw = blurred_difference(raw, chart.texture)
    to_chart_corrected = blurred_difference(corrected, chart.texture)
    assert to_chart_corrected < 0.5 * to_chart_raw, (to_chart_corrected, to_chart_raw)

    # After: the node corrects the new lens's frames with the new model, which changes the
    # picture (another focal length: the chart at another scale) ...
    change = blurred_difference(corrected_after, corrected)
    assert change > 5.0, change
    # ... to exactly what the new model predicts, much closer than the old picture is.
    expected_after = expected_corrected(chart, after)
    to_expected = blurred_difference(corrected_after, expected_after)
    assert to_expected < 0.25 * blurred_difference(corrected, expected_after), to_expected
    assert to_expected < 1.5, to_expected


@pytest.mark.ros
def test_demo_with_the_fisheye_params_changes_the_first_air_gap_and_corrects_to_f_theta(
        demo_runs: dict[str, DemoRun]) -> None:
    """``--params config/fisheye.yaml``: a 1280x960 prescription, corrected to f-theta."""
    result, out, _ = demo_runs['fisheye']
    log = result.stdout + result.stderr
    assert result.returncode == 0, log
    assert 'Traceback' not in log, log
    assert 'demo_camera publishes 1280x960 rgb8' in log, log
    # Prescription mode: the first air gap (after surface 1, 4.591 mm) 5 % longer, sent to both
    # nodes as one DOUBLE_ARRAY parameter.
    assert ('lens.surfaces.thickness_mm[1] (the first air gap, after surface 1) 4.591 -> '
            '4.82055 mm') in log, log
    for node in ('demo_camera', 'correct_node'):
        assert re.search(rf'/{node}/set_parameters_atomically -> successful=True', log), log
    assert re.search(r'node rebuild time .* model revision 2', log), log
    corrected = read_rgb(out / 'corrected.png')
    assert corrected.shape == (960, 1280, 3)
    assert blurred_difference(read_rgb(out / 'corrected_after_change.png'), corrected) > 5.0

    # The chart is flat and at infinity; output.projection is equidistant, so a vertical grid
    # line at pinhole column u of the camera's chart lands at c + F atan((u - c) / f_pinhole)
    # on the centre row of the corrected frame: the lens's departure from f-theta is gone.
    values = load_params_file(REPO / 'config' / 'fisheye.yaml')
    node_model = build_model(values, 1280, 960)
    camera_values = {k: v for k, v in values.items() if not k.startswith('output.')}
    pinhole = build_model(camera_values, 1280, 960).K_new
    edges = np.linspace(0.04 * 1280, 1280 - 1 - 0.04 * 1280, 21)
    expected = node_model.K_new[0, 2] + node_model.K_new[0, 0] * np.arctan(
        (edges - pinhole[0, 2]) / pinhole[0, 0])
    row = corrected[int(node_model.K_new[1, 2]) + 25]
    white = np.flatnonzero((row > 235).all(axis=1))
    lines = [run.mean() for run in np.split(white, np.flatnonzero(np.diff(white) > 1) + 1)]
    assert len(lines) >= 5, lines
    errors = [float(np.min(np.abs(expected - x))) for x in lines]
    assert max(errors) < 2.0, (lines, expected, errors)


@pytest.mark.ros
def test_demo_interrupted_stops_its_processes(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, '-m', 'mechdeconv_ros.tools.demo', '--seconds', '20', '--out',
         str(tmp_path)], cwd=REPO, env=demo_env(), stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    lines: list[str] = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            if 'measuring image_rect' in line:
                break
        else:
            pytest.fail('the demo ended before measuring:\n' + ''.join(lines))
        # Ctrl-C in a terminal: SIGINT to the demo's process group (the children have their own).
        os.killpg(proc.pid, signal.SIGINT)
        rest, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    log = ''.join(lines) + rest
    assert proc.returncode in (0, 130), log
    assert 'Traceback' not in log, log
    pids = [int(p) for p in re.findall(r'started \w+ \(pid (\d+)', log)]
    assert len(pids) == 2, log
    for pid in pids:
        assert not Path(f'/proc/{pid}').exists() or _is_zombie(pid), f'pid {pid} still runs'


def _is_zombie(pid: int) -> bool:
    try:
        return Path(f'/proc/{pid}/stat').read_text().split(')')[-1].split()[0] == 'Z'
    except OSError:
        return True


# ---------------------------------------------------------------------------------------------
# The camera node, in this process
# ---------------------------------------------------------------------------------------------


@pytest.fixture
def context() -> Iterator[Context]:
    """Give each camera test its own rclpy Context on a private domain."""
    ctx = Context()
    rclpy.init(context=ctx, domain_id=next_domain_id())
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


def case2_overrides(**extra: object) -> list[Parameter]:
    """Return the camera's parameters as the Case 2 params file gives them, plus ``extra``."""
    values = load_params_file(CASE2)
    # (Empty arrays would be BYTE_ARRAY overrides: the arrays keep their declared [].)
    names = [n for n in values if n.startswith(('lens.', 'sensor.', 'scene.'))
             and not isinstance(values[n], list)]      # rclpy infers no type from []
    params = [Parameter(n, value=values[n]) for n in names]
    return params + [Parameter(k, value=v) for k, v in extra.items()]


@pytest.mark.ros
@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'mono8'], ids=['rgb8', 'bgr8', 'mono8'])
def test_camera_publishes_the_chart_through_the_lens_stamped_now(
        context: Context, encoding: str) -> None:
    camera = DemoCamera(context=context,
                        parameter_overrides=case2_overrides(encoding=encoding, rate_hz=50.0))
    client = Node('camera_test_client', context=context)
    received: list[Image] = []
    client.create_subscription(Image, 'image_raw', received.append, qos_profile_sensor_data)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(camera)
    executor.add_node(client)
    try:
        deadline = time.monotonic() + 10.0
        while len(received) < 3 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert len(received) >= 3, 'no image_raw from the camera'
        msg = received[-1]
        now_ns = client.get_clock().now().nanoseconds
        stamp_ns = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        assert 0 <= now_ns - stamp_ns < 2 * 10**9     # set when published, not at start-up
        assert received[0].header.stamp != msg.header.stamp
        assert (msg.width, msg.height, msg.encoding) == (640, 480, encoding)
        assert msg.header.frame_id == 'camera_optical_frame'
        model = build_model(load_params_file(CASE2), 640, 480)
        expected = convert_rgb(Chart(model).render(model), encoding)
        pixels, _ = image_to_array(msg)
        assert_array_equal(pixels, expected)
    finally:
        executor.shutdown()
        client.destroy_node()
        camera.destroy_node()


@pytest.mark.ros
def test_camera_takes_an_atomic_lens_change_and_refuses_impossible_ones(
        context: Context) -> None:
    camera = DemoCamera(context=context, parameter_overrides=case2_overrides())
    try:
        before = camera._out.pixels.copy()
        model = build_model(load_params_file(CASE2), 640, 480)
        chart = Chart(model)

        # Inside the focal length: refused with the model's reason, nothing changes.
        result = camera.set_parameters_atomically([Parameter('scene.distance_mm', value=3.0)])
        assert not result.successful
        assert 'scene.distance_mm' in result.reason and 'focal length' in result.reason
        assert camera.get_parameter('scene.distance_mm').value == 1000.0
        assert_array_equal(camera._out.pixels, before)

        # A sensor size that is not the camera's: refused, with both names in the reason.
        result = camera.set_parameters_atomically([Parameter('sensor.width_px', value=800)])
        assert not result.successful and 'sensor.width_px' in result.reason

        # The demo's change, atomically: rendered through the new lens, chart fixed in the world.
        result = camera.set_parameters_atomically(
            [Parameter(name, value=value) for name, value in CHANGE.items()])
        assert result.successful, result.reason
        after = build_model({**load_params_file(CASE2), **CHANGE}, 640, 480)
        assert_array_equal(camera._out.pixels, chart.render(after))
        assert blurred_difference(camera._out.pixels, before) > 5.0

        # Size and rate together: a new preallocated image of the new size.
        result = camera.set_parameters_atomically([
            Parameter('width', value=320), Parameter('height', value=240),
            Parameter('sensor.width_px', value=320), Parameter('sensor.height_px', value=240),
            Parameter('rate_hz', value=10.0)])
        assert result.successful, result.reason
        assert camera._out.pixels.shape == (240, 320, 3)
        assert (camera._out.msg.width, camera._out.msg.height) == (320, 240)
    finally:
        camera.destroy_node()


@pytest.mark.ros
def test_camera_sweeps_a_moving_lens_and_renders_each_frame_at_its_state(
        context: Context, tmp_path: Path) -> None:
    """Issue 19: each frame comes with a lens_state of its stamp and is rendered at it."""
    from mechdeconv_ros.imaging.moving_maps import render_grid
    from mechdeconv_ros.schema.params import to_params_yaml
    from sensor_msgs.msg import JointState

    values = dict(load_params_file(Path(__file__).resolve().parents[1] / 'config' /
                                   'zoom.yaml'))
    values['lens.zoom.positions'] = values['lens.zoom.positions'][:3]
    values['lens.zoom.thickness_mm'] = values['lens.zoom.thickness_mm'][:9]
    values.update({'sensor.pixel_size_x_um': 100.0, 'sensor.pixel_size_y_um': 100.0,
                   'sensor.width_px': 240, 'sensor.height_px': 136})
    path = tmp_path / 'zoom_small.yaml'
    path.write_text(to_params_yaml(values, names=[
        n for n in values if n.startswith(('lens.', 'sensor.', 'scene.'))]))
    camera = DemoCamera(context=context, parameter_overrides=[
        rclpy.parameter.Parameter('params_file', value=str(path)),
        rclpy.parameter.Parameter('width', value=240),
        rclpy.parameter.Parameter('height', value=136),
        rclpy.parameter.Parameter('lens_sweep_s', value=0.5),
        rclpy.parameter.Parameter('rate_hz', value=20.0)])
    client = Node('camera_test_client', context=context)
    frames: list[Image] = []
    states: dict[tuple[int, int], float] = {}
    client.create_subscription(Image, 'image_raw', frames.append, qos_profile_sensor_data)

    def on_state(msg: JointState) -> None:
        states[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = msg.position[0]

    client.create_subscription(JointState, 'lens_state', on_state, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(camera)
    executor.add_node(client)
    try:
        deadline = time.monotonic() + 20.0
        while len(frames) < 8 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert len(frames) >= 8, 'no image_raw from the camera'
        paired = [(f, states.get((f.header.stamp.sec, f.header.stamp.nanosec)))
                  for f in frames]
        paired = [(f, p) for f, p in paired if p is not None]
        assert len(paired) >= 4
        positions = [p for _, p in paired]
        assert 0.0 <= min(positions) < max(positions) <= 0.125
        grid = render_grid(camera._model, build_model, camera._chart.camera_matrix(0.0))
        for msg, position in paired[-3:]:
            _, full = grid.at({'zoom': position})
            expected = cv2.remap(camera._chart.texture, full, None, cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=(40, 40, 40))
            pixels, _ = image_to_array(msg)
            assert_array_equal(pixels, expected)
    finally:
        executor.shutdown()
        client.destroy_node()
        camera.destroy_node()
