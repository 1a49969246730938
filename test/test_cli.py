# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The mechdeconv command line: outputs, JSON keys, exit codes, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path
import subprocess
import sys

import cv2
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.tools.cli import main
import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
CASE2 = str(ROOT / 'config' / 'case2.yaml')
CONFIG = ROOT / 'config'


def run(capsys, *argv):
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_info_json_has_every_documented_key(capsys):
    status, out, _ = run(capsys, 'info', '--params', CASE2, '--json')
    assert status == 0
    report = json.loads(out)
    for key in ('focal_length_mm', 'focal_length_sigma_mm', 'image_distance_mm', 'f_number',
                'hyperfocal_mm', 'K', 'D', 'distortion_model', 'P', 'fit_rms_px',
                'max_displacement_px'):
        assert key in report, key
    assert set(report['fov_deg']) == {'horizontal', 'vertical', 'diagonal'}
    assert set(report['depth_of_field_mm']) == {'near', 'far'}
    assert set(report['feature_resolution_mm']) == {'x', 'y'}
    assert set(report['footprint_mm']) == {'x', 'y'}
    curve = report['distortion_curve']
    assert len(curve['ideal_height_mm']) == len(curve['real_height_mm']) > 100
    assert_allclose(report['K'], build_model({'sensor.width_px': 640,
                                              'sensor.height_px': 480}).K)


def test_info_text_and_size_override(capsys):
    status, out, _ = run(capsys, 'info', '--params', CASE2, '--width', '1280', '--height', '720')
    assert status == 0
    assert '1280x720 px' in out and 'f = 4.43' in out


def test_camera_info_yaml(capsys):
    status, out, _ = run(capsys, 'camera-info', '--params', CASE2, '-p',
                         'lens.stop_offset_mm=0.5')
    assert status == 0
    data = yaml.safe_load(out)
    expected = build_model({'sensor.width_px': 640, 'sensor.height_px': 480,
                            'lens.stop_offset_mm': 0.5})
    assert_allclose(data['distortion_coefficients']['data'], expected.D)


def test_correct_file_and_folder(tmp_path, capsys):
    image = np.full((480, 640, 3), 200, np.uint8)
    cv2.imwrite(str(tmp_path / 'a.png'), image)
    cv2.imwrite(str(tmp_path / 'b.png'), image)
    status, _, _ = run(capsys, 'correct', '--params', CASE2, str(tmp_path / 'a.png'),
                       str(tmp_path / 'out.png'))
    assert status == 0
    assert cv2.imread(str(tmp_path / 'out.png')).shape == (480, 640, 3)
    folder = tmp_path / 'in'
    folder.mkdir()
    for name in ('a.png', 'b.png'):
        (tmp_path / name).rename(folder / name)
    status, _, err = run(capsys, 'correct', '--params', CASE2, str(folder),
                         str(tmp_path / 'outdir'))
    assert status == 0
    assert sorted(p.name for p in (tmp_path / 'outdir').iterdir()) == ['a.png', 'b.png']
    assert 'correcting' in err  # the progress bar


def test_plot_writes_a_png(tmp_path, capsys):
    out = tmp_path / 'plot.png'
    status, _, _ = run(capsys, 'plot', '--params', CASE2, str(out))
    assert status == 0
    image = cv2.imread(str(out))
    assert image is not None and image.shape[0] > 500


@pytest.mark.parametrize('argv, words', [
    (['info', '--params', CASE2, '-p', 'scene.distance_mm=3.0'], 'scene.distance_mm'),
    (['info', '--params', CASE2, '-p', 'lens.r2_mm=4.0', '-p', 'lens.thickness_mm=0.0'],
     'afocal'),
    (['info', '--params', CASE2, '-p', 'sensor.pixel_size_x_um=-2.0'], 'sensor.pixel_size_x_um'),
    (['info', '--params', '/nonexistent.yaml'], '--params'),
    (['info', '--params', CASE2, '--width', '0'], '--width'),
    (['info'], 'image size is unknown'),
    (['correct', '--params', CASE2, '/nonexistent.png', 'x.png'], 'no such file'),
    (['info', '--params', CASE2, '-p', 'scene.focus_distance_mm=3.0'],
     'scene.focus_distance_mm: 3 mm is inside the focal length 4.437 mm'),
    (['info', '--params', CASE2, '-p', 'lens.stop_offset_mm=-10'],
     'lens.stop_offset_mm: -10 mm puts the stop'),
    (['camera-info', '--params', CASE2, '-p', 'lens.aperture_diameter_mm=1000'],
     'lens.aperture_diameter_mm: 1000 mm'),
    (['plot', '--params', CASE2, '-p', 'scene.circle_of_confusion_mm=5', 'x.png'],
     'scene.circle_of_confusion_mm: 5 mm is larger than'),
], ids=['scene-inside-f', 'afocal', 'negative-pixel', 'missing-file', 'zero-width',
        'no-size', 'missing-image', 'focus-inside-f', 'stop-behind-sensor', 'aperture-1000',
        'circle-of-confusion'])
def test_bad_input_is_one_line_and_status_2(capsys, argv, words):
    # In this process (main() is what the console script runs; the subprocess route is
    # test_the_console_entry_exits_2_in_one_line).
    status, _, err = run(capsys, *argv)
    assert status == 2
    assert 'Traceback' not in err
    assert len(err.strip().splitlines()) == 1, err
    assert words in err


def test_the_console_entry_exits_2_in_one_line():
    proc = subprocess.run([sys.executable, '-m', 'mechdeconv_ros.tools.cli', 'info', '--params',
                           CASE2, '-p', 'lens.stop_offset_mm=-10'],
                          capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        proc.stderr.strip()] and 'lens.stop_offset_mm: -10 mm puts the stop' in proc.stderr


def test_unreadable_image(tmp_path):
    bad = tmp_path / 'bad.png'
    bad.write_text('not an image')
    proc = subprocess.run([sys.executable, '-m', 'mechdeconv_ros.tools.cli', 'correct', '--params',
                           CASE2, str(bad), str(tmp_path / 'o.png')],
                          capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 2
    assert 'not a readable image' in proc.stderr


def test_params_file_that_describes_no_camera(tmp_path):
    """A params file with a focus distance inside f is refused like the same -p value."""
    text = Path(CASE2).read_text().replace('focus_distance_mm: 0.0', 'focus_distance_mm: 3.0')
    bad = tmp_path / 'bad.yaml'
    bad.write_text(text)
    proc = subprocess.run([sys.executable, '-m', 'mechdeconv_ros.tools.cli', 'info', '--params',
                           str(bad)], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith('mechdeconv: error: scene.focus_distance_mm: 3 mm')


def test_unusual_values_warn_once_on_stderr(tmp_path):
    """A far stop is accepted; the warning is printed once even for a folder of images."""
    folder = tmp_path / 'in'
    folder.mkdir()
    for name in ('a.png', 'b.png', 'c.png'):
        cv2.imwrite(str(folder / name), np.full((48, 64), 100, np.uint8))
    proc = subprocess.run([sys.executable, '-m', 'mechdeconv_ros.tools.cli', 'correct', '--params',
                           CASE2, '-p', 'lens.stop_offset_mm=7', str(folder),
                           str(tmp_path / 'out')],
                          capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if 'warning' in line]
    assert len(lines) == 1 and 'lens.stop_offset_mm: the stop is' in lines[0]


def test_lens_state_evaluates_the_moving_lens(capsys, tmp_path):
    from mechdeconv_ros.lenses.lens_table import values_at
    from mechdeconv_ros.schema.params import load_params_file

    zoom = str(CONFIG / 'zoom.yaml')
    status, out, err = run(capsys, 'info', '--params', zoom, '--lens-state', 'zoom=0.4',
                           '--json', '--width', '320', '--height', '180')
    assert status == 0, err
    report = json.loads(out)
    assert report['lens_state'] == {'zoom': 0.4}
    values = load_params_file(CONFIG / 'zoom.yaml')
    exact = build_model({**values_at(values, {'zoom': 0.4}), 'sensor.width_px': 320,
                         'sensor.height_px': 180})
    assert_allclose(report['K'], exact.K)
    assert_allclose(report['D'], exact.D, rtol=1e-9)
    # camera-info of the same state; clamped outside the table, with one warning.
    status, out, err = run(capsys, 'camera-info', '--params', zoom, '--lens-state', 'zoom=7')
    assert status == 0 and err.count('outside lens.zoom.positions') == 1
    long_end = build_model(values_at(values, {'zoom': 1.0}))
    assert_allclose(yaml.safe_load(out)['camera_matrix']['data'], long_end.K.ravel())
    # correct: the image of that state.
    image = np.random.default_rng(0).integers(0, 255, (540, 960), np.uint8)
    cv2.imwrite(str(tmp_path / 'in.png'), image)
    status, _, err = run(capsys, 'correct', '--params', zoom, '--lens-state', 'zoom=1',
                         str(tmp_path / 'in.png'), str(tmp_path / 'out.png'))
    assert status == 0, err
    from mechdeconv_ros.imaging.remap import Rectifier
    expected = Rectifier(long_end).correct(image)
    assert np.array_equal(cv2.imread(str(tmp_path / 'out.png'), cv2.IMREAD_UNCHANGED), expected)


@pytest.mark.parametrize('state, words', [
    ('focus=1', 'focus does not move'), ('zoom', 'expected zoom=X'), ('zoom=nan', 'finite')])
def test_lens_state_refusals(capsys, state, words):
    status, _, err = run(capsys, 'info', '--params', str(CONFIG / 'zoom.yaml'),
                         '--lens-state', state)
    assert status == 2 and words in err and err.startswith('mechdeconv: error: --lens-state')
