# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
correct_node with glass by name: lens.glass, lens.wavelength_nm, lens.surfaces.glass.

Real rclpy, the node in its own process (the harness of test_node.py, started once for this
module): ``ros2 param set lens.wavelength_nm 850.0`` is a set_parameters call, and the
published K must become the one of the glass's index at 850 nm (computed in-process by
build_model and checked against the thick-lens closed form).
"""

from __future__ import annotations

from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.node.image_msgs import image_to_array
from mechdeconv_ros.optics import glass
from mechdeconv_ros.optics import thick_lens
import numpy as np
import numpy.testing as npt
import pytest
from rclpy.parameter import Parameter
from ros_helpers import make_image
from test_node import (  # noqa: F401 - harness, outputs: fixtures of this module too
    _exchange_until_model, assert_camera_infos, double, expected_model, Harness, harness,
    Outputs, outputs, SMALL, test_pattern)

pytestmark = pytest.mark.ros


def string(name: str, value: str) -> Parameter:
    """Return a STRING parameter."""
    return Parameter(name, Parameter.Type.STRING, value)


def test_wavelength_set_rebuilds_with_the_glass_index(
        harness: Harness, outputs: Outputs) -> None:  # noqa: F811 - test_node's fixtures
    width, height = SMALL
    src = test_pattern(width, height)
    msg = make_image(src, 'mono8')
    try:
        results = harness.client.set_parameters(string('lens.glass', 'N-BK7'))
        assert [r.successful for r in results] == [True], results[0].reason
        harness.values['lens.glass'] = 'N-BK7'
        at_d = expected_model(harness.values, width, height)
        assert_camera_infos(_exchange_until_model(harness, outputs, msg, at_d), at_d)

        results = harness.client.set_parameters(double('lens.wavelength_nm', 850.0))
        assert [r.successful for r in results] == [True], results[0].reason
        harness.values['lens.wavelength_nm'] = 850.0
        at_850 = expected_model(harness.values, width, height)
        got = _exchange_until_model(harness, outputs, msg, at_850)
        assert_camera_infos(got, at_850)
        # The published K is the thick lens's at N-BK7's index at 850 nm: f from eq. 8,
        # v = f l / (l - f), f_x = v / p_x.
        n = glass.refractive_index('N-BK7', 850.0)
        f = thick_lens.thick_lens_focal_length(n, harness.values['lens.r1_mm'],
                                               harness.values['lens.r2_mm'],
                                               harness.values['lens.thickness_mm'])
        distance = harness.values['scene.distance_mm']
        fx = f * distance / (distance - f) / (harness.values['sensor.pixel_size_x_um'] * 1e-3)
        npt.assert_allclose(got['info'].k[0], fx, rtol=1e-9)
        assert got['info'].k[0] > at_d.K[0, 0] * 1.005     # n falls: f grows by ~1.2 %
        image, _ = image_to_array(got['image'])
        npt.assert_array_equal(image, Rectifier(at_850).correct(src))

        # A wavelength the glass's formula does not cover is refused, naming it; the model
        # stays.
        revision = harness.revision()
        result = harness.client.set_parameters_atomically(
            double('lens.wavelength_nm', 2490.0), string('lens.glass', 'HOYA:TAFD25'))
        assert not result.successful
        assert 'lens.wavelength_nm' in result.reason and '365.01-1013.98 nm' in result.reason
        results = harness.client.set_parameters(string('lens.glass', 'N-BK8'))
        assert not results[0].successful
        assert 'lens.glass' in results[0].reason and 'SCHOTT:N-BK7' in results[0].reason
        assert harness.client.get_parameters('lens.glass') == {'lens.glass': 'N-BK7'}
        assert_camera_infos(_exchange_until_model(harness, outputs, msg, at_850), at_850)
        assert harness.revision() == revision
    finally:
        restore = harness.client.set_parameters_atomically(
            string('lens.glass', ''), double('lens.wavelength_nm', 587.56))
        assert restore.successful, restore.reason
        harness.values.update({'lens.glass': '', 'lens.wavelength_nm': 587.56})
    model = expected_model(harness.values, width, height)
    assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)


def test_surface_glasses_are_a_string_array(
        harness: Harness, outputs: Outputs) -> None:  # noqa: F811 - test_node's fixtures
    width, height = SMALL
    msg = make_image(test_pattern(width, height), 'mono8')
    assert harness.client.get_parameters('lens.surfaces.glass') == {'lens.surfaces.glass': []}
    change = {'lens.surfaces.radius_mm': [4.0, -4.0], 'lens.surfaces.thickness_mm': [3.0, 0.0],
              'lens.surfaces.refractive_index': [1.5, 1.0]}
    params = [Parameter(k, Parameter.Type.DOUBLE_ARRAY, v) for k, v in change.items()]
    params.append(Parameter('lens.surfaces.glass', Parameter.Type.STRING_ARRAY,
                            ['S-LAH66', 'AIR']))
    result = harness.client.set_parameters_atomically(*params)
    assert result.successful, result.reason
    try:
        values = dict(harness.values, **change, **{'lens.surfaces.glass': ['S-LAH66', 'AIR']})
        model = expected_model(values, width, height)
        assert model.prescription.surfaces[0].refractive_index == glass.refractive_index(
            'S-LAH66', 587.56)
        assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)
        # One name per surface: a wrong count is refused naming the parameter.
        result = harness.client.set_parameters_atomically(
            Parameter('lens.surfaces.glass', Parameter.Type.STRING_ARRAY, ['S-LAH66']))
        assert not result.successful and 'lens.surfaces.glass' in result.reason
    finally:
        restore = [Parameter(k, Parameter.Type.DOUBLE_ARRAY, []) for k in change]
        restore.append(Parameter('lens.surfaces.glass', Parameter.Type.STRING_ARRAY, []))
        cleared = harness.client.set_parameters_atomically(*restore)
        assert cleared.successful, cleared.reason
    model = expected_model(harness.values, width, height)
    assert_camera_infos(_exchange_until_model(harness, outputs, msg, model), model)
    assert np.isfinite(model.K).all()
