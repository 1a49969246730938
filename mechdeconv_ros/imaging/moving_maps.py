# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Remap tables of a moving lens: precomputed over the zoom/focus table, derived per frame.

A full model of a long prescription costs a few hundred ms (the 22-surface zoom of
config/zoom.yaml: 0.25 to 0.5 s at 1920x1080, ray aiming dominates), so a lens that moves
between frames cannot be rebuilt per frame. The remap of a lens state is smooth in the state
and in the pixel, so it is precomputed coarsely in both and interpolated:

1. **Grid over the states** (:func:`build_moving_maps`, in the rebuild thread): a full model
   is built at every table row and ``refine - 1`` states between consecutive rows of each
   mechanism (both mechanisms: their product). Each keeps only what a frame needs: K, K_new,
   D and the source positions of a coarse NODE grid of output pixels.
2. **Node grid over the pixels**: nodes every :data:`NODE_STEP` output pixels, placed where
   ``cv2.resize`` (INTER_LINEAR, integer factor ``s``) puts its samples, ``x_i = (i - 1) s +
   (s - 1) / 2``, one node beyond every edge, so that resizing the node map to ``(n s)`` pixels
   and cropping ``s`` pixels interpolates every output pixel between four nodes and never
   clamps. The map is ``c + (u - c') s(rho)`` with s smooth: bilinear interpolation from 16 px
   nodes is within 0.005 px of the exact map (1920x1080, measured on config/zoom.yaml).
3. **Per frame** (:meth:`MovingMaps.at`): the node maps, K, K_new and D of the grid states of
   the table interval holding the frame's state are blended with Lagrange weights in each
   joint position (quadratic through the rows and the mid-row with ``refine`` 2: the gaps are
   linear between rows but kinked at each row, so no interpolation reaches across one; tensor
   product for two mechanisms; D is blended when they all chose the same distortion model,
   else the heaviest one's is used), and the node map is resized to the full CV_32FC2 map
   that ``cv2.remap`` takes as is (no ``convertMaps``): one ``cv2.resize`` per frame, about a
   third of the remap itself. A frame at the same state as the previous one reuses its map.

Memory: per grid state ``(W/16 + 2) (H/16 + 2) x 2`` float32 (68 kB at 1920x1080) plus a few
matrices; the per-frame map is ``W H x 8`` bytes (16.6 MB at 1080p) in two buffers that
alternate (the previous frame's map stays valid while the next is written; nothing is
allocated per frame while the lens moves). The 17-row zoom with ``refine`` 2: 33 states, 2.3 MB.

Outside a model's valid field the exact tables paint black; here a node beyond it gets the
position its curve gives at the field's end (held), so the border of the valid field is
resolved to a node cell, not a pixel (with ``output.alpha`` 0, the default, the whole output
is inside the field). Vignetting correction is not applied on this path.
"""

from __future__ import annotations

from dataclasses import dataclass
import itertools
import math
import threading
from typing import Any, Callable, Mapping, Sequence

import cv2
from mechdeconv_ros.lenses.lens_table import LensState, Mechanism, values_at
from mechdeconv_ros.model.projection import raw_from_normalised
import numpy as np
import numpy.typing as npt

#: Output pixels between two nodes of the coarse map at 1920 px wide and up (bilinear error
#: ~ step^2: 0.005 px at 16 px on config/zoom.yaml at 1920x1080); narrower images get nodes
#: as many per image width (:func:`node_step`), at least every 2 px.
NODE_STEP = 16
#: Grid states per table interval (2: the rows and the mid-rows).
REFINE = 2

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class StateCamera:
    """The camera of a frame at one lens state: what its CameraInfos carry, and its map."""

    state: dict[str, float]
    K: FloatArray
    K_new: FloatArray
    D: tuple[float, ...]
    distortion_model: str
    nodes: npt.NDArray[np.float32]         # (ny, nx, 2) source positions of the nodes

    @property
    def P(self) -> FloatArray:  # noqa: N802 - the ROS CameraInfo field name
        """Return ``[K_new | 0]``."""
        return np.hstack([self.K_new, np.zeros((3, 1))])


def node_step(out_width: int) -> int:
    """Return the node spacing for an output width: 120 nodes across, 2 to 16 px apart."""
    return int(min(NODE_STEP, max(2, out_width // 120)))


def node_positions(size: int, step: int = NODE_STEP) -> tuple[FloatArray, int]:
    """
    Return the output coordinates of the nodes along one axis, and the resized length.

    :param size: the output width (or height), px.
    :param step: pixels between nodes.
    :return: ``(x_i, n step)``: cv2.resize of ``n`` nodes to ``n step`` pixels puts node i at
        ``(i - 1) step + (step - 1) / 2`` after cropping ``step`` pixels.
    """
    count = -(-size // step) + 2
    return (np.arange(count) - 1) * step + (step - 1) / 2.0, count * step


def node_map(model: Any, step: int = NODE_STEP) -> npt.NDArray[np.float32]:
    """
    Return the source pixel of every node of a model's output (held beyond its valid field).

    :param model: a LensModel.
    :param step: pixels between nodes.
    :return: ``(ny, nx, 2)`` float32.
    """
    xs, _ = node_positions(model.out_width, step)
    ys, _ = node_positions(model.out_height, step)
    u, v = np.meshgrid(xs, ys)
    xn = (u - model.K_new[0, 2]) / model.K_new[0, 0]
    yn = (v - model.K_new[1, 2]) / model.K_new[1, 1]
    # The maps' equation (an off-centre, tilted sensor too); beyond the field the node keeps
    # the edge's scale (hold).
    map_u, map_v = raw_from_normalised(model, xn, yn, hold=True)
    out = np.empty(u.shape + (2,), np.float32)
    out[..., 0] = map_u
    out[..., 1] = map_v
    return out


def _camera(model: Any, state: Mapping[str, float], step: int) -> StateCamera:
    return StateCamera(dict(state), np.array(model.K, dtype=np.float64),
                       np.array(model.K_new, dtype=np.float64), tuple(float(d) for d in model.D),
                       str(model.distortion_model), node_map(model, step))


def grid_axis(mech: Mechanism, refine: int = REFINE) -> FloatArray:
    """
    Return the joint positions a mechanism's grid holds: its rows and ``refine - 1`` between.

    :param mech: the mechanism.
    :param refine: states per table interval (>= 1).
    :return: increasing positions.
    """
    p = mech.positions
    t = np.arange(refine) / refine
    inner = (p[:-1, None] + (p[1:] - p[:-1])[:, None] * t[None, :]).reshape(-1)
    return np.append(inner, p[-1])


def lagrange_weights(axis: FloatArray, position: float, refine: int = 1
                     ) -> list[tuple[int, float]]:
    """
    Return the Lagrange weights of the grid positions of the table interval holding a position.

    The gaps are linear in the joint position between two table rows but have a kink at each
    row, so the interpolation never reaches across a row: it runs through the ``refine + 1``
    grid positions of the row interval (``refine`` 1: linear, 2: quadratic, error ~
    step^(refine + 1)). Weights sum to 1 and are exact at the grid positions.

    :param axis: increasing grid positions, ``refine`` per table interval.
    :param position: inside ``[axis[0], axis[-1]]``.
    :param refine: grid positions per table interval.
    :return: ``[(index, weight), ...]``.
    """
    n = axis.size
    j = int(np.clip(np.searchsorted(axis, position, side='right') - 1, 0, n - 2))
    if axis[j] == position:
        return [(j, 1.0)]
    first = (j // refine) * refine
    window = range(first, min(first + refine, n - 1) + 1)
    out = []
    for m in window:
        w = 1.0
        for k in window:
            if k != m:
                w *= (position - axis[k]) / (axis[m] - axis[k])
        out.append((m, w))
    return out


class MovingMaps:
    """The precomputed grid of a moving lens and the per-frame interpolation (module doc)."""

    def __init__(self, mechanisms: Sequence[Mechanism], axes: Sequence[FloatArray],
                 cameras: Mapping[tuple[int, ...], StateCamera], width: int, height: int,
                 out_width: int, out_height: int, step: int = NODE_STEP,
                 refine: int = REFINE) -> None:
        """
        Keep a built grid.

        :param mechanisms: the moving mechanisms, in grid axis order.
        :param axes: the joint positions of each axis.
        :param cameras: grid index tuple -> camera at that state.
        :param width: raw image width.
        :param height: raw image height.
        :param out_width: corrected image width.
        :param out_height: corrected image height.
        :param step: node spacing.
        :param refine: grid states per table interval (the interpolation's degree).
        """
        self.refine = int(refine)
        self.mechanisms = tuple(mechanisms)
        self.axes = tuple(np.asarray(a, dtype=np.float64) for a in axes)
        self.cameras = dict(cameras)
        self.width, self.height = int(width), int(height)
        self.out_width, self.out_height = int(out_width), int(out_height)
        self.step = int(step)
        _, self._resized_w = node_positions(self.out_width, self.step)
        _, self._resized_h = node_positions(self.out_height, self.step)
        self._lock = threading.Lock()
        self._last: tuple[tuple[float, ...], StateCamera, np.ndarray] | None = None
        # Two per-frame buffers, alternating: the map handed out last stays valid while the
        # next state's is written (allocated on first use: a still lens never needs two).
        self._buffers: list[np.ndarray | None] = [None, None]
        self._next_buffer = 0

    @property
    def memory_bytes(self) -> int:
        """Return the bytes the grid holds (node maps and matrices), without frame buffers."""
        per = next(iter(self.cameras.values())).nodes.nbytes + 3 * 9 * 8 + 16 * 8
        return per * len(self.cameras)

    @property
    def frame_map_bytes(self) -> int:
        """Return the bytes of one per-frame map (CV_32FC2 over the resized node grid)."""
        return self._resized_w * self._resized_h * 8

    def clamp(self, state: LensState) -> tuple[dict[str, float], tuple[str, ...]]:
        """
        Return the state clamped into the tables, and the mechanisms that were clamped.

        :param state: mechanism -> joint position (missing: the first row).
        :return: ``(state, clamped names)``.
        """
        out, clamped = {}, []
        for mech, axis in zip(self.mechanisms, self.axes):
            p = float(state.get(mech.name, axis[0]))
            q = min(max(p, float(axis[0])), float(axis[-1]))
            if q != p:
                clamped.append(mech.name)
            out[mech.name] = q
        return out, tuple(clamped)

    def camera_at(self, state: LensState) -> StateCamera:
        """
        Blend the grid's cameras at a state (no full map).

        :param state: mechanism -> joint position; clamped into the table.
        :return: the camera at that state.
        """
        state, _ = self.clamp(state)
        corners: list[tuple[tuple[int, ...], float]] = [((), 1.0)]
        for mech, axis in zip(self.mechanisms, self.axes):
            weights = lagrange_weights(axis, state[mech.name], self.refine)
            corners = [(idx + (j,), w * wj) for idx, w in corners for j, wj in weights]
        cams = [(self.cameras[idx], w) for idx, w in corners if w != 0.0]
        K = sum(w * c.K for c, w in cams)
        K_new = sum(w * c.K_new for c, w in cams)
        nodes = sum(np.float32(w) * c.nodes for c, w in cams).astype(np.float32, copy=False)
        models = {c.distortion_model for c, _ in cams}
        # r_d is linear in plumb_bob's coefficients: the blend of D is the blend of the
        # distortion curves, each within its fit's error of its state's trace.
        if len(models) == 1 and len({len(c.D) for c, _ in cams}) == 1:
            D = tuple(float(sum(w * c.D[i] for c, w in cams)) for i in range(len(cams[0][0].D)))
            model = cams[0][0].distortion_model
        else:
            nearest = max(cams, key=lambda cw: cw[1])[0]     # the largest weight
            D, model = nearest.D, nearest.distortion_model
        return StateCamera(state, K, K_new, D, model, nodes)

    def full_map(self, camera: StateCamera, out: np.ndarray | None = None) -> np.ndarray:
        """
        Resize a camera's node map to the CV_32FC2 source map of every output pixel.

        :param camera: from :meth:`camera_at`.
        :param out: a ``(resized_h, resized_w, 2)`` float32 buffer to write into, or None.
        :return: ``(out_height, out_width, 2)`` float32 (a view of the resized buffer).
        """
        big = cv2.resize(camera.nodes, (self._resized_w, self._resized_h), dst=out,
                         interpolation=cv2.INTER_LINEAR)
        s = self.step
        return big[s:s + self.out_height, s:s + self.out_width]

    def at(self, state: LensState) -> tuple[StateCamera, np.ndarray]:
        """
        Return the camera and the full map of a frame at a state (the last one reused).

        Thread-safe (one frame at a time holds the lock; the map returned is not written
        again while the same state keeps coming, nor by the next state's map: two buffers
        alternate).

        :param state: mechanism -> joint position.
        :return: ``(camera, map)``.
        """
        state, _ = self.clamp(state)
        key = tuple(state[m.name] for m in self.mechanisms)
        with self._lock:
            last = self._last
            if last is not None and last[0] == key:
                return last[1], last[2]
            camera = self.camera_at(state)
            k = self._next_buffer
            if self._buffers[k] is None:
                self._buffers[k] = np.empty((self._resized_h, self._resized_w, 2), np.float32)
            full = self.full_map(camera, out=self._buffers[k])
            self._next_buffer = 1 - k
            self._last = (key, camera, full)
            return camera, full


def build_moving_maps(values: Mapping[str, Any], mechanisms: Sequence[Mechanism],
                      build: Callable[[Mapping[str, Any]], Any], *, refine: int = REFINE,
                      step: int | None = None,
                      progress: Callable[[int, int], None] | None = None) -> MovingMaps:
    """
    Build the grid of a moving lens: a full model at every grid state.

    :param values: checked parameter values (with the tables).
    :param mechanisms: the moving mechanisms (:func:`mechdeconv_ros.lenses.lens_table.mechanisms`).
    :param build: values of a still lens -> LensModel (its image size fixed by the caller).
    :param refine: grid states per table interval.
    :param step: node spacing, output px (None: :func:`node_step` of the output width).
    :param progress: called with ``(done, total)`` after each state.
    :return: the grid.
    :raises ValueError: when a state's model cannot be built (the model's reason).
    """
    axes = [grid_axis(m, refine) for m in mechanisms]
    cameras: dict[tuple[int, ...], StateCamera] = {}
    total = int(math.prod(a.size for a in axes))
    model = None
    for done, idx in enumerate(itertools.product(*(range(a.size) for a in axes)), 1):
        state = {m.name: float(a[i]) for m, a, i in zip(mechanisms, axes, idx)}
        model = build(values_at(values, state, tuple(mechanisms)))
        if step is None:
            step = node_step(model.out_width)
        cameras[idx] = _camera(model, state, step)
        if progress is not None:
            progress(done, total)
    return MovingMaps(mechanisms, axes, cameras, model.width, model.height, model.out_width,
                      model.out_height, step, refine)


class MovingRectifier:
    """
    The per-frame correction of a moving lens: the grid, and the map of the frame's state.

    Stands where :class:`~mechdeconv_ros.imaging.remap.Rectifier` stands in the active model record
    (``model``, ``correct``, ``gain``, ``colour``, ``gain_for``, ``out_shape``,
    ``vignetting_warning``);
    the frame path calls :meth:`prepare` with the frame's lens state first. ``prepare`` and
    ``correct`` run in the executor thread only (the map they share is theirs).
    """

    def __init__(self, model: Any, grid: MovingMaps) -> None:
        """
        Keep a model (its sizes and interpolation) and the grid of its lens.

        :param model: the LensModel at the tables' first rows (the still model).
        :param grid: :func:`build_moving_maps` of its values.
        """
        self.model = model
        self.grid = grid
        self.gain = None
        # One map for every channel: lateral colour is not followed while groups move.
        self.colour = None
        self.vignetting_warning: str | None = None
        off = [name for name in ('output.vignetting_correction',
                                 'output.lateral_color_correction')
               if bool(model.values.get(name, False))]
        if off:
            self.vignetting_warning = (
                f"{' and '.join(off)}: not applied while lens groups move "
                '(lens.zoom.joint / lens.focus.joint set)')
        self.camera, self._map = grid.at({})

    def prepare(self, state: LensState) -> StateCamera:
        """
        Make the next :meth:`correct` use the map of a lens state.

        :param state: mechanism -> joint position (clamped into the tables).
        :return: the camera of that state (K, K_new, D for the CameraInfos).
        """
        self.camera, self._map = self.grid.at(state)
        return self.camera

    def gain_for(self, channels: int) -> None:
        """Return None: no vignetting gain on a moving lens."""
        return None

    @property
    def out_shape(self) -> tuple[int, int]:
        """Return ``(out_height, out_width)``."""
        return self.model.out_height, self.model.out_width

    def correct(self, src: np.ndarray, dst: np.ndarray | None = None, *,
                nearest: bool = False, gain: bool = True,
                colours: Sequence[int] | None = None) -> np.ndarray:
        """
        Correct one frame with the prepared state's map.

        :param src: the raw image (the model's size).
        :param dst: optional preallocated output.
        :param nearest: nearest-neighbour (depth images).
        :param gain: ignored (no vignetting gain here).
        :param colours: ignored (one map for every channel here).
        :return: the corrected image.
        :raises ValueError: when ``src`` does not have the model's size.
        """
        if src.shape[:2] != (self.model.height, self.model.width):
            raise ValueError(f'frame is {src.shape[1]}x{src.shape[0]} px but the model is '
                             f'{self.model.width}x{self.model.height} px')
        flag = cv2.INTER_NEAREST if nearest else self.model.interpolation
        return cv2.remap(src, self._map, None, flag, dst=dst, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0)


def is_moving(model: Any) -> bool:
    """Return True when a model's lens has moving groups (its source has tables)."""
    return bool(getattr(model.source, 'moving', ()))


def moving_rectifier(model: Any, build: Callable[[Mapping[str, Any], int, int], Any],
                     progress: Callable[[int, int], None] | None = None) -> MovingRectifier:
    """
    Build the grid of a moving lens's model and its rectifier (seconds: one model per state).

    :param model: a LensModel whose source is a
        :class:`~mechdeconv_ros.lenses.moving_source.MovingSource`.
    :param build: ``build_model(values, width, height)``.
    :param progress: called with ``(done, total)`` after each state.
    :return: the rectifier.
    """
    source = model.source
    first = dict(source.state)

    def build_state(values: Mapping[str, Any]) -> Any:
        thickness = values['lens.surfaces.thickness_mm']
        if list(thickness) == list(model.values['lens.surfaces.thickness_mm']) and first:
            return model        # the grid's first state is the model itself
        return build(values, model.width, model.height)

    grid = build_moving_maps(source.table_values, source.moving, build_state,
                             progress=progress)
    return MovingRectifier(model, grid)


def distortion_node_map(model: Any, ideal_K: FloatArray, step: int) -> npt.NDArray[np.float32]:
    """
    Return, at the nodes of a model's RAW image, the pixel of an ideal image it sees.

    The inverse of :func:`node_map` (what :func:`mechdeconv_ros.imaging.remap.distortion_maps`
    gives per pixel): raw node -> real radius -> ideal radius -> ``ideal_K`` pixel. For rendering
    what a moving lens sees (the demo camera); outside the valid field the nodes point far
    outside the ideal image.

    :param model: a LensModel.
    :param ideal_K: camera matrix of the ideal image.
    :param step: pixels between nodes.
    :return: ``(ny, nx, 2)`` float32.
    """
    xs, _ = node_positions(model.width, step)
    ys, _ = node_positions(model.height, step)
    u, v = np.meshgrid(xs, ys)
    rect = model.rect_from_raw(np.stack([u, v], axis=-1))
    xn = (rect[..., 0] - model.K_new[0, 2]) / model.K_new[0, 0]
    yn = (rect[..., 1] - model.K_new[1, 2]) / model.K_new[1, 1]
    out = np.empty(u.shape + (2,), np.float32)
    out[..., 0] = ideal_K[0, 2] + ideal_K[0, 0] * xn
    out[..., 1] = ideal_K[1, 2] + ideal_K[1, 1] * yn
    out[~np.isfinite(out)] = -1000.0
    return out


def render_grid(model: Any, build: Callable[[Mapping[str, Any], int, int], Any],
                ideal_K: FloatArray) -> MovingMaps:
    """
    Build the grid that renders what a moving lens sees of an ideal image, at any state.

    Same states and interpolation as :func:`moving_rectifier`, the node maps inverted
    (:func:`distortion_node_map`); ``at(state)[1]`` is the map over the raw image.

    :param model: a LensModel of a moving lens (at its first rows).
    :param build: ``build_model(values, width, height)``.
    :param ideal_K: camera matrix of the ideal image (e.g. a chart's).
    :return: the grid (its "output" is the raw image).
    """
    source = model.source
    step = node_step(model.width)
    axes = [grid_axis(m) for m in source.moving]
    cameras: dict[tuple[int, ...], StateCamera] = {}
    for idx in itertools.product(*(range(a.size) for a in axes)):
        state = {m.name: float(a[i]) for m, a, i in zip(source.moving, axes, idx)}
        at = build(values_at(source.table_values, state, source.moving), model.width,
                   model.height)
        cameras[idx] = StateCamera(state, at.K, at.K_new, tuple(at.D), at.distortion_model,
                                   distortion_node_map(at, ideal_K, step))
    return MovingMaps(source.moving, axes, cameras, model.width, model.height, model.width,
                      model.height, step)
