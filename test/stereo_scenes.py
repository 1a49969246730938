# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Raw stereo pairs of textured planes, rendered through an independent route (test helper).

The route runs from each RAW pixel outwards, never through the rectification's maps: every raw
pixel of each camera is supersampled (``SUPERSAMPLE`` x ``SUPERSAMPLE`` points), each point's
scene direction comes from the camera's exact inverse,
:func:`mechdeconv_ros.model.projection.directions_of` (the radial map's inverse, and Newton on
the chief-ray lines for a tilted sensor: a different code path from the forward trace
:func:`~mechdeconv_ros.model.projection.pixels_of` the maps use), the ray leaves the camera's
entrance pupil (the left camera's at the origin; the right camera's at ``t`` with its axes the
columns of ``R``: ``d_left = R d_right``, docs/design.md section 8) and meets the nearest
textured plane of the scene. The texture is a band-limited noise (Gaussian-blurred white noise
plus a coarser octave) sampled bilinearly at about 2.5 px per texel at the plane's depth, so the
supersampling anti-aliases it; the pixel is the mean of its samples, then 8-bit quantised. No
blur, no noise: a matcher's scatter comes from quantisation and its own interpolation only.

The truth (:func:`render_pair`'s third result) is computed on the TRUE rig's rectified grid by
plain geometry (K_rect, R1, R2 of :func:`mechdeconv_ros.model.stereo.build_stereo` with the true
rig, not its maps): each rectified pixel's ray meets the scene, and its disparity is
``f B / Z`` with Z the depth along the rectified axis.

:func:`render_pair` is the entry point (also for the live rotation estimate's tests):
``render_pair(stereo_values, true_rig_values, scene, size) -> (left, right, truth)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import cv2
from mechdeconv_ros.model.projection import directions_of
from mechdeconv_ros.model.stereo import build_stereo, StereoModel
import numpy as np

#: Samples per raw pixel along each axis (the anti-aliasing box filter).
SUPERSAMPLE = 2
#: Texels of each plane's texture image (it tiles beyond).
TEXTURE_TEXELS = 512
#: Raw rays traced per batch (bounds the intermediates).
_BATCH = 1 << 18


@dataclass(frozen=True)
class Plane:
    """
    A textured rectangle in the left camera's frame (mm).

    Its points are ``origin + a e_a + b e_b`` for ``0 <= a <= size[0]``, ``0 <= b <= size[1]``
    (``e_a``, ``e_b`` orthonormal); its texture is ``seed``'s noise, one texel per
    ``texel_mm``.
    """

    origin: tuple[float, float, float]
    e_a: tuple[float, float, float]
    e_b: tuple[float, float, float]
    size: tuple[float, float]
    texel_mm: float
    seed: int


def facing(centre: Sequence[float], width_mm: float, height_mm: float, seed: int,
           yaw_deg: float = 0.0, texel_px: float = 2.5, focal_px: float = 1000.0) -> Plane:
    """
    Return a rectangle centred at ``centre``, facing the left camera (turned by ``yaw_deg``).

    :param centre: its centre, mm, left camera frame.
    :param width_mm: its width along its (turned) X.
    :param height_mm: its height along Y.
    :param seed: its texture's seed.
    :param yaw_deg: turned about Y (a slanted wall), deg.
    :param texel_px: a texel's size in the image at its centre's depth, px.
    :param focal_px: the focal length that size is for.
    :return: the plane.
    """
    yaw = np.radians(yaw_deg)
    e_a = np.array([np.cos(yaw), 0.0, -np.sin(yaw)])
    e_b = np.array([0.0, 1.0, 0.0])
    origin = np.asarray(centre, float) - 0.5 * width_mm * e_a - 0.5 * height_mm * e_b
    return Plane(tuple(origin), tuple(e_a), tuple(e_b), (width_mm, height_mm),
                 float(centre[2]) * texel_px / focal_px, seed)


def depth_scene(seed: int = 0, focal_px: float = 1000.0) -> list[Plane]:
    """
    Return a textured scene with depth from 1.5 to 8 m (mm, left camera frame).

    A wall at 8 m behind everything, a slanted wall, and boxes at 1.5 to 5 m, placed by
    ``seed`` so that several scenes give the estimate different matches.

    :param seed: placement and textures.
    :param focal_px: the cameras' focal length: the textures have about 2.5 px texels.
    :return: the planes.
    """
    rng = np.random.default_rng(seed)
    # The back wall is slanted so that its disparity runs through every sub-pixel fraction.
    planes = [facing((0.0, 0.0, 6500.0), 40000.0, 30000.0, seed * 100 + 1, yaw_deg=-35.0,
                     focal_px=focal_px),
              facing((rng.uniform(-1500, -800), rng.uniform(-300, 300), 5000.0), 1800.0,
                     2500.0, seed * 100 + 2, yaw_deg=rng.uniform(25.0, 40.0),
                     focal_px=focal_px)]
    for k, depth in enumerate((1500.0, 2200.0, 3200.0, 4500.0)):
        half_w = 0.22 * depth
        planes.append(facing((rng.uniform(-half_w, half_w) + 60.0,
                              rng.uniform(-0.15, 0.15) * depth, depth),
                             rng.uniform(0.12, 0.2) * depth, rng.uniform(0.1, 0.16) * depth,
                             seed * 100 + 3 + k, focal_px=focal_px))
    return planes


def _wrap_blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """Blur a tiling image with a Gaussian that wraps around its edges."""
    pad = int(np.ceil(4 * sigma))
    padded = np.pad(image, pad, mode='wrap')
    return cv2.GaussianBlur(padded, (0, 0), sigma)[pad:-pad, pad:-pad]


def _texture(seed: int) -> np.ndarray:
    """Return a band-limited noise texture (float32, about 0-255, tiling)."""
    rng = np.random.default_rng(seed)
    fine = _wrap_blur(rng.random((TEXTURE_TEXELS, TEXTURE_TEXELS)).astype(np.float32), 1.0)
    coarse = _wrap_blur(rng.random((TEXTURE_TEXELS, TEXTURE_TEXELS)).astype(np.float32), 6.0)
    texture = (fine - fine.mean()) / fine.std() + 0.8 * (coarse - coarse.mean()) / coarse.std()
    return (128.0 + 40.0 * texture).astype(np.float32)


def _bilinear(texture: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Sample a tiling texture bilinearly at texel coordinates (numpy, no OpenCV remap)."""
    n = texture.shape[0]
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    i0, j0 = x0.astype(np.int64) % n, y0.astype(np.int64) % n
    i1, j1 = (i0 + 1) % n, (j0 + 1) % n
    return ((texture[j0, i0] * (1 - fx) + texture[j0, i1] * fx) * (1 - fy)
            + (texture[j1, i0] * (1 - fx) + texture[j1, i1] * fx) * fy)


def trace_scene(scene: Sequence[Plane], origin: np.ndarray, dirs: np.ndarray,
                textures: Mapping[int, np.ndarray] | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the nearest hit of each ray: its texture value and the point (mm, left frame).

    :param scene: the planes.
    :param origin: the rays' common origin, mm.
    :param dirs: ``(N, 3)`` directions (NaN: no ray).
    :param textures: seed -> texture (made when missing).
    :return: ``(value (N,), point (N, 3))``; NaN where no plane is hit.
    """
    textures = {} if textures is None else textures
    n = dirs.shape[0]
    best = np.full(n, np.inf)
    value = np.full(n, np.nan)
    for plane in scene:
        p0, e_a, e_b = (np.asarray(x, float) for x in (plane.origin, plane.e_a, plane.e_b))
        normal = np.cross(e_a, e_b)
        rel = origin - p0
        with np.errstate(invalid='ignore', divide='ignore'):
            # The hit is origin + t d; its plane coordinates are rel . e + t (d . e).
            t = -(rel @ normal) / (dirs @ normal)
            a = rel @ e_a + t * (dirs @ e_a)
            b = rel @ e_b + t * (dirs @ e_b)
            take = (t > 0) & (t < best) & (a >= 0) & (a <= plane.size[0]) & \
                (b >= 0) & (b <= plane.size[1])
        if not take.any():
            continue
        texture = textures.get(plane.seed)
        if texture is None:
            texture = textures[plane.seed] = _texture(plane.seed)
        best[take] = t[take]
        value[take] = _bilinear(texture, a[take] / plane.texel_mm, b[take] / plane.texel_mm)
    with np.errstate(invalid='ignore'):
        point = origin + np.where(np.isfinite(best), best, np.nan)[:, None] * dirs
    return value, point


def render_camera(model: Any, rot: np.ndarray, origin: np.ndarray, scene: Sequence[Plane],
                  textures: dict[int, np.ndarray]) -> np.ndarray:
    """
    Render one camera's raw image: each raw pixel supersampled, its rays by the exact inverse.

    :param model: the camera's LensModel.
    :param rot: the camera's axes in the left frame (columns): ``d_left = rot @ d_camera``.
    :param origin: its entrance pupil in the left frame, mm.
    :param scene: the planes.
    :param textures: the texture cache.
    :return: ``(height, width)`` uint8; 0 where no plane is hit.
    """
    w, h = model.width, model.height
    offsets = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
    ou, ov = np.meshgrid(offsets, offsets)
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pix = np.stack([(u.reshape(-1, 1) + ou.reshape(1, -1)).ravel(),
                    (v.reshape(-1, 1) + ov.reshape(1, -1)).ravel()], axis=-1)
    values = np.empty(pix.shape[0])
    for start in range(0, pix.shape[0], _BATCH):
        part = pix[start:start + _BATCH]
        dirs = directions_of(model, part) @ rot.T
        values[start:start + _BATCH] = trace_scene(scene, origin, dirs, textures)[0]
    mean = np.nan_to_num(values, nan=0.0).reshape(h * w, SUPERSAMPLE * SUPERSAMPLE).mean(axis=1)
    return np.clip(np.round(mean), 0, 255).astype(np.uint8).reshape(h, w)


def rectified_truth(stereo: StereoModel, scene: Sequence[Plane]) -> dict[str, np.ndarray]:
    """
    Return the true disparity of each rectified pixel of both cameras, by geometry.

    :param stereo: the TRUE stereo model (its K_rect, R1, R2, rig; not its maps).
    :param scene: the planes.
    :return: ``disparity`` (left rectified grid: ``f B / Z``, Z along the rectified axis),
        ``disparity_right`` (right grid, the same surface's), ``depth_mm`` (left grid); NaN
        where no plane is hit.
    """
    w, h = stereo.width, stereo.height
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rect = np.stack([u, v, np.ones_like(u)], axis=-1).reshape(-1, 3) @ np.linalg.inv(
        stereo.K_rect).T
    fb = stereo.K_rect[0, 0] * stereo.baseline_m * 1000.0
    out = {}
    for name, rot, origin in (('disparity', stereo.R1, np.zeros(3)),
                              ('disparity_right', stereo.R1, stereo.rig.t_mm)):
        # Both rectified cameras look along R1^T's axes (R2 = R1 R): d_left = R1^T d_rect.
        _, point = trace_scene(scene, origin, rect @ rot)
        depth = (point @ stereo.R1.T)[:, 2] - (origin @ stereo.R1.T)[2]
        out[name] = (fb / depth).reshape(h, w)
        if name == 'disparity':
            out['depth_mm'] = depth.reshape(h, w)
    return out


def render_pair(stereo_values: Mapping[str, Any], true_rig_values: Mapping[str, Any],
                scene: Sequence[Plane], size: tuple[int, int]
                ) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """
    Render a raw stereo pair through the lenses of ``stereo_values`` on the true rig.

    :param stereo_values: pair values (the lenses; their ``rig.*`` are ignored).
    :param true_rig_values: the true ``rig.*`` values (missing ones: the defaults).
    :param scene: the planes (:func:`depth_scene`).
    :param size: the raw ``(width, height)`` of both cameras (where ``*.sensor.*_px`` is 0).
    :return: ``(left, right, truth)``: raw uint8 images and ``truth`` with ``stereo`` (the
        true StereoModel), ``disparity``, ``disparity_right`` and ``depth_mm``
        (:func:`rectified_truth`).
    """
    values = {k: v for k, v in stereo_values.items() if not k.startswith('rig.')}
    values.update(true_rig_values)
    stereo = build_stereo(values, size, size)
    textures: dict[int, np.ndarray] = {}
    left = render_camera(stereo.left, np.eye(3), np.zeros(3), scene, textures)
    right = render_camera(stereo.right, stereo.rig.R, stereo.rig.t_mm, scene, textures)
    truth: dict[str, Any] = {'stereo': stereo, **rectified_truth(stereo, scene)}
    return left, right, truth
