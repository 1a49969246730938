# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Property-based tests over the whole parameter space of the core.

Every combination either builds a finite, monotonic radial map, finite maps and a finite
CameraInfo, or is refused with a ModelError that names a schema parameter. No NaN or inf may
reach a map, a matrix or a report.
"""

from __future__ import annotations

import json
import math

from hypothesis import given, HealthCheck, settings, strategies as st
from mechdeconv_ros.model import build_model, camera_info_yaml, ModelError
from mechdeconv_ros.params import SPECS
from mechdeconv_ros.remap import build_float_maps, Rectifier
import numpy as np
import yaml

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])


def _in_range(name: str, **kwargs) -> st.SearchStrategy:
    spec = SPECS[name]
    return st.floats(spec.minimum, spec.maximum, allow_nan=False, **kwargs)


def _radius() -> st.SearchStrategy:
    # Mostly lens-like radii, sometimes flat or extreme.
    return st.one_of(st.floats(-50.0, 50.0), st.just(0.0), _in_range('lens.r1_mm'))


thick_lens_values = st.fixed_dictionaries({
    'lens.refractive_index': st.one_of(st.floats(1.0, 2.0), _in_range('lens.refractive_index')),
    'lens.r1_mm': _radius(),
    'lens.r2_mm': _radius(),
    'lens.thickness_mm': st.one_of(st.floats(0.0, 10.0), _in_range('lens.thickness_mm')),
    'lens.aperture_diameter_mm': st.floats(0.01, 20.0),
    'lens.stop_offset_mm': st.one_of(st.floats(-5.0, 5.0), _in_range('lens.stop_offset_mm')),
    'lens.focal_length_mm': st.one_of(st.just(0.0), st.floats(0.5, 200.0)),
    'sensor.pixel_size_x_um': st.floats(0.5, 20.0),
    'sensor.pixel_size_y_um': st.floats(0.5, 20.0),
    'scene.distance_mm': st.one_of(st.just(0.0), st.floats(1.0, 1e5), _in_range(
        'scene.distance_mm')),
    'scene.focus_distance_mm': st.one_of(st.just(0.0), st.floats(1.0, 1e5)),
    'output.alpha': _in_range('output.alpha'),
    'sensor.width_px': st.integers(1, 96),
    'sensor.height_px': st.integers(1, 96),
})


def _check_built_or_refused(values: dict) -> None:
    try:
        model = build_model(values)
    except ModelError as err:
        assert err.parameter in SPECS, err.parameter
        assert str(err).startswith(err.parameter)
        assert len(err.reason) > 10
        return
    curve = model.curve
    assert np.all(np.isfinite(curve.ideal_mm)) and np.all(np.isfinite(curve.real_mm))
    assert np.all(np.diff(curve.real_mm) > 0), 'the radial map must be strictly increasing'
    for matrix in (model.K, model.K_new, model.P):
        assert np.all(np.isfinite(matrix))
    assert model.K_new[0, 0] > 0 and model.K_new[1, 1] > 0
    assert all(math.isfinite(d) for d in model.D)
    assert math.isfinite(model.fit_rms_px) and math.isfinite(model.max_displacement_px)
    map_x, map_y = build_float_maps(model)
    assert np.all(np.isfinite(map_x)) and np.all(np.isfinite(map_y))
    Rectifier(model).correct(np.zeros((model.height, model.width), np.uint8))
    # The report is strict JSON (no NaN/inf) and the CameraInfo YAML is finite.
    json.dumps(model.report(), allow_nan=False)
    info = yaml.safe_load(camera_info_yaml(model))
    for key in ('camera_matrix', 'distortion_coefficients', 'projection_matrix'):
        assert all(math.isfinite(x) for x in info[key]['data'])


@SETTINGS
@given(thick_lens_values)
def test_thick_lens_space(values):
    _check_built_or_refused(values)


@st.composite
def prescriptions(draw):
    count = draw(st.integers(1, 6))
    radii = draw(st.lists(_radius(), min_size=count, max_size=count))
    thickness = draw(st.lists(st.floats(0.0, 20.0), min_size=count, max_size=count))
    index = draw(st.lists(st.one_of(st.just(1.0), st.floats(1.0, 2.0)), min_size=count,
                          max_size=count))
    semi = draw(st.one_of(st.just([]), st.lists(st.floats(0.0, 30.0), min_size=count,
                                                max_size=count)))
    # Sometimes mismatched arrays or a wrong stop: those must be refused, not crash.
    if draw(st.booleans()) and draw(st.booleans()):
        thickness = thickness[:-1]
    return {
        'lens.surfaces.radius_mm': radii,
        'lens.surfaces.thickness_mm': thickness,
        'lens.surfaces.refractive_index': index,
        'lens.surfaces.semi_diameter_mm': semi,
        'lens.stop_surface': draw(st.integers(0, 7)),
        'scene.distance_mm': draw(st.one_of(st.just(0.0), st.floats(1.0, 1e5))),
        'sensor.pixel_size_x_um': draw(st.floats(0.5, 20.0)),
        'sensor.pixel_size_y_um': draw(st.floats(0.5, 20.0)),
        'sensor.width_px': draw(st.integers(1, 64)),
        'sensor.height_px': draw(st.integers(1, 64)),
    }


@SETTINGS
@given(prescriptions())
def test_prescription_space(values):
    _check_built_or_refused(values)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.sampled_from(sorted(SPECS)), st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**12, 10**12), st.text(
        max_size=5), st.booleans(), st.lists(st.floats(), max_size=3), st.none()))
def test_hostile_single_values(name, value):
    """Any value for any parameter is either accepted or refused with the parameter's name."""
    values = {'sensor.width_px': 32, 'sensor.height_px': 24, name: value}
    try:
        build_model(values)
    except ModelError as err:
        assert err.parameter in SPECS
        assert err.parameter == name or name in ('lazy_subscription', 'remap_threads') or \
            err.parameter != ''
