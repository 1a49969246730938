# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Property-based tests over the whole parameter space of the core.

Every combination either builds a finite, monotonic radial map, finite maps and a finite
CameraInfo, or is refused with a ModelError that names a schema parameter. No NaN or inf may
reach a map, a matrix or a report. Every accepted combination also describes a camera that can
exist (docs/design.md section 7), checked here by :func:`physical_violations`, written
independently of the model's own validation with 2x2 paraxial matrices.

The strategies mix lens-like values (most examples, so the accepted space is exercised; the
last tests check that enough are accepted) with the whole range of every parameter.
"""

from __future__ import annotations

import json
import math

from hypothesis import given, HealthCheck, settings, strategies as st
from mechdeconv_ros.imaging.remap import build_float_maps, Rectifier
from mechdeconv_ros.model.camera_yaml import camera_info_yaml
from mechdeconv_ros.model.model import build_model, ModelError
from mechdeconv_ros.schema.params import SPECS
import numpy as np
import pytest
import yaml

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])


def _in_range(name: str, **kwargs) -> st.SearchStrategy:
    spec = SPECS[name]
    return st.floats(spec.minimum, spec.maximum, allow_nan=False, **kwargs)


def _radius() -> st.SearchStrategy:
    # Mostly lens-like radii, sometimes flat or extreme.
    signed = st.builds(lambda m, s: m * s, st.floats(2.0, 60.0), st.sampled_from([-1.0, 1.0]))
    return _mostly(signed, st.floats(-50.0, 50.0), st.just(0.0), _in_range('lens.r1_mm'))


def _mostly(likely: st.SearchStrategy, *rest: st.SearchStrategy) -> st.SearchStrategy:
    """Draw from ``likely`` about three times in four, else from the wider strategies."""
    wider = st.one_of(*rest)
    return st.integers(0, 3).flatmap(lambda k: likely if k < 3 else wider)


thick_lens_values = st.fixed_dictionaries({
    'lens.refractive_index': _mostly(st.floats(1.4, 2.0), st.floats(1.0, 2.0),
                                     _in_range('lens.refractive_index')),
    'lens.r1_mm': _radius(),
    'lens.r2_mm': _radius(),
    'lens.thickness_mm': _mostly(st.floats(0.5, 6.0), st.floats(0.0, 10.0),
                                 _in_range('lens.thickness_mm')),
    'lens.aperture_diameter_mm': _mostly(st.floats(0.01, 3.0), st.floats(0.01, 20.0),
                                         _in_range('lens.aperture_diameter_mm')),
    'lens.stop_offset_mm': _mostly(st.floats(-3.0, 3.0), st.floats(-5.0, 5.0),
                                   _in_range('lens.stop_offset_mm')),
    'lens.focal_length_mm': st.one_of(st.just(0.0), st.just(0.0), st.floats(0.5, 200.0)),
    'sensor.pixel_size_x_um': st.floats(0.5, 20.0),
    'sensor.pixel_size_y_um': st.floats(0.5, 20.0),
    'scene.distance_mm': _mostly(st.one_of(st.just(0.0), st.floats(200.0, 1e5)),
                                 st.floats(1.0, 1e5), _in_range('scene.distance_mm')),
    'scene.focus_distance_mm': _mostly(st.one_of(st.just(0.0), st.floats(200.0, 1e5)),
                                       st.floats(0.0, 1e5), _in_range(
                                           'scene.focus_distance_mm')),
    'scene.circle_of_confusion_mm': _mostly(st.just(0.0), st.floats(0.0, 0.05),
                                            _in_range('scene.circle_of_confusion_mm')),
    'output.alpha': _in_range('output.alpha'),
    'sensor.width_px': _mostly(st.integers(16, 96), st.integers(1, 96)),
    'sensor.height_px': _mostly(st.integers(16, 96), st.integers(1, 96)),
})


# ---------------------------------------------------------------------------------------------
# Independent physical checks of an accepted model
# ---------------------------------------------------------------------------------------------

TOL = 1e-6


def _abcd(lens, z_end: float, count: int | None = None) -> np.ndarray:
    """Return the (y, n u) matrix from the object-space plane z = 0 to the plane z_end."""
    z_vertices = np.concatenate(([0.0], np.cumsum([s.thickness_mm for s in
                                                   lens.surfaces[:-1]])))
    m = np.eye(2)
    z, n = 0.0, lens.object_index
    for i, surface in enumerate(lens.surfaces):
        if z_vertices[i] > z_end or (count is not None and i >= count):
            break
        m = np.array([[1.0, (z_vertices[i] - z) / n], [0.0, 1.0]]) @ m
        c = 0.0 if surface.radius_mm == 0 else 1.0 / surface.radius_mm
        m = np.array([[1.0, 0.0], [-(surface.refractive_index - n) * c, 1.0]]) @ m
        z, n = z_vertices[i], surface.refractive_index
    return np.array([[1.0, (z_end - z) / n], [0.0, 1.0]]) @ m


def _height(lens, h: float, u: float, z: float) -> float:
    """Return the height at plane z of the ray (h at z = 0, slope u in object space)."""
    if z <= 0.0:
        return h + u * z
    return float((_abcd(lens, z) @ np.array([h, lens.object_index * u]))[0])


def _sag(r: float, a: float) -> float:
    """Return the sag of a sphere at height a, continued flat beyond its hemisphere."""
    if r == 0.0:
        return 0.0
    return r - math.copysign(math.sqrt(r * r - min(a, abs(r)) ** 2), r)


def physical_violations(model) -> list[str]:
    """
    Return the physical rules an accepted model breaks (docs/design.md section 7); [] when none.

    Written from the rules, not from the model's code: first-order optics with 2x2 matrices
    on (y, n u), the marginal ray through the rim of the physical stop, sags
    ``r - sign(r) sqrt(r^2 - a^2)``.
    """
    vals = model.values
    lens = model.prescription
    surfaces = lens.surfaces
    z_vertices = np.concatenate(([0.0], np.cumsum([s.thickness_mm for s in surfaces[:-1]])))
    z_last = float(z_vertices[-1])
    system = _abcd(lens, z_last)
    power = -system[1, 0]
    f = 1.0 / power
    z_h = (1.0 - system[1, 1]) / power
    z_h2 = z_last + (system[0, 0] - 1.0) / power
    distance = float(vals['scene.distance_mm']) or math.inf
    v = 1.0 / (1.0 / f - 1.0 / distance)
    sensor_z = z_h2 + v
    z_scene = z_h - distance
    out = []
    if abs(f - model.focal_length_mm) > 1e-6 * f:
        out.append(f'focal length {f} vs the model {model.focal_length_mm}')
    focus = float(vals['scene.focus_distance_mm'])
    if focus and not focus > f:
        out.append(f'focus distance {focus} inside f = {f}')
    if not sensor_z > z_last:
        out.append(f'image plane {sensor_z} not behind the last vertex {z_last}')
    if not z_scene < lens.stop_z_mm < sensor_z:
        out.append(f'stop {lens.stop_z_mm} not between the scene {z_scene} and the sensor '
                   f'{sensor_z}')
    c = float(vals['scene.circle_of_confusion_mm']) or 0.001 * f
    diagonal = math.hypot(model.width * model.pixel_mm[0], model.height * model.pixel_mm[1])
    if c > diagonal * (1 + TOL):
        out.append(f'circle of confusion {c} larger than the sensor diagonal {diagonal}')
    # The marginal ray: from the axial scene point through the rim of the physical stop.
    rho = float(vals['lens.aperture_diameter_mm']) / 2.0
    if math.isinf(distance):
        h, u = rho / _height(lens, 1.0, 0.0, lens.stop_z_mm), 0.0
    else:
        u = rho / _height(lens, -z_scene, 1.0, lens.stop_z_mm)
        h = -u * z_scene
    heights = [abs(_height(lens, h, u, float(z))) for z in z_vertices]
    index_before = [lens.object_index] + [s.refractive_index for s in surfaces[:-1]]
    dummy = [s.refractive_index == index_before[i] for i, s in enumerate(surfaces)]
    for i, s in enumerate(surfaces):
        r, semi = s.radius_mm, s.semi_diameter_mm
        if r and semi > abs(r) * (1 + TOL):
            out.append(f'surface {i}: semi-diameter {semi} beyond the hemisphere |r| = {r}')
        if r and not dummy[i] and heights[i] > abs(r) * (1 + TOL):
            out.append(f'surface {i}: beam height {heights[i]} beyond |r| = {abs(r)}')
        if semi and heights[i] > semi * (1 + TOL):
            out.append(f'surface {i}: beam height {heights[i]} beyond the semi-diameter {semi}')
    # Glass elements: consecutive non-dummy surfaces with glass between them.
    real = [i for i in range(len(surfaces)) if not dummy[i]]
    groups, current = [], []
    for i in real:
        current.append(i)
        if surfaces[i].refractive_index == 1.0:
            groups.append(current)
            current = []
    for group in groups:
        if len(group) < 2:
            continue
        width = max([heights[i] for i in group] + [surfaces[i].semi_diameter_mm for i in group])
        for i, j in zip(group[:-1], group[1:]):
            edge = (z_vertices[j] + _sag(surfaces[j].radius_mm, width)
                    - z_vertices[i] - _sag(surfaces[i].radius_mm, width))
            if edge < -TOL * max(1.0, width):
                out.append(f'surfaces {i}-{j}: edge thickness {edge} < 0 at a = {width}')
    return out


ACCEPTED: dict[str, list[bool]] = {'thick': [], 'prescription': []}


def _check_built_or_refused(values: dict, kind: str = '') -> None:
    try:
        model = build_model(values)
    except ModelError as err:
        assert err.parameter in SPECS, err.parameter
        assert str(err).startswith(err.parameter)
        assert len(err.reason) > 10
        if kind:
            ACCEPTED[kind].append(False)
        return
    if kind:
        ACCEPTED[kind].append(True)
    assert physical_violations(model) == [], values
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
    _check_built_or_refused(values, 'thick')


@st.composite
def _lens_like_surfaces(draw):
    """Return 1-3 air-spaced elements (glass then air), each 1-2 surfaces of glass."""
    radii, thickness, index = [], [], []
    for _ in range(draw(st.integers(1, 3))):
        glass = draw(st.floats(1.4, 1.9))
        for k in range(draw(st.integers(1, 2))):     # a singlet or a cemented doublet
            # Mostly a converging front (r > 0), so that many systems focus.
            radii.append(draw(_mostly(st.floats(3.0, 60.0), _radius())) if k == 0 else
                         draw(_radius()))
            thickness.append(draw(st.floats(1.0, 8.0)))
            index.append(glass)
            glass = draw(st.floats(1.4, 1.9))
        radii.append(draw(_mostly(st.floats(-60.0, -3.0), _radius())))
        thickness.append(draw(st.floats(0.2, 10.0)))
        index.append(1.0)
    return radii, thickness, index


@st.composite
def _any_surfaces(draw):
    """Return 1-6 surfaces of any radius, thickness and index."""
    count = draw(st.integers(1, 6))
    radii = draw(st.lists(_radius(), min_size=count, max_size=count))
    thickness = draw(st.lists(st.floats(0.0, 20.0), min_size=count, max_size=count))
    index = draw(st.lists(st.one_of(st.just(1.0), st.floats(1.0, 2.0)), min_size=count,
                          max_size=count))
    return radii, thickness, index


@st.composite
def prescriptions(draw):
    radii, thickness, index = draw(_mostly(_lens_like_surfaces(), _any_surfaces()))
    count = len(radii)
    semi = draw(_mostly(st.just([]), st.lists(
        _mostly(st.floats(0.0, 3.0), st.floats(0.0, 30.0)), min_size=count, max_size=count)))
    stop = draw(_mostly(st.integers(0, count - 1), st.integers(0, 7)))
    # Sometimes mismatched arrays: those must be refused, not crash.
    if draw(st.booleans()) and draw(st.booleans()) and draw(st.booleans()):
        thickness = thickness[:-1]
    return {
        'lens.surfaces.radius_mm': radii,
        'lens.surfaces.thickness_mm': thickness,
        'lens.surfaces.refractive_index': index,
        'lens.surfaces.semi_diameter_mm': semi,
        'lens.stop_surface': stop,
        # Mostly a stop that the surfaces can pass (it is the physical stop, behind glass).
        'lens.aperture_diameter_mm': draw(_mostly(st.floats(0.01, 1.0),
                                                  st.floats(0.01, 30.0))),
        'scene.distance_mm': draw(_mostly(st.one_of(st.just(0.0), st.floats(200.0, 1e5)),
                                          st.floats(1.0, 1e5))),
        'scene.focus_distance_mm': draw(st.one_of(st.just(0.0), st.floats(0.0, 1e5))),
        'scene.circle_of_confusion_mm': draw(st.one_of(st.just(0.0), st.floats(0.0, 0.5))),
        'sensor.pixel_size_x_um': draw(st.floats(0.5, 20.0)),
        'sensor.pixel_size_y_um': draw(st.floats(0.5, 20.0)),
        'sensor.width_px': draw(_mostly(st.integers(16, 64), st.integers(1, 64))),
        'sensor.height_px': draw(_mostly(st.integers(16, 64), st.integers(1, 64))),
    }


@SETTINGS
@given(prescriptions())
def test_prescription_space(values):
    _check_built_or_refused(values, 'prescription')


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


@pytest.mark.parametrize('kind', ['thick', 'prescription'])
def test_the_strategies_reach_the_accepted_space(kind):
    """The space tests above must build many models, not only refuse (they run first)."""
    seen = ACCEPTED[kind]
    if not seen:
        pytest.skip('runs after test_thick_lens_space and test_prescription_space')
    # Most random prescriptions describe no camera (afocal, diverging, image inside the glass,
    # mismatched arrays on purpose); about 15 % build, and at least 12 % must.
    assert sum(seen) >= 0.12 * len(seen), f'{sum(seen)} of {len(seen)} accepted'


@pytest.mark.parametrize('values, words', [
    ({'scene.focus_distance_mm': 3.0}, 'focus distance'),
    ({'lens.aperture_diameter_mm': 7.0}, 'edge thickness'),
    ({'lens.aperture_diameter_mm': 9.0}, 'beyond |r|'),
    ({'scene.distance_mm': 10.0, 'lens.stop_offset_mm': 10.5,
      'lens.aperture_diameter_mm': 0.001}, 'not between the scene'),
    ({'scene.circle_of_confusion_mm': 4.0}, 'circle of confusion'),
], ids=['focus', 'edge', 'hemisphere', 'stop', 'circle'])
def test_the_independent_checks_catch_what_the_model_refuses(monkeypatch, values, words):
    """With the model's own checks switched off, physical_violations finds each bad case."""
    from mechdeconv_ros.lenses import refusals
    monkeypatch.setattr(refusals, 'check_focus_distance', lambda *args: None)
    monkeypatch.setattr(refusals, 'check_surfaces', lambda *args: [])
    monkeypatch.setattr(refusals, 'check_circle_of_confusion', lambda *args: None)
    model = build_model({'sensor.width_px': 640, 'sensor.height_px': 480, **values})
    assert any(words in v for v in physical_violations(model)), physical_violations(model)
