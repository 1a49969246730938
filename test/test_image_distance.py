# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
lens.image_distance_mm: the sensor a given distance behind the last vertex (defocus).

Closed forms for a thin lens with its stop on it (exit pupil at H'), scene at infinity: the
raw pinhole's image distance becomes v + dz (heights scale by (v + dz) / v), the blur circle
is D |dz| / v; 0 keeps the sensor on the paraxial image plane (the model as before).
"""

from __future__ import annotations

import math

from mechdeconv_ros.model.model import build_model, ModelError
from mechdeconv_ros.optics.prescription import vertex_z
from mechdeconv_ros.schema.params import load_params_file
from mechdeconv_ros.tools.cli import format_report
import numpy as np
from numpy.testing import assert_allclose
import pytest
from ros_helpers import REPO

pytestmark = pytest.mark.filterwarnings('error')

#: A thin biconvex lens (t = 0.05 mm, f = 50 mm) with its stop on the front vertex.
THIN = {'sensor.width_px': 640, 'sensor.height_px': 480, 'sensor.pixel_size_x_um': 2.0,
        'sensor.pixel_size_y_um': 2.0, 'lens.surfaces.radius_mm': [0.0, 50.0, -50.0],
        'lens.surfaces.thickness_mm': [0.0, 0.05, 0.0],
        'lens.surfaces.refractive_index': [1.0, 1.5, 1.0], 'lens.stop_surface': 0,
        'lens.aperture_diameter_mm': 2.0, 'scene.distance_mm': 0.0}
#: A stop 30 mm in front of an f = 20 mm singlet: its exit pupil is real, 60 mm behind.
FAR_STOP = {'sensor.width_px': 640, 'sensor.height_px': 480,
            'lens.surfaces.radius_mm': [0.0, 20.0, -20.0],
            'lens.surfaces.thickness_mm': [30.0, 1.0, 0.0],
            'lens.surfaces.refractive_index': [1.0, 1.5, 1.0], 'lens.stop_surface': 0,
            'lens.aperture_diameter_mm': 1.0, 'scene.distance_mm': 0.0}


def back_focus(values: dict) -> float:
    model = build_model(values)
    z_image, _ = model.source.image_plane(math.inf if values['scene.distance_mm'] == 0.0
                                          else values['scene.distance_mm'])
    return z_image - float(vertex_z(model.prescription)[-1])


@pytest.mark.parametrize('dz', [-0.5, -0.1, 0.1, 1.0], ids=['-0.5', '-0.1', '+0.1', '+1'])
def test_thin_lens_heights_scale_by_v_plus_dz(dz: float) -> None:
    focused = build_model(THIN)
    v = focused.image_distance_mm
    model = build_model({**THIN, 'lens.image_distance_mm': back_focus(THIN) + dz})
    # camera_info's focal length follows where rays land: (v + dz) / p (to O(t / v)).
    assert_allclose(model.image_distance_mm, v + dz, rtol=2e-5)
    assert_allclose(model.K[0, 0], (v + dz) / 2e-3, rtol=2e-5)
    # The traced heights near the axis are the pinhole's: slope 1, no scale error in the map.
    assert_allclose(model.curve.real_mm[1] / model.curve.ideal_mm[1], 1.0, rtol=1e-9)
    # A thin lens has (almost) no distortion, defocused or not.
    assert model.max_displacement_px < 1e-3
    defocus = model.source.defocus(math.inf)
    assert_allclose(defocus['defocus_mm'], dz, rtol=1e-9)
    assert_allclose(defocus['blur_diameter_mm'], 2.0 * abs(dz) / v, rtol=1e-6)


def test_zero_and_the_back_focus_are_the_model_as_before() -> None:
    focused = build_model(THIN)
    same = build_model({**THIN, 'lens.image_distance_mm': back_focus(THIN)})
    assert_allclose(same.K, focused.K, rtol=1e-12)
    assert_allclose(same.curve.real_mm, focused.curve.real_mm, rtol=0, atol=1e-12)
    assert focused.report()['sensor_plane']['image_distance_mm'] is None
    assert focused.report()['sensor_plane']['defocus_mm'] == 0.0


def test_thick_lens_and_prescription_both_honour_it() -> None:
    case2 = {'sensor.width_px': 640, 'sensor.height_px': 480}
    focused = build_model(case2)
    moved = build_model({**case2, 'lens.image_distance_mm': back_focus(
        {**case2, 'scene.distance_mm': 1000.0}) + 0.05})
    assert moved.K[0, 0] > focused.K[0, 0]
    assert_allclose(moved.source.defocus(1000.0)['defocus_mm'], 0.05, rtol=1e-9)
    report = moved.report()
    sensor = report['sensor_plane']
    assert sensor['blur_diameter_um'] > 0.0
    assert_allclose(sensor['blur_diameter_px'], sensor['blur_diameter_um'] / 4.0625, rtol=1e-12)
    assert 'sensor: ' in format_report(report) and ' px)' in format_report(report)
    # A blur of more than 2 px is noted.
    assert any(w.startswith('lens.image_distance_mm:') for w in moved.warnings)
    assert not any(w.startswith('lens.image_distance_mm:') for w in focused.warnings)


def test_wide_prescription_defocused_keeps_slope_one_and_changes_k() -> None:
    values = load_params_file(REPO / 'config' / 'wide_angle.yaml')
    values['scene.distance_mm'] = 0.0
    focused = build_model(values)
    moved = build_model({**values, 'lens.image_distance_mm': back_focus(values) + 0.02})
    assert moved.K[0, 0] != focused.K[0, 0]
    # Near the axis the traced chief ray lands where the pinhole of K puts it.
    theta = np.array([0.0, 1e-4])
    heights, _ = moved.source.real_heights(theta, math.inf)
    assert_allclose(heights[1] / (moved.image_distance_mm * math.tan(theta[1])), 1.0,
                    rtol=1e-7)
    # The relative illumination is traced on the sensor's plane.
    assert moved.illumination(with_fraction=False).ri[0] == pytest.approx(1.0)


def test_sensor_inside_a_bulging_last_surface_is_refused() -> None:
    bulge = {'sensor.width_px': 640, 'sensor.height_px': 480,
             'lens.surfaces.radius_mm': [10.0, 30.0], 'lens.surfaces.thickness_mm': [3.0, 0.0],
             'lens.surfaces.refractive_index': [1.5, 1.0],
             'lens.surfaces.semi_diameter_mm': [4.0, 4.0], 'lens.stop_surface': 0,
             'lens.aperture_diameter_mm': 1.0}
    sag = 30.0 - math.sqrt(30.0 ** 2 - 4.0 ** 2)
    with pytest.raises(ModelError) as err:
        build_model({**bulge, 'lens.image_distance_mm': 0.9 * sag})
    assert err.value.parameter == 'lens.image_distance_mm'
    assert f'{sag:.4g} mm' in str(err.value)
    build_model({**bulge, 'lens.image_distance_mm': 1.1 * sag})


def test_sensor_across_the_exit_pupil_is_refused() -> None:
    build_model({**FAR_STOP, 'lens.image_distance_mm': 50.0})    # v_K > 0: a camera
    with pytest.raises(ModelError) as err:
        build_model({**FAR_STOP, 'lens.image_distance_mm': 70.0})
    assert err.value.parameter == 'lens.image_distance_mm'
    assert 'exit pupil (z = 90.8' in str(err.value)


def test_datasheet_lens_refuses_it() -> None:
    with pytest.raises(ModelError) as err:
        build_model({'sensor.width_px': 640, 'sensor.height_px': 480,
                     'lens.datasheet.field_angle_deg': [0.0, 10.0, 20.0],
                     'lens.datasheet.image_height_mm': [0.0, 1.0, 2.0],
                     'lens.focal_length_mm': 5.7, 'lens.image_distance_mm': 6.0})
    assert err.value.parameter == 'lens.image_distance_mm'
