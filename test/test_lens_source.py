# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The lens-source seam: today's two sources, and a source that knows only a height table."""

from __future__ import annotations

import math

from mechdeconv_ros.lenses import lens_source as ls
from mechdeconv_ros.lenses.sources import source_for
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import check_values
from mechdeconv_ros.tools.cli import format_report
import numpy as np
from numpy.testing import assert_allclose
import pytest

CASE2 = {'sensor.width_px': 640, 'sensor.height_px': 480}
PRESCRIPTION = {**CASE2, 'lens.surfaces.radius_mm': [10.0, -10.0],
                'lens.surfaces.thickness_mm': [2.0, 5.0],
                'lens.surfaces.refractive_index': [1.5, 1.0], 'lens.stop_surface': 0,
                'lens.aperture_diameter_mm': 1.0}


class _Table(ls.LensSource):
    """A source written as a new one would be: it imports only the seam (``ls``)."""

    mode = 'table'
    lens_parameter = 'lens.table'
    stop_parameter = 'lens.table'

    def __init__(self, values, efl_mm, k1=0.0):
        self.values = values
        self.efl_mm = efl_mm
        # Real heights of a table: f tan(theta) (1 + k1 tan^2 theta), up to 60 deg.
        self.theta = np.linspace(0.0, math.radians(60.0), 1201)
        tan = np.tan(self.theta)
        self.height = efl_mm * tan * (1.0 + k1 * tan * tan)

    def first_order(self):
        return ls.FirstOrder(self.efl_mm, 0.0, 0.0)

    def real_heights(self, field_angle_rad, distance_mm, guide=None):
        theta = np.asarray(field_angle_rad, dtype=np.float64)
        real = np.interp(theta, self.theta, self.height, right=np.nan)
        return real, None


@pytest.mark.parametrize('values, kind', [
    (CASE2, ls.ThickLensSource), (PRESCRIPTION, ls.PrescriptionSource)],
    ids=['thick', 'prescription'])
def test_the_values_pick_their_source_and_the_model_is_the_same_through_it(values, kind):
    """build_model with the source it would pick itself gives the same model."""
    checked = check_values(values)
    source = source_for(checked)
    assert type(source) is kind
    assert source.prescription is not None and source.stop_z_mm is not None
    by_values = build_model(values)
    by_source = build_model(values, source=source)
    assert by_source.summary['mode'] == kind.mode
    assert by_values.D == by_source.D
    assert_allclose(by_source.curve.real_mm, by_values.curve.real_mm, rtol=0, atol=0)


def test_a_table_source_plugs_in_and_says_what_does_not_apply():
    """A height table without surfaces builds a model; tolerances and illumination say n/a."""
    values = {**CASE2, 'scene.distance_mm': 0.0}
    table = _Table(check_values(values), 6.0)
    model = build_model(values, source=table)
    assert model.prescription is None
    assert_allclose(model.focal_length_mm, 6.0)
    assert_allclose(model.image_distance_mm, 6.0)     # scene at infinity: v = f
    # No distortion in the table: the corrected image is the raw one.
    assert model.max_displacement_px < 1e-3
    assert model.distortion_model == 'plumb_bob'
    assert model.equivalent_max_error_px < 1e-3
    summary = model.summary
    assert summary['mode'] == 'table' and summary['stop_z_mm'] is None
    assert math.isnan(summary['focal_length_sigma_mm'])
    assert math.isnan(summary['corner_sigma_px'])
    with pytest.raises(ls.NotApplicable):
        model.illumination()
    report = model.report()
    assert report['relative_illumination'] is None
    assert any('relative illumination' in w for w in report['warnings'])
    assert 'lens (table)' in format_report(report)


def test_a_table_with_barrel_distortion_is_fitted():
    """The table's distortion reaches D: a barrel table gives k1 < 0."""
    values = {**CASE2, 'scene.distance_mm': 0.0}      # at infinity v = f: r_d = r_real / f
    model = build_model(values, source=_Table(check_values(values), 6.0, k1=-0.05))
    assert model.distortion_model == 'plumb_bob'
    assert_allclose(model.D[0], -0.05, rtol=0.05)
    assert model.max_displacement_px > 1.0


def test_a_table_that_ends_inside_the_sensor_refuses_with_its_parameter():
    """A table too short for the sensor is refused naming the source's parameter."""
    values = {**CASE2, 'sensor.pixel_size_x_um': 1000.0, 'sensor.pixel_size_y_um': 1000.0}
    table = _Table(check_values(values), 1.0)
    table.theta, table.height = table.theta[:2], table.height[:2]
    with pytest.raises(ls.ModelError) as err:
        build_model(values, source=table)
    assert err.value.parameter == 'lens.table'
