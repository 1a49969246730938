# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
How a model's maps are built and what is logged about them (imaging/model_maps.py), no ROS.

Real models on small images: a static lens gets one Rectifier, its gain map ready for the
last frame's channel count and its colour maps folded for the last frame's colours; the
lateral-colour traces and a vignetting limit inside the image are logged once per model; a
moving lens gets its grid once per model; an encoding that ignores the colour correction or
the gain is noted once.
"""

from __future__ import annotations

from pathlib import Path

from mechdeconv_ros.imaging.model_maps import ModelMaps
from mechdeconv_ros.imaging.moving_maps import MovingRectifier
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import load_params_file
import pytest

CONFIG = Path(__file__).resolve().parents[1] / 'config'
W, H = 64, 48


class Log:
    """A ``log(level, message)`` that keeps its lines."""

    def __init__(self) -> None:
        """Start empty."""
        self.lines: list[tuple[str, str]] = []

    def __call__(self, level: str, message: str) -> None:
        """Keep one line."""
        self.lines.append((level, message))

    def having(self, text: str) -> list[tuple[str, str]]:
        """Return the lines that contain ``text``."""
        return [line for line in self.lines if text in line[1]]


def _case2(**overrides) -> dict:
    values = dict(load_params_file(CONFIG / 'case2.yaml'))
    values.update({'sensor.width_px': 0, 'sensor.height_px': 0,
                   'sensor.pixel_size_x_um': 40.0, 'sensor.pixel_size_y_um': 40.0})
    values.update(overrides)
    return values


def test_a_static_lens_gets_one_rectifier_with_the_gain_of_the_last_frame():
    """The gain map is replicated for the channels the frame path last reported."""
    log = Log()
    maps = ModelMaps(log)
    model = build_model(_case2(**{'output.vignetting_correction': True}), W, H)
    first = maps.build(model)
    assert type(first) is Rectifier and first.gain is not None
    assert set(first._gains) == {1}
    maps.frame_done(first, 'rgb8', 3, (0, 1, 2), False)
    again = maps.build(model)
    assert set(again._gains) == {3}
    assert maps.channels == 3 and maps.colours == (0, 1, 2)


def test_a_vignetting_limit_inside_the_image_is_warned_once_per_model():
    """A gain limit that ends the field inside the image: one warning per model."""
    log = Log()
    maps = ModelMaps(log)
    values = _case2(**{'output.vignetting_correction': True,
                       'output.max_vignetting_gain': 1.0001})
    model = build_model(values, W, H)
    rectifier = maps.build(model)
    assert rectifier.vignetting_warning
    maps.build(model)
    assert log.having('output.max_vignetting_gain') == [('warning',
                                                         rectifier.vignetting_warning)]
    maps.build(build_model(values, W, H))       # another model (a new frame size, say)
    assert len(log.having('output.max_vignetting_gain')) == 2


def test_lateral_colour_is_folded_for_the_last_colours_and_logged_once_per_model():
    """The three traces are logged once per model; the maps use the frame's colour order."""
    log = Log()
    maps = ModelMaps(log)
    values = dict(load_params_file(CONFIG / 'cooke_triplet.yaml'))
    values.update({'sensor.width_px': 0, 'sensor.height_px': 0,
                   'output.lateral_color_correction': True})
    model = build_model(values, W, H)
    rectifier = maps.build(model)
    assert rectifier.colour is not None
    maps.build(model)
    traced = log.having('R, G, B traced at')
    assert len(traced) == 1 and traced[0][0] == 'info'
    assert 'largest R-B separation' in traced[0][1]


def test_an_encoding_that_ignores_colour_or_gain_is_noted_once():
    """No known colours with lateral colour on, a depth image with a gain map: once each."""
    log = Log()
    maps = ModelMaps(log)

    class Both:
        colour = object()
        gain = object()

    for _ in range(3):
        maps.frame_done(Both(), 'mono16', 1, None, False)
        maps.frame_done(Both(), '32FC1', 1, None, True)
    assert len(log.having('mono16 has no known colour channels')) == 1
    assert len(log.having('32FC1 is a depth encoding')) == 1
    assert all(level == 'info' for level, _ in log.lines)

    class Neither:
        colour = None
        gain = None

    quiet = Log()
    ModelMaps(quiet).frame_done(Neither(), '32FC1', 1, None, True)
    assert quiet.lines == []


@pytest.fixture(scope='module')
def zoom_model():
    values = dict(load_params_file(CONFIG / 'zoom.yaml'))
    values['lens.zoom.positions'] = values['lens.zoom.positions'][:2]
    values['lens.zoom.thickness_mm'] = values['lens.zoom.thickness_mm'][:6]
    values.update({'sensor.pixel_size_x_um': 100.0, 'sensor.pixel_size_y_um': 100.0,
                   'sensor.width_px': 0, 'sensor.height_px': 0})
    return build_model(values, 120, 68)


def test_a_moving_lens_gets_its_grid_once_per_model(zoom_model):
    """The grid is built once for the model in use (cached), logged once; a new model rebuilds."""
    log = Log()
    builds = []

    def build(values, width, height):
        builds.append((width, height))
        return build_model(values, width, height)

    maps = ModelMaps(log, build)
    first = maps.build(zoom_model)
    assert isinstance(first, MovingRectifier) and first.model is zoom_model
    count = len(builds)
    assert count > 0 and set(builds) == {(120, 68)}
    assert maps.build(zoom_model) is first
    assert len(builds) == count
    assert len(log.having('lens states precomputed')) == 1
