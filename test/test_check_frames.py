# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Frames a real camera sends (issue 36, item 4): JPEG, Bayer, motion blur, 10/12-bit, dim.

The fisheye's box room and grid (test/check_scenes.py) at half size (640 x 480, a 4 um
pitch: the model is the same lens with that sensor), rendered through the TRUE description,
then sent as each kind of :func:`check_scenes.as_sent`. No kind may read
``description_off`` with the true description, and a wrong one (the axis centred: 16 and
12 px of the full frame off) is still flagged. The 100-frame run over the kinds is
benchmarks/check_real_frames.py (docs/design.md section 2.17).
"""

from __future__ import annotations

import json
from pathlib import Path

from check_scenes import as_sent, box_room, grid, half_size, KINDS, Lens, PIXEL_MM
import cv2
from mechdeconv_ros.imaging import plumb_check as pc
from mechdeconv_ros.imaging.remap import build_float_maps, Rectifier
from mechdeconv_ros.imaging.straight_edges import grey
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.tools.cli import main
import numpy as np
import pytest
from test_check import MAX_RMS_PX, OFFSET_PX, REPO, values

OFF = OFFSET_PX['fisheye']


def half_values(offset_px: tuple[float, float]) -> dict:
    """Return the fisheye's values for the half-size sensor (offsets in full-size px)."""
    vals = values('fisheye', offset_px)
    vals['sensor.width_px'], vals['sensor.height_px'] = 640, 480
    vals['sensor.pixel_size_x_um'] = vals['sensor.pixel_size_y_um'] = 2000.0 * PIXEL_MM
    return vals


@pytest.fixture(scope='module')
def frames() -> list[np.ndarray]:
    """Render the room and a grid through the true description, at half size."""
    lens = Lens('fisheye')
    return [half_size(box_room(lens, OFF)), half_size(grid(lens, OFF, 0.0, 0.0, 10.0))]


@pytest.fixture(scope='module')
def models() -> dict:
    """Build the true and the nominal (centred) descriptions of the half-size sensor."""
    return {'true': build_model(half_values(OFF)),
            'nominal': build_model(half_values((0.0, 0.0)))}


def test_sixteen_bit_data_is_read_at_its_depth() -> None:
    rng = np.random.default_rng(0)
    base = rng.integers(0, 256, (64, 64)).astype(np.float64)
    for top in (1023, 4095, 65535):
        data = np.rint(base * top / 255.0).astype(np.uint16)
        np.testing.assert_allclose(grey(data), grey(base.astype(np.uint8)), atol=0.6)


def test_a_dim_frame_is_brightened_to_the_reference_level() -> None:
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 41, (64, 64)).astype(np.uint8)
    out = grey(frame)
    np.testing.assert_allclose(np.percentile(out[::4, ::4], 99), 128.0, rtol=1e-3)
    bright = rng.integers(0, 256, (64, 64)).astype(np.uint8)
    np.testing.assert_allclose(grey(bright), bright.astype(np.float32))


@pytest.mark.parametrize('kind', KINDS)
def test_the_true_description_is_never_off(frames: list, models: dict, kind: str) -> None:
    sent = [as_sent(f, kind, seed) for seed, f in enumerate(frames)]
    result = pc.check_images(models['true'], sent, MAX_RMS_PX)
    assert result.verdict != 'description_off', (kind, result.as_dict())
    assert result.verdict == 'ok', (kind, result.as_dict())
    wrong = pc.check_images(models['nominal'], sent, MAX_RMS_PX)
    assert wrong.verdict == 'description_off', (kind, wrong.as_dict())


@pytest.mark.parametrize('kind', ['mono16_12bit', 'dim20'])
def test_the_nodes_route_reads_them_too(frames: list, models: dict, kind: str) -> None:
    # The node checks its corrected frame (mono16 stays uint16 through the remap) and
    # carries the chains back through the maps: the same depth and contrast rules apply.
    model = models['true']
    rect = Rectifier(model)
    map_x, map_y = build_float_maps(model)
    chains = []
    for seed, frame in enumerate(frames):
        sent = as_sent(frame, kind, seed)
        corrected = rect.correct(sent)
        assert corrected.dtype == sent.dtype
        chains += pc.chains_from_corrected(corrected, map_x, map_y)
    result = pc.check_chains(model, chains, MAX_RMS_PX)
    assert result.verdict == 'ok', (kind, result.as_dict())


def test_cli_reads_a_twelve_bit_png(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    # mechdeconv check reads 16-bit PNGs unchanged: a 12-bit room (values to 4095) of the
    # full-size sensor against config/fisheye.yaml (the axis centred, 16 and 12 px off).
    lens = Lens('fisheye')
    path = tmp_path / 'room12.png'
    cv2.imwrite(str(path), as_sent(box_room(lens, OFF), 'mono16_12bit'))
    assert main(['check', '--params', str(REPO / 'config/fisheye.yaml'), '--json',
                 str(path)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['verdict'] == 'description_off', out
    assert out['edges'] >= 10
    assert abs(out['estimate']['sensor.axis_offset_x_mm']['value'] / PIXEL_MM - OFF[0]) <= 4.0
