# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""Tests of mechdeconv_ros.node.image_msgs: Image <-> numpy views, output buffers, CameraInfo."""

from __future__ import annotations

import array
from types import SimpleNamespace
from typing import Any

import cv2
from mechdeconv_ros.node import image_msgs
from mechdeconv_ros.node.image_msgs import (
    camera_info_from_model, ENCODINGS, fill_camera_info, image_to_array, lookup_encoding,
    MalformedImageError, new_output_image, OutputImagePool, UnsupportedEncodingError)
from mechdeconv_ros.schema.params import MAX_SIDE_PX
import numpy as np
import numpy.testing as npt
import pytest
from sensor_msgs.msg import CameraInfo, Image

RNG_SEED = 0


def make_image(pixels: np.ndarray, encoding: str, *, pad: int = 0,
               bigendian: bool = False) -> Image:
    """
    Build an Image holding ``pixels`` with ``pad`` bytes of padding per row.

    :param pixels: ``(H, W)`` or ``(H, W, C)`` array in the encoding's dtype (native order).
    :param encoding: the encoding name.
    :param pad: extra bytes at the end of every row (filled with 0xAB).
    :param bigendian: store multi-byte values big-endian and set ``is_bigendian``.
    :return: the message.
    """
    height, width = pixels.shape[:2]
    stored = pixels.astype(pixels.dtype.newbyteorder('>' if bigendian else '<'))
    rows = stored.reshape(height, -1).view(np.uint8)
    padded = np.full((height, rows.shape[1] + pad), 0xAB, np.uint8)
    padded[:, :rows.shape[1]] = rows
    msg = Image()
    msg.width, msg.height, msg.encoding = width, height, encoding
    msg.step = padded.shape[1]
    msg.is_bigendian = int(bigendian)
    msg.data = array.array('B', padded.tobytes())
    return msg


def random_pixels(encoding: str, height: int = 7, width: int = 5) -> np.ndarray:
    """Return seeded random pixels of the encoding's dtype and channel count (Bayer: even)."""
    enc = ENCODINGS[encoding]
    if enc.bayer:
        height, width = height + height % 2, width + width % 2
    rng = np.random.default_rng(RNG_SEED)
    shape: tuple[int, ...] = (height, width)
    if enc.channels > 1:
        shape = (height, width, enc.channels)
    if enc.dtype == np.float32:
        return rng.uniform(0.2, 10.0, shape).astype(np.float32)
    return rng.integers(0, np.iinfo(enc.dtype).max, shape, endpoint=True).astype(enc.dtype)


def buffer_of(msg: Image) -> np.ndarray:
    """Return a uint8 view on the message's data."""
    return np.frombuffer(msg.data, np.uint8)


@pytest.mark.parametrize('encoding', sorted(ENCODINGS))
def test_every_encoding_round_trips_without_copy(encoding: str) -> None:
    pixels = random_pixels(encoding)
    msg = make_image(pixels, encoding)
    view, enc = image_to_array(msg)
    assert enc.name == encoding
    assert view.dtype == ENCODINGS[encoding].dtype and view.dtype.isnative
    npt.assert_array_equal(view, pixels)
    assert np.shares_memory(view, buffer_of(msg)), 'the view must not copy the frame'


@pytest.mark.parametrize(('encoding', 'depth'), [
    ('16UC1', True), ('32FC1', True), ('mono16', False), ('mono8', False), ('rgb8', False)],
    ids=['16UC1', '32FC1', 'mono16', 'mono8', 'rgb8'])
def test_depth_encodings_are_flagged(encoding: str, depth: bool) -> None:
    assert lookup_encoding(encoding).depth is depth


@pytest.mark.parametrize('encoding', ['mono8', 'rgb8', 'bgra8', '16UC1', 'mono16', '32FC1'])
def test_step_padding_gives_a_strided_view(encoding: str) -> None:
    pixels = random_pixels(encoding, height=6, width=9)
    itemsize = ENCODINGS[encoding].dtype.itemsize
    msg = make_image(pixels, encoding, pad=4 * itemsize)
    view, _ = image_to_array(msg)
    npt.assert_array_equal(view, pixels)
    assert view.strides[0] == msg.step
    assert np.shares_memory(view, buffer_of(msg))


def test_odd_step_of_16_bit_image_is_copied_aligned() -> None:
    pixels = random_pixels('16UC1', height=4, width=5)
    msg = make_image(pixels, '16UC1', pad=3)     # step 13: rows start at odd addresses
    view, _ = image_to_array(msg)
    npt.assert_array_equal(view, pixels)
    assert view.flags.aligned


@pytest.mark.parametrize('encoding', ['16UC1', 'mono16', '32FC1'])
def test_big_endian_is_swapped_to_native(encoding: str) -> None:
    pixels = random_pixels(encoding)
    msg = make_image(pixels, encoding, bigendian=True, pad=2 * ENCODINGS[encoding].dtype.itemsize)
    assert not np.array_equal(buffer_of(msg)[:2], pixels.reshape(-1).view(np.uint8)[:2]), \
        'the fixture must really store big-endian bytes'
    view, _ = image_to_array(msg)
    assert view.dtype.isnative
    npt.assert_array_equal(view, pixels)


def test_big_endian_flag_on_8_bit_image_needs_no_copy() -> None:
    pixels = random_pixels('rgb8')
    msg = make_image(pixels, 'rgb8', bigendian=True)
    view, _ = image_to_array(msg)
    npt.assert_array_equal(view, pixels)
    assert np.shares_memory(view, buffer_of(msg))


@pytest.mark.parametrize(('encoding', 'expected'), [
    ('bayer_rgbg8', 'debayer'),
    ('bayer_grbg12', 'debayer'),
    ('yuv422', 'YUV'),
    ('yuv422_yuy2', 'YUV'),
    ('16SC1', 'Supported'),
    ('8UC2', 'Supported'),
    ('jpeg', 'decompress'),
    ('', 'empty'),
], ids=['bayer8', 'bayer16', 'yuv422', 'yuy2', '16SC1', '8UC2', 'jpeg', 'empty'])
def test_unsupported_encoding_names_it_and_the_fix(encoding: str, expected: str) -> None:
    msg = make_image(np.zeros((2, 2), np.uint8), encoding)
    with pytest.raises(UnsupportedEncodingError) as info:
        image_to_array(msg)
    assert f"'{encoding}'" in str(info.value)
    assert expected in str(info.value)
    assert info.value.encoding == encoding


def test_unknown_bayer_message_names_the_read_ones_and_image_proc() -> None:
    with pytest.raises(UnsupportedEncodingError, match="image_proc's debayer") as info:
        lookup_encoding('BAYER_RGGB8')
    assert 'bayer_rggb8' in str(info.value)


@pytest.mark.parametrize('encoding', [f'bayer_{t}{b}' for b in (8, 16)
                                      for t in ('rggb', 'bggr', 'gbrg', 'grbg')])
def test_bayer_encodings_are_read_as_one_channel_mosaics(encoding: str) -> None:
    enc = lookup_encoding(encoding)
    assert enc.channels == 1 and enc.bayer == encoding[6:10]
    assert enc.dtype == (np.uint8 if encoding.endswith('8') else np.uint16)
    assert not enc.depth
    pixels = random_pixels(encoding, height=6, width=8)
    view, _ = image_to_array(make_image(pixels, encoding, pad=4))
    npt.assert_array_equal(view, pixels)


@pytest.mark.parametrize(('width', 'height'), [(7, 6), (8, 5), (1, 1)],
                         ids=['odd-width', 'odd-height', 'one-pixel'])
def test_bayer_mosaic_of_odd_size_is_malformed(width: int, height: int) -> None:
    msg = make_image(np.zeros((height, width), np.uint8), 'bayer_rggb8')
    with pytest.raises(MalformedImageError, match='even width and height'):
        image_to_array(msg)


def test_short_bayer_buffer_is_malformed() -> None:
    msg = make_image(np.zeros((6, 8), np.uint16), 'bayer_gbrg16')
    del msg.data[-3:]
    with pytest.raises(MalformedImageError, match='less than step'):
        image_to_array(msg)


def _malformed(**fields: Any) -> Image:
    msg = make_image(np.zeros((4, 6), np.uint16), '16UC1')
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg


@pytest.mark.parametrize(('fields', 'match'), [
    ({'data': array.array('B', bytes(47))}, 'less than step'),
    ({'step': 11}, 'step 11 is less than'),
    ({'width': 0}, 'zero size'),
    ({'height': 0}, 'zero size'),
    ({'width': MAX_SIDE_PX + 1}, 'beyond the limit'),
    ({'width': 16000, 'height': 16000}, 'beyond the limit'),
], ids=['short-data', 'short-step', 'zero-width', 'zero-height', 'wide', 'huge-area'])
def test_malformed_frames_are_refused(fields: dict[str, Any], match: str) -> None:
    with pytest.raises(MalformedImageError, match=match):
        image_to_array(_malformed(**fields))


def test_data_longer_than_needed_is_accepted() -> None:
    pixels = random_pixels('mono8')
    msg = make_image(pixels, 'mono8')
    msg.data.extend(bytes(10))
    view, _ = image_to_array(msg)
    npt.assert_array_equal(view, pixels)


@pytest.mark.parametrize('encoding', sorted(e for e in ENCODINGS if not ENCODINGS[e].bayer))
def test_output_image_is_written_in_place(encoding: str) -> None:
    out = new_output_image(9, 6, encoding)
    enc = ENCODINGS[encoding]
    assert isinstance(out.msg.data, array.array) and out.msg.data.typecode == 'B'
    assert out.msg.step == 9 * enc.bytes_per_pixel
    assert len(out.msg.data) == out.msg.step * 6
    assert out.msg.is_bigendian == int(image_msgs.HOST_IS_BIGENDIAN)
    src = random_pixels(encoding, height=6, width=9)
    identity_x, identity_y = np.meshgrid(np.arange(9, dtype=np.float32),
                                         np.arange(6, dtype=np.float32))
    result = cv2.remap(src, identity_x, identity_y, cv2.INTER_NEAREST, dst=out.pixels)
    assert result is out.pixels or np.shares_memory(result, out.pixels)
    # The message itself carries the pixels: decode it as a receiver would.
    decoded, _ = image_to_array(out.msg)
    npt.assert_array_equal(decoded, src)


def test_pool_reuses_and_evicts() -> None:
    pool = OutputImagePool(capacity=2)
    first = pool.get(4, 3, 'mono8')
    assert pool.get(4, 3, 'mono8') is first
    pool.get(4, 3, 'rgb8')
    pool.get(4, 3, 'mono8')                  # most recent again
    pool.get(8, 3, 'mono8')                  # evicts rgb8, not mono8
    assert len(pool) == 2
    assert pool.get(4, 3, 'mono8') is first


def test_pool_refuses_bad_requests() -> None:
    pool = OutputImagePool()
    with pytest.raises(UnsupportedEncodingError):
        pool.get(4, 3, 'yuv422')
    with pytest.raises(MalformedImageError):
        pool.get(0, 3, 'mono8')


def _stub_model() -> SimpleNamespace:
    k = np.array([[500.0, 0.0, 319.5], [0.0, 480.0, 239.5], [0.0, 0.0, 1.0]])
    k_new = np.array([[450.0, 0.0, 399.5], [0.0, 432.0, 299.5], [0.0, 0.0, 1.0]])
    return SimpleNamespace(
        width=640, height=480, out_width=800, out_height=600, K=k, K_new=k_new,
        D=(-0.1, 0.01, 0.0, 0.0, -0.001), distortion_model='plumb_bob',
        P=np.hstack([k_new, np.zeros((3, 1))]), projection='pinhole')


def test_camera_info_raw_describes_the_raw_camera() -> None:
    model = _stub_model()
    info = camera_info_from_model(model, rectified=False)  # type: ignore[arg-type]
    assert (info.width, info.height) == (640, 480)
    assert info.distortion_model == 'plumb_bob'
    npt.assert_allclose(info.k, model.K.ravel())
    npt.assert_allclose(info.d, model.D)
    npt.assert_allclose(info.r, np.eye(3).ravel())
    npt.assert_allclose(info.p, model.P.ravel())


def test_camera_info_rect_describes_the_corrected_image() -> None:
    model = _stub_model()
    info = fill_camera_info(CameraInfo(), model, rectified=True)  # type: ignore[arg-type]
    assert (info.width, info.height) == (800, 600)
    assert info.distortion_model == 'plumb_bob'
    npt.assert_allclose(info.d, np.zeros(5))
    npt.assert_allclose(info.k, model.K_new.ravel())
    npt.assert_allclose(np.reshape(info.p, (3, 4))[:, :3], np.reshape(info.k, (3, 3)))
    npt.assert_allclose(info.r, np.eye(3).ravel())


def test_camera_info_rect_of_an_equidistant_output_is_an_ideal_fisheye() -> None:
    model = _stub_model()
    model.projection = 'equidistant'
    info = fill_camera_info(CameraInfo(), model, rectified=True)  # type: ignore[arg-type]
    assert info.distortion_model == 'equidistant'
    npt.assert_array_equal(info.d, np.zeros(4))
    npt.assert_allclose(info.k, model.K_new.ravel())
    raw = camera_info_from_model(model, rectified=False)  # type: ignore[arg-type]
    assert raw.distortion_model == 'plumb_bob'


def test_camera_info_rational_polynomial_keeps_eight_coefficients() -> None:
    model = _stub_model()
    model.D = (-0.1, 0.01, 0.0, 0.0, -0.001, 0.02, 0.003, 0.0004)
    model.distortion_model = 'rational_polynomial'
    info = camera_info_from_model(model, rectified=False)  # type: ignore[arg-type]
    assert info.distortion_model == 'rational_polynomial'
    npt.assert_allclose(info.d, model.D)
