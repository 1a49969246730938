# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Demosaicing of raw Bayer frames before the correction (no ROS).

A Bayer sensor records one colour per pixel through a 2x2 colour-filter tile repeated over the
image. The ROS encodings (sensor_msgs/image_encodings.hpp) name the tile from the top-left
pixel, row by row: ``bayer_rggb8`` has R at (row 0, col 0), G at (0, 1) and (1, 0), B at
(1, 1). OpenCV names the same tile by the two pixels at (row 1, col 1) and (1, 2) of the
image, so ROS ``rggb`` is ``cv2.COLOR_BayerBG2RGB``, ``bggr`` is ``BayerRG``, ``gbrg`` is
``BayerGR`` and ``grbg`` is ``BayerGB`` (image_pipeline's image_proc/src/debayer.cpp uses the
same table; ``test/test_debayer.py`` checks it on a mosaic built from a known RGB image).

Methods (parameter ``debayer``): ``bilinear`` (OpenCV's default: each missing colour is the
mean of its nearest same-colour neighbours), ``edge_aware`` (OpenCV's ``_EA``: interpolates
along the edge, not across it; 8 and 16 bit) and ``vng`` (OpenCV's variable number of
gradients, the sharpest and slowest; 8 bit only). image_proc's debayer node declares
``debayer`` = 3 (VNG) by default, so ``vng`` is our default too. OpenCV has no 16-bit VNG: a
16-bit mosaic with ``vng`` is demosaiced ``edge_aware`` instead (the next best that OpenCV
supports at 16 bit), and :meth:`Demosaicer.demosaic` says so once, for the caller to log.
(image_proc would stop with an OpenCV error on that combination.)

A mosaic must have an even width and height (a whole number of tiles);
:func:`mechdeconv_ros.node.image_msgs.image_to_array` refuses other sizes as malformed frames.
The result is ``rgb8`` / ``rgb16``, written into a buffer kept per size, so a stream allocates
nothing per frame.

OpenCV's VNG runs on one thread (its bilinear and edge-aware demosaicing are already cheap), so
``vng`` demosaics horizontal stripes on a small thread pool, as many stripes as OpenCV may use
threads (``cv2.getNumThreads()``, which the node sets from ``remap_threads``); cv2 releases
the GIL. Each stripe starts on an even row (the Bayer phase stays that of the frame) and is
demosaiced with :data:`STRIPE_OVERLAP` extra rows on either side that are then cropped: VNG
reads a 5x5 neighbourhood and fills the two top and four bottom rows of whatever it is given
from their inner neighbours, so with 8 rows of overlap every kept row is computed from the same
pixels as in the whole-frame call, and the result is bit-identical to ``cv2.cvtColor`` on the
whole frame (``test/test_debayer.py`` checks it for the four tiles).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
import os
import threading
from typing import Any

import cv2
from mechdeconv_ros.schema.params import BAYER_PATTERNS, DEBAYER_METHODS, DEFAULT_DEBAYER
import numpy as np
import numpy.typing as npt


#: The OpenCV code of each (ROS pattern, method), producing RGB channel order.
_CODES: dict[tuple[str, str], int] = {
    ('rggb', 'bilinear'): cv2.COLOR_BayerBG2RGB,
    ('bggr', 'bilinear'): cv2.COLOR_BayerRG2RGB,
    ('gbrg', 'bilinear'): cv2.COLOR_BayerGR2RGB,
    ('grbg', 'bilinear'): cv2.COLOR_BayerGB2RGB,
    ('rggb', 'edge_aware'): cv2.COLOR_BayerBG2RGB_EA,
    ('bggr', 'edge_aware'): cv2.COLOR_BayerRG2RGB_EA,
    ('gbrg', 'edge_aware'): cv2.COLOR_BayerGR2RGB_EA,
    ('grbg', 'edge_aware'): cv2.COLOR_BayerGB2RGB_EA,
    ('rggb', 'vng'): cv2.COLOR_BayerBG2RGB_VNG,
    ('bggr', 'vng'): cv2.COLOR_BayerRG2RGB_VNG,
    ('gbrg', 'vng'): cv2.COLOR_BayerGR2RGB_VNG,
    ('grbg', 'vng'): cv2.COLOR_BayerGB2RGB_VNG,
}


#: Rows demosaiced on either side of a VNG stripe and cropped (even: keeps the Bayer phase).
STRIPE_OVERLAP = 8
#: The fewest rows of a VNG stripe (smaller frames are demosaiced whole).
MIN_STRIPE_ROWS = 64
#: The most stripes (and pool threads).
MAX_STRIPES = 8

_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _stripe_pool() -> ThreadPoolExecutor:
    """Return the process's VNG stripe pool, created on first use."""
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(min(MAX_STRIPES, os.cpu_count() or 1),
                                       thread_name_prefix='mechdeconv_vng')
        return _pool


def stripe_count(height: int, threads: int | None = None) -> int:
    """
    Return how many stripes a VNG demosaic of ``height`` rows runs in.

    :param height: rows of the mosaic.
    :param threads: threads allowed (default ``cv2.getNumThreads()``).
    :return: 1 (whole frame) up to :data:`MAX_STRIPES`.
    """
    threads = cv2.getNumThreads() if threads is None else threads
    return max(1, min(threads, MAX_STRIPES, height // MIN_STRIPE_ROWS))


def _demosaic_striped(mosaic: npt.NDArray[Any], code: int, dst: npt.NDArray[Any],
                      stripes: int, scratch: dict[Any, npt.NDArray[Any]] | None = None
                      ) -> npt.NDArray[Any]:
    """
    Demosaic ``stripes`` horizontal stripes with overlap on the pool, into ``dst``.

    ``scratch`` keeps each stripe's output buffer (with its overlap rows) between calls.
    """
    height, width = mosaic.shape
    edges = [height * i // stripes // 2 * 2 for i in range(stripes + 1)]
    scratch = {} if scratch is None else scratch

    def one(index: int) -> None:
        top, bottom = edges[index], edges[index + 1]
        start = max(top - STRIPE_OVERLAP, 0)
        stop = min(bottom + STRIPE_OVERLAP, height)
        shape = (stop - start, width, 3)
        part = scratch.get((index, stripes))
        if part is None or part.shape != shape or part.dtype != mosaic.dtype:
            part = scratch[(index, stripes)] = np.empty(shape, mosaic.dtype)
        cv2.cvtColor(mosaic[start:stop], code, dst=part)
        dst[top:bottom] = part[top - start:bottom - start]

    for future in [_stripe_pool().submit(one, i) for i in range(stripes)]:
        future.result()
    return dst


def bayer_encoding(pattern: str, bits: int) -> str:
    """
    Return the ROS encoding name of a Bayer pattern.

    :param pattern: one of :data:`BAYER_PATTERNS`.
    :param bits: 8 or 16.
    :return: e.g. ``'bayer_rggb8'``.
    """
    return f'bayer_{pattern}{bits}'


def method_for(method: str, dtype: Any) -> str:
    """
    Return the method really used for a mosaic of this dtype (16-bit VNG -> edge_aware).

    :param method: one of :data:`DEBAYER_METHODS`.
    :param dtype: the mosaic's dtype (uint8 or uint16).
    :return: the method.
    :raises ValueError: for an unknown method.
    """
    if method not in DEBAYER_METHODS:
        raise ValueError(f"debayer: expected one of {', '.join(DEBAYER_METHODS)}, got {method!r}")
    if method == 'vng' and np.dtype(dtype) != np.uint8:
        return 'edge_aware'
    return method


def demosaic(mosaic: npt.NDArray[Any], pattern: str, method: str = DEFAULT_DEBAYER,
             dst: npt.NDArray[Any] | None = None, threads: int | None = None,
             scratch: dict[Any, npt.NDArray[Any]] | None = None) -> npt.NDArray[Any]:
    """
    Demosaic one Bayer frame into RGB.

    :param mosaic: ``(H, W)`` uint8 or uint16, H and W even; a row-padded view is fine.
    :param pattern: one of :data:`BAYER_PATTERNS` (ROS naming).
    :param method: one of :data:`DEBAYER_METHODS` (16-bit ``vng`` runs ``edge_aware``).
    :param dst: optional ``(H, W, 3)`` output of the mosaic's dtype, written in place.
    :param threads: threads for ``vng`` stripes (default ``cv2.getNumThreads()``; 1 = the
        whole frame in one call); the result is the same for any count.
    :param scratch: optional dict in which the ``vng`` stripes keep their buffers between
        calls (one caller at a time per dict).
    :return: ``(H, W, 3)`` RGB of the mosaic's dtype (``dst`` when given).
    :raises ValueError: for an unknown pattern or method, a mosaic that is not 2-D uint8 /
        uint16, or an odd size.
    """
    if pattern not in BAYER_PATTERNS:
        raise ValueError(f"Bayer pattern: expected one of {', '.join(BAYER_PATTERNS)}, "
                         f'got {pattern!r}')
    if mosaic.ndim != 2 or mosaic.dtype not in (np.uint8, np.uint16):
        raise ValueError(f'a Bayer mosaic is one channel of uint8 or uint16, got shape '
                         f'{mosaic.shape} {mosaic.dtype}')
    height, width = mosaic.shape
    if height % 2 or width % 2:
        raise ValueError(f'a Bayer mosaic needs an even width and height (a whole number of '
                         f'2x2 tiles), got {width}x{height}')
    used = method_for(method, mosaic.dtype)
    code = _CODES[(pattern, used)]
    stripes = stripe_count(height, threads) if used == 'vng' else 1
    if stripes == 1:
        return cv2.cvtColor(mosaic, code, dst=dst)
    if dst is None:
        dst = np.empty((height, width, 3), mosaic.dtype)
    return _demosaic_striped(mosaic, code, dst, stripes, scratch)


class Demosaicer:
    """
    Demosaic frames into a buffer kept per (size, dtype); remembers the 16-bit VNG note.

    Not thread-safe: one instance per frame callback group. The returned image is reused by
    the next call of the same size: correct it before demosaicing the next frame.
    """

    def __init__(self) -> None:
        """Create it with no buffer."""
        self._buffer: npt.NDArray[Any] | None = None
        self._scratch: dict[Any, npt.NDArray[Any]] = {}
        self._noted = False

    def demosaic(self, mosaic: npt.NDArray[Any], pattern: str,
                 method: str) -> tuple[npt.NDArray[Any], str | None]:
        """
        Demosaic one frame into the kept buffer.

        :param mosaic: see :func:`demosaic`.
        :param pattern: see :func:`demosaic`.
        :param method: see :func:`demosaic`.
        :return: ``(rgb, note)``; ``note`` is a line to log, given once per instance, the
            first time a 16-bit mosaic is asked for ``vng``; otherwise None.
        :raises ValueError: see :func:`demosaic`.
        """
        shape = (*mosaic.shape[:2], 3)
        buffer = self._buffer
        if buffer is None or buffer.shape != shape or buffer.dtype != mosaic.dtype:
            buffer = self._buffer = np.empty(shape, mosaic.dtype)
        rgb = demosaic(mosaic, pattern, method, dst=buffer, scratch=self._scratch)
        note = None
        if not self._noted and method_for(method, mosaic.dtype) != method:
            self._noted = True
            note = (f"debayer: OpenCV's VNG demosaics 8-bit mosaics only; 16-bit "
                    f'bayer_{pattern}16 frames are demosaiced edge_aware instead')
        return rgb, note
