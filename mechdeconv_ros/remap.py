# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Remap maps from a LensModel, and the per-frame correction.

For a corrected (output) pixel ``(u, v)`` with normalised ideal coordinates
``x_n = (u - c'_x) / f'_x``, ``y_n = (v - c'_y) / f'_y`` (``K_new``), the ideal sensor radius is
``rho_i = v_img * hypot(x_n, y_n)`` and the source pixel is

    ``map_x = c_x + f_x x_n s(rho_i)``,  ``map_y = c_y + f_y y_n s(rho_i)``,
    ``s = R(rho_i) / rho_i``

with ``R`` the traced radial map: no inversion is needed, the forward trace maps ideal to real.
``s`` depends on the radius only, and ``K_new`` is centred, so ``s`` is computed on one quadrant
of the output and mirrored; the quadrant's radius look-up runs through ``cv2.remap`` on a
one-row table, which is several times faster than ``np.interp`` per pixel. Pixels outside the
valid field are sent far outside the source so ``BORDER_CONSTANT`` paints them 0.

The maps are converted once to OpenCV's fixed-point form (CV_16SC2 + CV_16UC1), the fastest
bilinear remap on our machines, and a nearest-neighbour CV_16SC2 map is kept for depth images
(no invented depths).
"""

from __future__ import annotations

import cv2
from mechdeconv_ros.model import LensModel
import numpy as np
import numpy.typing as npt

#: Where invalid output pixels point: far enough outside any source for BORDER_CONSTANT.
_OUTSIDE = -1000.0


def _quadrant_scale(model: LensModel, xn: npt.NDArray[np.float32],
                    yn: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """
    Return ``s = R(rho) / rho`` on the grid ``yn x xn`` (both >= 0); -1 outside the field.

    :param model: the lens model.
    :param xn: normalised ideal x of the quadrant's columns.
    :param yn: normalised ideal y of the quadrant's rows.
    :return: ``(len(yn), len(xn))`` float32.
    """
    curve = model.curve
    v = model.image_distance_mm
    samples = len(curve.ideal_mm)
    step = curve.valid_ideal_mm / (samples - 1)
    # Table of s over the uniformly spaced ideal radii (s(0) = 1: paraxial at the centre).
    with np.errstate(invalid='ignore', divide='ignore'):
        table = np.where(curve.ideal_mm > 0.0, curve.real_mm / curve.ideal_mm, 1.0)
    table = np.ascontiguousarray(table[None, :], dtype=np.float32)
    # One CV_32FC2 map (x = table index, y = 0 on the one-row table) for cv2.remap.
    index = np.zeros((len(yn), len(xn), 2), np.float32)
    np.hypot(xn[None, :], yn[:, None], out=index[..., 0])
    index[..., 0] *= np.float32(v / step)
    scale = cv2.remap(table, index, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                      borderValue=-1.0)
    scale[index[..., 0] > samples - 1] = -1.0
    return scale


Map = npt.NDArray[np.float32]


def build_float_maps(model: LensModel) -> tuple[Map, Map]:
    """
    Build the float source-pixel maps of the corrected image.

    :param model: the lens model.
    :return: ``(map_x, map_y)``, each ``(out_height, out_width)`` float32, raw-image pixels;
        invalid pixels point outside the source.
    """
    ow, oh = model.out_width, model.out_height
    fx, fy, cx, cy = model.K[0, 0], model.K[1, 1], model.K[0, 2], model.K[1, 2]
    xn = ((np.arange(ow) - model.K_new[0, 2]) / model.K_new[0, 0]).astype(np.float32)
    yn = ((np.arange(oh) - model.K_new[1, 2]) / model.K_new[1, 1]).astype(np.float32)
    # Output column u and ow-1-u have opposite xn (likewise rows): compute the lower-right
    # quadrant, then mirror it: map_x(ow-1-u) = 2 c_x - map_x(u), and map_y likewise.
    c0, r0 = ow // 2, oh // 2
    scale = _quadrant_scale(model, xn[c0:], yn[r0:])
    invalid = scale < 0.0
    map_x = np.empty((oh, ow), np.float32)
    map_y = np.empty((oh, ow), np.float32)
    quad_x = map_x[r0:, c0:]
    quad_y = map_y[r0:, c0:]
    np.multiply(scale, (xn[c0:] * np.float32(fx))[None, :], out=quad_x)
    quad_x += np.float32(cx)
    np.multiply(scale, (yn[r0:] * np.float32(fy))[:, None], out=quad_y)
    quad_y += np.float32(cy)
    if invalid.any():
        # Far outside, and still outside after the mirroring (2 c - outside is far beyond).
        quad_x[invalid] = _OUTSIDE
        quad_y[invalid] = _OUTSIDE
    np.subtract(np.float32(2.0 * cx), quad_x[:, ow - 2 * c0:ow - c0][:, ::-1],
                out=map_x[r0:, :c0])
    map_y[r0:, :c0] = quad_y[:, ow - 2 * c0:ow - c0][:, ::-1]
    map_x[:r0] = map_x[oh - r0:oh][::-1]
    np.subtract(np.float32(2.0 * cy), map_y[oh - r0:oh][::-1], out=map_y[:r0])
    return map_x, map_y


class Rectifier:
    """
    The maps of one LensModel, built once, and the per-frame correction.

    ``correct`` is safe to call from one thread at a time per instance; build a new Rectifier
    for a new model instead of mutating one, so a frame never sees two models.
    """

    def __init__(self, model: LensModel) -> None:
        """
        Build the fixed-point maps (bilinear/cubic/lanczos table and nearest-neighbour).

        :param model: the lens model.
        """
        self.model = model
        map_x, map_y = build_float_maps(model)
        self.map1, self.map2 = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)
        self._nearest_map: np.ndarray | None = None

    @property
    def nearest_map(self) -> np.ndarray:
        """
        Return the nearest-neighbour CV_16SC2 map, derived on first use.

        Only depth images need it, so a rebuild does not pay for it. It is the fixed-point map
        rounded to the nearest source pixel (OpenCV's ``INTER_TAB_SIZE`` = 32 fractions per
        pixel, ``map2`` packs ``32 * frac_y + frac_x``). It differs from converting the float
        maps with ``nninterpolation=True`` only where a source position lies within 1/64 px of
        the half-way point between two pixels, where either neighbour is as near.
        """
        if self._nearest_map is None:
            frac_x = (self.map2 & 31).astype(np.int16)
            frac_y = (self.map2 >> 5).astype(np.int16)
            nearest = self.map1.copy()
            nearest[..., 0] += frac_x >= 16
            nearest[..., 1] += frac_y >= 16
            self._nearest_map = nearest
        return self._nearest_map

    @property
    def out_shape(self) -> tuple[int, int]:
        """Return ``(out_height, out_width)``."""
        return self.model.out_height, self.model.out_width

    def correct(self, src: np.ndarray, dst: np.ndarray | None = None, *,
                nearest: bool = False) -> np.ndarray:
        """
        Correct one frame.

        :param src: ``(H, W)`` or ``(H, W, C)`` (C <= 4) uint8, uint16 or float32 raw image; a
            row-padded view is fine.
        :param dst: optional preallocated ``(out_height, out_width[, C])`` output of the same
            dtype, written in place (e.g. a view on an outgoing message's buffer).
        :param nearest: use nearest-neighbour regardless of the model's interpolation (depth).
        :return: the corrected image (``dst`` when given). Pixels outside the valid field or
            the source are 0.
        :raises ValueError: when ``src`` does not have the model's size.
        """
        if src.shape[:2] != (self.model.height, self.model.width):
            raise ValueError(f'frame is {src.shape[1]}x{src.shape[0]} px but the model is '
                             f'{self.model.width}x{self.model.height} px')
        if nearest or self.model.interpolation == cv2.INTER_NEAREST:
            return cv2.remap(src, self.nearest_map, None, cv2.INTER_NEAREST, dst=dst,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return cv2.remap(src, self.map1, self.map2, self.model.interpolation, dst=dst,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def distortion_maps(model: LensModel, ideal_K: npt.NDArray[np.float64] | None = None
                    ) -> tuple[Map, Map]:
    """
    Build maps that render what the camera sees from an ideal pinhole image.

    For each raw pixel the real radius is inverted to the ideal radius (the map is monotonic),
    giving the position in an ideal image with camera matrix ``ideal_K``. Used to synthesise
    distorted test frames and the demo camera; the correction never needs it.

    :param model: the lens model.
    :param ideal_K: camera matrix of the ideal image (default: ``model.K_new``).
    :return: ``(map_x, map_y)`` over the raw image, float32; invalid pixels point outside.
    """
    ideal_K = model.K_new if ideal_K is None else ideal_K
    u, v = np.meshgrid(np.arange(model.width, dtype=np.float64),
                       np.arange(model.height, dtype=np.float64))
    rect = model.rect_from_raw(np.stack([u, v], axis=-1))
    xn = (rect[..., 0] - model.K_new[0, 2]) / model.K_new[0, 0]
    yn = (rect[..., 1] - model.K_new[1, 2]) / model.K_new[1, 1]
    map_x = ideal_K[0, 2] + ideal_K[0, 0] * xn
    map_y = ideal_K[1, 2] + ideal_K[1, 1] * yn
    bad = ~np.isfinite(map_x) | ~np.isfinite(map_y)
    map_x[bad] = _OUTSIDE
    map_y[bad] = _OUTSIDE
    return map_x.astype(np.float32), map_y.astype(np.float32)


def distort_image(model: LensModel, ideal: np.ndarray,
                  ideal_K: npt.NDArray[np.float64] | None = None) -> np.ndarray:
    """
    Render the raw (distorted) image of an ideal pinhole image through the lens model.

    :param model: the lens model.
    :param ideal: the ideal image, camera matrix ``ideal_K`` (default ``model.K_new``).
    :param ideal_K: its camera matrix.
    :return: the raw image, ``(model.height, model.width[, C])``.
    """
    map_x, map_y = distortion_maps(model, ideal_K)
    return cv2.remap(ideal, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=0)
