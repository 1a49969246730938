# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Refusals of lenses that cannot exist, each at its closed-form limit (docs/design.md section 7).

Every rule is tested just inside (accepted, or at least not refused by that rule) and just
outside (refused with a reason that names the parameter, says why and gives the limit).
"""

from __future__ import annotations

import math

from mechdeconv_ros.model.model import build_model, ModelError
from mechdeconv_ros.optics.thick_lens import thick_lens_focal_length, thick_lens_principal_planes
import pytest

CASE2 = {'sensor.width_px': 640, 'sensor.height_px': 480}
N, R, T = 1.5168, 4.0, 3.0
F = thick_lens_focal_length(N, R, -R, T)
Z_H, Z_H2 = thick_lens_principal_planes(N, R, -R, T)
#: Plano-convex lens (flat back, z_H = 0) with the stop on the front vertex, scene at infinity:
#: the axial beam is d_a wide on the front surface, so 2|r| bounds d_a exactly.
PLANO = {**CASE2, 'lens.r1_mm': R, 'lens.r2_mm': 0.0, 'lens.thickness_mm': 5.0,
         'lens.stop_offset_mm': 0.0, 'scene.distance_mm': 0.0}
INSIDE, OUTSIDE = 1.0 - 1e-6, 1.0 + 1e-6


def refused(values, width=0, height=0):
    with pytest.raises(ModelError) as info:
        build_model(values, width, height)
    err = info.value
    assert str(err).startswith(f'{err.parameter}: ')
    return err


def test_case2_numbers():
    assert F == pytest.approx(4.4369, abs=1e-4)
    assert Z_H == pytest.approx(1.1338, abs=1e-4)


# --- scene.focus_distance_mm -----------------------------------------------------------------

@pytest.mark.parametrize('focus', [3.0, 0.001, F * OUTSIDE ** -1])
def test_focus_inside_the_focal_length_is_refused(focus):
    err = refused({**CASE2, 'scene.focus_distance_mm': focus})
    assert err.parameter == 'scene.focus_distance_mm'
    assert 'inside the focal length 4.437 mm' in err.reason


def test_focus_just_outside_the_focal_length_is_accepted():
    model = build_model({**CASE2, 'scene.focus_distance_mm': F * OUTSIDE})
    assert model.summary['focus_distance_mm'] == pytest.approx(F * OUTSIDE)


# --- lens.stop_offset_mm: behind the image plane, in front of the scene ----------------------

def _sensor_z(distance):
    v = F * distance / (distance - F)
    return Z_H2 + v


@pytest.mark.parametrize('offset', [-10.0, -1000.0])
def test_stop_behind_the_sensor_is_refused(offset):
    err = refused({**CASE2, 'lens.stop_offset_mm': offset})
    assert err.parameter == 'lens.stop_offset_mm'
    assert 'behind the image plane' in err.reason
    limit = Z_H - _sensor_z(1000.0)
    assert f'must be above {limit:.4g} mm' in err.reason


def test_stop_at_the_image_plane_limit():
    limit = Z_H - _sensor_z(1000.0)
    err = refused({**CASE2, 'lens.stop_offset_mm': limit - 1e-6})
    assert 'behind the image plane' in err.reason
    # Just inside the rule: whatever else is said, it is not this refusal.
    try:
        build_model({**CASE2, 'lens.stop_offset_mm': limit + 1e-6})
    except ModelError as other:
        assert 'image plane' not in other.reason
    build_model({**CASE2, 'lens.stop_offset_mm': -4.0})    # a rear stop is a lens


def test_stop_in_front_of_the_scene_is_refused():
    values = {**CASE2, 'scene.distance_mm': 100.0, 'lens.aperture_diameter_mm': 0.001}
    err = refused({**values, 'lens.stop_offset_mm': 100.0})
    assert err.parameter == 'lens.stop_offset_mm'
    assert 'in front of the scene' in err.reason
    assert 'below the scene distance 100 mm' in err.reason
    try:
        build_model({**values, 'lens.stop_offset_mm': 100.0 - 1e-6})
    except ModelError as other:
        assert 'scene' not in other.reason


# --- lens.aperture_diameter_mm: the surfaces' clear aperture ---------------------------------

def test_issue_example_aperture_wider_than_the_surfaces():
    err = refused({**CASE2, 'lens.aperture_diameter_mm': 1000.0})
    assert err.parameter == 'lens.aperture_diameter_mm'
    assert 'the 8 mm diameter (2|r|)' in err.reason and 'radius 4 mm' in err.reason
    assert 'the largest aperture is' in err.reason


def test_aperture_limit_is_the_sphere_diameter():
    model = build_model({**PLANO, 'lens.aperture_diameter_mm': 2 * R * INSIDE})
    assert model.focal_length_mm == pytest.approx(R / (N - 1.0))
    err = refused({**PLANO, 'lens.aperture_diameter_mm': 2 * R * OUTSIDE})
    assert err.parameter == 'lens.aperture_diameter_mm'
    assert 'the largest aperture is 8 mm' in err.reason


def _singlet(semi, **extra):
    """Return a prescription plano-convex singlet, stop on its front vertex, scene at inf."""
    return {**CASE2, 'lens.surfaces.radius_mm': [R, 0.0],
            'lens.surfaces.thickness_mm': [5.0, 0.0],
            'lens.surfaces.refractive_index': [N, 1.0],
            'lens.surfaces.semi_diameter_mm': semi, 'lens.stop_surface': 0,
            'scene.distance_mm': 0.0, **extra}


def test_semi_diameter_bounds_the_stop():
    build_model(_singlet([2.0, 0.0], **{'lens.aperture_diameter_mm': 4.0 * INSIDE}))
    err = refused(_singlet([2.0, 0.0], **{'lens.aperture_diameter_mm': 4.0 * OUTSIDE}))
    assert err.parameter == 'lens.aperture_diameter_mm'
    assert 'lens.surfaces.semi_diameter_mm[0]' in err.reason
    assert 'the largest aperture is 4 mm' in err.reason


def test_semi_diameter_wider_than_the_sphere_is_refused():
    build_model(_singlet([R * INSIDE, 0.0]))
    err = refused(_singlet([R * OUTSIDE, 0.0]))
    assert err.parameter == 'lens.surfaces.semi_diameter_mm'
    assert 'surface 0' in err.reason and '|r| = 4 mm' in err.reason


def test_cooke_triplet_stop_is_at_its_limit():
    """The triplet: its stop (surface 3) is as wide as the semi-diameter optiland gave it."""
    from mechdeconv_ros.schema.params import load_params_file
    from pathlib import Path
    values = load_params_file(Path(__file__).parents[1] / 'config' / 'cooke_triplet.yaml')
    build_model(values)
    err = refused({**values, 'lens.aperture_diameter_mm': 7.61})
    assert 'surface 3' in err.reason and 'the largest aperture is 7.602 mm' in err.reason


# --- edge thickness: t - sag1(a) + sag2(a) >= 0 ----------------------------------------------

def test_edge_thickness_of_the_thick_lens():
    # Stop on the front vertex, scene at infinity: a = d_a / 2 on the front surface (the rear
    # one sees a narrower beam), and the symmetric lens's edge vanishes at
    # a = sqrt(R^2 - (R - t/2)^2).
    values = {**CASE2, 'lens.stop_offset_mm': Z_H, 'scene.distance_mm': 0.0}
    limit = 2.0 * math.sqrt(R * R - (R - T / 2.0) ** 2)
    assert limit == pytest.approx(6.245, abs=1e-3)
    build_model({**values, 'lens.aperture_diameter_mm': limit * INSIDE})
    err = refused({**values, 'lens.aperture_diameter_mm': limit * OUTSIDE})
    assert err.parameter == 'lens.thickness_mm'
    assert 'surfaces cross' in err.reason
    assert f'lens.aperture_diameter_mm at most {limit:.4g} mm' in err.reason
    assert 'at least 3 mm thick' in err.reason


def test_edge_thickness_of_a_prescription_element():
    def element(semi):
        return {**CASE2, 'lens.surfaces.radius_mm': [R, -R],
                'lens.surfaces.thickness_mm': [T, 0.0],
                'lens.surfaces.refractive_index': [N, 1.0],
                'lens.surfaces.semi_diameter_mm': [semi, semi]}
    limit = math.sqrt(R * R - (R - T / 2.0) ** 2)
    build_model(element(limit * INSIDE))
    err = refused(element(limit * OUTSIDE))
    assert err.parameter == 'lens.surfaces.thickness_mm'
    assert 'between surfaces 0 and 1' in err.reason
    assert 'semi_diameter_mm smaller' in err.reason


# --- the image plane behind the last surface -------------------------------------------------

def test_image_plane_inside_the_lens_is_refused():
    # Scene at infinity: back focal distance f (1 - (n - 1) t / (n r1)) = 0 at t = n r1/(n-1).
    limit = N * R / (N - 1.0)
    values = {**CASE2, 'scene.distance_mm': 0.0, 'lens.stop_offset_mm': 0.0}
    err = refused({**values, 'lens.thickness_mm': limit * OUTSIDE})
    assert err.parameter == 'lens.thickness_mm'
    assert 'inside the lens' in err.reason
    try:
        build_model({**values, 'lens.thickness_mm': limit * INSIDE})
    except ModelError as other:
        assert 'inside the lens' not in other.reason


# --- scene.circle_of_confusion_mm ------------------------------------------------------------

def test_circle_of_confusion_larger_than_the_sensor():
    diagonal = math.hypot(640 * 4.0625e-3, 480 * 4.4375e-3)
    build_model({**CASE2, 'scene.circle_of_confusion_mm': diagonal * INSIDE})
    err = refused({**CASE2, 'scene.circle_of_confusion_mm': diagonal * OUTSIDE})
    assert err.parameter == 'scene.circle_of_confusion_mm'
    assert f'{diagonal:.4g} mm diagonal' in err.reason


def test_circle_of_confusion_uses_the_image_size_when_the_sensor_size_is_zero():
    values = {'sensor.width_px': 0, 'sensor.height_px': 0, 'scene.circle_of_confusion_mm': 3.0}
    build_model(values, 640, 480)                      # 3.36 mm diagonal
    err = refused(values, 320, 240)                    # 1.68 mm diagonal
    assert '1.681 mm diagonal' in err.reason


def test_default_circle_of_confusion_on_a_tiny_sensor():
    err = refused({'sensor.width_px': 1, 'sensor.height_px': 1,
                   'sensor.pixel_size_x_um': 1.0, 'sensor.pixel_size_y_um': 1.0})
    assert err.parameter == 'scene.circle_of_confusion_mm'
    assert '0.1 % of f' in err.reason


# --- warnings: possible but unusual ----------------------------------------------------------

def test_far_stop_warns_once_in_the_report():
    near = build_model({**CASE2, 'lens.stop_offset_mm': Z_H + F - 0.01,
                        'lens.aperture_diameter_mm': 0.2})
    far = build_model({**CASE2, 'lens.stop_offset_mm': Z_H + F + 0.01,
                       'lens.aperture_diameter_mm': 0.2})
    assert not near.warnings
    assert len(far.warnings) == 1 and far.warnings[0].startswith('lens.stop_offset_mm: ')
    assert 'farther than the focal length' in far.warnings[0]
    assert far.summary['warnings'].count(far.warnings[0]) == 1
    assert far.warnings[0] in far.report()['warnings']


def test_fast_aperture_warns():
    # n = 2 plano-convex: f = r / (n - 1) = 4 mm, and 2|r| = 8 mm allows f/0.5.
    values = {**PLANO, 'lens.refractive_index': 2.0}
    slow = build_model({**values, 'lens.aperture_diameter_mm': 4.0 / 0.7 * INSIDE})
    fast = build_model({**values, 'lens.aperture_diameter_mm': 4.0 / 0.7 * OUTSIDE})
    assert not slow.warnings
    assert [w for w in fast.warnings if 'faster than f/0.7' in w]


def test_existing_configs_build_without_refusal():
    from mechdeconv_ros.schema.params import load_params_file
    from pathlib import Path
    paths = sorted(p for p in (Path(__file__).parents[1] / 'config').glob('*.yaml')
                   if not p.name.startswith('stereo'))     # stereo_node's: test_stereo.py
    assert paths
    for path in paths:
        build_model(load_params_file(path))


def test_rim_and_sag_of_conics_and_aspheres():
    """The rim and sag helpers read conic and asphere terms when a surface has them."""
    from types import SimpleNamespace

    from mechdeconv_ros.optics.surfaces import domain_limit_mm as _rim_mm
    from mechdeconv_ros.optics.surfaces import sag_at_height as _sag

    def surface(radius, conic=0.0, asphere=()):
        return SimpleNamespace(radius_mm=radius, curvature_per_mm=1.0 / radius if radius else 0.0,
                               conic=conic, asphere=asphere)

    assert _rim_mm(surface(-4.0)) == pytest.approx(4.0)
    assert _rim_mm(surface(4.0, -0.5)) == pytest.approx(4.0 / math.sqrt(0.5))
    assert math.isinf(_rim_mm(surface(4.0, -1.0))) and math.isinf(_rim_mm(surface(0.0)))
    assert _sag(surface(4.0), 3.0) == pytest.approx(4.0 - math.sqrt(7.0))
    assert _sag(surface(-4.0), 3.0) == pytest.approx(-(4.0 - math.sqrt(7.0)))
    assert _sag(surface(4.0), 9.0) == pytest.approx(4.0)         # a flat bevel beyond the rim
    assert _sag(surface(4.0, -1.0), 2.0) == pytest.approx(0.5)   # paraboloid a^2 / (2 r)
    assert _sag(surface(0.0, 0.0, (1e-3,)), 2.0) == pytest.approx(16e-3)
