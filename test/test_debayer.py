# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Tests of imaging.debayer: the ROS tile <-> OpenCV code table, methods, refusals, CLI.

A mosaic is built from a known smooth RGB image by keeping, at each pixel, the channel the
tile puts there; demosaicing it must give that RGB image back (to a few grey levels: the
interpolation is exact only on linear ramps). A wrong code (e.g. OpenCV's ``BayerRG`` for ROS
``rggb``) swaps red and blue and misses by tens of levels.
"""

from __future__ import annotations

from pathlib import Path

import cv2
from mechdeconv_ros.imaging.debayer import _CODES, demosaic, Demosaicer, method_for, stripe_count
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import BAYER_PATTERNS, check_values, DEBAYER_METHODS, SPECS
from mechdeconv_ros.tools.cli import main
import numpy as np
import numpy.testing as npt
import pytest

#: Channel index of each tile letter in RGB order.
_CHANNEL = {'r': 0, 'g': 1, 'b': 2}


def smooth_rgb(height: int = 48, width: int = 64, dtype: type = np.uint8) -> np.ndarray:
    """Return a smooth RGB image whose three channels differ everywhere."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    rgb = np.stack([0.55 + 0.25 * np.sin(x / 9.0), 0.45 + 0.2 * np.cos(y / 7.0),
                    0.3 + 0.15 * np.sin((x + y) / 11.0)], axis=-1)
    top = np.iinfo(dtype).max
    return np.round(rgb * top).astype(dtype)


def mosaic_of(rgb: np.ndarray, pattern: str) -> np.ndarray:
    """Return the Bayer mosaic a sensor with this tile records of ``rgb``."""
    mosaic = np.empty(rgb.shape[:2], rgb.dtype)
    for letter, (dy, dx) in zip(pattern, ((0, 0), (0, 1), (1, 0), (1, 1))):
        mosaic[dy::2, dx::2] = rgb[dy::2, dx::2, _CHANNEL[letter]]
    return mosaic


@pytest.mark.parametrize('method', DEBAYER_METHODS)
@pytest.mark.parametrize('pattern', BAYER_PATTERNS)
def test_each_tile_gives_back_the_rgb_image(pattern: str, method: str) -> None:
    rgb = smooth_rgb()
    out = demosaic(mosaic_of(rgb, pattern), pattern, method)
    assert out.shape == rgb.shape and out.dtype == np.uint8
    inner = (slice(4, -4), slice(4, -4))
    # Within a few levels (VNG is not exact on curved ramps); a swapped R/B is > 20 off.
    npt.assert_allclose(out[inner], rgb[inner], atol=6)
    swapped = demosaic(mosaic_of(rgb[..., ::-1], pattern), pattern, method)
    assert np.abs(swapped[inner].astype(int) - rgb[inner]).max() > 20


@pytest.mark.parametrize('pattern', BAYER_PATTERNS)
def test_vng_in_stripes_is_bit_identical_to_the_whole_frame_call(pattern: str) -> None:
    rng = np.random.default_rng(7)
    code = _CODES[(pattern, 'vng')]
    # Noise (every neighbour matters), rows that do not split evenly, odd stripe heights.
    for height, width in ((1080, 96), (642, 34), (258, 40)):
        mosaic = rng.integers(0, 256, (height, width), dtype=np.uint8)
        whole = cv2.cvtColor(mosaic, code)
        for threads in (2, 3, 4, 8):
            assert stripe_count(height, threads) > 1
            out = np.empty_like(whole)
            assert demosaic(mosaic, pattern, 'vng', dst=out, threads=threads) is out
            npt.assert_array_equal(out, whole, err_msg=f'{height} rows, {threads} stripes')
    npt.assert_array_equal(demosaic(mosaic, pattern, 'vng', threads=4), whole)
    assert stripe_count(100, 4) == 1, 'a small frame is demosaiced whole'
    # The Demosaicer's stripes (OpenCV's thread count) keep their buffers between frames.
    previous = cv2.getNumThreads()
    cv2.setNumThreads(3)
    try:
        demosaicer = Demosaicer()
        first, _ = demosaicer.demosaic(mosaic, pattern, 'vng')
        npt.assert_array_equal(first, whole)
        kept = dict(demosaicer._scratch)
        other = rng.integers(0, 256, mosaic.shape, dtype=np.uint8)
        again, _ = demosaicer.demosaic(other, pattern, 'vng')
        npt.assert_array_equal(again, cv2.cvtColor(other, code))
        assert len(kept) == 3 and all(demosaicer._scratch[k] is v for k, v in kept.items())
    finally:
        cv2.setNumThreads(previous)


@pytest.mark.parametrize('pattern', BAYER_PATTERNS)
@pytest.mark.parametrize('method', ['bilinear', 'edge_aware'])
def test_16_bit_tiles(pattern: str, method: str) -> None:
    rgb = smooth_rgb(dtype=np.uint16)
    out = demosaic(mosaic_of(rgb, pattern), pattern, method)
    assert out.dtype == np.uint16
    inner = (slice(4, -4), slice(4, -4))
    npt.assert_allclose(out[inner], rgb[inner], atol=6 * 257)


def test_16_bit_vng_falls_back_to_edge_aware_and_says_so_once() -> None:
    assert method_for('vng', np.uint16) == 'edge_aware'
    assert method_for('vng', np.uint8) == 'vng'
    mosaic = mosaic_of(smooth_rgb(dtype=np.uint16), 'grbg')
    demosaicer = Demosaicer()
    first, note = demosaicer.demosaic(mosaic, 'grbg', 'vng')
    assert note is not None and 'edge_aware' in note and 'VNG' in note
    npt.assert_array_equal(first, demosaic(mosaic, 'grbg', 'edge_aware'))
    again, note = demosaicer.demosaic(mosaic, 'grbg', 'vng')
    assert note is None and again is first, 'the buffer is reused, the note given once'


def test_demosaicer_writes_into_one_buffer_per_size() -> None:
    demosaicer = Demosaicer()
    small = mosaic_of(smooth_rgb(8, 10), 'rggb')
    a, _ = demosaicer.demosaic(small, 'rggb', 'bilinear')
    b, _ = demosaicer.demosaic(small, 'rggb', 'bilinear')
    assert a is b
    c, _ = demosaicer.demosaic(mosaic_of(smooth_rgb(12, 10), 'rggb'), 'rggb', 'bilinear')
    assert c.shape == (12, 10, 3)


@pytest.mark.parametrize(('mosaic', 'pattern', 'method', 'match'), [
    (np.zeros((6, 8), np.uint8), 'rgbg', 'vng', 'Bayer pattern'),
    (np.zeros((6, 8), np.uint8), 'rggb', 'ahd', 'debayer'),
    (np.zeros((6, 8, 3), np.uint8), 'rggb', 'vng', 'one channel'),
    (np.zeros((6, 8), np.float32), 'rggb', 'bilinear', 'one channel'),
    (np.zeros((6, 7), np.uint8), 'rggb', 'bilinear', 'even width'),
    (np.zeros((5, 8), np.uint16), 'rggb', 'bilinear', 'even width'),
], ids=['tile', 'method', 'three-channels', 'float', 'odd-width', 'odd-height'])
def test_refusals(mosaic: np.ndarray, pattern: str, method: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        demosaic(mosaic, pattern, method)


def test_parameter_defaults_to_image_procs_vng_and_refuses_others() -> None:
    assert SPECS['debayer'].default == 'vng'
    assert 'image_proc' in SPECS['debayer'].description
    assert not SPECS['debayer'].is_model, 'a demosaicing change must not rebuild the model'
    with pytest.raises(ValueError, match='debayer'):
        check_values({'debayer': 'ahd'})


def test_cli_corrects_a_bayer_png(tmp_path: Path) -> None:
    rgb = smooth_rgb(240, 320)
    for bits, scale in ((8, 1), (16, 257)):
        src = tmp_path / f'raw{bits}.png'
        mosaic = mosaic_of(rgb.astype(np.uint16 if bits == 16 else np.uint8) * scale, 'gbrg')
        assert cv2.imwrite(str(src), mosaic)
        out = tmp_path / f'out{bits}.png'
        assert main(['correct', '--bayer', 'gbrg', '-p', 'debayer=edge_aware', str(src),
                     str(out)]) == 0
        written = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
        assert written.dtype == mosaic.dtype and written.shape == (240, 320, 3)
        model = build_model(check_values({}), 320, 240)
        expected = Rectifier(model).correct(demosaic(mosaic, 'gbrg', 'edge_aware'))
        # cv2.imwrite writes BGR: the file holds the corrected RGB in BGR order.
        npt.assert_array_equal(written[..., ::-1], expected)


def test_cli_refuses_a_colour_or_odd_input_with_bayer(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    colour = tmp_path / 'colour.png'
    cv2.imwrite(str(colour), smooth_rgb(40, 40))
    odd = tmp_path / 'odd.png'
    cv2.imwrite(str(odd), np.zeros((41, 40), np.uint8))
    assert main(['correct', '--bayer', 'rggb', str(colour), str(tmp_path / 'o.png')]) == 2
    assert 'one-channel' in capsys.readouterr().err
    assert main(['correct', '--bayer', 'rggb', str(odd), str(tmp_path / 'o.png')]) == 2
    assert 'even width and height' in capsys.readouterr().err
