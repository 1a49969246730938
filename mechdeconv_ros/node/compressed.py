# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Decode (and encode) sensor_msgs/CompressedImage payloads the way image_transport does.

This module imports no rclpy (only the encodings of :mod:`mechdeconv_ros.node.image_msgs`): it
takes the message's ``format`` string and its ``data`` bytes and returns a numpy image plus the raw
``Image.encoding`` it stands for, so it is tested without a graph and the node is thin wiring
around it.

``format`` strings, as written by the publishers a robot meets:

- compressed_image_transport (the ``compressed`` plugin of image_transport, ROS 2):
  ``"<encoding>; jpeg compressed bgr8"`` (colour), ``"<encoding>; jpeg compressed mono8"``
  (grey; older releases end in ``"compressed "``), ``"<encoding>; png compressed bgr8"`` /
  ``"bgr16"`` (colour) and ``"<encoding>; png compressed "`` (grey, at the encoding's own bit
  depth, so a ``mono16`` image travels as a 16-bit PNG).
- cv_bridge's ``cv2_to_compressed_imgmsg`` and many drivers: just the codec, ``"jpeg"``,
  ``"jpg"`` or ``"png"``.

Decoding follows compressed_image_transport's subscriber: ``cv2.imdecode`` with
``IMREAD_UNCHANGED`` (so a 16-bit PNG stays 16-bit, an alpha channel stays, and no EXIF
rotation is applied); the encoding is the part before ``;``; colour data is in BGR order when
the rest says ``compressed bgr...`` and in RGB order otherwise, and is converted to the named
encoding's channel order; a 16-bit encoding carried by an 8-bit JPEG is scaled by 256. Without
``;`` the encoding follows the decoded pixels: ``mono8``/``mono16`` (one channel, 8/16 bit),
``bgr8`` (three), ``bgra8`` (four).

Refused, with a message saying why (the node counts them and goes on with the next frame):
data that is neither JPEG nor PNG or does not decode (:class:`UndecodableImageError`, a
:class:`~mechdeconv_ros.node.image_msgs.MalformedImageError`), a size beyond the node's limits
(checked from the file header, before any pixel is allocated), pixels that do not fit the
named encoding (a colour JPEG labelled ``mono8``, a 16-bit PNG labelled ``bgr8``), and a
format naming an encoding this node cannot correct or a codec other than JPEG/PNG
(:class:`UnsupportedCompressedFormatError`, an
:class:`~mechdeconv_ros.node.image_msgs.UnsupportedEncodingError`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
from mechdeconv_ros.node.image_msgs import (
    check_frame_size, Encoding, lookup_encoding, MalformedImageError, UnsupportedEncodingError)
import numpy as np
import numpy.typing as npt

#: The codecs this module decodes and encodes.
CODECS = ('jpeg', 'png')

#: The Image encodings a JPEG or PNG payload can be decoded to for this node.
DECODABLE_ENCODINGS = ('mono8', 'mono16', 'bgr8', 'rgb8', 'bgra8', 'rgba8', '8UC1', '8UC3',
                       '8UC4', '16UC1')

#: Encodings with an RGB/BGR channel order (sensor_msgs::image_encodings::isColor).
COLOUR_ENCODINGS = ('bgr8', 'rgb8', 'bgra8', 'rgba8')

#: Encodings image_transport treats as grey when compressing (JPEG target mono8).
MONO_ENCODINGS = ('mono8', 'mono16', '8UC1', '16UC1')

#: Default quality/level, as compressed_image_transport's ``jpeg_quality`` / ``png_level``.
DEFAULT_JPEG_QUALITY = 95
DEFAULT_PNG_LEVEL = 3

_JPEG_MAGIC = b'\xff\xd8\xff'
_PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
_CODEC_WORDS = {'jpeg': 'jpeg', 'jpg': 'jpeg', 'png': 'png'}
_OTHER_CODECS = ('tiff', 'tif', 'qoi', 'bmp', 'webp', 'avif', 'jp2', 'h264', 'h265', 'hevc',
                 'av1', 'vp8', 'vp9', 'theora', 'ffmpeg', 'zstd', 'rvl')


class UnsupportedCompressedFormatError(UnsupportedEncodingError):
    """The format names a codec or an encoding this node cannot decode to and correct."""


class UndecodableImageError(MalformedImageError):
    """The data is not a JPEG/PNG that decodes to pixels fitting the format's encoding."""


@dataclass(frozen=True)
class CompressedFormat:
    """
    A parsed ``CompressedImage.format``.

    ``encoding`` is the raw encoding the format names (``None`` when it names none, as
    ``"jpeg"``), ``codec`` is ``'jpeg'``, ``'png'`` or ``None`` (not named: taken from the
    data), and ``stored_bgr`` says colour data was stored in BGR order (``compressed bgr8``).
    """

    encoding: str | None
    codec: str | None
    stored_bgr: bool


@dataclass(frozen=True)
class DecodedImage:
    """A decoded frame: contiguous pixels, their Image encoding and the codec."""

    pixels: npt.NDArray[Any]
    encoding: Encoding
    codec: str


def _unsupported(fmt: str, encoding: str, why: str) -> UnsupportedCompressedFormatError:
    return UnsupportedCompressedFormatError(
        encoding, f"compressed image format '{fmt}': {why}")


def parse_format(fmt: str) -> CompressedFormat:
    """
    Parse a ``CompressedImage.format`` string.

    :param fmt: e.g. ``"bgr8; jpeg compressed bgr8"``, ``"mono16; png compressed "``,
        ``"jpeg"``, ``"png"`` or ``""`` (codec taken from the data).
    :return: the parsed format.
    :raises UnsupportedCompressedFormatError: for the ``compressedDepth`` transport, a codec
        other than JPEG/PNG, or an encoding JPEG/PNG input cannot give this node.
    """
    head, sep, rest = fmt.partition(';')
    if not sep:
        head, rest = '', fmt
    encoding = head.strip() or None
    words = rest.strip().lower().replace(',', ' ').split()
    if any(word.startswith('compresseddepth') for word in words):
        raise _unsupported(fmt, encoding or '', 'it is the compressedDepth transport (a '
                           'quantised depth header before the PNG); subscribe to the raw '
                           'depth image instead (image_transport:=raw)')
    codecs = {_CODEC_WORDS[word] for word in words if word in _CODEC_WORDS}
    if len(codecs) > 1:
        raise _unsupported(fmt, encoding or '', 'it names both JPEG and PNG')
    codec = codecs.pop() if codecs else None
    if codec is None:
        other = [word for word in words if word in _OTHER_CODECS]
        if other or (words and not sep):
            raise _unsupported(fmt, encoding or '', f"codec '{(other or words)[0]}' is not "
                               'decoded here: only JPEG and PNG are (publish with '
                               'format:=jpeg or format:=png)')
    if encoding is not None and encoding not in DECODABLE_ENCODINGS:
        raise _unsupported(fmt, encoding, f"the encoding '{encoding}' it names is not one "
                           'JPEG/PNG input can give this node. Supported: '
                           + ', '.join(DECODABLE_ENCODINGS))
    stored_bgr = 'compressed bgr' in ' '.join(words)
    return CompressedFormat(encoding, codec, stored_bgr)


def _jpeg_size(data: memoryview) -> tuple[int, int] | None:
    """Return ``(width, height)`` from the first JPEG frame header (SOFn), or None."""
    i, n = 2, len(data)
    while i + 4 <= n:
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:              # fill byte
            i += 1
            continue
        if marker == 0x01 or 0xD0 <= marker <= 0xD8:     # markers without a length
            i += 2
            continue
        if marker in (0xD9, 0xDA):      # end of image or start of scan before any frame
            return None
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            if i + 9 > n:
                return None
            height = (data[i + 5] << 8) | data[i + 6]
            width = (data[i + 7] << 8) | data[i + 8]
            return width, height
        i += 2 + ((data[i + 2] << 8) | data[i + 3])
    return None


def _png_size(data: memoryview) -> tuple[int, int] | None:
    """Return ``(width, height)`` from the PNG IHDR chunk, or None."""
    if len(data) < 24 or bytes(data[12:16]) != b'IHDR':
        return None
    return int.from_bytes(data[16:20], 'big'), int.from_bytes(data[20:24], 'big')


def sniff_codec(data: Any) -> str:
    """
    Return ``'jpeg'`` or ``'png'`` from the data's signature.

    :param data: the compressed bytes (bytes, array.array('B'), numpy uint8, ...).
    :return: the codec.
    :raises UndecodableImageError: when the data is empty or neither JPEG nor PNG.
    """
    view = memoryview(data).cast('B')
    if len(view) == 0:
        raise UndecodableImageError('compressed image has no data')
    head = bytes(view[:8])
    if head.startswith(_JPEG_MAGIC):
        return 'jpeg'
    if head.startswith(_PNG_MAGIC):
        return 'png'
    raise UndecodableImageError(
        f'compressed data ({len(view)} bytes, starting {head.hex(" ")}) is neither JPEG nor '
        'PNG')


def _colour_code(channels: int, stored: str, target: str) -> int | None:
    """Return the cv2.COLOR_* code from the decoded layout to ``target`` (None: as is)."""
    source = stored.upper() + ('A' if channels == 4 else '')
    wanted = target[:-1].upper()        # 'bgra8' -> 'BGRA'
    if source == wanted:
        return None
    return int(getattr(cv2, f'COLOR_{source}2{wanted}'))


def decode(fmt: str, data: Any) -> DecodedImage:
    """
    Decode a CompressedImage payload to the raw encoding its format names.

    :param fmt: ``CompressedImage.format``.
    :param data: ``CompressedImage.data`` (any buffer of bytes; not copied before decoding).
    :return: the pixels (``(H, W)`` or ``(H, W, C)``, C-contiguous, native byte order), their
        encoding and the codec.
    :raises UnsupportedCompressedFormatError: see :func:`parse_format`; also 16-bit colour
        and two-channel (grey + alpha) data, which this node does not correct.
    :raises UndecodableImageError: data that is not JPEG/PNG, whose codec differs from the
        format's, that does not decode, or whose pixels do not fit the named encoding.
    :raises MalformedImageError: a zero or absurd size (from the header, before decoding).
    """
    parsed = parse_format(fmt)
    codec = sniff_codec(data)
    if parsed.codec is not None and parsed.codec != codec:
        raise UndecodableImageError(
            f"compressed image format '{fmt}' says {parsed.codec.upper()} but the data is "
            f'{codec.upper()}')
    view = memoryview(data).cast('B')
    size = _jpeg_size(view) if codec == 'jpeg' else _png_size(view)
    if size is None:
        raise UndecodableImageError(
            f'{codec.upper()} data ({len(view)} bytes) has no readable image header')
    check_frame_size(size[0], size[1], f'{codec.upper()} image')
    pixels = cv2.imdecode(np.frombuffer(view, np.uint8), cv2.IMREAD_UNCHANGED)
    if pixels is None or pixels.size == 0:
        raise UndecodableImageError(
            f'{codec.upper()} data ({len(view)} bytes) does not decode (corrupt or truncated)')
    channels = 1 if pixels.ndim == 2 else int(pixels.shape[2])
    bits = 8 * pixels.dtype.itemsize
    encoding = parsed.encoding
    if encoding is None:
        by_layout = {(1, 8): 'mono8', (1, 16): 'mono16', (3, 8): 'bgr8', (4, 8): 'bgra8'}
        encoding = by_layout.get((channels, bits))
        if encoding is None:
            raise _unsupported(fmt, f'{bits}-bit x {channels}', f'the data decodes to '
                               f'{channels} channel(s) of {bits} bit, which this node does '
                               'not correct (mono8/16, bgr8 or bgra8 are)')
    target = lookup_encoding(encoding)
    if target.dtype.itemsize * 8 != bits:
        if codec == 'jpeg' and bits == 8 and target.dtype == np.uint16:
            # compressed_image_transport sends 16-bit images as 8-bit JPEG and scales back.
            pixels = pixels.astype(np.uint16) * np.uint16(256)
        else:
            raise UndecodableImageError(
                f"compressed image format '{fmt}' names {encoding} "
                f'({target.dtype.itemsize * 8}-bit) but the {codec.upper()} holds {bits}-bit '
                'samples')
    if encoding in COLOUR_ENCODINGS and channels in (3, 4):
        # Without ';' (cv_bridge's "jpeg") the pixels are OpenCV's own BGR, as imencode wrote.
        bgr = parsed.stored_bgr or parsed.encoding is None
        code = _colour_code(channels, 'bgr' if bgr else 'rgb', encoding)
        if code is not None:
            pixels = cv2.cvtColor(pixels, code)
    elif channels != target.channels:
        raise UndecodableImageError(
            f"compressed image format '{fmt}' names {encoding} ({target.channels} channel(s)) "
            f'but the {codec.upper()} decodes to {channels}')
    return DecodedImage(np.ascontiguousarray(pixels), target, codec)


def encode(pixels: npt.NDArray[Any], encoding: str, codec: str = 'jpeg', *,
           jpeg_quality: int = DEFAULT_JPEG_QUALITY,
           png_level: int = DEFAULT_PNG_LEVEL) -> tuple[str, bytes]:
    """
    Encode an image as compressed_image_transport's publisher does.

    Colour images are stored as BGR (alpha dropped), format ``"<enc>; jpeg compressed bgr8"``
    or ``"<enc>; png compressed bgr8"``; grey images as ``"<enc>; jpeg compressed mono8"``
    (16-bit scaled down by 256) or ``"<enc>; png compressed "`` at their own bit depth.

    :param pixels: ``(H, W)`` or ``(H, W, C)`` array in the encoding's dtype.
    :param encoding: its Image encoding (one of :data:`COLOUR_ENCODINGS` or
        :data:`MONO_ENCODINGS`).
    :param codec: ``'jpeg'`` or ``'png'``.
    :param jpeg_quality: 1..100.
    :param png_level: zlib level 0..9.
    :return: ``(format, data)``.
    :raises UnsupportedCompressedFormatError: for another codec or encoding.
    :raises ValueError: when OpenCV cannot encode the pixels.
    """
    if codec not in CODECS:
        raise _unsupported(codec, encoding, 'only jpeg and png are encoded')
    if encoding in COLOUR_ENCODINGS:
        channels = 4 if encoding.endswith('a8') else 3
        code = _colour_code(channels, encoding[:3], 'bgr8')
        image = cv2.cvtColor(pixels, code) if code is not None else pixels
        stored = 'bgr8'
    elif encoding in MONO_ENCODINGS:
        image = pixels
        if codec == 'jpeg' and pixels.dtype == np.uint16:
            image = (pixels >> 8).astype(np.uint8)
        stored = 'mono8' if codec == 'jpeg' else ''
    else:
        raise _unsupported(f'{encoding}; {codec} compressed', encoding,
                           'only 8-bit colour and mono8/mono16 images are encoded')
    if codec == 'jpeg':
        params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]
    else:
        params = [cv2.IMWRITE_PNG_COMPRESSION, int(png_level)]
    ok, buffer = cv2.imencode('.jpg' if codec == 'jpeg' else '.png', image, params)
    if not ok:
        raise ValueError(f'OpenCV could not encode a {encoding} image as {codec}')
    return f'{encoding}; {codec} compressed {stored}', buffer.tobytes()
