# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Wide-angle, fisheye and aspheric lenses against optiland 0.6.3 over the whole field.

The reference is ``test/data/optiland_wide_reference.json``, written by
``tools/make_optiland_reference.py --only wide`` (optiland is pinned in
requirements-reference.txt and is not installed by ``make test``). For every design it holds
the prescription (also as ``lens.surfaces.*`` parameter values), optiland's paraxial data and
the real chief-ray height on the paraxial focal plane at up to 97 field angles from the axis
to the largest angle optiland's robust ray aiming reaches (searched to 20 deg past the design
field; past 90 deg for the fisheye) or to the fold of the real height, every chief ray aimed
at the stop centre within 1e-9 mm.

Asserted:

- the two shipped configs (config/wide_angle.yaml, config/fisheye.yaml) are the reference's
  lenses, parameter for parameter, on sensors whose corners lie beyond the image circle;
- focal length and back focal plane agree to 1e-6 relative;
- the traced curve (real height at the same object-space field angle) agrees within 0.01 px
  at the design's pixel pitch over optiland's whole reach (clear apertures opened), and with
  the clear apertures the lens passes at least its whole design field;
- a field angle traces alike alone, in a sparse batch (any order) or in a dense one;
- for the aspheres, a scalar conic + asphere trace written here (a third witness) agrees
  with the reference within 0.01 px and with our tracer within 1e-6 px.

When optiland is installed, a few values are re-traced live, and our own chief rays past
the reach of optiland's aimer are launched in optiland, which lands them where we do.

"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path
from typing import Any

from mechdeconv_ros.model.model import make_prescription
from mechdeconv_ros.optics import raytrace
from mechdeconv_ros.optics.raytrace import image_plane, paraxial, Prescription
from mechdeconv_ros.schema import params
import numpy as np
from numpy.testing import assert_allclose
import pytest

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / 'test' / 'data' / 'optiland_wide_reference.json'
GENERATOR = ROOT / 'tools' / 'make_optiland_reference.py'
DATA = json.loads(REFERENCE.read_text())
LENSES = DATA['lenses']
KEYS = list(LENSES)
CONFIGS = {lens['config']: key for key, lens in LENSES.items() if lens['config']}

PARAXIAL_RTOL = 1e-6
CURVE_TOL_PX = 0.01

#: The package's chief-ray trace by field angle in rad (it passes 90 deg).
ANGLE_TRACER = raytrace.trace_field_angles


def is_aspheric(lens: dict[str, Any]) -> bool:
    """Return whether any surface of the design has a conic or an asphere term."""
    return any(s['conic'] != 0.0 or any(s['asphere'])
               for s in lens['prescription']['surfaces'])


def values_of(lens: dict[str, Any], clear_apertures: bool = True) -> dict[str, Any]:
    """Return full parameter values describing the lens (schema defaults elsewhere)."""
    values = params.defaults()
    for name, value in lens['params'].items():
        assert name in params.SPECS, f'{name} is not a parameter'
        values[name] = value
    if not clear_apertures:
        values['lens.surfaces.semi_diameter_mm'] = []
    return values


def prescription_of(lens: dict[str, Any], clear_apertures: bool = True) -> Prescription:
    """Build our prescription through the product's parameter path."""
    return make_prescription(values_of(lens, clear_apertures))


def pixel_mm(lens: dict[str, Any]) -> float:
    """Return the pitch at which the 0.01 px tolerance is measured, in mm."""
    return lens['sensor']['tolerance_pixel_um'] * 1e-3


def traced(p: Prescription, angles_deg: np.ndarray) -> np.ndarray:
    """
    Return our real chief-ray heights on the paraxial focal plane at object-space angles.

    The package's trace by field angle, which reaches past 90 deg.
    """
    sensor_z, _ = image_plane(p, math.inf)
    angles = np.asarray(angles_deg, dtype=float)
    return np.asarray(ANGLE_TRACER(p, math.inf, sensor_z, np.radians(angles)), dtype=float)


def test_provenance_and_coverage() -> None:
    """The reference says what made it; every design is traced past its design field."""
    prov = DATA['provenance']
    assert prov['versions']['optiland'] == '0.6.3'
    assert prov['command'].split()[1] == 'tools/make_optiland_reference.py'
    assert {'wide_angle_160', 'fisheye_170'} <= set(LENSES)
    assert any(is_aspheric(lens) for lens in LENSES.values())
    assert LENSES['wide_angle_160']['design_field_deg'] == 80.0
    assert LENSES['fisheye_170']['design_field_deg'] == 85.0
    for key, lens in LENSES.items():
        curve = lens['curve']
        angles = np.asarray(curve['field_angle_deg'])
        assert len(angles) >= 64, key
        assert np.all(np.diff(angles) > 0), key
        assert angles[0] == 0.0 and angles[-1] == lens['curve_end_deg'], key
        # the curve ends where optiland stops tracing or before the real height folds
        assert lens['curve_end_deg'] == lens['optiland_reach_deg'] or \
            lens['curve_end_deg'] < lens['fold_near_deg'] <= lens['optiland_reach_deg'], key
        assert lens['curve_end_deg'] >= lens['design_field_deg'], key
        assert curve['monotonic'] and np.all(np.diff(np.abs(curve['real_height_mm'])) > 0), key
        # no ray runs backwards between two surfaces (optiland would follow it, a lens cannot)
        assert curve['min_step_between_surfaces_mm'] >= -1e-9, key
        # optiland aimed every chief ray at the stop centre
        assert lens['aiming']['max_stop_residual_mm'] < 1e-9, key
        assert np.max(np.abs(curve['stop_height_mm'])) < 1e-9, key
        assert lens['prescription']['stop_surface'] == \
            lens['params']['lens.stop_surface'], key


@pytest.mark.parametrize('config', sorted(CONFIGS), ids=sorted(CONFIGS))
def test_config_is_the_reference_lens(config: str) -> None:
    """config/wide_angle.yaml and config/fisheye.yaml carry the reference's lens and sensor."""
    lens = LENSES[CONFIGS[config]]
    values = params.load_params_file(ROOT / config)
    expected = values_of(lens)
    for name in lens['params']:
        if name in params.SPECS:
            assert_allclose(values[name] if values[name] != [] else 0.0, expected[name],
                            rtol=1e-12, atol=0, err_msg=name)
    sensor = lens['sensor']
    assert values['sensor.width_px'] == sensor['width_px']
    assert values['sensor.height_px'] == sensor['height_px']
    assert values['sensor.pixel_size_x_um'] == sensor['pixel_x_um']
    assert values['sensor.pixel_size_y_um'] == sensor['pixel_y_um']
    assert values['scene.distance_mm'] == 0.0, 'the scene is at infinity'
    # the sensor's corners lie beyond the image circle (black corners in the raw image)
    assert sensor['corner_radius_mm'] > lens['image_circle_radius_mm']
    assert lens['sensor_corner_beyond_image_circle']
    if 'output.projection' in params.SPECS and CONFIGS[config] == 'fisheye_170':
        assert values['output.projection'] == 'equidistant'


@pytest.mark.parametrize('key', KEYS, ids=KEYS)
def test_paraxial_data(key: str) -> None:
    """Focal length, image distance and back focal plane agree with optiland (1e-6)."""
    lens = LENSES[key]
    ref = lens['paraxial']
    p = prescription_of(lens)
    par = paraxial(p)
    sensor_z, v = image_plane(p, math.inf)
    assert_allclose(par.efl_mm, ref['efl_mm'], rtol=PARAXIAL_RTOL)
    assert_allclose(v, ref['image_distance_mm'], rtol=PARAXIAL_RTOL)
    assert_allclose(sensor_z, ref['sensor_z_mm'], rtol=PARAXIAL_RTOL)
    assert_allclose(p.stop_z_mm, lens['prescription']['stop_z_mm'], rtol=0, atol=1e-12)


@pytest.mark.parametrize('key', KEYS, ids=KEYS)
def test_whole_field_curve(key: str, record_property: Any) -> None:
    """Real chief-ray heights agree within 0.01 px from the axis to optiland's reach."""
    lens = LENSES[key]
    angles = np.asarray(lens['curve']['field_angle_deg'])
    ref = np.asarray(lens['curve']['real_height_mm'])
    ours = traced(prescription_of(lens, clear_apertures=False), angles)
    assert not np.any(np.isnan(ours)), \
        f'our tracer lost rays optiland traced (from {angles[np.isnan(ours)][0]:.2f} deg)'
    diff = (ours - ref) / pixel_mm(lens)
    worst = float(np.max(np.abs(diff)))
    record_property('max_abs_difference_px', worst)
    print(f'\n{key}: max |ours - optiland| = {worst:.2e} px over {angles.size} fields up to '
          f'{angles[-1]:.2f} deg (optiland reaches {lens["optiland_reach_deg"]:.2f} deg)')
    assert_allclose(diff, 0.0, rtol=0, atol=CURVE_TOL_PX)
    # the comparison measures something: the curve is far from the ideal pinhole
    f = lens['paraxial']['efl_mm']
    pinhole = f * np.tan(np.radians(angles[angles < 89.0]))
    distortion = (np.abs(ref[angles < 89.0]) - pinhole) / pixel_mm(lens)
    assert np.max(np.abs(distortion)) > 100 * CURVE_TOL_PX


def test_fisheye_field_ends_where_its_surfaces_cross() -> None:
    """
    Both tracers follow the fisheye past 90 deg and end its field at the same angle.

    Without clear apertures the field ends where the chief ray would have to run backwards
    from the first element's rear surface to the second element's front one (the two
    surfaces cross at that height): optiland's end (refined to 0.02 deg) and ours agree.
    """
    lens = LENSES['fisheye_170']
    assert lens['optiland_reach_deg'] > 90.0
    assert 'the surfaces cross' in lens['reach_end']
    p = prescription_of(lens, clear_apertures=False)
    angles = np.arange(0.0, lens['optiland_reach_deg'] + 1.0, 0.005)
    ours = traced(p, angles)
    end = float(angles[np.isfinite(ours)][-1])
    assert np.all(np.isfinite(ours[angles <= lens['optiland_reach_deg']]))
    assert abs(end - lens['optiland_reach_deg']) < 0.03


@pytest.mark.parametrize('key', KEYS, ids=KEYS)
def test_clear_apertures_pass_the_design_field(key: str) -> None:
    """With its clear semi-diameters the lens passes its whole design field, then clips."""
    lens = LENSES[key]
    angles = np.asarray(lens['curve']['field_angle_deg'])
    inside = angles <= lens['design_field_deg']
    ours = traced(prescription_of(lens), angles[inside])
    assert np.all(np.isfinite(ours)), 'a clear aperture clips a chief ray of the design field'
    assert_allclose((ours - np.asarray(lens['curve']['real_height_mm'])[inside])
                    / pixel_mm(lens), 0.0, rtol=0, atol=CURVE_TOL_PX)


# --- a third witness for the aspheres: a scalar trace written here ------------------------

def _sag(surface: dict[str, Any], r: float) -> tuple[float, float]:
    """Return the sag z(r) of a conic + even asphere and its slope dz/dr."""
    c = 0.0 if surface['radius_mm'] == 0.0 else 1.0 / surface['radius_mm']
    root = math.sqrt(1.0 - (1.0 + surface['conic']) * c * c * r * r)
    z, slope = c * r * r / (1.0 + root), c * r / root
    for a, power in zip(surface['asphere'], range(4, 17, 2)):
        z += a * r ** power
        slope += power * a * r ** (power - 1)
    return z, slope


def _hand_trace(lens: dict[str, Any], theta: float) -> float:
    """
    Trace the chief ray at field angle theta (rad) through a stop in object space.

    The stop is the first (flat) surface, so the chief ray starts at its centre with the
    direction (-sin theta, cos theta); each intersection is Newton's method on
    z0 + t dz - z_vertex = sag(y0 + t dy) to 1e-15 mm, refraction is the vector Snell law.
    """
    surfaces = lens['prescription']['surfaces']
    assert lens['prescription']['stop_surface'] == 0 and surfaces[0]['radius_mm'] == 0.0
    y, z = 0.0, 0.0
    dy, dz = -math.sin(theta), math.cos(theta)
    n, vertex = 1.0, 0.0
    for i, s in enumerate(surfaces):
        vertex += surfaces[i - 1]['thickness_mm'] if i else 0.0
        t = (vertex - z) / dz
        for _ in range(100):
            sag, slope = _sag(s, y + t * dy)
            step = (z + t * dz - vertex - sag) / (dz - slope * dy)
            t -= step
            if abs(step) < 1e-15:
                break
        y, z = y + t * dy, z + t * dz
        slope = _sag(s, y)[1]
        norm = math.hypot(slope, 1.0)
        ny, nz = -slope / norm, 1.0 / norm
        mu = n / s['refractive_index']
        cos_i = dy * ny + dz * nz
        cos_t = math.sqrt(1.0 - mu * mu * (1.0 - cos_i * cos_i))
        dy, dz = mu * dy + (cos_t - mu * cos_i) * ny, mu * dz + (cos_t - mu * cos_i) * nz
        n = s['refractive_index']
    return y + (lens['paraxial']['sensor_z_mm'] - z) / dz * dy


ASPHERIC = [key for key, lens in LENSES.items() if is_aspheric(lens)]


@pytest.mark.parametrize('key', ASPHERIC, ids=ASPHERIC)
def test_aspheres_against_hand_trace(key: str, record_property: Any) -> None:
    """
    A scalar conic + asphere trace written here confirms the reference and our tracer.

    optiland's even-asphere intersection (Newton-Raphson, tolerance 1e-10) differs from the
    scalar trace by ~2e-4 px at 5 um pixels; ours agrees with the scalar one to 1e-6 px.
    """
    lens = LENSES[key]
    angles = np.asarray(lens['curve']['field_angle_deg'])
    hand = np.array([_hand_trace(lens, math.radians(a)) for a in angles])
    ref = np.asarray(lens['curve']['real_height_mm'])
    worst = float(np.max(np.abs(hand - ref)) / pixel_mm(lens))
    record_property('optiland_vs_hand_max_px', worst)
    assert worst < CURVE_TOL_PX
    ours = traced(prescription_of(lens, clear_apertures=False), angles)
    assert_allclose((ours - hand) / pixel_mm(lens), 0.0, rtol=0, atol=1e-6)


# --- live re-check with optiland, when it is installed -----------------------------------

@pytest.fixture(scope='module')
def generator() -> Any:
    """Load tools/make_optiland_reference.py (skip when optiland is not installed)."""
    pytest.importorskip('optiland')
    spec = importlib.util.spec_from_file_location('make_optiland_reference', GENERATOR)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize('key', ['fisheye_170', 'aspheric_singlet'],
                         ids=['fisheye_170', 'aspheric_singlet'])
def test_live_optiland_recheck(generator: Any, key: str) -> None:
    """Optiland re-traces a few reference values live from the recorded prescription."""
    lens = LENSES[key]
    rows = [dict(s, is_stop=(i == lens['prescription']['stop_surface']))
            for i, s in enumerate(lens['prescription']['surfaces'])]
    rows[-1]['thickness_mm'] = lens['paraxial']['sensor_z_mm'] - sum(
        s['thickness_mm'] for s in rows[:-1])
    aperture = (lens['aperture']['type'], lens['aperture']['value'])
    optic = generator.build_wide_optic(rows, lens['wavelength_um'], aperture,
                                       lens['reach_searched_to_deg'])
    curve = lens['curve']
    picks = np.array([8, 64, len(curve['field_angle_deg']) - 1])
    angles = np.asarray(curve['field_angle_deg'])[picks]
    live = generator.trace_chief(optic, np.zeros(3), -angles / lens['reach_searched_to_deg'],
                                 'robust', lens['wavelength_um'])
    assert np.max(np.abs(live['y_stop'])) < 1e-9
    assert_allclose(live['y_img'], np.asarray(curve['real_height_mm'])[picks], rtol=0,
                    atol=1e-9)


@pytest.mark.parametrize('key', ['wide_angle_160'], ids=['wide_angle_160'])
def test_live_optiland_confirms_our_rays_past_its_reach(generator: Any, key: str) -> None:
    """
    Past the reach of optiland's aimer, optiland traces our aimed chief rays to our heights.

    optiland's robust aimer gives up on the wide-angle lens at 95.6 deg; our field goes on.

    Our object-space chief rays (the ends of our field, clear apertures opened) are launched in
    optiland as they are, 200 mm back along themselves: they cross optiland's stop at its centre
    and land where our tracer puts them.
    """
    from optiland.rays import RealRays

    lens = LENSES[key]
    rows = [dict(s, is_stop=(i == lens['prescription']['stop_surface']))
            for i, s in enumerate(lens['prescription']['surfaces'])]
    rows[-1]['thickness_mm'] = lens['paraxial']['sensor_z_mm'] - sum(
        s['thickness_mm'] for s in rows[:-1])
    optic = generator.build_wide_optic(rows, lens['wavelength_um'],
                                       (lens['aperture']['type'], lens['aperture']['value']),
                                       lens['reach_searched_to_deg'])
    p = prescription_of(lens, clear_apertures=False)
    sensor_z, _ = image_plane(p, math.inf)
    theta = np.radians(np.linspace(0.0, lens['optiland_reach_deg'] + 2.0, 400))
    ours = ANGLE_TRACER(p, math.inf, sensor_z, theta)
    rays = raytrace.aim_chief_rays(p, math.inf, field_angle_rad=theta)
    pick = np.flatnonzero(np.isfinite(ours))[-8:]
    assert np.degrees(theta[pick[-1]]) > lens['optiland_reach_deg']
    y, z, dy, dz = (np.asarray(a, dtype=float)[pick] for a in rays)
    back = 200.0
    n = pick.size
    z += float(optic.surfaces[1].geometry.cs.z)     # optiland's z of our first vertex
    launched = RealRays(np.zeros(n), y - back * dy, z - back * dz, np.zeros(n), dy, dz,
                        np.ones(n), np.full(n, lens['wavelength_um']))
    optic.surfaces.trace(launched)
    stop = optic.surfaces[optic.surfaces.stop_index]
    assert np.max(np.abs(np.asarray(stop.y, dtype=float))) < 1e-9
    assert_allclose(np.asarray(launched.y, dtype=float), ours[pick], rtol=0,
                    atol=1e-3 * CURVE_TOL_PX * pixel_mm(lens))


@pytest.mark.parametrize('key', ['wide_angle_160', 'fisheye_170'],
                         ids=['wide_angle_160', 'fisheye_170'])
def test_isolated_wide_fields_trace_as_in_a_dense_batch(key: str) -> None:
    """A wide field traced alone lands where optiland puts it (no dependence on sampling)."""
    lens = LENSES[key]
    p = prescription_of(lens, clear_apertures=False)
    sensor_z, _ = image_plane(p, math.inf)
    angles = np.asarray(lens['curve']['field_angle_deg'])
    picks = [int(np.searchsorted(angles, a)) for a in (50.0, lens['design_field_deg'])]
    picks.append(angles.size - 2)                   # the end of the field, but one sample
    alone = [float(ANGLE_TRACER(p, math.inf, sensor_z, np.radians(angles[[i]]))[0])
             for i in picks]
    assert_allclose(alone, np.asarray(lens['curve']['real_height_mm'])[picks], rtol=0,
                    atol=CURVE_TOL_PX * pixel_mm(lens))


@pytest.mark.parametrize('key', ['wide_angle_160', 'fisheye_170'])
def test_sparse_batch_traces_as_a_dense_one(key: str) -> None:
    """Three fields from the axis to the design field, traced together, land as optiland's."""
    lens = LENSES[key]
    p = prescription_of(lens, clear_apertures=False)
    sensor_z, _ = image_plane(p, math.inf)
    angles = np.asarray(lens['curve']['field_angle_deg'])
    picks = [0, int(np.searchsorted(angles, 40.0)),
             int(np.searchsorted(angles, lens['design_field_deg']))]
    batch = ANGLE_TRACER(p, math.inf, sensor_z, np.radians(angles[picks]))
    assert_allclose(batch, np.asarray(lens['curve']['real_height_mm'])[picks], rtol=0,
                    atol=CURVE_TOL_PX * pixel_mm(lens))


@pytest.mark.parametrize('distance', [math.inf, 500.0], ids=['infinity', '500mm'])
@pytest.mark.parametrize('key', ['wide_angle_160', 'fisheye_170'])
def test_an_angle_traces_alike_in_any_batch(key: str, distance: float) -> None:
    """Random sparse batches (any order) of a dense grid trace as the dense grid does."""
    rng = np.random.default_rng(7)
    p = prescription_of(LENSES[key], clear_apertures=False)
    sensor_z, _ = image_plane(p, distance)
    grid = np.radians(np.linspace(0.0, 102.0 if math.isinf(distance) else 89.0, 512))
    dense = ANGLE_TRACER(p, distance, sensor_z, grid)
    assert np.isfinite(dense[:400]).all()
    for _ in range(12):
        picks = rng.permutation(rng.choice(grid.size, rng.integers(1, 5), replace=False))
        batch = ANGLE_TRACER(p, distance, sensor_z, grid[picks])
        assert_allclose(batch, dense[picks], rtol=0, atol=1e-9,
                        err_msg=f'{key} at {np.degrees(grid[picks])} deg')
