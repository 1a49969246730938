# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The rectified pair's remap tables, traced exactly per pixel, and the per-pair rectification.

For a rectified pixel ``(u, v)`` of camera i (both share ``K_rect``), the scene direction in
the rectified frame is ``K_rect^-1 (u, v, 1)``, in camera i's frame ``d_i = R_i^T K_rect^-1
(u, v, 1)`` (``R_i`` = R1 or R2, rectified-from-camera), and the raw pixel is the chief ray's
landing point :func:`mechdeconv_ros.model.projection.pixels_of` ``(model_i, d_i)``: through the
lens, the sensor's offset and tilt and any port, with no fitted D anywhere (for a finite
``scene.distance_mm`` the direction is seen from the entrance pupil,
:func:`mechdeconv_ros.model.stereo.pixels_from_pupil`). Pixels no chief ray
reaches point far outside the raw image, so ``BORDER_CONSTANT`` paints them 0.

Vignetting (``output.vignetting_correction``): each camera's gain ``min(1 / RI, max_gain)`` at
the raw pixel its rectified pixel reads (:func:`camera_gain`), multiplied after the remap.
Lateral colour (``output.lateral_color_correction``): each colour channel gets its own map,
traced through that channel's chief rays (the single camera's channel traces), and the
channels are remapped in one pass (:class:`~mechdeconv_ros.imaging.channel_remap.
ChannelRemap`), as the single camera does.

The maps are CV_32FC1 pairs (the single camera's measurement: as fast as the fixed-point form
at 720p and above, :mod:`mechdeconv_ros.imaging.remap`). Building them costs one forward trace
per pixel and camera (a second or so at 1280x720 each); it runs when the model changes, never
per frame.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Sequence

import cv2
from mechdeconv_ros.imaging.channel_remap import ChannelRemap
from mechdeconv_ros.lenses.lens_errors import FloatArray
from mechdeconv_ros.model.model import LensModel
from mechdeconv_ros.model.stereo import pixels_from_pupil, StereoModel
import numpy as np

Map = np.ndarray
#: Where rectified pixels that no chief ray reaches point: outside any raw image.
_OUTSIDE = -1000.0
#: Rectified rows traced per band (bounds the float64 intermediates to a few MB).
_BAND_ROWS = 64


def camera_maps(model: LensModel, rot: FloatArray, k_rect: FloatArray,
                size: tuple[int, int]) -> tuple[Map, Map]:
    """
    Return one camera's maps: rectified pixel -> raw pixel, traced per pixel.

    :param model: the camera's lens model (or a colour channel's, same K).
    :param rot: its rectified-from-camera rotation (R1 or R2).
    :param k_rect: the shared rectified camera matrix.
    :param size: the rectified ``(width, height)``.
    :return: ``(map_x, map_y)``, ``(height, width)`` float32 raw pixel coordinates.
    """
    width, height = size
    map_x = np.empty((height, width), np.float32)
    map_y = np.empty((height, width), np.float32)
    # Camera direction of each rectified pixel: d = R^T K^-1 (u, v, 1); as rows, d = q @ M.
    m = np.linalg.inv(k_rect).T @ rot
    u = np.arange(width, dtype=np.float64)
    for top in range(0, height, _BAND_ROWS):
        rows = np.arange(top, min(top + _BAND_ROWS, height), dtype=np.float64)
        uu, vv = np.meshgrid(u, rows)
        q = np.stack([uu, vv, np.ones_like(uu)], axis=-1)
        raw = pixels_from_pupil(model, q @ m)
        bad = ~np.isfinite(raw).all(axis=-1)
        raw[bad] = _OUTSIDE
        map_x[top:top + rows.size] = raw[..., 0]
        map_y[top:top + rows.size] = raw[..., 1]
    return map_x, map_y


def stereo_maps(stereo: StereoModel) -> tuple[tuple[Map, Map], tuple[Map, Map]]:
    """
    Return both cameras' maps from rectified pixel to raw pixel.

    :param stereo: the stereo model.
    :return: ``((map_lx, map_ly), (map_rx, map_ry))``, each ``(height, width)`` float32.
    """
    size = (stereo.width, stereo.height)
    return (camera_maps(stereo.left, stereo.R1, stereo.K_rect, size),
            camera_maps(stereo.right, stereo.R2, stereo.K_rect, size))


def _channel_maps(model: LensModel, rot: FloatArray, k_rect: FloatArray,
                  size: tuple[int, int]) -> list[tuple[Map, Map]]:
    """Return a map per colour channel (R, G, B), each through its own chief rays."""
    return [camera_maps(replace(model, curve=channel.curve, field_curve=channel.field,
                                _summary_cache={}, _illumination_cache={}, _lateral_cache={}),
                        rot, k_rect, size)
            for channel in model.lateral_color().channels]


def camera_gain(model: LensModel, map_x: Map, map_y: Map, max_gain: float) -> Map:
    """
    Return the vignetting gain of each rectified pixel, from RI where its ray lands.

    gain = min(1 / RI(rho), max_gain), rho the raw pixel's distance from the lens axis on the
    sensor (mm), as the single camera's gain map; 0 where RI < 1 / max_gain (the corrected
    field ends) and where no chief ray lands.

    :param model: the camera's lens model.
    :param map_x: its rectified-to-raw x map.
    :param map_y: its y map.
    :param max_gain: ``output.max_vignetting_gain``.
    :return: ``(height, width)`` float32.
    """
    rho = np.hypot((map_x - model.K[0, 2]) * model.pixel_mm[0],
                   (map_y - model.K[1, 2]) * model.pixel_mm[1])
    ri = model.illumination(with_fraction=False).at(rho)
    with np.errstate(divide='ignore'):
        gain = np.where(ri >= 1.0 / max_gain, 1.0 / np.maximum(ri, 1e-12), 0.0)
    gain[map_x <= _OUTSIDE] = 0.0
    return np.minimum(gain, max_gain).astype(np.float32)


#: OpenCV depth of each image dtype the gain multiplies.
_CV_DEPTH = {np.dtype(np.uint8): cv2.CV_8U, np.dtype(np.uint16): cv2.CV_16U,
             np.dtype(np.int16): cv2.CV_16S, np.dtype(np.float32): cv2.CV_32F,
             np.dtype(np.float64): cv2.CV_64F}


class StereoRectifier:
    """
    The maps of one StereoModel, built once, and the per-pair rectification.

    Build a new one for a new model rather than changing one, so a pair never mixes two
    models. ``rectify`` is safe from one thread at a time per instance.
    """

    def __init__(self, stereo: StereoModel, lateral: bool | None = None,
                 vignetting: bool | None = None) -> None:
        """
        Trace both cameras' maps.

        :param stereo: the stereo model.
        :param lateral: per-channel maps for lateral colour; None = the pair's
            ``output.lateral_color_correction``.
        :param vignetting: gain maps for the vignetting correction; None = the pair's
            ``output.vignetting_correction``.
        """
        self.stereo = stereo
        (self.left_x, self.left_y), (self.right_x, self.right_y) = stereo_maps(stereo)
        self.interpolation = stereo.left.interpolation
        values = stereo.left.values
        if vignetting is None:
            vignetting = bool(values.get('output.vignetting_correction', False))
        self.gains: tuple[Map, Map] | None = None
        self._merged: dict[tuple[int, int], Map] = {}
        if vignetting:
            max_gain = float(values['output.max_vignetting_gain'])
            self.gains = (camera_gain(stereo.left, self.left_x, self.left_y, max_gain),
                          camera_gain(stereo.right, self.right_x, self.right_y, max_gain))
        if lateral is None:
            lateral = bool(stereo.left.values.get('output.lateral_color_correction', False))
        self.colour: tuple[ChannelRemap, ChannelRemap] | None = None
        if lateral:
            size = (stereo.width, stereo.height)
            self.colour = tuple(
                ChannelRemap(_channel_maps(model, rot, stereo.K_rect, size), model.width,
                             model.height)
                for model, rot in ((stereo.left, stereo.R1), (stereo.right, stereo.R2)))

    @property
    def out_shape(self) -> tuple[int, int]:
        """Return the rectified ``(height, width)``."""
        return self.stereo.height, self.stereo.width

    def _one(self, index: int, src: np.ndarray, colours: Sequence[int] | None,
             dst: np.ndarray | None) -> np.ndarray:
        model = self.stereo.models[index]
        if src.shape[:2] != (model.height, model.width):
            side = ('left', 'right')[index]
            raise ValueError(f'{side} frame is {src.shape[1]}x{src.shape[0]} px but the '
                             f'{side} camera is {model.width}x{model.height} px')
        if colours and self.colour is not None and src.ndim == 3:
            out = self.colour[index].remap(src, colours, self.interpolation, dst)
        else:
            map_x, map_y = ((self.left_x, self.left_y), (self.right_x, self.right_y))[index]
            out = cv2.remap(src, map_x, map_y, self.interpolation, dst=dst,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if self.gains is not None:
            channels = 1 if out.ndim == 2 else out.shape[2]
            gain = self._merged.get((index, channels))
            if gain is None:
                gain = self.gains[index] if channels == 1 else \
                    cv2.merge([self.gains[index]] * channels)
                self._merged[(index, channels)] = gain
            # In place; cv2 saturates integer images instead of wrapping.
            cv2.multiply(out, gain, dst=out, dtype=_CV_DEPTH[out.dtype])
        return out

    def rectify(self, left: np.ndarray, right: np.ndarray, *,
                colours: Sequence[int] | None = None,
                dst: tuple[Any, Any] = (None, None)) -> tuple[np.ndarray, np.ndarray]:
        """
        Rectify one pair.

        :param left: the left raw image, ``(H, W)`` or ``(H, W, C)``.
        :param right: the right raw image.
        :param colours: the colour (0 R, 1 G, 2 B) of each channel (lateral colour); None: one
            map for every channel.
        :param dst: optional preallocated outputs, written in place.
        :return: ``(left_rect, right_rect)``; pixels no chief ray reaches are 0.
        :raises ValueError: when a frame does not have its camera's size.
        """
        return (self._one(0, left, colours, dst[0]), self._one(1, right, colours, dst[1]))
