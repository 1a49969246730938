# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""Maps and per-frame correction: symmetry, dtypes, strided input, depth, sizes."""

from __future__ import annotations

import cv2
from mechdeconv_ros.imaging.remap import build_float_maps, distort_image, Rectifier
from mechdeconv_ros.model.model import build_model
import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest


@pytest.fixture(scope='module')
def model():
    return build_model({}, 320, 240)


@pytest.mark.parametrize('size', [(320, 240), (321, 241), (1, 1), (2, 3)],
                         ids=['even', 'odd', 'one-pixel', 'tiny'])
def test_maps_equal_the_direct_evaluation(size):
    """The mirrored-quadrant fast path equals the model's own per-point map everywhere."""
    model = build_model({}, *size)
    map_x, map_y = build_float_maps(model)
    v, u = np.mgrid[0:model.out_height, 0:model.out_width].astype(np.float64)
    direct = model.raw_from_rect(np.stack([u, v], axis=-1))
    valid = np.isfinite(direct[..., 0])
    assert_allclose(map_x[valid], direct[..., 0][valid], atol=2e-3)
    assert_allclose(map_y[valid], direct[..., 1][valid], atol=2e-3)
    assert np.all(map_x[~valid] < -100)


def test_maps_are_point_symmetric(model):
    map_x, map_y = build_float_maps(model)
    cx, cy = model.K[0, 2], model.K[1, 2]
    assert_allclose(map_x + map_x[::-1, ::-1], 2 * cx, atol=1e-3)
    assert_allclose(map_y + map_y[::-1, ::-1], 2 * cy, atol=1e-3)


@pytest.mark.parametrize('dtype, channels', [
    (np.uint8, 1), (np.uint8, 3), (np.uint8, 4), (np.uint16, 1), (np.float32, 1)],
    ids=['mono8', 'rgb8', 'rgba8', 'mono16', '32FC1'])
def test_correct_dtypes_and_preallocated_dst(model, dtype, channels):
    rng = np.random.default_rng(0)
    shape = (240, 320) if channels == 1 else (240, 320, channels)
    src = (rng.random(shape) * 200).astype(dtype)
    rect = Rectifier(model)
    expected = rect.correct(src)
    dst = np.empty_like(expected)
    out = rect.correct(src, dst)
    assert out is dst or np.shares_memory(out, dst)
    assert_array_equal(dst, expected)
    assert dst.dtype == dtype and dst.shape == src.shape


def test_row_padded_input_view(model):
    """A view with padded rows (ROS step > width * bytes) is corrected like the packed image."""
    rng = np.random.default_rng(0)
    packed = rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)
    buffer = np.zeros((240, 336 * 3), np.uint8)
    buffer[:, :960] = packed.reshape(240, 960)
    view = np.lib.stride_tricks.as_strided(buffer, (240, 320, 3), (336 * 3, 3, 1))
    rect = Rectifier(model)
    assert_array_equal(rect.correct(view), rect.correct(packed))


def test_nearest_invents_no_values(model):
    rng = np.random.default_rng(0)
    depth = rng.choice(np.array([0.0, 1.5, 2.25, 7.0], np.float32), size=(240, 320))
    out = Rectifier(model).correct(depth, nearest=True)
    assert set(np.unique(out)) <= {0.0, 1.5, 2.25, 7.0}
    linear = Rectifier(model).correct(depth)
    assert len(np.unique(linear)) > 4, 'bilinear blends depths: that is why depth uses nearest'


def test_outside_the_field_is_black():
    model = build_model({'output.alpha': 1.0}, 640, 480)
    out = Rectifier(model).correct(np.full((480, 640), 255, np.uint8))
    # Barrel distortion: the raw outline bulges at the corners, so the edge midpoints are
    # outside the source once every source pixel is in view.
    assert out[0, 320] == 0 and out[240, 320] == 255 and out[0, 0] > 0


def test_wrong_size_is_refused(model):
    with pytest.raises(ValueError, match='320x240'):
        Rectifier(model).correct(np.zeros((10, 10), np.uint8))


def test_distort_then_correct_is_identity_inside(model):
    v, u = np.mgrid[0:240, 0:320].astype(np.float32)
    scene = 100 + 50 * np.sin(u / 11.0) + 50 * np.cos(v / 13.0)
    back = Rectifier(model).correct(distort_image(model, scene))
    inner = (slice(6, 234), slice(6, 314))
    assert np.abs(back[inner] - scene[inner]).mean() < 0.2
    assert cv2.PSNR(back[inner].astype(np.float64), scene[inner].astype(np.float64),
                    255) > 40
