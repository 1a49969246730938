# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
What a frame message becomes, and what a refused one is counted as (correct_node's frame path).

:func:`read_image` (sensor_msgs/Image) and :func:`read_compressed` (sensor_msgs/
CompressedImage, JPEG/PNG by :mod:`mechdeconv_ros.node.compressed`) return the pixels as a numpy
view and their :class:`~mechdeconv_ros.node.image_msgs.Encoding`, or raise :class:`FrameRefused`
after counting the frame in :class:`~mechdeconv_ros.node.diagnostics.FrameStats`: an unknown
encoding in ``rejected_encodings``, a malformed Image in ``frames_failed``, an undecodable
payload in ``frames_undecodable``. :func:`demosaic_frame` turns a Bayer mosaic into
``rgb8`` / ``rgb16`` (:mod:`mechdeconv_ros.imaging.debayer`). :func:`compressed_output` encodes a
corrected image as image_transport's compressed plugin writes it; :func:`sensor_qos` is the
frame topics' QoS. Called in the executor thread only (the frame callback), which owns the
counters.
"""

from __future__ import annotations

import array
import time
from typing import Any, Callable

from mechdeconv_ros.imaging.debayer import Demosaicer
from mechdeconv_ros.node.compressed import decode, encode, UnsupportedCompressedFormatError
from mechdeconv_ros.node.diagnostics import FrameStats
from mechdeconv_ros.node.image_msgs import (
    DEMOSAICED, Encoding, image_to_array, MalformedImageError, UnsupportedEncodingError)
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CompressedImage, Image


def sensor_qos() -> QoSProfile:
    """
    Return the default QoS of the image and camera-info topics.

    Best effort, keep last 1, volatile: a live stream wants the newest frame, never a queue of
    old ones, and a best-effort subscription matches reliable and best-effort publishers. Users
    can change history, depth and reliability per topic with the ``qos_overrides.*`` parameters.

    :return: a new profile.
    """
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


class FrameRefused(Exception):
    """A frame that cannot be read: ``kind`` groups the log throttling, ``line`` is logged."""

    def __init__(self, kind: str, error: str, line: str = '') -> None:
        """
        Keep the reason.

        :param kind: the kind of problem (one log line per kind and throttle period).
        :param error: the text for ``/diagnostics`` (``last_error``).
        :param line: the log line (default ``error``).
        """
        super().__init__(error)
        self.kind, self.error, self.line = kind, error, line or error


def _unsupported(stats: FrameStats, err: Any) -> FrameRefused:
    stats.rejected_encodings += 1
    stats.last_rejected_encoding = err.encoding
    return FrameRefused('encoding', str(err), f'{err} ({stats.rejected_encodings} frames so far)')


def read_image(msg: Image, stats: FrameStats) -> tuple[Any, Encoding]:
    """
    Return a raw Image's pixels and encoding; count and refuse what cannot be read.

    :param msg: the message.
    :param stats: the frame counters.
    :return: ``(pixels, encoding)``.
    :raises FrameRefused: an unknown encoding, a malformed or unreadable frame.
    """
    try:
        return image_to_array(msg)
    except UnsupportedEncodingError as err:
        raise _unsupported(stats, err) from None
    except MalformedImageError as err:
        stats.frames_failed += 1
        error = f'malformed frame: {err}'
        raise FrameRefused('malformed', error, f'{error} ({stats.frames_failed} so far)') from None
    except Exception as err:        # noqa: B902 - one bad frame must not stop the stream
        stats.frames_failed += 1
        raise FrameRefused('unreadable', f'unreadable frame: {err!r}') from None


def read_compressed(msg: CompressedImage, stats: FrameStats) -> tuple[Any, Encoding]:
    """
    Decode a CompressedImage; count and refuse what does not decode; time the decoding.

    :param msg: the message.
    :param stats: the frame counters (``decode_time_ms_*`` too).
    :return: ``(pixels, encoding)``.
    :raises FrameRefused: a format it cannot produce, or data that does not decode.
    """
    start = time.perf_counter()
    try:
        decoded = decode(msg.format, msg.data)
    except (UnsupportedCompressedFormatError, UnsupportedEncodingError) as err:
        raise _unsupported(stats, err) from None
    except Exception as err:        # noqa: B902 - UndecodableImageError and anything else
        stats.frames_undecodable += 1
        error = f'undecodable frame: {err}' if isinstance(err, MalformedImageError) else \
            f'undecodable frame: {err!r}'
        raise FrameRefused('undecodable', error,
                           f'{error} ({stats.frames_undecodable} so far)') from None
    stats.add_decode_time((time.perf_counter() - start) * 1e3)
    return decoded.pixels, decoded.encoding


def demosaic_frame(pixels: Any, encoding: Encoding, demosaicer: Demosaicer, method: str,
                   stats: FrameStats) -> tuple[Any, Encoding, str | None]:
    """
    Demosaic a Bayer frame (``encoding.bayer`` set) into ``rgb8`` / ``rgb16``.

    :param pixels: the ``(H, W)`` mosaic (even sides: :func:`read_image` checked them).
    :param encoding: its Bayer encoding.
    :param demosaicer: the frame path's demosaicer (keeps the output buffer).
    :param method: the ``debayer`` parameter.
    :param stats: the frame counters.
    :return: ``(rgb, encoding, note)``; ``note`` is a line to log once (16-bit VNG).
    :raises FrameRefused: when OpenCV cannot demosaic it (counted in ``frames_failed``).
    """
    try:
        rgb, note = demosaicer.demosaic(pixels, encoding.bayer, method)
    except Exception as err:        # noqa: B902 - one bad frame must not stop the stream
        stats.frames_failed += 1
        raise FrameRefused('demosaic', f'{encoding.name} frame not demosaiced: {err}') from None
    return rgb, DEMOSAICED[rgb.dtype], note


#: The parameters of ``image_rect/compressed``, in the order :func:`compressed_settings` gives.
COMPRESSED_PARAMS = ('image_rect.compressed.format', 'image_rect.compressed.jpeg_quality',
                     'image_rect.compressed.png_level')


def compressed_settings(value: Callable[[str], Any]) -> tuple[str, int, int]:
    """
    Return ``(format, jpeg_quality, png_level)`` of ``image_rect/compressed``.

    The node reads them once at start-up and again after a set that names one of
    :data:`COMPRESSED_PARAMS`, not per frame (each read takes the live model's lock).

    :param value: the node's parameter values by name.
    :return: the three settings, coerced.
    """
    fmt, quality, level = (value(name) for name in COMPRESSED_PARAMS)
    return str(fmt), int(quality), int(level)


def compressed_output(pixels: Any, encoding: Encoding, header: Any,
                      settings: tuple[str, int, int]) -> CompressedImage:
    """
    Encode a corrected image for ``image_rect/compressed``.

    :param pixels: the corrected pixels.
    :param encoding: their encoding.
    :param header: the input frame's header.
    :param settings: :func:`compressed_settings` of the node.
    :return: the message.
    :raises FrameRefused: when the encoding cannot be compressed (e.g. 32FC1).
    """
    try:
        fmt, data = encode(pixels, encoding.name, settings[0], jpeg_quality=settings[1],
                           png_level=settings[2])
    except Exception as err:        # noqa: B902 - image_rect is out already
        raise FrameRefused('compressed output',
                           f'image_rect/compressed not published: {err}') from None
    msg = CompressedImage(format=fmt)
    msg.header = header
    msg.data = array.array('B', data)
    return msg
