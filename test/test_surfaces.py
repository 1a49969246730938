# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Tests of the conic and even-asphere surface geometry and its use in the trace and the model.

Closed forms (sphere and paraboloid sags), the intersection round trip (the point lies on the
sag to 1e-12 mm), normals against a finite-difference gradient, 3-D refraction against the
2-D one, a sphere written as an asphere with zero coefficients tracing identically, and the
refusals of bad conic and asphere parameters naming the parameter.
"""

from __future__ import annotations

import math
from pathlib import Path

from mechdeconv_ros.model.model import build_model, make_prescription, ModelError
from mechdeconv_ros.optics import raytrace as rt
from mechdeconv_ros.optics import surfaces as sf
from mechdeconv_ros.schema.params import defaults, load_params_file
import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

pytestmark = pytest.mark.filterwarnings('error')

REPO = Path(__file__).resolve().parents[1]


def surface(radius: float, conic: float = 0.0, asphere: tuple[float, ...] = (),
            semi: float = 0.0) -> rt.Surface:
    return rt.Surface(radius, 2.0, 1.5, semi, conic, asphere)


# --- sag ------------------------------------------------------------------------------------

def test_sphere_sag_is_the_circle() -> None:
    r = np.linspace(0.0, 9.9, 50)
    assert_allclose(sf.sag(surface(10.0), r * r), 10.0 - np.sqrt(100.0 - r * r), atol=1e-13)
    assert_allclose(sf.sag(surface(-10.0), r * r), -(10.0 - np.sqrt(100.0 - r * r)),
                    atol=1e-13)


def test_parabola_sag_is_c_r2_over_2() -> None:
    r = np.linspace(0.0, 50.0, 50)
    assert_allclose(sf.sag(surface(8.0, -1.0), r * r), r * r / 16.0, rtol=1e-14)


def test_asphere_terms_add_to_the_conic() -> None:
    r = np.linspace(0.0, 3.0, 20)
    terms = (1e-3, -2e-5, 3e-7, 0.0, 0.0, 0.0, 1e-12)
    expected = sf.sag(surface(20.0, -0.5), r * r) + sum(
        a * r ** (2 * j + 4) for j, a in enumerate(terms))
    assert_allclose(sf.sag(surface(20.0, -0.5, terms), r * r), expected, rtol=1e-13)


def test_sag_is_nan_outside_its_domain() -> None:
    # Oblate ellipsoid k = 3: defined up to r = R / sqrt(1 + k) = 5 mm.
    assert sf.domain_limit_mm(surface(10.0, 3.0)) == pytest.approx(5.0)
    z = sf.sag(surface(10.0, 3.0), np.array([4.99 ** 2, 5.01 ** 2]))
    assert math.isfinite(z[0]) and math.isnan(z[1])
    assert sf.domain_limit_mm(surface(10.0, -2.0)) == math.inf


def test_sag_slope_matches_a_finite_difference() -> None:
    s = surface(-15.0, -2.3, (2e-4, -1e-6, 4e-9))
    u = np.linspace(0.1, 30.0, 40)
    h = 1e-6
    numeric = (sf.sag(s, u + h) - sf.sag(s, u - h)) / (2 * h)
    assert_allclose(sf.sag_slope(s, u), numeric, rtol=1e-7, atol=1e-10)


# --- intersection ---------------------------------------------------------------------------

SHAPES = [pytest.param(surface(12.0), id='sphere'),
          pytest.param(surface(-9.0, -1.0), id='paraboloid'),
          pytest.param(surface(12.0, 0.6), id='oblate'),
          pytest.param(surface(15.0, -3.0, (1e-4, -2e-6, 1e-8)), id='hyperbolic-asphere'),
          pytest.param(surface(0.0, 0.0, (5e-4, 1e-6)), id='flat-asphere'),
          pytest.param(surface(-20.0, 0.0, (-3e-4,)), id='spherical-asphere')]


def random_rays(rng: np.random.Generator, count: int):
    x = rng.uniform(-3.0, 3.0, count)
    y = rng.uniform(-3.0, 3.0, count)
    z = rng.uniform(-5.0, -1.0, count)
    k = np.stack([rng.uniform(-0.4, 0.4, count), rng.uniform(-0.4, 0.4, count),
                  np.ones(count)])
    k /= np.linalg.norm(k, axis=0)
    return x, y, z, k[0], k[1], k[2]


@pytest.mark.parametrize('shape', SHAPES)
def test_intersection_lies_on_the_sag(shape: rt.Surface) -> None:
    rng = np.random.default_rng(11)
    x, y, z, kx, ky, kz = random_rays(rng, 500)
    s, nx, ny, nz, bad = sf.intersect(shape, x, y, z, kx, ky, kz)
    assert not bad.any()
    px, py, pz = x + s * kx, y + s * ky, z + s * kz
    assert_allclose(pz, sf.sag(shape, px * px + py * py), atol=1e-12)
    assert_allclose(nx * nx + ny * ny + nz * nz, 1.0, atol=1e-14)
    assert np.all(nz > 0)


@pytest.mark.parametrize('shape', SHAPES)
def test_normal_is_the_sag_gradient(shape: rt.Surface) -> None:
    rng = np.random.default_rng(12)
    x, y, z, kx, ky, kz = random_rays(rng, 200)
    s, nx, ny, nz, _ = sf.intersect(shape, x, y, z, kx, ky, kz)
    px, py = x + s * kx, y + s * ky
    h = 1e-6

    def z(a, b):
        return sf.sag(shape, a * a + b * b)

    dzdx = (z(px + h, py) - z(px - h, py)) / (2 * h)
    dzdy = (z(px, py + h) - z(px, py - h)) / (2 * h)
    norm = np.sqrt(1.0 + dzdx ** 2 + dzdy ** 2)
    assert_allclose(np.stack([nx, ny, nz]), np.stack([-dzdx, -dzdy, np.ones_like(dzdx)]) / norm,
                    atol=1e-8)


@pytest.mark.parametrize('shape', SHAPES)
def test_meridional_intersection_equals_the_3d_one(shape: rt.Surface) -> None:
    rng = np.random.default_rng(13)
    _, y, z, _, ky, _ = random_rays(rng, 100)
    kz = np.sqrt(1.0 - ky * ky)
    s2, nx2, ny2, nz2, bad2 = sf.intersect(shape, 0.0, y, z, 0.0, ky, kz)
    s3, nx3, ny3, nz3, bad3 = sf.intersect(shape, np.zeros_like(y), y, z, np.zeros_like(y),
                                           ky, kz)
    assert nx2 == 0.0
    assert_array_equal(bad2, bad3)
    assert_allclose(np.stack([s2, ny2, nz2]), np.stack([s3, ny3, nz3]), rtol=1e-14, atol=1e-15)


def test_a_rotated_ray_intersects_a_rotated_point() -> None:
    # Rotational symmetry: the meridional ray rotated by 40 deg about z meets the rotated point.
    shape = surface(15.0, -3.0, (1e-4, -2e-6, 1e-8))
    y, z, ky = np.array([1.5]), np.array([-2.0]), np.array([0.2])
    kz = np.sqrt(1.0 - ky * ky)
    s2, _, ny2, nz2, _ = sf.intersect(shape, 0.0, y, z, 0.0, ky, kz)
    a = math.radians(40.0)
    s3, nx3, ny3, nz3, _ = sf.intersect(shape, -math.sin(a) * y, math.cos(a) * y, z,
                                        -math.sin(a) * ky, math.cos(a) * ky, kz)
    assert_allclose(s3, s2, rtol=1e-13)
    assert_allclose([nx3[0], ny3[0], nz3[0]],
                    [-math.sin(a) * ny2[0], math.cos(a) * ny2[0], nz2[0]], atol=1e-14)


def test_rays_outside_the_domain_or_missing_fail() -> None:
    # Oblate ellipsoid with domain r <= 5 mm: a ray parallel to the axis at r = 6 misses it.
    y = np.array([1.0, 6.0])
    _, _, _, _, bad = sf.intersect(surface(10.0, 3.0), 0.0, y, np.full(2, -1.0), 0.0,
                                   np.zeros(2), np.ones(2))
    assert_array_equal(bad, [False, True])
    # A sphere of radius 2: a parallel ray at height 3 misses it.
    _, _, _, _, bad = sf.intersect(surface(2.0), 0.0, np.array([3.0]), np.array([-1.0]), 0.0,
                                   np.zeros(1), np.ones(1))
    assert bad.all()


# --- refraction -----------------------------------------------------------------------------

def test_3d_refraction_keeps_snell_and_the_plane_of_incidence() -> None:
    rng = np.random.default_rng(14)
    k = rng.normal(size=(3, 50)) * [[0.3], [0.3], [1.0]]
    k[2] = np.abs(k[2])
    k /= np.linalg.norm(k, axis=0)
    n = rng.normal(size=(3, 50)) * [[0.2], [0.2], [1.0]]
    n[2] = np.abs(n[2])
    n /= np.linalg.norm(n, axis=0)
    front = np.einsum('ij,ij->j', k, n) > 0    # rays that meet the surface from the front
    assert front.sum() > 40
    k, n = k[:, front], n[:, front]
    out = np.stack(sf.refract(*k, *n, 1.0, 1.6))
    assert_allclose(np.linalg.norm(out, axis=0), 1.0, atol=1e-14)
    # n |k x N| is preserved and k, k', N are coplanar.
    assert_allclose(1.6 * np.linalg.norm(np.cross(out.T, n.T), axis=1),
                    np.linalg.norm(np.cross(k.T, n.T), axis=1), atol=1e-14)
    assert_allclose(np.einsum('ij,ij->j', np.cross(k.T, n.T).T, out), 0.0, atol=1e-14)
    # Meridional scalars give the same as the 2-D components.
    kx0, ky0, kz0 = sf.refract(0.0, k[1], k[2], 0.0, n[1], n[2], 1.0, 1.6)
    zero = np.zeros(k.shape[1])
    full = np.stack(sf.refract(zero, k[1], k[2], zero, n[1], n[2], 1.0, 1.6))
    assert kx0 == 0.0
    assert_allclose(np.stack([ky0, kz0]), full[1:], atol=1e-15)


def test_total_internal_reflection_is_nan() -> None:
    kx, ky, kz = sf.refract(0.0, np.array([0.8]), np.array([0.6]), 0.0, np.array([0.0]),
                            np.array([1.0]), 1.6, 1.0)
    assert np.isnan(ky).all() and np.isnan(kz).all()


# --- trace and model ------------------------------------------------------------------------

def triplet_values() -> dict:
    return load_params_file(REPO / 'config' / 'cooke_triplet.yaml')


def test_zero_coefficients_trace_identically() -> None:
    values = triplet_values()
    count = len(values['lens.surfaces.radius_mm'])
    lens = make_prescription(values)
    zero = dict(values, **{'lens.surfaces.conic': [0.0] * count,
                           'lens.surfaces.asphere_a4': [0.0] * count,
                           'lens.surfaces.asphere_a16': [0.0] * count})
    lens0 = make_prescription(zero)
    assert lens0.surfaces[0].asphere == (0.0,) * 7
    z, _ = rt.image_plane(lens, math.inf)
    tan = np.linspace(0.0, 0.4, 64)
    assert_array_equal(rt.trace_chief_rays(lens0, math.inf, z, tan),
                       rt.trace_chief_rays(lens, math.inf, z, tan))


def test_tiny_asphere_terms_move_the_trace_a_little() -> None:
    # A 1e-9 mm^-3 a4 on every surface of the triplet changes the image heights by less than
    # about a4 r^4 (n' - n) f / r scale, and not by nothing.
    values = triplet_values()
    count = len(values['lens.surfaces.radius_mm'])
    lens = make_prescription(values)
    lens_a = make_prescription(dict(values, **{'lens.surfaces.asphere_a4': [1e-9] * count}))
    z, _ = rt.image_plane(lens, math.inf)
    tan = np.linspace(0.0, 0.35, 32)
    base = rt.trace_chief_rays(lens, math.inf, z, tan)
    moved = rt.trace_chief_rays(lens_a, math.inf, z, tan)
    diff = np.abs(moved - base)
    assert 1e-8 < diff.max() < 1e-4


def test_a_hyperbolic_plano_convex_lens_focuses_parallel_light_exactly() -> None:
    # A plano-convex lens whose rear surface is the hyperboloid k = -n^2 images an axial point
    # at infinity without spherical aberration.
    n = 1.5
    radius = -10.0
    rear = rt.Surface(radius, 0.0, 1.0, 0.0, -n * n)
    lens = rt.Prescription((rt.Surface(0.0, 3.0, n), rear), 0.0)
    # (Collimated light in glass of index n meets air at the conic k = -n^2: the rays of every
    # height cross the axis at the paraxial rear focus.)
    par = rt.paraxial(lens)
    heights = np.array([0.5, 1.0, 2.0, 3.0])
    rays = rt.Rays(heights, np.full(4, -1.0), np.zeros(4), np.ones(4))
    out = rt.transfer_to_plane(rt.trace_surfaces(lens, rays), par.rear_focal_z_mm)
    assert_allclose(out.y, 0.0, atol=1e-9)


def test_model_builds_with_aspheres() -> None:
    values = triplet_values()
    count = len(values['lens.surfaces.radius_mm'])
    values['lens.surfaces.conic'] = [0.0, 0.0, -0.2, 0.0, 0.0, 0.0][:count]
    values['lens.surfaces.asphere_a4'] = [1e-6] + [0.0] * (count - 1)
    model = build_model(values)
    assert model.prescription.surfaces[2].conic == -0.2
    assert model.prescription.surfaces[0].asphere[0] == 1e-6


@pytest.mark.parametrize(('key', 'value', 'message'), [
    ('lens.surfaces.conic', [0.0, 0.0], 'lens.surfaces.conic: has 2 values'),
    ('lens.surfaces.asphere_a6', [0.0] * 7, 'lens.surfaces.asphere_a6: has 7 values'),
    ('lens.surfaces.asphere_a8', [math.nan] * 6, 'lens.surfaces.asphere_a8'),
    ('lens.surfaces.asphere_a4', [math.inf] + [0.0] * 5, 'lens.surfaces.asphere_a4'),
    ('lens.surfaces.conic', [30.0, 0, 0, 0, 0, 0], 'lens.surfaces.conic: surface 0: k = 30'),
])
def test_bad_conic_or_asphere_is_refused_by_name(key: str, value: list, message: str) -> None:
    values = triplet_values()
    values[key] = value
    with pytest.raises(ModelError, match=message.replace('[', r'\[')):
        build_model(values)


def test_conic_and_asphere_params_are_in_the_schema() -> None:
    names = defaults()
    for key in ('lens.surfaces.conic', 'lens.surfaces.asphere_a4', 'lens.surfaces.asphere_a16'):
        assert names[key] == []
