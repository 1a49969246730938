# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Tests of the exact chief-ray tracer, in layers.

Closed forms (paraxial data, Gaussian image plane, a flat plate, a monocentric surface),
invariants (zero field, symmetry, paraxial limit, Snell invariant, stop handling, aiming) and
failures (semi-diameter, TIR, missed sphere). Every test runs with warnings as errors, so a
RuntimeWarning escaping the errstate scopes fails it.
"""

from __future__ import annotations

import math

from mechdeconv_ros.optics import raytrace as rt
from mechdeconv_ros.optics import surfaces as sf
from mechdeconv_ros.optics import thick_lens
import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

pytestmark = pytest.mark.filterwarnings('error')

N_BK7 = 1.5168
CASE2_ARGS = (N_BK7, 4.0, -4.0, 3.0)   # n, r1_mm, r2_mm, t_mm
#: Case 2 sensor corner: 640 x 480 pixels of 4.0625 x 4.4375 um.
CORNER_MM = math.hypot(320 * 4.0625e-3, 240 * 4.4375e-3)


def case2(stop_offset_mm: float = 0.2) -> rt.Prescription:
    return thick_lens.thick_lens(*CASE2_ARGS, stop_offset_mm)


def with_stop(prescription: rt.Prescription, stop_z_mm: float) -> rt.Prescription:
    return rt.Prescription(prescription.surfaces, stop_z_mm, prescription.object_index)


#: Stop positions of the Case 2 lens: in front (air), inside the glass, behind (air).
STOPS = [pytest.param(-1.0, id='stop-front'), pytest.param(0.9337868480725624, id='stop-glass'),
         pytest.param(4.0, id='stop-behind')]
DISTANCES = [pytest.param(1000.0, id='l=1000'), pytest.param(math.inf, id='l=inf'),
             pytest.param(30.0, id='l=30')]


def fields(prescription, distance, max_height_mm=None, count=64):
    """Return sensor z, v and tan of the field up to the corner (half of it for a rear stop)."""
    if max_height_mm is None:
        # A stop behind Case 2 leaves no real chief ray beyond about 14 degrees.
        rear_stop = prescription.stop_z_mm > rt.vertex_z(prescription)[-1]
        max_height_mm = CORNER_MM / 2 if rear_stop else CORNER_MM
    sensor_z, v = rt.image_plane(prescription, distance)
    return sensor_z, v, np.linspace(0.0, max_height_mm, count) / v


# --- prescription -------------------------------------------------------------------------

@pytest.mark.parametrize(('surfaces', 'kwargs', 'message'), [
    ((), {}, 'at least one surface'),
    ((rt.Surface(4, 3, 1.5), rt.Surface(-4, 0, 0.9)), {}, 'surface 1: refractive index 0.9 < 1'),
    ((rt.Surface(math.nan, 3, 1.5),), {}, 'surface 0: radius must be finite'),
    ((rt.Surface(4, -3, 1.5), rt.Surface(-4, 0, 1)), {}, 'surface 0: thickness -3 mm < 0'),
    ((rt.Surface(4, 3, 1.5, -1.0),), {}, 'surface 0: semi-diameter -1 mm < 0'),
    ((rt.Surface(4, 3, 1.5),), {'stop_z_mm': math.inf}, 'stop position must be finite'),
    ((rt.Surface(4, 3, 1.5),), {'object_index': 0.5}, 'object-space refractive index 0.5'),
    (('x',), {}, 'surface 0: expected a Surface'),
], ids=['empty', 'index<1', 'nan-radius', 'negative-thickness', 'negative-semi-diameter',
        'inf-stop', 'object-index', 'not-a-surface'])
def test_prescription_validation(surfaces, kwargs, message):
    kwargs = {'stop_z_mm': 0.0, **kwargs}
    with pytest.raises(ValueError, match=message):
        rt.Prescription(surfaces, **kwargs)


def test_prescription_takes_a_list_and_vertex_z():
    lens = rt.Prescription([rt.Surface(4, 3, 1.5), rt.Surface(0, 2, 1), rt.Surface(-4, 9, 1.6)],
                           0.0)
    assert isinstance(lens.surfaces, tuple)
    assert hash(lens) == hash(rt.Prescription(lens.surfaces, 0.0))
    assert_array_equal(rt.vertex_z(lens), [0.0, 3.0, 5.0])


# --- paraxial closed forms ------------------------------------------------------------------

@pytest.mark.parametrize(('n', 'r1', 'r2', 't'), [
    pytest.param(*CASE2_ARGS, id='case2'),
    pytest.param(N_BK7, 6.0, 0.0, 2.0, id='plano-convex-front'),
    pytest.param(N_BK7, 0.0, -6.0, 2.0, id='plano-convex-rear'),
    pytest.param(1.6, 5.0, 10.0, 2.0, id='meniscus'),
    pytest.param(1.7, -8.0, 8.0, 1.0, id='biconcave'),
    pytest.param(N_BK7, 7.0, -11.0, 0.0, id='thin'),
])
def test_paraxial_equals_thick_lens_closed_form(n, r1, r2, t):
    par = rt.paraxial(thick_lens.thick_lens(n, r1, r2, t, 0.0))
    f = thick_lens.thick_lens_focal_length(n, r1, r2, t)
    z_h, z_h2 = thick_lens.thick_lens_principal_planes(n, r1, r2, t)
    assert_allclose(par.efl_mm, f, rtol=1e-13)
    assert_allclose([par.front_principal_z_mm, par.rear_principal_z_mm], [z_h, z_h2],
                    rtol=1e-12, atol=1e-14)
    assert_allclose([par.front_focal_z_mm, par.rear_focal_z_mm], [z_h - f, z_h2 + f],
                    rtol=1e-12, atol=1e-14)
    assert par.last_vertex_z_mm == t
    if t == 0:
        assert_allclose(par.efl_mm, 1 / ((n - 1) * (1 / r1 - 1 / r2)), rtol=1e-14)


def test_case2_paraxial_numbers():
    par = rt.paraxial(case2())
    assert_allclose([par.efl_mm, par.front_principal_z_mm, par.rear_principal_z_mm],
                    [4.437, 1.134, 1.866], atol=1e-3)
    assert isinstance(par.efl_mm, float)


def test_paraxial_afocal():
    plate = rt.Prescription((rt.Surface(0, 2, 1.5), rt.Surface(0, 0, 1)), 0.0)
    with pytest.raises(ValueError, match='afocal'):
        rt.paraxial(plate)


def test_plate_in_front_keeps_f_and_shifts_the_front_planes():
    t, n, gap = 2.0, 1.8, 1.0
    lens = case2()
    plate_lens = rt.Prescription((rt.Surface(0, t, n), rt.Surface(0, gap, 1.0)) + lens.surfaces,
                                 lens.stop_z_mm + t + gap)
    bare, plated = rt.paraxial(lens), rt.paraxial(plate_lens)
    shift = t + gap                       # the lens moved back by the plate and the gap
    assert_allclose(plated.efl_mm, bare.efl_mm, rtol=1e-13)
    assert_allclose(plated.rear_principal_z_mm, bare.rear_principal_z_mm + shift, rtol=1e-13)
    # Seen through the plate, object space looks t (1 - 1/n) shorter.
    assert_allclose(plated.front_principal_z_mm,
                    bare.front_principal_z_mm + shift - t * (1 - 1 / n), rtol=1e-13)


@pytest.mark.parametrize('distance', [math.inf, 1000.0, 50.0, 4.5],
                         ids=['inf', '1000', '50', 'near-f'])
def test_image_plane_gaussian(distance):
    lens = case2()
    par = rt.paraxial(lens)
    sensor_z, v = rt.image_plane(lens, distance)
    assert_allclose(v, 1.0 / (1.0 / par.efl_mm - 1.0 / distance), rtol=1e-13)
    assert_allclose(sensor_z, par.rear_principal_z_mm + v, rtol=1e-13)
    if math.isinf(distance):
        assert v == pytest.approx(par.efl_mm, rel=1e-15)
        return
    # Independently: a real ray leaving the axial object point at a tiny angle focuses there.
    object_z = par.front_principal_z_mm - distance
    angle = 1e-7
    start = rt.Rays(np.array([0.0]), np.array([object_z]), np.array([math.sin(angle)]),
                    np.array([math.cos(angle)]))
    out = rt.trace_surfaces(lens, start)
    crossing = out.z[0] - out.y[0] * out.dz[0] / out.dy[0]
    assert_allclose(crossing, sensor_z, rtol=1e-9)


@pytest.mark.parametrize(('distance', 'message'), [
    (4.0, 'scene distance 4 mm is inside the focal length 4.437 mm'),
    (0.0, 'must be > 0'), (-10.0, 'must be > 0'), (math.nan, 'must be > 0'),
], ids=['inside-f', 'zero', 'negative', 'nan'])
def test_image_plane_no_real_image(distance, message):
    with pytest.raises(ValueError, match=message):
        rt.image_plane(case2(), distance)


def test_image_plane_diverging_lens():
    with pytest.raises(ValueError, match='diverging'):
        rt.image_plane(thick_lens.thick_lens(1.7, -8.0, 8.0, 1.0, 0.0), 1000.0)


# --- Snell's law and flat plates ---------------------------------------------------------------

def test_refract_preserves_n_sin_and_unit_length():
    rng = np.random.default_rng(0)
    incidence = rng.uniform(-1.2, 1.2, 1000)
    tilt = rng.uniform(-0.5, 0.5, 1000)
    normal_y, normal_z = np.sin(tilt), np.cos(tilt)
    dy, dz = np.sin(tilt + incidence), np.cos(tilt + incidence)
    out_y, out_z = sf.refract(0.0, dy, dz, 0.0, normal_y, normal_z, 1.0, N_BK7)[1:]
    assert_allclose(N_BK7 * (out_y * normal_z - out_z * normal_y),
                    1.0 * (dy * normal_z - dz * normal_y), atol=1e-15)
    assert_allclose(np.hypot(out_y, out_z), 1.0, rtol=1e-15)
    assert_allclose(np.arcsin(N_BK7 * (out_y * normal_z - out_z * normal_y)), incidence,
                    atol=1e-12)


def test_refract_normal_incidence_and_tir():
    out = sf.refract(0.0, np.array([0.0, math.sin(0.8)]), np.array([1.0, math.cos(0.8)]),
                     0.0, np.zeros(2), np.ones(2), N_BK7, 1.0)[1:]
    assert_array_equal(out[0][:1], [0.0])
    assert_array_equal(out[1][:1], [1.0])
    assert np.isnan(out[0][1]) and np.isnan(out[1][1])   # 1.5168 sin(0.8) = 1.09 > 1


@pytest.mark.parametrize('angle_deg', [0.0, 5.0, 30.0, 60.0, -45.0])
def test_flat_plate_lateral_displacement(angle_deg):
    t, n = 2.5, 1.7
    plate = rt.Prescription((rt.Surface(0, t, n), rt.Surface(0, 0, 1.0)), 0.0)
    i = math.radians(angle_deg)
    start = rt.Rays(np.array([0.3]), np.array([-1.0]), np.array([math.sin(i)]),
                    np.array([math.cos(i)]))
    out = rt.trace_surfaces(plate, start)
    assert_allclose([out.dy[0], out.dz[0]], [math.sin(i), math.cos(i)], atol=1e-15)
    undeviated = 0.3 + (out.z[0] + 1.0) * math.tan(i)
    displacement = (undeviated - out.y[0]) * math.cos(i)
    expected = t * math.sin(i) * (1 - math.cos(i) / math.sqrt(n * n - math.sin(i) ** 2))
    assert_allclose(displacement, expected, rtol=1e-12, atol=1e-15)


def plate_in_front(lens, t=2.0, n=1.8, gap=1.0):
    """Return a plate of thickness t and index n, gap mm in front of ``lens`` (stop moved)."""
    return rt.Prescription((rt.Surface(0, t, n), rt.Surface(0, gap, 1.0)) + lens.surfaces,
                           lens.stop_z_mm + t + gap)


def test_plate_in_collimated_space_changes_no_chief_ray():
    # Object at infinity, stop behind the plate: the plate shifts each bundle sideways but
    # keeps its direction, and the chief ray is the one that reaches the stop centre.
    lens = case2()
    plated = plate_in_front(lens)
    sensor_z, _, tan = fields(lens, math.inf)
    plated_sensor_z, _ = rt.image_plane(plated, math.inf)
    assert_allclose(plated_sensor_z, sensor_z + 3.0, rtol=1e-14)
    bare = rt.trace_chief_rays(lens, math.inf, sensor_z, tan)
    through = rt.trace_chief_rays(plated, math.inf, plated_sensor_z, tan)
    assert np.all(np.isfinite(bare))
    assert_allclose(through, bare, rtol=1e-12, atol=1e-15)
    assert_array_equal(rt.trace_chief_rays(plated, 1000.0, plated_sensor_z, [0.0]), [0.0])


# --- exact closed form of the aiming: a monocentric surface ----------------------------------

@pytest.mark.parametrize('distance', [math.inf, 200.0], ids=['inf', 'l=200'])
def test_stop_at_centre_of_curvature_is_undeviated(distance):
    # One surface into glass, stop at its centre of curvature (in the glass): every chief ray
    # meets the sphere along its normal, is not refracted and goes straight through the centre.
    r, n = 5.0, 1.6
    lens = rt.Prescription((rt.Surface(r, 0.0, n),), stop_z_mm=r)
    sensor_z, _ = rt.image_plane(lens, distance)
    tan = np.linspace(-0.8, 0.8, 33)
    heights = rt.trace_chief_rays(lens, distance, sensor_z, tan)
    if math.isinf(distance):
        expected = -tan * (sensor_z - r)
    else:
        object_z = rt.paraxial(lens).front_principal_z_mm - distance
        expected = -tan * distance * (sensor_z - r) / (r - object_z)
    assert_allclose(heights, expected, rtol=1e-12, atol=1e-14)


# --- invariants -----------------------------------------------------------------------------

@pytest.mark.parametrize('distance', DISTANCES)
@pytest.mark.parametrize('stop_z', STOPS)
def test_zero_field_images_on_axis_exactly(stop_z, distance):
    lens = with_stop(case2(), stop_z)
    sensor_z, _ = rt.image_plane(lens, distance)
    heights = rt.trace_chief_rays(lens, distance, sensor_z, np.zeros(3))
    assert_array_equal(heights, 0.0)


@pytest.mark.parametrize('distance', DISTANCES)
@pytest.mark.parametrize('stop_z', STOPS)
def test_trace_is_odd_in_the_field(stop_z, distance):
    lens = with_stop(case2(), stop_z)
    sensor_z, _, tan = fields(lens, distance)
    up = rt.trace_chief_rays(lens, distance, sensor_z, tan)
    down = rt.trace_chief_rays(lens, distance, sensor_z, -tan)
    assert np.all(np.isfinite(up))
    assert np.all(up[1:] < 0)                          # real, inverted image
    assert_array_equal(down, -up)


@pytest.mark.parametrize('distance', DISTANCES)
@pytest.mark.parametrize('stop_z', STOPS)
def test_small_fields_reach_the_paraxial_magnification(stop_z, distance):
    lens = with_stop(case2(), stop_z)
    sensor_z, v = rt.image_plane(lens, distance)
    ideal = v * np.array([1e-7, 1e-6, 1e-3, 2e-3])
    ratio = rt.radial_map(lens, distance, sensor_z, v, ideal) / ideal
    assert_allclose(ratio[:2], 1.0, rtol=0, atol=1e-9)
    # Distortion is third order: the relative error grows as the field squared.
    assert_allclose((ratio[3] - 1) / (ratio[2] - 1), 4.0, rtol=1e-3)


def test_stop_in_object_space_same_with_and_without_aiming():
    lens = with_stop(case2(), -1.0)
    for distance in (math.inf, 1000.0, 30.0):
        sensor_z, _, tan = fields(lens, distance, count=257)
        direct = rt.trace_chief_rays(lens, distance, sensor_z, tan, aim=False)
        aimed = rt.trace_chief_rays(lens, distance, sensor_z, tan, aim=True)
        automatic = rt.trace_chief_rays(lens, distance, sensor_z, tan)
        assert np.all(np.isfinite(direct))
        assert_array_equal(automatic, direct)
        assert_allclose(aimed, direct, rtol=1e-12, atol=1e-15)


def test_a_stop_behind_the_vertex_cannot_skip_aiming():
    with pytest.raises(ValueError, match='must be aimed'):
        rt.aim_chief_rays(case2(), 1000.0, [0.1], aim=False)


@pytest.mark.parametrize('distance', DISTANCES)
@pytest.mark.parametrize('stop_z', STOPS)
def test_chief_rays_cross_the_stop_centre(stop_z, distance):
    lens = with_stop(case2(), stop_z)
    _, _, tan = fields(lens, distance, count=2048)
    rays = rt.aim_chief_rays(lens, distance, tan)
    before_stop = int(np.sum(rt.vertex_z(lens) <= stop_z))
    at_stop = rt.transfer_to_plane(rt.trace_surfaces(lens, rays, 0, before_stop), stop_z)
    assert np.all(np.isfinite(at_stop.y))
    assert np.max(np.abs(at_stop.y)) < 1e-9


def test_case2_distortion_is_barrel():
    lens = case2()
    sensor_z, v = rt.image_plane(lens, 1000.0)
    ideal = np.linspace(0.0, CORNER_MM, 1025)
    real = rt.radial_map(lens, 1000.0, sensor_z, v, ideal)
    ratio = real[1:] / ideal[1:]
    assert np.all(np.diff(real) > 0)                     # monotonic map
    assert np.all(np.diff(ratio) < 0) and ratio[-1] < 1  # barrel, growing with the field
    assert_allclose(ratio[-1], 0.98222, atol=5e-5)       # vs optiland 0.6.3: agrees to 1e-12


def test_shape_and_nan_input():
    lens = case2()
    sensor_z, _ = rt.image_plane(lens, 1000.0)
    tan = np.array([[0.0, 0.1], [math.nan, -0.2]])
    heights = rt.trace_chief_rays(lens, 1000.0, sensor_z, tan)
    assert heights.shape == (2, 2)
    assert np.isnan(heights[1, 0])
    assert np.all(np.isfinite(heights.ravel()[[0, 1, 3]]))
    assert rt.trace_chief_rays(lens, 1000.0, sensor_z, 0.1).shape == ()


def test_object_behind_the_first_vertex_is_rejected():
    # A thick plano-convex rod: f = 4 mm but H lies 5.33 mm behind the front vertex, so a
    # scene 4.5 mm from H (a real image by the Gaussian formula) would sit inside the glass.
    lens = thick_lens.thick_lens(1.5, 0.0, -2.0, 8.0, 0.0)
    sensor_z, _ = rt.image_plane(lens, 4.5)
    with pytest.raises(ValueError, match='not in front of the first surface'):
        rt.trace_chief_rays(lens, 4.5, sensor_z, [0.1])


# --- failures -------------------------------------------------------------------------------

def test_semi_diameter_clips_to_nan():
    bare = case2()
    sensor_z, v, tan = fields(bare, 1000.0, count=9)
    free = rt.trace_chief_rays(bare, 1000.0, sensor_z, tan)
    rays = rt.trace_surfaces(bare, rt.aim_chief_rays(bare, 1000.0, tan), 0, 1)
    limit = 0.5 * (abs(rays.y[4]) + abs(rays.y[5]))      # between the 5th and 6th field
    clipped_lens = rt.Prescription((rt.Surface(4.0, 3.0, N_BK7, limit),
                                    rt.Surface(-4.0, 0.0, 1.0)), bare.stop_z_mm)
    clipped = rt.trace_chief_rays(clipped_lens, 1000.0, sensor_z, tan)
    assert_array_equal(clipped[:5], free[:5])
    assert np.all(np.isnan(clipped[5:]))


def test_aperture_diameter_does_not_clip():
    lens = thick_lens.thick_lens(*CASE2_ARGS, 0.2, aperture_diameter_mm=0.01)
    sensor_z, _, tan = fields(lens, 1000.0)
    assert_array_equal(rt.trace_chief_rays(lens, 1000.0, sensor_z, tan),
                       rt.trace_chief_rays(case2(), 1000.0, sensor_z, tan))


def test_total_internal_reflection_is_nan():
    # Object space is glass (n = 1.5) up to a flat window into air, then the lens; the stop
    # lies in the object glass. Rays steeper than asin(1/1.5) = 41.8 deg cannot leave it.
    lens = case2()
    immersed = rt.Prescription((rt.Surface(0, 1.0, 1.0),) + lens.surfaces, -0.5,
                               object_index=1.5)
    sensor_z, _ = rt.image_plane(immersed, math.inf)
    tan = np.array([0.2, math.tan(math.radians(43.0)), 3.0])
    window = rt.trace_surfaces(immersed, rt.aim_chief_rays(immersed, math.inf, tan), 0, 1)
    assert np.isfinite(window.dy[0]) and np.all(np.isnan(window.dy[1:]))
    heights = rt.trace_chief_rays(immersed, math.inf, sensor_z, tan)
    assert np.isfinite(heights[0]) and np.all(np.isnan(heights[1:]))
    aimed = rt.trace_chief_rays(immersed, math.inf, sensor_z, tan, aim=True)
    assert np.isfinite(aimed[0]) and np.all(np.isnan(aimed[1:]))


def test_missed_sphere_is_nan():
    # Through a stop 1 mm in front, a ray at tan 10 passes 4.97 mm from the centre of the
    # r = 4 front sphere: it misses it.
    lens = with_stop(case2(), -1.0)
    sensor_z, _ = rt.image_plane(lens, math.inf)
    heights = rt.trace_chief_rays(lens, math.inf, sensor_z, np.array([0.1, 10.0, -10.0]))
    assert np.isfinite(heights[0])
    assert np.all(np.isnan(heights[1:]))


def test_no_chief_ray_through_the_lens_is_nan():
    # Stop 1 mm behind the Case 2 lens: beyond about 14 degrees spherical aberration leaves no
    # ray inside the lens edge that reaches the stop centre (the lens ends where its two
    # spheres meet, 3.12 mm from the axis). Failure is NaN, never a wrong number.
    lens = with_stop(case2(), 4.0)
    sensor_z, _ = rt.image_plane(lens, 1000.0)
    heights = rt.trace_chief_rays(lens, 1000.0, sensor_z, np.array([0.1, 0.3, 1.0]))
    assert np.isfinite(heights[0])
    assert np.all(np.isnan(heights[1:]))


def test_valid_field_ends_once_where_the_chief_ray_ends():
    # Same lens: a brute-force scan of y_stop(h) finds a chief ray at tan = 0.2628 and none at
    # tan = 0.2630 (the ray would have to pass outside the lens). The traced field is
    # valid up to that edge, without holes, and NaN beyond it.
    lens = with_stop(case2(), 4.0)
    sensor_z, _ = rt.image_plane(lens, 1000.0)
    tan = np.linspace(0.0, 0.45, 2048)
    heights = rt.trace_chief_rays(lens, 1000.0, sensor_z, tan)
    valid = np.isfinite(heights)
    count = int(valid.sum())
    assert valid[:count].all()
    assert 0.2628 <= tan[count - 1] < tan[count] <= 0.2630 + np.diff(tan)[0]
    assert np.all(np.diff(heights[:count]) < 0)
