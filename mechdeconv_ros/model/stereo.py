# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A stereo pair without a checkerboard: two lens models, the rig, and the exact rectification.

Frames (docs/design.md section 8): each camera's optical frame is REP-103's (X right,
Y down, Z ahead), with its origin at the camera's paraxial entrance pupil. In the LEFT
camera's frame the right camera's entrance pupil is at ``t = (baseline, offset_y, offset_z)``
mm and its axes are the columns of

    R = R_x(rx) R_y(ry) R_z(rz),   R_x(a) = [[1, 0, 0], [0, cos a, -sin a], [0, sin a, cos a]]

(right-handed active rotations about the left camera's axes, applied z first); a scene point
is ``X_r = R^T (X_l - t)`` in the right camera's frame (a direction ``d_r = R^T d_l``).

Rectification (as OpenCV's stereoRectify, each camera turned half way): with ``R_h`` the
rotation by half of R's angle about R's axis (``R_h R_h = R``), the middle orientation sees
the baseline at ``t_m = R_h^T t``; ``W`` is the smallest rotation taking ``t_m`` to the +X
axis. Then

    R1 = W R_h^T   (rectified-from-left: d_rect = R1 d_l),   R2 = W R_h = R1 R,

so ``R1 t = |t| e_x``: both rectified cameras look the same way and the baseline is their
rows' direction, the right camera ``B = |t|`` to the right. Both share one pinhole
``K_rect = [[f, 0, cx], [0, f, cy], [0, 0, 1]]`` (equal fx = fy, cx and cy: a point at
infinity has zero disparity) and one size; ``P1 = K_rect [I | 0]``,
``P2 = K_rect [I | (-B, 0, 0)]``, so ``P2[0, 3] = -f B`` with B in METRES (the ROS
CameraInfo convention). A point at depth Z (rectified frame, m) has disparity
``u_l - u_r = f B / Z`` px.

``f`` and the principal point follow ``output.alpha`` over both cameras' raw outlines, seen
through each camera's exact inverse (:func:`mechdeconv_ros.model.projection.directions_of`,
refined on the forward trace for a non-symmetric port, :func:`exact_directions`) and turned
into the rectified frame: 0 frames the largest window inside both (only pixels valid in both
images), 1 the smallest window holding all of both; in between, f and the window's centre
interpolate linearly (as the single camera's ``output.alpha``). Where a fisheye's image
circle, or 85 deg from the rectified axis (the pinhole limit), ends inside a raw image, its
outline follows that edge.

A finite ``scene.distance_mm`` (the single camera measures that plane from its front principal
point H) is converted to the pair's origin E by :func:`pupil_tangent_scale`.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Mapping

from mechdeconv_ros.lenses.lens_errors import FloatArray, ModelError, scene_distance
from mechdeconv_ros.model.model import build_model, LensModel
from mechdeconv_ros.model.projection import directions_of, pixels_of
from mechdeconv_ros.optics.ports import entrance_pupil_z
from mechdeconv_ros.schema.stereo_params import (
    check_stereo_values, RIG_PARAMS, split_values)
import numpy as np

#: Raw outline points per image side that frame the rectified window.
_OUTLINE_PER_SIDE = 96
#: Rays closer than this to the rectified image plane (z / |d| = cos 85 deg, the single
#: camera's pinhole limit) are not framed: the window ends before them.
_MIN_Z = math.cos(math.radians(85.0))


def rig_rotation(rx_deg: float, ry_deg: float, rz_deg: float) -> FloatArray:
    """
    Return ``R = R_x(rx) R_y(ry) R_z(rz)``: the right camera's axes in the left camera's frame.

    Right-handed active rotations about the left camera's axes, applied z first. (Kept here
    until ``optics/pose.py`` provides the same function; the two must agree.)

    :param rx_deg: about X (pitch), deg.
    :param ry_deg: about Y (yaw), deg.
    :param rz_deg: about Z (roll), deg.
    :return: 3x3 rotation matrix.
    """
    a, b, c = (math.radians(x) for x in (rx_deg, ry_deg, rz_deg))
    rot_x = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)],
                      [0.0, math.sin(a), math.cos(a)]])
    rot_y = np.array([[math.cos(b), 0.0, math.sin(b)], [0.0, 1.0, 0.0],
                      [-math.sin(b), 0.0, math.cos(b)]])
    rot_z = np.array([[math.cos(c), -math.sin(c), 0.0], [math.sin(c), math.cos(c), 0.0],
                      [0.0, 0.0, 1.0]])
    return rot_x @ rot_y @ rot_z


@dataclass(frozen=True)
class Rig:
    """The right camera relative to the left (mm, deg): see the module docstring."""

    baseline_mm: float
    offset_y_mm: float = 0.0
    offset_z_mm: float = 0.0
    rotation_x_deg: float = 0.0
    rotation_y_deg: float = 0.0
    rotation_z_deg: float = 0.0

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> Rig:
        """
        Read the rig from pair values (``rig.*``; missing ones take their defaults).

        :param values: pair parameter values (the full set or :func:`split_values`' pair part).
        :return: the rig.
        """
        full = check_stereo_values({k: values[k] for k in RIG_PARAMS if k in values},
                                   partial=False)
        return cls(*(float(full[name]) for name in RIG_PARAMS))

    @property
    def R(self) -> FloatArray:  # noqa: N802 - the convention's name
        """Return the right camera's axes as columns, in the left camera's frame."""
        return rig_rotation(self.rotation_x_deg, self.rotation_y_deg, self.rotation_z_deg)

    @property
    def t_mm(self) -> FloatArray:
        """Return the right camera's entrance pupil in the left camera's frame, mm."""
        return np.array([self.baseline_mm, self.offset_y_mm, self.offset_z_mm])


@dataclass(frozen=True)
class StereoModel:
    """
    Both cameras, the rig and the rectified pair: build it with :func:`build_stereo`.

    ``R1``/``R2`` are rectified-from-camera rotations (``d_rect = R1 @ d_left``), ``K_rect``
    the shared rectified pinhole, ``P1``/``P2`` the 3x4 projections (``P2[0, 3] = -f B``, B in
    metres), ``width`` x ``height`` the rectified size.
    """

    left: LensModel
    right: LensModel
    rig: Rig
    R1: FloatArray
    R2: FloatArray
    K_rect: FloatArray
    P1: FloatArray
    P2: FloatArray
    width: int
    height: int
    baseline_m: float
    #: The checked pair values the model was built from (every STEREO_SCHEMA name).
    values: Mapping[str, Any] | None = None

    @property
    def models(self) -> tuple[LensModel, LensModel]:
        """Return ``(left, right)``."""
        return self.left, self.right

    @property
    def rotations(self) -> tuple[FloatArray, FloatArray]:
        """Return ``(R1, R2)``."""
        return self.R1, self.R2


def _quaternion(rot: FloatArray) -> FloatArray:
    """Return the unit quaternion (w, x, y, z), w >= 0, of a rotation by less than 180 deg."""
    w = 0.5 * math.sqrt(max(0.0, 1.0 + float(np.trace(rot))))
    if w < 1e-9:
        raise ModelError('rig.rotation_y_deg', 'the right camera is turned by 180 deg')
    return np.array([w, (rot[2, 1] - rot[1, 2]) / (4.0 * w), (rot[0, 2] - rot[2, 0]) / (4.0 * w),
                     (rot[1, 0] - rot[0, 1]) / (4.0 * w)])


def _rotation_of(q: FloatArray) -> FloatArray:
    """Return the rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def half_rotation(rot: FloatArray) -> FloatArray:
    """
    Return ``R_h`` with ``R_h @ R_h = R``: half of R's angle about R's axis.

    :param rot: a rotation by less than 180 deg.
    :return: 3x3 rotation.
    """
    q = _quaternion(rot)
    return _rotation_of(q + np.array([1.0, 0.0, 0.0, 0.0]))


def _align_to_x(direction: FloatArray) -> FloatArray:
    """Return the smallest rotation W taking ``direction`` to +X (Rodrigues' formula)."""
    e = direction / np.linalg.norm(direction)
    k = np.cross(e, np.array([1.0, 0.0, 0.0]))
    s2, c = float(k @ k), float(e[0])
    if s2 < 1e-30:
        return np.eye(3)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + kx + kx @ kx * ((1.0 - c) / s2)


def rectifying_rotations(rig: Rig) -> tuple[FloatArray, FloatArray]:
    """
    Return ``(R1, R2)``: each camera turned half way, the baseline along the rectified X.

    :param rig: the rig.
    :return: rectified-from-left and rectified-from-right rotations (``R2 = R1 @ rig.R``).
    """
    half = half_rotation(rig.R)
    w = _align_to_x(half.T @ rig.t_mm)
    return w @ half.T, w @ half


def _camera_model(camera: str, values: Mapping[str, Any], size: tuple[int, int]) -> LensModel:
    """Build one camera's model; its refusals name the pair's parameter (``left.lens.r1_mm``)."""
    try:
        return build_model(values, int(size[0]), int(size[1]))
    except ModelError as err:
        name = err.parameter if err.parameter.startswith('output.') else \
            f'{camera}.{err.parameter}'
        raise ModelError(name, err.reason) from None


def exact_directions(model: LensModel, pixels: FloatArray, iterations: int = 3) -> FloatArray:
    """
    Return the scene directions of raw pixels, refined on the forward trace.

    :func:`~mechdeconv_ros.model.projection.directions_of` inverts the symmetric model (lens
    and sensor pose); a port that is tilted or decentred bends the chief rays off that, and only
    :func:`~mechdeconv_ros.model.projection.pixels_of` traces it. Gauss-Newton steps on the
    tangents ``(x/z, y/z)`` (numerical Jacobian of ``pixels_of``) make each direction the one
    whose chief ray lands on its pixel; where a step fails the inverse's direction stays.

    :param model: the camera's lens model.
    :param pixels: ``(N, 2)`` raw pixels.
    :param iterations: Gauss-Newton steps.
    :return: ``(N, 3)`` unit directions; NaN outside the traced field.
    """
    d = directions_of(model, pixels)
    with np.errstate(invalid='ignore'):
        ahead = np.isfinite(d).all(axis=1) & (d[:, 2] > _MIN_Z)
    if not ahead.any():
        return d
    tan = d[ahead, :2] / d[ahead, 2:3]
    target = np.asarray(pixels, dtype=np.float64)[ahead]
    eps = 1e-6

    def trace(t: FloatArray) -> FloatArray:
        return pixels_of(model, np.column_stack([t, np.ones(len(t))]))

    for _ in range(iterations):
        p = trace(tan)
        jx = (trace(tan + [eps, 0.0]) - p) / eps
        jy = (trace(tan + [0.0, eps]) - p) / eps
        det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
        r = target - p
        with np.errstate(invalid='ignore', divide='ignore'):
            step = np.column_stack([(jy[:, 1] * r[:, 0] - jy[:, 0] * r[:, 1]) / det,
                                    (jx[:, 0] * r[:, 1] - jx[:, 1] * r[:, 0]) / det])
        good = np.isfinite(step).all(axis=1)
        tan[good] += step[good]
    out = d.copy()
    refined = np.column_stack([tan, np.ones(len(tan))])
    refined /= np.linalg.norm(refined, axis=1, keepdims=True)
    landed = np.hypot(*(trace(tan) - target).T) < 1e-3
    rows = np.flatnonzero(ahead)
    out[rows[landed]] = refined[landed]
    return out


def pupil_tangent_scale(model: LensModel) -> float:
    """
    Return k: a direction's tangents seen from the entrance pupil E times k are those from H.

    The single camera measures a finite scene's directions from its front principal point H
    (``scene.distance_mm`` = l is the plane's distance from H); the pair's frames have their
    origins at the paraxial entrance pupils E. A point of that plane is at depth
    ``l + z_E - z_H`` from E and l from H, so ``tan_H = tan_E (l + z_E - z_H) / l``. At
    infinity (l = 0 in the parameter) k = 1: directions are the same from every point. A lens
    without surfaces (a datasheet table) or behind a port keeps k = 1 (section 8).

    :param model: the camera's lens model.
    :return: k.
    """
    distance = scene_distance(model.values)
    if not math.isfinite(distance) or model.prescription is None or \
            str(model.values.get('port.type', 'none')) != 'none':
        return 1.0
    offset = entrance_pupil_z(model.prescription) - model.source.first_order().front_principal_z_mm
    return (distance + offset) / distance if math.isfinite(offset) else 1.0


def pixels_from_pupil(model: LensModel, directions: FloatArray) -> FloatArray:
    """
    Return the raw pixels of directions seen from the camera's entrance pupil (the pair's frame).

    :param model: the camera's lens model.
    :param directions: ``(..., 3)`` in its optical frame, origin at its entrance pupil.
    :return: ``(..., 2)`` raw pixels (:func:`~mechdeconv_ros.model.projection.pixels_of`).
    """
    d = np.array(directions, dtype=np.float64)
    k = pupil_tangent_scale(model)
    if k != 1.0:
        d[..., :2] *= k
    return pixels_of(model, d)


def directions_from_pupil(model: LensModel, pixels: FloatArray) -> FloatArray:
    """
    Return the unit directions raw pixels see from the camera's entrance pupil (pair's frame).

    :param model: the camera's lens model.
    :param pixels: ``(N, 2)`` raw pixels.
    :return: ``(N, 3)`` unit directions (:func:`exact_directions`, then from E).
    """
    d = exact_directions(model, pixels)
    k = pupil_tangent_scale(model)
    if k != 1.0:
        d[..., :2] /= k
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return d


def _pinhole_visible(model: LensModel, rot: FloatArray, pixels: FloatArray) -> FloatArray:
    """Return whether raw pixels see a direction the rectified pinhole shows (field, 85 deg)."""
    d = directions_of(model, pixels) @ rot.T
    with np.errstate(invalid='ignore'):
        return np.isfinite(d).all(axis=1) & (d[:, 2] > _MIN_Z)


def _clipped_to_field(model: LensModel, rot: FloatArray, side: FloatArray) -> FloatArray:
    """
    Move outline points the rectified pinhole cannot show inward, to where it can.

    A fisheye's image circle inside the sensor, or a field wider than 85 deg from the
    rectified axis: each such point moves along its line to the lens axis pixel (bisection,
    1/4096 of the way) to the last point that is seen; a line never seen is dropped.
    """
    bad = ~_pinhole_visible(model, rot, side)
    if not bad.any():
        return side
    centre = model.K[:2, 2]
    low, high = np.zeros(int(bad.sum())), np.ones(int(bad.sum()))
    for _ in range(12):
        mid = 0.5 * (low + high)
        seen = _pinhole_visible(model, rot, centre + mid[:, None] * (side[bad] - centre))
        low = np.where(seen, mid, low)
        high = np.where(seen, high, mid)
    out = side.copy()
    out[bad] = centre + low[:, None] * (side[bad] - centre)
    keep = np.ones(len(side), bool)
    keep[np.flatnonzero(bad)[low == 0.0]] = False
    return out[keep]


def _rectified_outline(model: LensModel, rot: FloatArray) -> list[FloatArray]:
    """
    Return the raw outline's sides (top, bottom, left, right) in normalised rectified coords.

    Each side is ``(N, 2)`` (x/z, y/z) of the directions its pixel edges see, turned by
    ``rot``; where the traced field or the rectified pinhole's 85 deg end inside the raw image,
    the side follows that edge instead (:func:`_clipped_to_field`).
    """
    w, h = model.width, model.height
    xs = np.linspace(-0.5, w - 0.5, _OUTLINE_PER_SIDE)
    ys = np.linspace(-0.5, h - 0.5, _OUTLINE_PER_SIDE)
    sides = [np.stack([xs, np.full_like(xs, -0.5)], axis=1),
             np.stack([xs, np.full_like(xs, h - 0.5)], axis=1),
             np.stack([np.full_like(ys, -0.5), ys], axis=1),
             np.stack([np.full_like(ys, w - 0.5), ys], axis=1)]
    out = []
    for side in sides:
        d = directions_from_pupil(model, _clipped_to_field(model, rot, side)) @ rot.T
        with np.errstate(invalid='ignore'):
            keep = np.isfinite(d).all(axis=1) & (d[:, 2] > 0.5 * _MIN_Z)
        out.append(d[keep, :2] / d[keep, 2:3])
    return out


def _rig_blame(rig: Rig) -> str:
    """Return the rotation parameter to blame for fields that do not overlap (the largest)."""
    angles = {'rig.rotation_x_deg': rig.rotation_x_deg, 'rig.rotation_y_deg': rig.rotation_y_deg,
              'rig.rotation_z_deg': rig.rotation_z_deg}
    name = max(angles, key=lambda k: abs(angles[k]))
    return name if angles[name] != 0.0 else 'rig.rotation_y_deg'


def rectified_camera(outlines: list[list[FloatArray]], size: tuple[int, int], alpha: float,
                     rig: Rig) -> FloatArray:
    """
    Return ``K_rect`` framing both cameras' rectified outlines by ``output.alpha``.

    :param outlines: per camera, :func:`_rectified_outline`'s four sides.
    :param size: the rectified ``(width, height)``.
    :param alpha: 0 = the largest window inside both outlines, 1 = the smallest holding both.
    :param rig: the rig (whose rotation is blamed when the fields do not overlap).
    :return: 3x3 ``K_rect``.
    :raises ModelError: when an outline is empty or the two fields do not overlap.
    """
    inner = [-math.inf, math.inf, -math.inf, math.inf]     # x_lo, x_hi, y_lo, y_hi
    outer = [math.inf, -math.inf, math.inf, -math.inf]
    for camera, (top, bottom, left, right) in zip(('left', 'right'), outlines):
        if min(len(top), len(bottom), len(left), len(right)) == 0:
            raise ModelError('output.projection',
                             f'a side of the {camera} raw image sees no direction a pinhole '
                             'can show (within 85 deg of the rectified axis)')
        inner = [max(inner[0], float(np.max(left[:, 0]))), min(inner[1], float(np.min(
            right[:, 0]))), max(inner[2], float(np.max(top[:, 1]))),
            min(inner[3], float(np.min(bottom[:, 1])))]
        every = np.concatenate([top, bottom, left, right])
        outer = [min(outer[0], float(every[:, 0].min())), max(outer[1], float(every[:, 0].max())),
                 min(outer[2], float(every[:, 1].min())), max(outer[3], float(every[:, 1].max()))]
    if inner[0] >= inner[1] or inner[2] >= inner[3]:
        raise ModelError(_rig_blame(rig), "the two cameras' fields do not overlap once "
                                          'rectified: no pixel is seen by both')
    w, h = size
    f0 = max(w / (inner[1] - inner[0]), h / (inner[3] - inner[2]))
    f1 = min(w / (outer[1] - outer[0]), h / (outer[3] - outer[2]))
    f = f0 * (1.0 - alpha) + f1 * alpha
    centre_x = 0.5 * ((inner[0] + inner[1]) * (1.0 - alpha) + (outer[0] + outer[1]) * alpha)
    centre_y = 0.5 * ((inner[2] + inner[3]) * (1.0 - alpha) + (outer[2] + outer[3]) * alpha)
    return np.array([[f, 0.0, (w - 1) / 2.0 - f * centre_x],
                     [0.0, f, (h - 1) / 2.0 - f * centre_y], [0.0, 0.0, 1.0]])


def _checked_pair(values: Mapping[str, Any]) -> tuple[dict[str, Any], ...]:
    """Return ``(all, left, right, pair)`` values; a schema refusal becomes a ModelError."""
    try:
        full = check_stereo_values(values)
        return (full, *split_values(full))
    except ValueError as err:
        name = str(err).split(':', 1)[0].split('[', 1)[0].strip(" '")
        raise ModelError(name, str(err).split(':', 1)[-1].strip()) from None


def build_stereo(values: Mapping[str, Any], left_size: tuple[int, int] = (0, 0),
                 right_size: tuple[int, int] = (0, 0)) -> StereoModel:
    """
    Build the stereo model of one pair parameter set.

    :param values: pair parameter name -> value (:data:`~mechdeconv_ros.schema.stereo_params.
        STEREO_SCHEMA`); missing names take their defaults.
    :param left_size: the left images' ``(width, height)``, used where ``left.sensor.*_px``
        is 0.
    :param right_size: likewise for the right camera.
    :return: the model.
    :raises ModelError: naming the parameter at fault (``rig.baseline_mm`` 0, fields that do
        not overlap, every single-camera refusal with its ``left.``/``right.`` prefix).
    """
    full, left_values, right_values, pair = _checked_pair(values)
    if str(pair['output.projection']) != 'pinhole':
        raise ModelError('output.projection', 'a rectified pair is pinhole (rows are epipolar '
                                              'lines only of pinhole images)')
    left = _camera_model('left', left_values, left_size)
    right = _camera_model('right', right_values, right_size)
    rig = Rig.from_values(pair)
    r1, r2 = rectifying_rotations(rig)
    width = int(pair['output.width_px']) or left.width
    height = int(pair['output.height_px']) or left.height
    outlines = [_rectified_outline(left, r1), _rectified_outline(right, r2)]
    k_rect = rectified_camera(outlines, (width, height), float(pair['output.alpha']), rig)
    baseline_m = float(np.linalg.norm(rig.t_mm)) * 1e-3
    p1 = np.hstack([k_rect, np.zeros((3, 1))])
    p2 = p1.copy()
    p2[0, 3] = -k_rect[0, 0] * baseline_m
    return StereoModel(left=left, right=right, rig=rig, R1=r1, R2=r2, K_rect=k_rect, P1=p1,
                       P2=p2, width=width, height=height, baseline_m=baseline_m, values=full)


def rectified_points(stereo: StereoModel, side: str, pixels: FloatArray) -> FloatArray:
    """
    Return where raw pixels of one camera land in its rectified image (the maps' inverse).

    raw pixel -> :func:`directions_from_pupil` -> R1 or R2 -> K_rect; a matched feature's
    vertical disparity in the rectified pair is the difference of the two results' y.

    :param stereo: the stereo model.
    :param side: ``'left'`` or ``'right'``.
    :param pixels: ``(N, 2)`` raw pixels of that camera.
    :return: ``(N, 2)`` rectified pixels; NaN outside the traced field or behind the
        rectified image plane.
    """
    model, rot = {'left': (stereo.left, stereo.R1), 'right': (stereo.right, stereo.R2)}[side]
    q = directions_from_pupil(model, np.asarray(pixels, dtype=np.float64)) @ (
        stereo.K_rect @ rot).T
    with np.errstate(invalid='ignore', divide='ignore'):
        out = q[:, :2] / q[:, 2:3]
        out[~(q[:, 2] > 0.0)] = np.nan
    return out


def stereo_camera_infos(stereo: StereoModel) -> dict[str, dict[str, Any]]:
    """
    Return the four CameraInfo contents of a calibrated stereo camera, as plain lists.

    ``left``/``right`` (``camera_info``): the raw camera's size, K and D (the equivalent fit,
    as the single camera publishes), R = the rectifying rotation, P = P1/P2.
    ``left_rect``/``right_rect`` (``camera_info_rect``): the rectified size, K = P[:3, :3],
    D = 0 (plumb_bob), R = I and the same P.

    :param stereo: the stereo model.
    :return: ``{'left', 'right', 'left_rect', 'right_rect'}`` -> ``{'width', 'height',
        'distortion_model', 'D', 'K', 'R', 'P'}`` (K, R row-major 9 floats, P 12).
    """
    def flat(matrix: FloatArray) -> list[float]:
        return [float(x) for x in np.asarray(matrix, dtype=np.float64).ravel()]

    out: dict[str, dict[str, Any]] = {}
    for name, model, rot, proj in (('left', stereo.left, stereo.R1, stereo.P1),
                                   ('right', stereo.right, stereo.R2, stereo.P2)):
        out[name] = {'width': model.width, 'height': model.height,
                     'distortion_model': model.distortion_model,
                     'D': [float(x) for x in model.D], 'K': flat(model.K), 'R': flat(rot),
                     'P': flat(proj)}
        out[f'{name}_rect'] = {'width': stereo.width, 'height': stereo.height,
                               'distortion_model': 'plumb_bob', 'D': [0.0] * 5,
                               'K': flat(proj[:, :3]), 'R': flat(np.eye(3)), 'P': flat(proj)}
    return out
