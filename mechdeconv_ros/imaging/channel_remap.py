# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
One remap with a different map for each colour channel (lateral colour correction, no ROS).

``cv2.remap`` applies one map to every channel of an interleaved image. Three remaps of the
split planes, and a merge, cost about three times one RGB remap. Instead the channels are
folded into ONE single-channel remap:

- the source's channels are split (``cv2.split`` into views, about 0.6 ms at 1080p) into a
  row-planar buffer of shape ``(H, C (W + GAP))``: row y holds channel 0's row, GAP zero
  columns, channel 1's row, GAP zeros, ...; plane c starts at column ``c (W + GAP)``;
- the output ``(H', W', C)`` viewed as ``(H', C W')`` single-channel has its channel c of
  pixel u at column ``C u + c``; the folded map sends that column to
  ``(map_x_c(u) + c (W + GAP), map_y_c(u))`` in the planar source, ``map_c`` the channel's own
  source positions;
- so ``cv2.remap`` of the planar buffer with the folded map writes the interleaved,
  per-channel-corrected image directly into the output (no merge). Rows of all planes sit side
  by side, so the three reads of one output pixel stay within one source row's cache lines.

Borders: between planes lie ``GAP`` = 8 zero columns, wider than the reach of the widest
kernel (Lanczos-4 reads 3 columns left and 4 right), and a source x outside
``[-MARGIN, W - 1 + MARGIN]`` (MARGIN = 4: every tap already lands on the border there) is sent
far outside; so each plane is sampled exactly as ``BORDER_CONSTANT`` (0) samples the channel
alone. Rows need nothing: the planes share them. OpenCV's remap holds source coordinates in
int16, so the folded width ``C (W + GAP)`` must stay below 32767 (W <= 10914 for three
channels, 8183 for four); wider images use three remaps of the split planes and a merge.

The folded maps are OpenCV's fixed-point maps (``CV_16SC2`` + ``CV_16UC1``, 6 bytes per output
sample instead of 8 for two float32 maps: the folded map is C times the output, and its
reads dominate); :func:`folded_maps` says why they are also exact.
"""

from __future__ import annotations

from typing import Any, Sequence

import cv2
import numpy as np
import numpy.typing as npt

#: Zero columns between two planes of the row-planar source.
GAP = 8
#: A source x further than this outside [0, W - 1] reads only border (zero) taps.
MARGIN = 4
#: Where an output pixel with no source points (far outside every plane, int16).
OUTSIDE = -16000
#: OpenCV's remap holds coordinates in int16.
INT16_LIMIT = 32767

Map = npt.NDArray[np.float32]


def folds(width: int, channels: int) -> bool:
    """
    Return True when a source this wide can be folded into one remap (int16 coordinates).

    :param width: source width in pixels.
    :param channels: channels of the image.
    :return: whether ``channels (width + GAP)`` fits OpenCV's int16 coordinates.
    """
    return channels * (width + GAP) + MARGIN < INT16_LIMIT


def folded_maps(maps: Sequence[tuple[Map, Map]], order: Sequence[int], width: int,
                height: int, nearest: bool = False
                ) -> tuple[npt.NDArray[np.int16], npt.NDArray[np.uint16] | None]:
    """
    Fold per-channel maps into the fixed-point maps of one remap of the planar source.

    Each channel's float map is converted to OpenCV's fixed point (``CV_16SC2`` integer
    source pixel + ``CV_16UC1`` 1/32-px fraction index) first, and the plane offset is added
    to the integer x: so every channel is sampled exactly as a remap of that channel alone
    with the same map (adding the offset to a float32 x instead would move some positions by
    one float32 step across a 1/32-px rounding boundary).

    :param maps: ``(map_x, map_y)`` per colour (e.g. R, G, B), each ``(H', W')`` float32
        source pixels; invalid pixels point outside the source.
    :param order: for each image channel, the index into ``maps`` of its colour (``rgb8``
        ``(0, 1, 2)``, ``bgr8`` ``(2, 1, 0)``, ``rgba8`` ``(0, 1, 2, 1)``: alpha follows
        green).
    :param width: source width W.
    :param height: source height H.
    :param nearest: build the nearest-neighbour map (rounded positions, no ``map2``).
    :return: ``(map1, map2)``: ``(H', C W', 2)`` int16 and ``(H', C W')`` uint16 (None when
        ``nearest``), for the ``(H, C (W + GAP))`` planar source.
    """
    out_h, out_w = maps[0][0].shape
    channels = len(order)
    fold_1 = np.empty((out_h, out_w, channels, 2), np.int16)
    fold_2 = None if nearest else np.empty((out_h, out_w, channels), np.uint16)
    for c, colour in enumerate(order):
        map_x, map_y = maps[colour]
        outside = ((map_x < -MARGIN) | (map_x > width - 1 + MARGIN) |
                   (map_y < -MARGIN) | (map_y > height - 1 + MARGIN))
        map_1, map_2 = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2, nninterpolation=nearest)
        map_1[..., 0] += np.int16(c * (width + GAP))
        map_1[outside] = OUTSIDE
        fold_1[:, :, c] = map_1
        if fold_2 is not None:
            map_2[outside] = 0
            fold_2[..., c] = map_2
    return (fold_1.reshape(out_h, out_w * channels, 2),
            None if fold_2 is None else fold_2.reshape(out_h, out_w * channels))


class ChannelRemap:
    """
    Per-channel maps of one corrected image and the per-frame folded remap.

    Folded maps are built on first use for each channel order (``rgb`` and ``bgr`` differ)
    and kept; build a new instance for new maps. Not thread-safe: one frame at a time.
    """

    def __init__(self, maps: Sequence[tuple[Map, Map]], width: int, height: int) -> None:
        """
        Keep the per-colour maps.

        :param maps: ``(map_x, map_y)`` per colour, all of one output size.
        :param width: source width.
        :param height: source height.
        """
        self.maps = [(np.asarray(x, np.float32), np.asarray(y, np.float32)) for x, y in maps]
        self.width, self.height = int(width), int(height)
        self._folded: dict[tuple[Any, ...], tuple[npt.NDArray[Any], Any]] = {}
        self._planar: npt.NDArray[Any] | None = None

    def prepare(self, order: Sequence[int], nearest: bool = False) -> None:
        """
        Build the folded maps of a channel order now (at rebuild time, not on a frame).

        :param order: see :func:`folded_maps`.
        :param nearest: for nearest-neighbour interpolation.
        """
        key = (*order, nearest)
        if key not in self._folded and folds(self.width, len(order)):
            self._folded[key] = folded_maps(self.maps, order, self.width, self.height, nearest)

    def _planes(self, src: npt.NDArray[Any]) -> list[npt.NDArray[Any]]:
        """Split ``src`` into the row-planar buffer (kept per dtype and size); return views."""
        channels = src.shape[2]
        stride = self.width + GAP
        shape = (self.height, channels * stride)
        planar = self._planar
        if planar is None or planar.shape != shape or planar.dtype != src.dtype:
            planar = self._planar = np.zeros(shape, src.dtype)    # the gaps stay 0
        views = [planar[:, c * stride:c * stride + self.width] for c in range(channels)]
        cv2.split(src, views)
        return views

    def remap(self, src: npt.NDArray[Any], order: Sequence[int], interpolation: int,
              dst: npt.NDArray[Any] | None = None) -> npt.NDArray[Any]:
        """
        Correct one interleaved frame, each channel with its colour's map.

        :param src: ``(H, W, C)`` image (uint8, uint16 or float32); a strided view is fine.
        :param order: the colour of each channel, see :func:`folded_maps`.
        :param interpolation: an OpenCV interpolation flag.
        :param dst: optional ``(H', W', C)`` output of ``src``'s dtype, written in place.
        :return: the corrected image (``dst`` when given).
        """
        channels = len(order)
        nearest = interpolation == cv2.INTER_NEAREST
        out_h, out_w = self.maps[0][0].shape
        if dst is None:
            dst = np.empty((out_h, out_w, channels), src.dtype)
        self.prepare(order, nearest)
        views = self._planes(src)
        folded = self._folded.get((*order, nearest))
        if folded is None:          # too wide to fold: one remap per plane, then a merge
            planes = [cv2.remap(view, *self.maps[colour], interpolation,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
                      for view, colour in zip(views, order)]
            return cv2.merge(planes, dst=dst)
        flat = dst.reshape(out_h, out_w * channels)
        cv2.remap(self._planar, folded[0], folded[1], interpolation, dst=flat,
                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return dst
