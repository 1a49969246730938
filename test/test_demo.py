# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
End-to-end test of ``python -m mechdeconv_ros.demo`` (what ``make demo`` runs).

The demo starts the real ``correct_node`` and ``demo_camera`` processes. The pictures it saves
are checked against the lens model: the corrected frame must show the camera's chart
undistorted (much closer to the chart than the raw frame is), and after the lens change the
corrected frame must be the chart as the NEW lens sees it, corrected by the new model.
A second test interrupts the demo as Ctrl-C would and checks that nothing is left running.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest

from mechdeconv_ros.demo_camera import Chart
from mechdeconv_ros.model import build_model, LensModel
from mechdeconv_ros.params import load_params_file
from mechdeconv_ros.remap import Rectifier

REPO = Path(__file__).resolve().parents[1]
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
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess,
                                                                   Path, float]:
    """Run the demo once with short measuring windows; return (result, out folder, seconds)."""
    out = tmp_path_factory.mktemp('demo_out')
    start = time.monotonic()
    result = subprocess.run(
        [sys.executable, '-m', 'mechdeconv_ros.demo', '--seconds', '2', '--out', str(out)],
        cwd=REPO, env=demo_env(), stdin=subprocess.DEVNULL, capture_output=True, text=True,
        timeout=120)
    return result, out, time.monotonic() - start


@pytest.mark.ros
def test_demo_exits_0_in_time_and_both_nodes_accept_the_lens(
        demo_run: tuple[subprocess.CompletedProcess, Path, float]) -> None:
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
        demo_run: tuple[subprocess.CompletedProcess, Path, float]) -> None:
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
def test_demo_interrupted_stops_its_processes(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, '-m', 'mechdeconv_ros.demo', '--seconds', '20', '--out',
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
