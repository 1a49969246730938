# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""Tests of the thick-lens closed forms (paper eq. 7-9) and the tolerance propagation."""

from __future__ import annotations

import math

from mechdeconv_ros.optics import thick_lens
import numpy as np
from numpy.testing import assert_allclose
import pytest

pytestmark = pytest.mark.filterwarnings('error')

CASE2 = {'n': 1.5168, 'r1': 4.0, 'r2': -4.0, 't': 3.0}
CASE2_ARGS = (1.5168, 4.0, -4.0, 3.0)   # n, r1_mm, r2_mm, t_mm

LENSES = [
    pytest.param(1.5168, 4.0, -4.0, 3.0, id='case2-biconvex'),
    pytest.param(1.5168, 6.0, 0.0, 2.0, id='plano-convex-front'),
    pytest.param(1.5168, 0.0, -6.0, 2.0, id='plano-convex-rear'),
    pytest.param(1.6, 5.0, 10.0, 2.0, id='positive-meniscus'),
    pytest.param(1.6, 10.0, 5.0, 2.0, id='negative-meniscus'),
    pytest.param(1.7, -8.0, 8.0, 1.0, id='biconcave'),
]


def test_case2_numbers():
    f = thick_lens.thick_lens_focal_length(*CASE2_ARGS)
    z_h, z_h2 = thick_lens.thick_lens_principal_planes(*CASE2_ARGS)
    assert_allclose(f, 4.437, atol=1e-3)
    assert_allclose(z_h, 1.134, atol=1e-3)
    assert_allclose(z_h2, 1.866, atol=1e-3)


@pytest.mark.parametrize(('n', 'r1', 'r2', 't'), [p for p in LENSES if 0.0 not in p.values])
def test_focal_length_is_paper_eq8(n, r1, r2, t):
    eq8 = n * r1 * r2 / ((n - 1) * (n * r2 - n * r1 + t * (n - 1)))
    assert_allclose(thick_lens.thick_lens_focal_length(n, r1, r2, t), eq8, rtol=1e-13)


@pytest.mark.parametrize(('n', 'r1', 'r2', 't'), [p for p in LENSES if 0.0 not in p.values])
def test_principal_planes_are_paper_formula(n, r1, r2, t):
    f = thick_lens.thick_lens_focal_length(n, r1, r2, t)
    z_h, z_h2 = thick_lens.thick_lens_principal_planes(n, r1, r2, t)
    assert_allclose(z_h, -f * (n - 1) * t / (n * r2), rtol=1e-13)
    assert_allclose(z_h2, t - f * (n - 1) * t / (n * r1), rtol=1e-13)


@pytest.mark.parametrize('front_curved', [True, False], ids=['flat-rear', 'flat-front'])
def test_plano_convex_both_ways(front_curved):
    n, radius, t = 1.5168, 6.0, 2.0
    r1, r2 = (radius, 0.0) if front_curved else (0.0, -radius)
    f = thick_lens.thick_lens_focal_length(n, r1, r2, t)
    z_h, z_h2 = thick_lens.thick_lens_principal_planes(n, r1, r2, t)
    assert_allclose(f, radius / (n - 1), rtol=1e-14)
    if front_curved:   # H at the curved vertex, H' inside the glass at t - t/n
        assert_allclose((z_h, z_h2), (0.0, t - t / n), atol=1e-14)
    else:
        assert_allclose((z_h, z_h2), (t / n, t), atol=1e-14)


@pytest.mark.parametrize('t', [0.0, 1e-7], ids=['t=0', 't=1e-7'])
def test_thin_lens_limit_is_lensmaker(t):
    n, r1, r2 = 1.5168, 7.0, -11.0
    lensmaker = 1.0 / ((n - 1) * (1 / r1 - 1 / r2))
    assert_allclose(thick_lens.thick_lens_focal_length(n, r1, r2, t), lensmaker, rtol=1e-7)
    assert_allclose(thick_lens.thick_lens_principal_planes(n, r1, r2, t), (0.0, 0.0), atol=1e-6)


def test_meniscus_principal_planes_lie_outside_the_lens():
    z_h, z_h2 = thick_lens.thick_lens_principal_planes(1.6, 5.0, 10.0, 2.0)
    assert z_h < 0 and z_h2 < 0


@pytest.mark.parametrize(('r1', 'r2', 't'), [(5.0, 5.0, 0.0), (0.0, 0.0, 2.0),
                                             (5.0, 5.0 - 0.6 * 2.0 / 1.6, 2.0)],
                         ids=['equal-thin', 'flat-plate', 'afocal-meniscus'])
def test_afocal_lens_is_rejected(r1, r2, t):
    with pytest.raises(ValueError, match='r1 and r2 give an afocal lens'):
        thick_lens.thick_lens_focal_length(1.6, r1, r2, t)
    with pytest.raises(ValueError, match='afocal'):
        thick_lens.thick_lens(1.6, r1, r2, t, 0.2)


@pytest.mark.parametrize(('n', 't', 'what'), [(0.9, 3.0, 'refractive index'),
                                              (1.5, -1.0, 'thickness'),
                                              (math.nan, 3.0, 'refractive index')],
                         ids=['n<1', 't<0', 'n-nan'])
def test_invalid_lens_numbers(n, t, what):
    with pytest.raises(ValueError, match=what):
        thick_lens.thick_lens_focal_length(n, 4.0, -4.0, t)


def test_thick_lens_prescription():
    lens = thick_lens.thick_lens(*CASE2_ARGS, stop_offset_mm=0.2, aperture_diameter_mm=1.0)
    z_h, _ = thick_lens.thick_lens_principal_planes(*CASE2_ARGS)
    assert [s.radius_mm for s in lens.surfaces] == [4.0, -4.0]
    assert [s.refractive_index for s in lens.surfaces] == [1.5168, 1.0]
    assert [s.semi_diameter_mm for s in lens.surfaces] == [0.0, 0.0]   # never clipped
    assert lens.surfaces[0].thickness_mm == 3.0
    assert lens.stop_semi_diameter_mm == 0.5
    assert_allclose(lens.stop_z_mm, z_h - 0.2, rtol=1e-15)
    assert 0 < lens.stop_z_mm < 3.0     # Case 2: the stop is inside the glass
    with pytest.raises(ValueError, match='aperture diameter'):
        thick_lens.thick_lens(*CASE2_ARGS, stop_offset_mm=0.2, aperture_diameter_mm=-1.0)


@pytest.mark.parametrize(('f', 'n', 't'), [(4.437, 1.5168, 3.0), (25.0, 1.5168, 4.0),
                                           (6.0, 1.8, 0.0), (2.0, 1.5, 2.9)],
                         ids=['case2', 'f25', 'thin', 'nearly-ball'])
def test_biconvex_round_trip(f, n, t):
    radius = thick_lens.biconvex_for_focal_length(f, n, t)
    assert radius > 0
    assert_allclose(thick_lens.thick_lens_focal_length(n, radius, -radius, t), f, rtol=1e-12)
    # The weaker-curvature root: the other root of the quadratic is never longer.
    other = (n - 1) ** 2 * t * f / n / radius
    assert radius >= other


def test_biconvex_recovers_case2_radius():
    f = thick_lens.thick_lens_focal_length(*CASE2_ARGS)
    assert_allclose(thick_lens.biconvex_for_focal_length(f, 1.5168, 3.0), 4.0, rtol=1e-12)


def test_biconvex_thin_limit():
    assert_allclose(thick_lens.biconvex_for_focal_length(10.0, 1.5, 0.0), 2 * 0.5 * 10.0)


@pytest.mark.parametrize(('f', 'n', 't', 'what'), [(2.0, 1.5, 3.5, 'no biconvex lens'),
                                                   (-5.0, 1.5, 1.0, 'must be > 0'),
                                                   (5.0, 1.0, 1.0, 'must be > 1')],
                         ids=['too-thick', 'negative-f', 'n=1'])
def test_biconvex_impossible(f, n, t, what):
    with pytest.raises(ValueError, match=what):
        thick_lens.biconvex_for_focal_length(f, n, t)


def _focal(p):
    return thick_lens.thick_lens_focal_length(p['n'], p['r1'], p['r2'], p['t'])


def test_propagate_sigma_matches_monte_carlo():
    sigmas = {'r1': 0.01, 'r2': 0.01, 't': 0.02, 'n': 0.0005}
    sigma = thick_lens.propagate_sigma(_focal, CASE2, sigmas)
    rng = np.random.default_rng(0)
    samples = {k: CASE2[k] + sigmas[k] * rng.standard_normal(20000) for k in CASE2}
    n, r1, r2, t = samples['n'], samples['r1'], samples['r2'], samples['t']
    f = 1.0 / ((n - 1) * (1 / r1 - 1 / r2 + (n - 1) * t / (n * r1 * r2)))
    assert sigma > 0
    assert_allclose(sigma, np.std(f, ddof=1), rtol=0.05)


def test_propagate_sigma_linear_is_exact_and_skips_zero_sigma():
    calls = []

    def fn(p):
        calls.append(dict(p))
        return 3.0 * p['a'] - 4.0 * p['b'] + 100.0 * p['c']

    sigma = thick_lens.propagate_sigma(fn, {'a': 1.0, 'b': 2.0, 'c': 3.0},
                                       {'a': 0.1, 'b': 0.2, 'c': 0.0})
    assert_allclose(sigma, math.hypot(0.3, 0.8), rtol=1e-9)
    assert all(call['c'] == 3.0 for call in calls)     # c never varied
    assert len(calls) == 4


@pytest.mark.parametrize(('sigmas', 'what'), [({'x': 0.1}, 'unknown parameter'),
                                              ({'a': -0.1}, '< 0'),
                                              ({'a': math.inf}, 'finite')],
                         ids=['unknown', 'negative', 'inf'])
def test_propagate_sigma_rejects(sigmas, what):
    with pytest.raises(ValueError, match=what):
        thick_lens.propagate_sigma(lambda p: p['a'], {'a': 1.0}, sigmas)
