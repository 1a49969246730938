# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""Tests of mechdeconv_ros.node.compressed: CompressedImage format strings, JPEG/PNG decoding."""

from __future__ import annotations

import array

import cv2
from mechdeconv_ros.node.compressed import (
    CompressedFormat, decode, encode, parse_format, sniff_codec, UndecodableImageError,
    UnsupportedCompressedFormatError)
from mechdeconv_ros.node.image_msgs import MalformedImageError, UnsupportedEncodingError
from mechdeconv_ros.schema.params import MAX_SIDE_PX
import numpy as np
import numpy.testing as npt
import pytest

RNG_SEED = 0


def smooth_colour(height: int = 48, width: int = 64) -> np.ndarray:
    """Return a smooth BGR test image (JPEG keeps it within a few grey levels)."""
    y, x = np.mgrid[0:height, 0:width]
    return np.dstack([(x * 255 // (width - 1)), (y * 255 // (height - 1)),
                      np.full_like(x, 40)]).astype(np.uint8)


def imencode(ext: str, pixels: np.ndarray, *params: int) -> bytes:
    ok, buffer = cv2.imencode(ext, pixels, list(params))
    assert ok
    return buffer.tobytes()


@pytest.mark.parametrize('fmt, expected', [
    ('bgr8; jpeg compressed bgr8', CompressedFormat('bgr8', 'jpeg', True)),
    ('rgb8; jpeg compressed bgr8', CompressedFormat('rgb8', 'jpeg', True)),
    ('mono8; jpeg compressed mono8', CompressedFormat('mono8', 'jpeg', False)),
    ('mono8; jpeg compressed ', CompressedFormat('mono8', 'jpeg', False)),
    ('bgra8; png compressed bgr8', CompressedFormat('bgra8', 'png', True)),
    ('mono16; png compressed ', CompressedFormat('mono16', 'png', False)),
    ('mono16; png compressed mono16', CompressedFormat('mono16', 'png', False)),
    ('rgb8; png compressed', CompressedFormat('rgb8', 'png', False)),
    ('jpeg', CompressedFormat(None, 'jpeg', False)),
    ('jpg', CompressedFormat(None, 'jpeg', False)),
    ('png', CompressedFormat(None, 'png', False)),
    ('', CompressedFormat(None, None, False)),
])
def test_parse_format_reads_image_transport_and_cv_bridge_strings(
        fmt: str, expected: CompressedFormat) -> None:
    assert parse_format(fmt) == expected


@pytest.mark.parametrize('fmt, needle', [
    ('bgr16; png compressed bgr16', 'bgr16'),
    ('32FC1; png compressed ', '32FC1'),
    ('bayer_rggb8; jpeg compressed bgr8', 'bayer_rggb8'),
    ('16UC1; compressedDepth png', 'compressedDepth'),
    ('tiff', 'tiff'),
    ('bgr8; tiff compressed ', 'tiff'),
    ('h264', 'h264'),
])
def test_parse_format_refuses_what_it_cannot_produce(fmt: str, needle: str) -> None:
    with pytest.raises(UnsupportedCompressedFormatError, match=needle) as info:
        parse_format(fmt)
    assert isinstance(info.value, UnsupportedEncodingError)
    assert fmt in str(info.value)


def test_jpeg_bgr8_from_image_transport_decodes_close_to_the_source() -> None:
    src = smooth_colour()
    fmt, data = encode(src, 'bgr8', 'jpeg', jpeg_quality=95)
    assert fmt == 'bgr8; jpeg compressed bgr8'
    got = decode(fmt, data)
    assert got.encoding.name == 'bgr8' and got.codec == 'jpeg'
    assert got.pixels.shape == src.shape and got.pixels.dtype == np.uint8
    assert got.pixels.flags['C_CONTIGUOUS']
    assert np.abs(got.pixels.astype(int) - src).mean() < 3.0


def test_rgb8_travels_as_bgr_jpeg_and_comes_back_in_rgb_order() -> None:
    rgb = np.zeros((32, 32, 3), np.uint8)
    rgb[..., 0] = 250                   # pure red in RGB order
    fmt, data = encode(rgb, 'rgb8', 'jpeg')
    assert fmt == 'rgb8; jpeg compressed bgr8'
    got = decode(fmt, data)
    assert got.encoding.name == 'rgb8'
    npt.assert_allclose(got.pixels.mean(axis=(0, 1)), [250, 0, 0], atol=3)


@pytest.mark.parametrize('encoding', ['bgr8', 'rgb8'])
def test_png_colour_round_trip_is_exact(encoding: str) -> None:
    src = np.random.default_rng(RNG_SEED).integers(0, 256, (24, 40, 3), dtype=np.uint8)
    fmt, data = encode(src, encoding, 'png', png_level=1)
    assert fmt == f'{encoding}; png compressed bgr8'
    got = decode(fmt, data)
    assert got.encoding.name == encoding
    npt.assert_array_equal(got.pixels, src)


def test_png_rgba8_keeps_the_colours_with_an_opaque_alpha() -> None:
    src = np.random.default_rng(RNG_SEED).integers(0, 256, (16, 16, 4), dtype=np.uint8)
    fmt, data = encode(src, 'rgba8', 'png')
    assert fmt == 'rgba8; png compressed bgr8'      # image_transport drops alpha
    got = decode(fmt, data)
    assert got.encoding.name == 'rgba8' and got.pixels.shape == (16, 16, 4)
    npt.assert_array_equal(got.pixels[..., :3], src[..., :3])
    assert np.all(got.pixels[..., 3] == 255)


def test_png_without_bgr_marker_is_taken_in_rgb_order_as_image_transport_does() -> None:
    rgb = np.random.default_rng(RNG_SEED).integers(0, 256, (10, 12, 3), dtype=np.uint8)
    data = imencode('.png', rgb)        # channels written as they are, no BGR swap
    got = decode('rgb8; png compressed', data)
    npt.assert_array_equal(got.pixels, rgb)
    as_bgr = decode('bgr8; png compressed', data)
    npt.assert_array_equal(as_bgr.pixels, rgb[..., ::-1])


def test_16_bit_png_stays_16_bit() -> None:
    src = np.random.default_rng(RNG_SEED).integers(0, 65536, (20, 30), dtype=np.uint16)
    fmt, data = encode(src, 'mono16', 'png')
    assert fmt == 'mono16; png compressed '
    got = decode(fmt, data)
    assert got.encoding.name == 'mono16' and got.pixels.dtype == np.uint16
    npt.assert_array_equal(got.pixels, src)
    depth = decode('16UC1; png compressed ', imencode('.png', src))
    assert depth.encoding.name == '16UC1' and depth.encoding.depth
    npt.assert_array_equal(depth.pixels, src)


def test_mono16_through_8_bit_jpeg_is_scaled_back_by_256() -> None:
    src = (np.tile(np.arange(64, dtype=np.uint16), (16, 1)) * 1024)
    fmt, data = encode(src, 'mono16', 'jpeg', jpeg_quality=100)
    assert fmt == 'mono16; jpeg compressed mono8'
    got = decode(fmt, data)
    assert got.pixels.dtype == np.uint16 and got.encoding.name == 'mono16'
    npt.assert_allclose(got.pixels.astype(float), src.astype(float), atol=3 * 256)
    assert np.all(got.pixels % 256 == 0)


@pytest.mark.parametrize('fmt, ext, pixels, encoding', [
    ('jpeg', '.jpg', np.full((8, 8, 3), 100, np.uint8), 'bgr8'),
    ('jpg', '.jpg', np.full((8, 8), 100, np.uint8), 'mono8'),
    ('png', '.png', np.full((8, 8, 4), 100, np.uint8), 'bgra8'),
    ('png', '.png', np.full((8, 8), 1000, np.uint16), 'mono16'),
    ('', '.png', np.full((8, 8, 3), 7, np.uint8), 'bgr8'),
])
def test_codec_only_formats_take_the_encoding_from_the_pixels(
        fmt: str, ext: str, pixels: np.ndarray, encoding: str) -> None:
    got = decode(fmt, imencode(ext, pixels))
    assert got.encoding.name == encoding
    assert got.pixels.shape == pixels.shape and got.pixels.dtype == pixels.dtype
    npt.assert_allclose(got.pixels, pixels, atol=2)     # BGR stays BGR: no swap


def test_message_buffers_are_accepted() -> None:
    src = np.random.default_rng(RNG_SEED).integers(0, 256, (8, 9), dtype=np.uint8)
    data = array.array('B', imencode('.png', src))      # what rclpy hands a callback
    npt.assert_array_equal(decode('mono8; png compressed ', data).pixels, src)
    assert sniff_codec(data) == 'png'


@pytest.mark.parametrize('data, needle', [
    (b'', 'no data'),
    (bytes(np.random.default_rng(RNG_SEED).integers(0, 256, 500, dtype=np.uint8)),
     'neither JPEG nor PNG'),
    (b'\xff\xd8\xff\xe0\x00\x10JFIF\x00' + bytes(20), 'no readable image header'),
])
def test_bad_bytes_are_refused_with_a_clear_message(data: bytes, needle: str) -> None:
    with pytest.raises(UndecodableImageError, match=needle) as info:
        decode('bgr8; jpeg compressed bgr8', data)
    assert isinstance(info.value, MalformedImageError)


def test_truncated_png_does_not_decode() -> None:
    data = imencode('.png', np.random.default_rng(RNG_SEED).integers(
        0, 256, (64, 64, 3), dtype=np.uint8))
    with pytest.raises(UndecodableImageError, match='does not decode'):
        decode('bgr8; png compressed bgr8', data[:len(data) // 2])


def test_codec_named_by_the_format_must_match_the_data() -> None:
    png = imencode('.png', np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(UndecodableImageError, match='says JPEG but the data is PNG'):
        decode('bgr8; jpeg compressed bgr8', png)
    with pytest.raises(UndecodableImageError, match='says JPEG'):
        decode('jpeg', png)


@pytest.mark.parametrize('fmt, ext, pixels, needle', [
    ('mono8; jpeg compressed mono8', '.jpg', np.zeros((8, 8, 3), np.uint8), '1 channel'),
    ('bgr8; png compressed bgr8', '.png', np.zeros((8, 8), np.uint16), '16-bit'),
    ('mono16; png compressed ', '.png', np.zeros((8, 8), np.uint8), '8-bit samples'),
    ('bgr8; png compressed bgr8', '.png', np.zeros((8, 8), np.uint8), 'decodes to 1'),
])
def test_pixels_that_do_not_fit_the_named_encoding_are_refused(
        fmt: str, ext: str, pixels: np.ndarray, needle: str) -> None:
    with pytest.raises(UndecodableImageError, match=needle):
        decode(fmt, imencode(ext, pixels))


def test_16_bit_colour_without_an_encoding_is_unsupported() -> None:
    with pytest.raises(UnsupportedCompressedFormatError, match='16 bit'):
        decode('png', imencode('.png', np.zeros((4, 4, 3), np.uint16)))


def test_absurd_sizes_are_refused_from_the_header_before_decoding() -> None:
    png = bytearray(imencode('.png', np.zeros((4, 4), np.uint8)))
    png[16:20] = (MAX_SIDE_PX + 1).to_bytes(4, 'big')      # IHDR width (CRC now wrong)
    with pytest.raises(MalformedImageError, match='beyond the limit'):
        decode('png', bytes(png))
    jpeg = bytearray(imencode('.jpg', np.zeros((4, 4), np.uint8)))
    sof = jpeg.find(b'\xff\xc0')
    assert sof > 0
    jpeg[sof + 5:sof + 7] = (0).to_bytes(2, 'big')          # height 0
    with pytest.raises(MalformedImageError, match='zero size'):
        decode('jpeg', bytes(jpeg))


def test_encode_refuses_other_codecs_and_encodings() -> None:
    with pytest.raises(UnsupportedCompressedFormatError):
        encode(np.zeros((4, 4), np.uint8), 'mono8', 'tiff')
    with pytest.raises(UnsupportedCompressedFormatError):
        encode(np.zeros((4, 4), np.float32), '32FC1', 'png')
