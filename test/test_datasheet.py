# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Datasheet lenses (lens.datasheet.*): the table's interpolant, the TABLE source, its refusals.

Accuracy: an M12-class lens (config/wide_angle.yaml scaled to f = 4.0 mm, 2 um pixels,
3840x2880 px so the sensor holds its whole image circle) traced exactly, then given only as a
table every 5 deg of its own traced heights: the table's model reproduces the traced one
within 0.1 px over the whole field (docs/design.md section 2.13 quotes the measured error).
"""

from __future__ import annotations

import math

from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.lenses import datasheet as ds
from mechdeconv_ros.model.camera_yaml import camera_info_yaml
from mechdeconv_ros.model.model import build_model, ModelError
from mechdeconv_ros.schema.params import load_params_file
from mechdeconv_ros.tools.cli import format_report
from mechdeconv_ros.tools.plots import plot_model
import numpy as np
from numpy.testing import assert_allclose
import pytest
from ros_helpers import REPO

pytestmark = pytest.mark.filterwarnings('error')

PIXEL_MM = 0.002
SCALE = 4.0 / 1.889      # config/wide_angle.yaml has f = 1.889 mm


@pytest.fixture(scope='module')
def m12() -> dict:
    """Return the M12-class lens's values, its traced model and its 5-deg table's values."""
    values = load_params_file(REPO / 'config' / 'wide_angle.yaml')
    for key in ('lens.surfaces.radius_mm', 'lens.surfaces.thickness_mm',
                'lens.surfaces.semi_diameter_mm'):
        values[key] = [x * SCALE for x in values[key]]
    values['lens.aperture_diameter_mm'] *= SCALE
    values.update({'sensor.width_px': 3840, 'sensor.height_px': 2880,
                   'sensor.pixel_size_x_um': 1e3 * PIXEL_MM,
                   'sensor.pixel_size_y_um': 1e3 * PIXEL_MM, 'scene.distance_mm': 0.0})
    traced = build_model(values)
    last = math.degrees(traced.field_curve.max_field_angle_rad)
    angles = np.arange(0.0, last, 5.0)
    heights, _ = traced.source.real_heights(np.radians(angles), math.inf)
    table = {k: ([] if k.startswith('lens.surfaces.') else v) for k, v in values.items()}
    table.update(ds.table_params(angles, heights, traced.focal_length_mm))
    return {'values': values, 'traced': traced, 'table': table, 'angles': angles,
            'heights': heights}


def test_m12_lens_is_m12_class(m12: dict) -> None:
    assert_allclose(m12['traced'].focal_length_mm, 4.0, rtol=1e-3)
    assert m12['angles'][-1] >= 85.0


@pytest.mark.parametrize('projection', ['pinhole', 'equidistant'])
def test_table_every_5_deg_reproduces_the_trace_within_a_tenth_of_a_pixel(
        m12: dict, projection: str) -> None:
    traced = build_model({**m12['values'], 'output.projection': projection})
    table = build_model({**m12['table'], 'output.projection': projection})
    assert table.summary['mode'] == 'datasheet'
    assert_allclose(table.K, traced.K, rtol=1e-12)
    # The radial map over the whole valid field (both end at the table's last angle or
    # before), in pixels.
    end = min(table.curve.valid_ideal_mm, traced.curve.valid_ideal_mm)
    ideal = np.linspace(0.0, end, 4001)
    error_px = np.abs(table.curve.real_from_ideal(ideal)
                      - traced.curve.real_from_ideal(ideal)) / PIXEL_MM
    assert np.nanmax(error_px) < 0.1, np.nanmax(error_px)
    assert np.nanmax(error_px) < 0.02      # measured: 2e-3 and 6e-3 px (design.md 2.13)
    real = np.linspace(0.0, min(table.curve.valid_real_mm, traced.curve.valid_real_mm), 2001)
    assert_allclose(table.curve.angle_from_real(real), traced.curve.angle_from_real(real),
                    atol=0.05 * PIXEL_MM / 4.0)


@pytest.mark.parametrize('projection', ['pinhole', 'equidistant'])
def test_downstream_of_the_table_matches_the_trace(m12: dict, projection: str) -> None:
    # A 6.4 x 4.8 mm sensor: its corners (76 deg) inside the table's last point (90 deg).
    size = {'sensor.width_px': 3200, 'sensor.height_px': 2400, 'output.projection': projection}
    traced = build_model({**m12['values'], **size})
    table = build_model({**m12['table'], **size})
    # The corrected camera, the equivalent calibration and the displacement all follow.
    assert_allclose(table.K_new, traced.K_new, rtol=1e-5)
    assert table.distortion_model == traced.distortion_model
    assert abs(table.max_displacement_px - traced.max_displacement_px) < 0.1
    assert abs(table.equivalent_max_error_px - traced.equivalent_max_error_px) < 0.1
    points = np.stack(np.meshgrid(np.linspace(0, 3199, 9), np.linspace(0, 2399, 7)), -1)
    assert np.nanmax(np.abs(table.raw_from_rect(points) - traced.raw_from_rect(points))) < 0.1


def test_ten_degree_table_is_still_within_a_tenth_of_a_pixel(m12: dict) -> None:
    angles = m12['angles'][::2]
    table = {**m12['table'], **ds.table_params(angles, m12['heights'][::2],
                                               m12['traced'].focal_length_mm)}
    model = build_model(table)
    ideal = np.linspace(0.0, model.curve.valid_ideal_mm, 2001)
    error = np.abs(model.curve.real_from_ideal(ideal)
                   - m12['traced'].curve.real_from_ideal(ideal)) / PIXEL_MM
    assert np.nanmax(error) < 0.1, np.nanmax(error)


def test_report_plot_camera_info_and_correction_work_for_a_table(m12: dict, tmp_path) -> None:
    model = build_model({**m12['table'], 'sensor.width_px': 640, 'sensor.height_px': 480,
                         'sensor.pixel_size_x_um': 12.0, 'sensor.pixel_size_y_um': 12.0})
    report = model.report()
    assert report['mode'] == 'datasheet' and report['surfaces'] is None
    assert report['sensor_plane'] is None and report['stop_z_mm'] is None
    assert math.isnan(model.summary['focal_length_sigma_mm'])
    assert ds.NOT_APPLICABLE in report['warnings']
    assert 'lens (datasheet)' in format_report(report)
    assert 'distortion_model' in camera_info_yaml(model)
    plot_model(model, tmp_path / 'table.png')
    assert (tmp_path / 'table.png').stat().st_size > 10_000
    image = np.full((480, 640), 200, np.uint8)
    assert Rectifier(model).correct(image).shape == (480, 640)


def test_relative_illumination_from_the_table_drives_the_gain_map(m12: dict) -> None:
    angles = m12['angles']
    ri = np.cos(np.radians(angles)) ** 2 * 0.9 + 0.1
    values = {**m12['table'], 'sensor.width_px': 640, 'sensor.height_px': 480,
              'sensor.pixel_size_x_um': 12.0, 'sensor.pixel_size_y_um': 12.0,
              'lens.datasheet.relative_illumination': ri.tolist(),
              'output.vignetting_correction': True}
    model = build_model(values)
    curve = model.illumination()
    assert curve.ri[0] == 1.0
    theta = model.field_curve.angle_from_real(curve.height_mm)
    inside = np.isfinite(theta)
    assert_allclose(curve.ri[inside], np.interp(theta[inside], np.radians(angles), ri),
                    rtol=1e-12)
    assert np.all(curve.ri[~inside] == 0.0)
    flat = np.full((480, 640), 100, np.uint8)
    corrected = Rectifier(model).correct(flat)
    assert corrected[240, 320] == 100
    assert corrected[240, 620] > 100     # brighter towards the edge
    with pytest.raises(ValueError, match='relative_illumination'):
        build_model({**values, 'lens.datasheet.relative_illumination': []}).illumination()


def test_finite_scene_scales_the_table_by_v_over_f() -> None:
    values = {'sensor.width_px': 640, 'sensor.height_px': 480,
              **ds.table_params([0.0, 10.0, 20.0, 30.0], [0.0, 1.0, 2.02, 3.08], 5.7),
              'scene.distance_mm': 500.0}
    model = build_model(values)
    v = 5.7 * 500.0 / (500.0 - 5.7)
    assert_allclose(model.image_distance_mm, v, rtol=1e-12)
    heights, _ = model.source.real_heights(np.radians([10.0, 20.0]), 500.0)
    assert_allclose(heights, np.array([1.0, 2.02]) * v / 5.7, rtol=1e-12)


def test_interpolant_is_exact_at_the_points_with_slope_f_at_the_axis() -> None:
    table = ds.make_table({ds.FIELD: [5.0, 15.0, 25.0, 40.0], ds.HEIGHT: [0.5, 1.52, 2.6, 4.5],
                           ds.FOCAL: 5.7})
    assert not table.monotone_fallback
    assert_allclose(table.height(np.radians([0.0, 5.0, 15.0, 25.0, 40.0])),
                    [0.0, 0.5, 1.52, 2.6, 4.5], rtol=1e-13, atol=1e-15)
    eps = 1e-7
    assert_allclose(table.height(np.array([eps]))[0] / eps, 5.7, rtol=1e-6)
    assert math.isnan(table.height(np.radians([40.5]))[0])


def test_spline_reproduces_a_cubic_and_pchip_stays_monotone() -> None:
    x = np.array([0.0, 0.3, 1.0, 1.7, 3.0])
    y = 1.0 - 2.0 * x + 0.5 * x ** 2 + 0.25 * x ** 3
    assert_allclose(ds.spline_slopes(x, y), -2.0 + x + 0.75 * x ** 2, rtol=1e-12, atol=1e-12)
    steps = np.array([0.0, 1.0, 1.05, 1.1, 3.0])
    d = ds.pchip_slopes(x, steps, 5.0)
    dense = np.linspace(0.0, 3.0, 3001)
    k = np.clip(np.searchsorted(x, dense, side='right') - 1, 0, 3)
    h = x[k + 1] - x[k]
    t = (dense - x[k]) / h
    value = ((2 * t ** 3 - 3 * t ** 2 + 1) * steps[k] + (t ** 3 - 2 * t ** 2 + t) * h * d[k]
             + (3 * t ** 2 - 2 * t ** 3) * steps[k + 1] + (t ** 3 - t ** 2) * h * d[k + 1])
    assert np.all(np.diff(value) >= 0.0)


def test_a_table_whose_spline_would_fold_falls_back_to_pchip() -> None:
    # A plateau after a steep rise: the spline overshoots, PCHIP does not.
    table = ds.make_table({ds.FIELD: [0.0, 10.0, 20.0, 21.0, 22.0, 40.0],
                           ds.HEIGHT: [0.0, 1.0, 3.0, 3.001, 3.002, 3.003], ds.FOCAL: 5.7})
    assert table.monotone_fallback
    assert any('PCHIP' in w for w in table.warnings)
    dense = np.radians(np.linspace(0.0, 40.0, 4001))
    assert np.all(np.diff(table.height(dense)) > 0.0)


def test_table_params_checks_and_clears_the_prescription() -> None:
    params = ds.table_params([0, 10, 20], [0, 1, 2.1], 5.7, [1.0, 0.9, 0.8])
    assert params['lens.surfaces.radius_mm'] == []
    assert params[ds.ILLUMINATION] == [1.0, 0.9, 0.8]
    with pytest.raises(ds.TableError) as err:
        ds.table_params([0, 10, 20], [0, 1], 5.7)
    assert err.value.parameter == ds.HEIGHT


def test_focal_length_far_from_the_first_point_is_noted() -> None:
    table = ds.make_table({ds.FIELD: [0.0, 10.0], ds.HEIGHT: [0.0, 2.0], ds.FOCAL: 5.7})
    assert any('implies a focal length' in w for w in table.warnings)


BASE = {'sensor.width_px': 640, 'sensor.height_px': 480, 'lens.focal_length_mm': 5.7,
        ds.FIELD: [0.0, 10.0, 20.0], ds.HEIGHT: [0.0, 1.0, 2.02]}


@pytest.mark.parametrize(('change', 'parameter', 'needle'), [
    ({ds.HEIGHT: [0.0, 1.0]}, ds.HEIGHT, 'has 2 values'),
    ({ds.ILLUMINATION: [1.0, 0.9]}, ds.ILLUMINATION, 'has 2 values'),
    ({ds.FIELD: [0.0, 20.0, 10.0]}, ds.FIELD, 'not strictly increasing'),
    ({ds.FIELD: [0.0, 10.0, 10.0]}, ds.FIELD, 'not strictly increasing'),
    ({ds.HEIGHT: [0.0, 1.0, 1.0]}, ds.HEIGHT, 'does not increase'),
    ({ds.HEIGHT: [0.1, 1.0, 2.0]}, ds.HEIGHT, 'at 0 deg'),
    ({ds.FIELD: [1.0, 10.0, 20.0], ds.HEIGHT: [0.0, 1.0, 2.0]}, ds.HEIGHT, '> 0'),
    ({ds.HEIGHT: [0.0, math.nan, 2.0]}, ds.HEIGHT, 'finite'),
    ({ds.FIELD: [0.0, math.inf, 20.0]}, ds.FIELD, 'finite'),
    ({'lens.focal_length_mm': 0.0}, 'lens.focal_length_mm', 'effective focal length'),
    ({ds.ILLUMINATION: [1.0, 0.0, 0.5]}, ds.ILLUMINATION, '(0, 1.5]'),
    ({'lens.surfaces.radius_mm': [4.0, -4.0]}, 'lens.surfaces.radius_mm', 'both describe'),
    ({'lens.glass': 'N-BK7'}, 'lens.glass', 'does not apply'),
], ids=['heights-length', 'ri-length', 'angles-decrease', 'angles-repeat', 'heights-flat',
        'axis-height', 'off-axis-height', 'nan-height', 'inf-angle', 'no-focal-length',
        'ri-zero', 'prescription-too', 'glass'])
def test_refusals_name_the_parameter(change: dict, parameter: str, needle: str) -> None:
    with pytest.raises(ModelError) as err:
        build_model({**BASE, **change})
    assert err.value.parameter == parameter, str(err.value)
    assert needle in str(err.value), str(err.value)


def test_ignored_thick_lens_parameters_are_named_in_a_warning() -> None:
    model = build_model({**BASE, 'lens.r1_mm': 7.0, 'lens.wavelength_nm': 850.0})
    note = [w for w in model.warnings if 'not used by a datasheet lens' in w]
    assert note and 'lens.r1_mm' in note[0] and 'lens.wavelength_nm' in note[0]
    assert not any('not used' in w for w in build_model(BASE).warnings)
