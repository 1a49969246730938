# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
How a model's maps are built for the frames, and what is logged about them (no ROS).

The live model (:class:`~mechdeconv_ros.runtime.live_model.LiveModel`) calls
:meth:`ModelMaps.build` for every model it installs (``build_maps``), in the rebuild thread or,
for a new frame size, in the executor thread. It decides:

- **static or moving**: a lens whose groups move (``moving_maps.is_moving``) gets the grid
  of lens states (:class:`~mechdeconv_ros.imaging.moving_maps.MovingRectifier`, seconds: one
  model per grid state), cached for the model in use so that a second request for it gets
  the grid it has; every other lens one :class:`~mechdeconv_ros.imaging.remap.Rectifier`;
- **colour** (``output.lateral_color_correction``): the per-channel maps are folded for the
  channel colours of the last frame, and the three traces are logged once per model
  (wavelengths, map time, trace time, largest R-B separation);
- **gain** (``output.vignetting_correction``): the gain map is replicated for the channel
  count of the last frame, so the first frame after the swap does not pay for it; a gain
  limit that ends the corrected field inside the image is warned once per model (a new frame
  size builds a model's maps again).

The frame path reports each corrected frame (:meth:`ModelMaps.frame_done`): its channel
count and colours are the hints of the next build, and an encoding that ignores the colour
correction (no known colour channels) or the gain (a depth image) is noted once.

Threads: the hints are written by the executor only (an int and a tuple, read by the rebuild
thread as hints); the "logged once" records only suppress a repeated log line, so a race
between the two callers of :meth:`ModelMaps.build` at worst logs it twice. The moving cache
is one reference, swapped whole.
"""

from __future__ import annotations

import time
from typing import Any, Callable

from mechdeconv_ros.imaging.moving_maps import is_moving, moving_rectifier, MovingRectifier
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model

#: ``log(level, message)``, level one of ``'info'``, ``'warning'``, ``'error'``.
LogFunction = Callable[[str, str], None]


def _no_log(level: str, message: str) -> None:
    pass


class ModelMaps:
    """The map building policy of the frames and its log lines (module doc)."""

    def __init__(self, log: LogFunction = _no_log,
                 build: Callable[..., Any] = build_model) -> None:
        """
        Start with the hints of a one-channel frame of unknown colours.

        :param log: receives log lines as ``(level, message)``.
        :param build: builds the models of a moving lens's grid states.
        """
        self._log = log
        self._build_model = build
        self.channels = 1           # of the last frame: the rebuild prepares its gain map
        self.colours: tuple[int, ...] | None = None     # of the last frame: colour maps
        self._lateral_logged: Any = None
        self._warned_model: Any = None
        self._moving_cache: MovingRectifier | None = None
        self._colourless_noted: set[str] = set()
        self._depth_gain_noted = False

    def build(self, model: Any) -> Rectifier | MovingRectifier:
        """
        Build the remap tables and, with ``output.vignetting_correction``, the gain map.

        :param model: the model to correct frames with.
        :return: its rectifier (a moving lens: the grid's).
        """
        if is_moving(model):
            return self._moving(model)
        rectifier = Rectifier(model)
        if rectifier.colour is not None:   # lateral colour (issue #20)
            rectifier.prepare_colours(self.colours)
            if model is not self._lateral_logged:
                self._lateral_logged = model
                traces = model.lateral_color()
                self._log('info',
                          f'output.lateral_color_correction: R, G, B traced at '
                          f"{', '.join(f'{ch.wavelength_nm:g}' for ch in traces.channels)} nm "
                          f'and mapped in {rectifier.lateral_color_ms:.1f} ms (traces '
                          f'{traces.trace_ms:.1f} ms); largest R-B separation on the raw '
                          f'image {traces.max_rb_separation_px:.3g} px')
        if rectifier.gain is not None:
            rectifier.gain_for(self.channels)
            # (A new frame size builds a model's maps again: warn once per model.)
            if rectifier.vignetting_warning and model is not self._warned_model:
                self._warned_model = model
                self._log('warning', rectifier.vignetting_warning)
        return rectifier

    def _moving(self, model: Any) -> MovingRectifier:
        """Build the grid of a moving lens (issue 19), or return the one of the model in use."""
        cached = self._moving_cache
        if cached is not None and cached.model is model:
            return cached
        start = time.perf_counter()
        rectifier = moving_rectifier(model, self._build_model)
        grid = rectifier.grid
        self._log('info',
                  f'moving lens: {len(grid.cameras)} lens states precomputed in '
                  f'{time.perf_counter() - start:.1f} s, {grid.memory_bytes / 1e6:.1f} MB '
                  f'(+ {grid.frame_map_bytes / 1e6:.1f} MB per-frame map)')
        if rectifier.vignetting_warning:
            self._log('warning', rectifier.vignetting_warning)
        self._moving_cache = rectifier
        return rectifier

    def frame_done(self, rectifier: Any, encoding: str, channels: int,
                   colours: tuple[int, ...] | None, depth: bool) -> None:
        """
        Keep a corrected frame's hints; note once what its encoding ignores.

        :param rectifier: the active model's rectifier the frame was corrected with.
        :param encoding: the frame's encoding name.
        :param channels: its channel count.
        :param colours: its channels' colours (None: not known).
        :param depth: whether it is a depth image (never gain-corrected).
        """
        self.channels = channels
        self.colours = colours
        if rectifier.colour is not None and colours is None and \
                encoding not in self._colourless_noted:
            self._colourless_noted.add(encoding)
            self._log('info',
                      f'output.lateral_color_correction: {encoding} has no known colour '
                      'channels; it is corrected with the one map of the model')
        if depth and rectifier.gain is not None and not self._depth_gain_noted:
            self._depth_gain_noted = True
            self._log('info',
                      f'output.vignetting_correction: {encoding} is a depth encoding; '
                      'depth images are remapped but never gain-corrected')
