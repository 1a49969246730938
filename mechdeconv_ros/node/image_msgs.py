# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
sensor_msgs/Image <-> numpy views without copies, and CameraInfo from a lens model.

This is the only module besides the node that knows ROS message types. The pixel data of a
received ``Image`` is an ``array.array('B')``; :func:`image_to_array` returns a numpy view on
it, shaped ``(height, width)`` or ``(height, width, channels)``, honouring ``step`` padding
(the view is strided, nothing is copied). Only two cases copy, because OpenCV needs native,
aligned data: multi-byte pixels stored in the other byte order (``is_bigendian``), and a
``step`` that is not a multiple of the pixel's item size.

Output images are preallocated (:class:`OutputImagePool`): one ``Image`` per
``(width, height, encoding)`` whose ``data`` is set exactly once to
``array.array('B', bytes(n))``, with a numpy view on that buffer. ``cv2.remap(..., dst=view)``
then writes straight into the message, and ``publish()`` copies it synchronously, so the same
message is reused frame after frame. Never assign a numpy array or a memoryview to
``msg.data``: rclpy's setter iterates it element by element (34 to 62 ms at 640x480;
docs/design.md section 4.4).

Supported encodings (sensor_msgs/image_encodings.hpp names): ``mono8``, ``mono16``, ``rgb8``,
``bgr8``, ``rgb16``, ``bgr16``, ``rgba8``, ``bgra8``, ``8UC1``, ``8UC3``, ``8UC4``, ``16UC1``
and ``32FC1``. ``16UC1`` and ``32FC1`` are depth images: the node corrects them with
nearest-neighbour interpolation so that no depth value is invented between a foreground and a
background pixel. The Bayer mosaics ``bayer_rggb8``, ``bayer_bggr8``, ``bayer_gbrg8``,
``bayer_grbg8`` and their ``16`` forms are read as one channel (``Encoding.bayer`` names the
tile) and must have an even width and height; the node demosaics them
(:mod:`mechdeconv_ros.imaging.debayer`) into ``rgb8`` / ``rgb16`` before the correction.
"""

from __future__ import annotations

import array
from collections import OrderedDict
from dataclasses import dataclass
import sys
from typing import Any, TYPE_CHECKING

from mechdeconv_ros.schema.params import BAYER_PATTERNS, MAX_FRAME_PIXELS, MAX_SIDE_PX
import numpy as np
import numpy.typing as npt
from sensor_msgs.msg import CameraInfo, Image

if TYPE_CHECKING:
    from mechdeconv_ros.model.model import LensModel

#: True when this host stores multi-byte numbers big-endian (the value of ``is_bigendian`` of
#: every image this module creates).
HOST_IS_BIGENDIAN = sys.byteorder == 'big'


class ImageFormatError(ValueError):
    """An incoming Image the node cannot correct; the message says why and what to do."""


class UnsupportedEncodingError(ImageFormatError):
    """The Image's encoding is not one the node corrects (Bayer, YUV, compressed, ...)."""

    def __init__(self, encoding: str, message: str) -> None:
        """
        Create the error.

        :param encoding: the refused encoding.
        :param message: what is wrong and how to fix it.
        """
        super().__init__(message)
        self.encoding = encoding


class MalformedImageError(ImageFormatError):
    """The Image's size fields and data disagree, or its size is zero or absurd."""


@dataclass(frozen=True)
class Encoding:
    """
    How the pixels of one ``Image.encoding`` are laid out.

    ``depth`` marks depth images (16UC1 in mm, 32FC1 in m): they must be resampled with
    nearest-neighbour interpolation. ``bayer`` names the 2x2 tile of a raw Bayer mosaic
    (``'rggb'``, ...; empty for every other encoding).
    """

    name: str
    dtype: np.dtype
    channels: int
    depth: bool = False
    bayer: str = ''

    @property
    def bytes_per_pixel(self) -> int:
        """Return the size of one pixel in bytes (all channels)."""
        return self.dtype.itemsize * self.channels


def _enc(name: str, dtype: Any, channels: int, depth: bool = False, bayer: str = '') -> Encoding:
    return Encoding(name, np.dtype(dtype), channels, depth, bayer)


#: The encodings the node corrects, by name.
ENCODINGS: dict[str, Encoding] = {e.name: e for e in (
    _enc('mono8', np.uint8, 1),
    _enc('mono16', np.uint16, 1),
    _enc('rgb8', np.uint8, 3),
    _enc('bgr8', np.uint8, 3),
    _enc('rgb16', np.uint16, 3),
    _enc('bgr16', np.uint16, 3),
    _enc('rgba8', np.uint8, 4),
    _enc('bgra8', np.uint8, 4),
    _enc('8UC1', np.uint8, 1),
    _enc('8UC3', np.uint8, 3),
    _enc('8UC4', np.uint8, 4),
    _enc('16UC1', np.uint16, 1, depth=True),
    _enc('32FC1', np.float32, 1, depth=True),
    *(_enc(f'bayer_{tile}{bits}', np.uint8 if bits == 8 else np.uint16, 1, bayer=tile)
      for bits in (8, 16) for tile in BAYER_PATTERNS),
)}

#: The encoding a demosaiced Bayer frame is published in, by the mosaic's dtype.
DEMOSAICED = {np.dtype(np.uint8): ENCODINGS['rgb8'], np.dtype(np.uint16): ENCODINGS['rgb16']}

_SUPPORTED_TEXT = ', '.join(ENCODINGS)


def lookup_encoding(encoding: str) -> Encoding:
    """
    Return the layout of a supported encoding.

    :param encoding: the ``Image.encoding`` string.
    :return: its :class:`Encoding`.
    :raises UnsupportedEncodingError: naming the encoding and how to convert it.
    """
    found = ENCODINGS.get(encoding)
    if found is not None:
        return found
    lowered = encoding.lower()
    if lowered.startswith('bayer_'):
        fix = ('Bayer mosaics are read as bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8 '
               'and their 16-bit forms (lower case); for another tile or depth debayer first, '
               "e.g. with image_proc's debayer node")
    elif lowered.startswith(('yuv', 'uyvy', 'yuyv', 'nv12', 'nv21')):
        fix = ('it is packed/planar YUV: convert it to rgb8, bgr8 or mono8 first (most camera '
               'drivers have an output-format parameter; otherwise a colour-conversion node)')
    elif lowered in ('jpeg', 'jpg', 'png', 'compressed') or 'compressed' in lowered:
        fix = ('it is a compressed image: decompress first, e.g. image_transport republish '
               'compressed -> raw')
    elif not encoding:
        fix = 'the encoding field is empty: the publisher must set Image.encoding'
    else:
        fix = 'convert it to one of the supported encodings first'
    message = f"unsupported image encoding '{encoding}': {fix}. Supported: {_SUPPORTED_TEXT}"
    raise UnsupportedEncodingError(encoding, message)


def check_frame_size(width: int, height: int, what: str = 'image') -> None:
    """
    Reject a zero or absurd frame size.

    :param width: width in pixels.
    :param height: height in pixels.
    :param what: what the size is of, for the message.
    :raises MalformedImageError: when a side is 0, a side exceeds ``MAX_SIDE_PX`` or the area
        exceeds ``MAX_FRAME_PIXELS``.
    """
    if width <= 0 or height <= 0:
        raise MalformedImageError(f'{what} has a zero size ({width}x{height})')
    if width > MAX_SIDE_PX or height > MAX_SIDE_PX or width * height > MAX_FRAME_PIXELS:
        raise MalformedImageError(
            f'{what} size {width}x{height} is beyond the limit of this node '
            f'({MAX_SIDE_PX} px per side, {MAX_FRAME_PIXELS} px in all)')


def image_to_array(msg: Image) -> tuple[npt.NDArray[Any], Encoding]:
    """
    Return a numpy view on the pixels of an Image, and its encoding.

    The view shares memory with ``msg.data`` (row padding is skipped with a stride) except in
    the two cases described in the module docstring, where a contiguous native copy is made.

    :param msg: a received ``sensor_msgs/Image``.
    :return: ``(pixels, encoding)``; pixels has shape ``(height, width)`` for one channel,
        ``(height, width, channels)`` otherwise, and the encoding's dtype in native byte order.
    :raises UnsupportedEncodingError: for an encoding the node does not correct.
    :raises MalformedImageError: for a zero or absurd size, ``step < width * bytes_per_pixel``,
        ``data`` shorter than ``step * height`` or a Bayer mosaic of odd width or height.
    """
    enc = lookup_encoding(msg.encoding)
    width, height, step = int(msg.width), int(msg.height), int(msg.step)
    check_frame_size(width, height)
    if enc.bayer and (width % 2 or height % 2):
        raise MalformedImageError(
            f'{msg.encoding} is {width}x{height}: a Bayer mosaic needs an even width and '
            'height (whole 2x2 tiles)')
    row_bytes = width * enc.bytes_per_pixel
    if step < row_bytes:
        raise MalformedImageError(
            f'step {step} is less than width {width} x {enc.bytes_per_pixel} bytes per pixel '
            f'= {row_bytes} ({msg.encoding})')
    size = len(msg.data)
    if size < step * height:
        raise MalformedImageError(
            f'data has {size} bytes, less than step {step} x height {height} = '
            f'{step * height}')
    buffer = np.frombuffer(msg.data, dtype=np.uint8, count=step * height)
    rows = buffer.reshape(height, step)[:, :row_bytes]
    itemsize = enc.dtype.itemsize
    swap = itemsize > 1 and bool(msg.is_bigendian) != HOST_IS_BIGENDIAN
    if itemsize > 1 and step % itemsize != 0:
        rows = rows.copy()          # unaligned rows: OpenCV wants aligned pixels
    stored = enc.dtype.newbyteorder('S') if swap else enc.dtype
    pixels = rows.view(stored)
    if swap:
        pixels = pixels.astype(enc.dtype)   # byte swap into a native copy
    shape = (height, width) if enc.channels == 1 else (height, width, enc.channels)
    return pixels.reshape(shape), enc


@dataclass(frozen=True)
class OutputImage:
    """A preallocated output Image and a writable numpy view on its ``data``."""

    msg: Image
    pixels: npt.NDArray[Any]


def new_output_image(width: int, height: int, encoding: str) -> OutputImage:
    """
    Allocate an output Image whose pixels can be written in place.

    ``data`` is set once to a zeroed ``array.array('B')`` of ``height * step`` bytes;
    ``pixels`` is a view on it (no padding: ``step = width * bytes_per_pixel``; native byte
    order, so ``is_bigendian`` is the host's).

    :param width: width in pixels.
    :param height: height in pixels.
    :param encoding: a supported encoding.
    :return: the message and its pixel view, shaped like :func:`image_to_array`'s output.
    :raises UnsupportedEncodingError: for an unsupported encoding.
    :raises MalformedImageError: for a zero or absurd size.
    """
    enc = lookup_encoding(encoding)
    check_frame_size(width, height, 'output image')
    step = width * enc.bytes_per_pixel
    msg = Image()
    msg.width = width
    msg.height = height
    msg.encoding = encoding
    msg.is_bigendian = int(HOST_IS_BIGENDIAN)
    msg.step = step
    msg.data = array.array('B', bytes(step * height))
    # The view must be taken on msg.data after the assignment: the setter copies its argument.
    flat = np.frombuffer(msg.data, dtype=enc.dtype)
    shape = (height, width) if enc.channels == 1 else (height, width, enc.channels)
    return OutputImage(msg, flat.reshape(shape))


class OutputImagePool:
    """
    Preallocated output Images keyed by ``(width, height, encoding)``.

    Keeps the ``capacity`` most recently used entries, so a stream that alternates between a
    few sizes or encodings allocates nothing per frame, and one that changes size for good
    does not hold the old buffers forever. Not thread-safe: use it from one callback group.
    """

    def __init__(self, capacity: int = 4) -> None:
        """
        Create an empty pool.

        :param capacity: how many ``(size, encoding)`` entries to keep.
        """
        self._capacity = max(1, capacity)
        self._entries: OrderedDict[tuple[int, int, str], OutputImage] = OrderedDict()

    def get(self, width: int, height: int, encoding: str) -> OutputImage:
        """
        Return the output Image for this size and encoding, allocating it on first use.

        :param width: width in pixels.
        :param height: height in pixels.
        :param encoding: a supported encoding.
        :return: the preallocated message and its pixel view.
        """
        key = (width, height, encoding)
        entry = self._entries.get(key)
        if entry is None:
            entry = new_output_image(width, height, encoding)
            self._entries[key] = entry
            while len(self._entries) > self._capacity:
                self._entries.popitem(last=False)
        else:
            self._entries.move_to_end(key)
        return entry

    def __len__(self) -> int:
        """Return the number of preallocated entries."""
        return len(self._entries)


_IDENTITY_3X3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


def fill_camera_info(info: CameraInfo, model: LensModel, *, rectified: bool) -> CameraInfo:
    """
    Write a lens model into a CameraInfo (everything but the header).

    ``rectified=False`` gives the calibration-free replacement of a calibrated camera's
    ``camera_info``: the raw image size, ``K`` and ``D`` of the raw (distorted) camera with
    ``D`` the equivalent plumb_bob / rational_polynomial / equidistant coefficients
    (:mod:`mechdeconv_ros.model.camera_info_fit`: within 0.05 px, else the best fit, warned),
    ``R`` identity and
    ``P = [K_new | 0]``. ``rectified=True`` describes the corrected image itself: the output
    size, ``K = K_new``, ``D`` all zero (plumb_bob; ``equidistant`` with four zeros when
    ``output.projection`` is equidistant: the corrected image is then an ideal fisheye,
    r = f theta, with f from ``K_new``), ``R`` identity, the same ``P``.

    :param info: the message to fill (modified in place).
    :param model: the lens model.
    :param rectified: which of the two CameraInfos to write.
    :return: ``info``.
    """
    if rectified:
        info.width = int(model.out_width)
        info.height = int(model.out_height)
        if model.projection == 'equidistant':
            # An ideal fisheye (r = f theta): cv2.fisheye / image_geometry read D = 0 as such.
            info.distortion_model = 'equidistant'
            info.d = [0.0] * 4
        else:
            info.distortion_model = 'plumb_bob'
            info.d = [0.0] * 5
        info.k = np.asarray(model.K_new, dtype=np.float64).reshape(9)
    else:
        info.width = int(model.width)
        info.height = int(model.height)
        info.distortion_model = str(model.distortion_model)
        info.d = [float(v) for v in model.D]
        info.k = np.asarray(model.K, dtype=np.float64).reshape(9)
    info.r = np.array(_IDENTITY_3X3, dtype=np.float64)
    info.p = np.asarray(model.P, dtype=np.float64).reshape(12)
    info.binning_x = 0
    info.binning_y = 0
    info.roi.x_offset = 0
    info.roi.y_offset = 0
    info.roi.width = 0
    info.roi.height = 0
    info.roi.do_rectify = False
    return info


def camera_info_from_model(model: LensModel, *, rectified: bool) -> CameraInfo:
    """
    Return a new CameraInfo for a lens model; see :func:`fill_camera_info`.

    :param model: the lens model.
    :param rectified: False for the raw camera (``camera_info``), True for the corrected image
        (``camera_info_rect``).
    :return: the message, with an empty header.
    """
    return fill_camera_info(CameraInfo(), model, rectified=rectified)


def camera_infos_from_model(model: LensModel) -> tuple[CameraInfo, CameraInfo]:
    """
    Return the ``camera_info`` and ``camera_info_rect`` messages of a model.

    :param model: the lens model.
    :return: ``(raw camera, corrected image)``, see :func:`fill_camera_info`.
    """
    return (camera_info_from_model(model, rectified=False),
            camera_info_from_model(model, rectified=True))
