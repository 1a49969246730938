# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Tests of the traced relative illumination and the 3-D trace under it.

Closed forms (an unclipped Lambertian disk, the cos^4 law of a small stop), the 3-D trace
against the meridional tracer, and the forward flux count (rays uniform over scene and
entrance disk, binned on the sensor) as an independent reference on case2 and on a Cooke
triplet whose semi-diameters clip: the issue asks for 0.5 percentage points.
"""

from __future__ import annotations

import math
from pathlib import Path

from benchmarks import vignetting as vignetting_bench
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.optics import illumination as il
from mechdeconv_ros.optics import raytrace as rt
from mechdeconv_ros.optics import trace3d
from mechdeconv_ros.schema.params import load_params_file
import numpy as np
from numpy.testing import assert_allclose
import pytest

pytestmark = pytest.mark.filterwarnings('error')

CONFIG = Path(__file__).resolve().parent.parent / 'config'


def disk_projected_solid_angle(a: float, d: float, h: np.ndarray) -> np.ndarray:
    """Return the projected solid angle of a disk (radius a, distance d) seen from offset h."""
    return 0.5 * math.pi * (1.0 - (d * d + h * h - a * a)
                            / np.sqrt((d * d + h * h + a * a) ** 2 - 4.0 * a * a * h * h))


def stop_behind_lens() -> rt.Prescription:
    """Return a plano-convex lens whose flat rear face carries the stop (a disk seen)."""
    return rt.Prescription((rt.Surface(20.0, 2.0, 1.5), rt.Surface(0.0, 0.0, 1.0)), 2.0)


@pytest.mark.parametrize('radius', [3.0, 0.5, 0.05])
def test_unclipped_stop_is_a_lambertian_disk(radius):
    lens = stop_behind_lens()
    sensor_z, _ = rt.image_plane(lens, math.inf)
    d = sensor_z - 2.0
    heights = np.linspace(0.0, 0.6 * d, 13)
    area = il.beam_area(il.backward_system(lens, radius, 1, sensor_z), heights)
    exact = disk_projected_solid_angle(radius, d, heights)
    assert_allclose(area, exact, rtol=2e-4)
    assert_allclose(area[0], math.pi * radius ** 2 / (radius ** 2 + d * d), rtol=2e-4)


def test_small_stop_follows_cos4():
    lens = stop_behind_lens()
    sensor_z, _ = rt.image_plane(lens, math.inf)
    d = sensor_z - 2.0
    heights = np.linspace(0.0, 0.6 * d, 13)
    area = il.beam_area(il.backward_system(lens, 0.2, 1, sensor_z), heights)
    assert_allclose(area / area[0], np.cos(np.arctan(heights / d)) ** 4, atol=1e-4)


def test_3d_trace_matches_the_meridional_trace():
    values = load_params_file(CONFIG / 'cooke_triplet.yaml')
    lens = build_model(values).prescription
    rng = np.random.default_rng(3)
    y = rng.uniform(-4.0, 4.0, 200)
    slope = rng.uniform(-0.2, 0.2, 200)
    rays = rt.Rays(y, np.zeros(200), slope / np.hypot(1, slope), 1 / np.hypot(1, slope))
    flat = rt.trace_surfaces(lens, rays)
    clipped = trace3d.lens_system(lens, 0.0, None)
    ok, (x3, y3, z3, kx, ky, kz) = trace3d.trace_pass(clipped, 0.0, y, 0.0, 0.0, rays.dy,
                                                      rays.dz)
    passed = np.isfinite(flat.y)
    assert 50 < passed.sum() < 200
    np.testing.assert_array_equal(ok, passed)
    assert_allclose(y3[ok], flat.y[ok], atol=1e-9)
    assert_allclose(z3[ok], flat.z[ok], atol=1e-9)
    assert_allclose(ky[ok], flat.dy[ok], atol=1e-12)
    assert_allclose(x3[ok], 0.0, atol=0.0)
    # Without the semi-diameters more rays pass, and every clipped ray among them.
    free, _ = trace3d.trace_pass(clipped.without_semi_diameters(), 0.0, y, 0.0, 0.0, rays.dy,
                                 rays.dz)
    assert free.sum() > ok.sum()
    assert not np.any(ok & ~free)


@pytest.mark.parametrize('name,skew', [('cooke_triplet.yaml', 0.3), ('fisheye.yaml', 0.0)])
def test_trace_passes_is_the_margins_sign(name, skew):
    # trace_passes drops failed rays element by element (the beam scans); it must say
    # exactly what trace_margin >= 0 says. Rays as beam_area scans them (heights x
    # directions over the front element; skew ones too through the triplet: the fisheye's
    # small stop passes almost no random skew ray), most failing somewhere.
    lens = build_model(load_params_file(CONFIG / name)).prescription
    system = trace3d.lens_system(lens, 0.0, None)
    radius = system.elements[0].clear_radius_mm
    x = np.linspace(-0.5, 0.5, 3)[:, None, None] * radius
    y = np.linspace(-radius, radius, 120)[None, :, None]
    ky = np.linspace(-0.99, 0.99, 200)[None, None, :]
    kx = np.full(ky.shape, skew)
    kz = trace3d.direction_from_cosines(kx, ky)
    expected = trace3d.trace_margin(system, x, y, 0.0, kx, ky, kz) >= 0.0
    assert expected.shape == (3, 120, 200) and 300 < expected.sum() < expected.size / 2
    np.testing.assert_array_equal(trace3d.trace_passes(system, x, y, 0.0, kx, ky, kz), expected)


@pytest.mark.parametrize('aspheric', [False, True], ids=['spherical', 'aspheric'])
def test_reversed_trace_retraces_a_skew_ray(aspheric):
    values = load_params_file(CONFIG / 'cooke_triplet.yaml')
    if aspheric:
        values['lens.surfaces.conic'] = [-0.6, 0.0, 0.0, 0.0, 0.0, 1.5]
        values['lens.surfaces.asphere_a4'] = [2e-5, 0.0, 0.0, 0.0, 0.0, -3e-5]
        values['lens.surfaces.asphere_a6'] = [1e-7, 0.0, 0.0, 0.0, 0.0, 0.0]
    lens = build_model(values).prescription
    assert any(any(s.asphere) or s.conic for s in lens.surfaces) == aspheric
    system = trace3d.lens_system(lens, 0.0, None).without_semi_diameters()
    ok, (x, y, z, kx, ky, kz) = trace3d.trace_pass(system, 1.5, -2.0, 0.0, 0.05, 0.1,
                                                   math.sqrt(1 - 0.05 ** 2 - 0.1 ** 2))
    assert ok
    z0 = 60.0
    s = (z0 - z) / kz
    back = trace3d.reversed_system(system, z0)
    ok2, (x2, y2, z2, kx2, ky2, kz2) = trace3d.trace_pass(back, x + s * kx, y + s * ky, 0.0,
                                                          -kx, -ky, kz)
    assert ok2
    # Back on the plane z = 0 (z' = z0), where the ray started, travelling the other way.
    t = (z0 - z2) / kz2
    assert_allclose([x2 + t * kx2, y2 + t * ky2], [1.5, -2.0], atol=1e-9)
    assert_allclose([kx2, ky2], [-0.05, -0.1], atol=1e-12)


def _forward_reference(values, entrance_radius_mm, field_cosine, rays=1_500_000, bins=8):
    model = build_model(values)
    curve = il.relative_illumination(model, samples=64)
    radius, surface = il.stop_of(model.values)
    distance = float(values['scene.distance_mm']) or math.inf
    sensor_z, _ = rt.image_plane(model.prescription, distance)
    on_axis = il.beam_area(il.backward_system(model.prescription, radius, surface, sensor_z),
                           np.zeros(1))[0]
    edges, irradiance = il.forward_flux(
        model.prescription, radius, surface, distance, curve.corner_height_mm, bins=bins,
        rays=rays, entrance_radius_mm=entrance_radius_mm, field_cosine=field_cosine)
    traced = il.annulus_means(curve.height_mm, curve.ri, edges)
    return curve, traced, irradiance / on_axis


def test_forward_flux_agrees_on_case2():
    values = load_params_file(CONFIG / 'case2.yaml')
    curve, traced, counted = _forward_reference(values, 1.0, 0.42)
    assert_allclose(counted, traced, atol=0.005)
    assert 0.82 < curve.corner_ri < 0.86
    assert_allclose(curve.pupil_pass_fraction, 1.0)


def test_forward_flux_agrees_on_a_clipped_triplet():
    values = load_params_file(CONFIG / 'cooke_triplet.yaml')
    # A wider sensor (18.4 deg) and a tighter front element: the rim clips the corner beams.
    values['sensor.width_px'] = 3600
    values['sensor.height_px'] = 2400
    values['lens.surfaces.semi_diameter_mm'][0] = 8.0
    values['lens.surfaces.semi_diameter_mm'][5] = 6.8
    curve, traced, counted = _forward_reference(values, 9.0, 0.36)
    assert_allclose(counted, traced, atol=0.005)
    assert curve.pupil_pass_fraction[-1] < 0.9
    assert curve.corner_ri < 0.8


#: The retrofocus test lens whose front rim clips the corner beams (one definition, shared
#: with the vignetting benchmark).
WIDE = vignetting_bench.WIDE


def _stop_reference(values, stop_cosine, rays=1_500_000, bins=8):
    model = build_model(values)
    curve = il.relative_illumination(model)
    radius, surface = il.stop_of(model.values)
    distance = float(model.values['scene.distance_mm']) or math.inf
    sensor_z, _ = rt.image_plane(model.prescription, distance)
    on_axis = il.beam_area(il.backward_system(model.prescription, radius, surface, sensor_z),
                           np.zeros(1))[0]
    edges, irradiance = il.stop_flux(model.prescription, radius, surface, distance,
                                     curve.corner_height_mm, bins=bins, rays=rays,
                                     stop_cosine=stop_cosine)
    return curve, il.annulus_means(curve.height_mm, curve.ri, edges), irradiance / on_axis


def test_stop_flux_agrees_on_a_clipped_wide_angle_lens():
    curve, traced, counted = _stop_reference(WIDE, 0.75)
    assert_allclose(counted, traced, atol=0.005)
    assert curve.corner_ri < 0.65
    assert np.interp(curve.corner_height_mm, curve.height_mm, curve.pupil_pass_fraction) < 0.8


def test_stop_flux_agrees_with_the_forward_count_on_case2():
    values = load_params_file(CONFIG / 'case2.yaml')
    _, traced, counted = _stop_reference(values, 0.5)
    assert_allclose(counted, traced, atol=0.005)


@pytest.mark.parametrize('name', ['fisheye', 'wide_angle'])
def test_stop_flux_agrees_on_the_wide_angle_configs(name):
    values = load_params_file(CONFIG / f'{name}.yaml')
    # The physical stops pass f/1.8 and f/2 beams whose directions at the stop stay within
    # |k| < 0.22 and 0.51: the count samples 1.2 x what a pilot sees land (None), not 0.95,
    # which left about 8000 rays per annulus (1 % noise).
    curve, traced, counted = _stop_reference(values, None)
    assert_allclose(counted, traced, atol=0.005)
    # The traced curve is refined where a rim starts to clip (a bend), not only at cliffs.
    assert np.min(np.diff(curve.height_mm)) < 0.1 * np.max(np.diff(curve.height_mm))
