# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The parameter schema: defaults, coercion, params files."""

from __future__ import annotations

import math
from pathlib import Path

from mechdeconv_ros.schema import params
import pytest
import yaml

CONFIG = Path(__file__).resolve().parents[1] / 'config'


def test_schema_is_consistent():
    names = [spec.name for spec in params.SCHEMA]
    assert len(names) == len(set(names))
    for spec in params.SCHEMA:
        assert spec.type in ('double', 'integer', 'string', 'bool', 'double_array',
                             'integer_array', 'string_array')
        assert spec.description.endswith('.'), spec.name
        # Every default passes its own checks.
        assert params.coerce(spec, spec.default) == spec.default
        if spec.minimum is not None and spec.maximum is not None:
            assert spec.minimum < spec.maximum


def test_issue_contract_names_are_declared():
    contract = """lens.refractive_index lens.r1_mm lens.r2_mm lens.thickness_mm
    lens.aperture_diameter_mm lens.stop_offset_mm lens.focal_length_mm lens.exposure_constant_q
    lens.tolerance.r1_mm lens.tolerance.r2_mm lens.tolerance.thickness_mm
    lens.tolerance.refractive_index lens.tolerance.aperture_diameter_mm
    lens.surfaces.radius_mm lens.surfaces.thickness_mm lens.surfaces.refractive_index
    lens.surfaces.semi_diameter_mm lens.stop_surface sensor.pixel_size_x_um
    sensor.pixel_size_y_um sensor.width_px sensor.height_px scene.distance_mm
    scene.focus_distance_mm scene.circle_of_confusion_mm output.alpha output.interpolation
    output.width_px output.height_px""".split()
    # Issue 14: the vignetting correction.
    contract += ['output.vignetting_correction', 'output.max_vignetting_gain']
    # Issue 11: aspheric surfaces.
    contract += ['lens.surfaces.conic', 'output.projection'] + [
        f'lens.surfaces.asphere_a{p}' for p in (4, 6, 8, 10, 12, 14, 16)]
    # Issue 18: glass by name, the sensor's distance, datasheet lenses.
    contract += ['lens.glass', 'lens.wavelength_nm', 'lens.surfaces.glass',
                 'lens.image_distance_mm', 'lens.datasheet.field_angle_deg',
                 'lens.datasheet.image_height_mm', 'lens.datasheet.relative_illumination']
    # Issue 20: lateral colour (debayer is a node parameter: no model change).
    contract += ['output.lateral_color_correction', 'lens.channel_wavelengths_nm']
    assert 'debayer' in params.SPECS and 'debayer' not in params.MODEL_PARAMS
    # Issue 19: moving groups.
    contract += [f'lens.{m}.{k}' for m in ('zoom', 'focus')
                 for k in ('joint', 'positions', 'surfaces', 'thickness_mm')]
    # Issue 25: the camera as assembled (sensor offset and tilt, and their tolerances).
    contract += [f'sensor.{k}' for k in ('axis_offset_x_mm', 'axis_offset_y_mm', 'tilt_x_deg',
                                         'tilt_y_deg')]
    contract += [f'sensor.tolerance.{k}' for k in ('axis_offset_x_mm', 'axis_offset_y_mm',
                                                   'tilt_x_deg', 'tilt_y_deg')]
    # Issue 26: the straight-edge check (its check.* are node parameters: no model change).
    contract += ['lens.tolerance.image_distance_mm']
    for name in ('check.rate_hz', 'check.window', 'check.max_rms_px', 'check.apply'):
        assert name in params.SPECS and name not in params.MODEL_PARAMS
    # Issue 27: underwater (the scene's medium and the port).
    contract += ['scene.medium', 'scene.salinity_psu', 'scene.temperature_c',
                 'scene.medium_index', 'port.type', 'port.thickness_mm', 'port.glass',
                 'port.refractive_index', 'port.distance_mm', 'port.tilt_x_deg',
                 'port.tilt_y_deg', 'port.radius_mm', 'port.center_offset_mm',
                 'port.decenter_x_mm', 'port.decenter_y_mm']
    assert set(contract) <= set(params.SPECS)
    assert set(contract) == set(params.MODEL_PARAMS)


@pytest.mark.parametrize('name, value, expected', [
    ('lens.r1_mm', 5, 5.0),
    ('sensor.width_px', 640.0, 640),
    ('output.interpolation', 'cubic', 'cubic'),
    ('lens.surfaces.radius_mm', (1, 2.5), [1.0, 2.5]),
    ('lazy_subscription', False, False),
    ('lens.surfaces.glass', ('N-BK7', ''), ['N-BK7', '']),
], ids=['int-for-double', 'whole-float-for-int', 'choice', 'tuple-array', 'bool',
        'string-array'])
def test_coerce_accepts(name, value, expected):
    assert params.coerce(params.SPECS[name], value) == expected


@pytest.mark.parametrize('name, value, words', [
    ('lens.r1_mm', math.inf, 'finite'),
    ('lens.r1_mm', 'four', 'expected a number'),
    ('lens.r1_mm', True, 'expected a number'),
    ('lens.refractive_index', 0.9, 'below the minimum 1'),
    ('sensor.width_px', 640.5, 'integer'),
    ('output.interpolation', 'area', 'one of nearest, linear, cubic, lanczos4'),
    ('lens.surfaces.radius_mm', [1.0, math.nan], 'lens.surfaces.radius_mm[1]'),
    ('lazy_subscription', 1, 'true or false'),
    ('lens.surfaces.glass', ['N-BK7', 1.5], 'list of strings'),
    ('lens.surfaces.glass', 'N-BK7', 'list of strings'),
], ids=['inf', 'string', 'bool-for-double', 'below-range', 'fraction', 'choice',
        'nan-in-array', 'int-for-bool', 'number-in-string-array', 'string-for-array'])
def test_coerce_refuses_with_the_name(name, value, words):
    with pytest.raises(ValueError) as info:
        params.coerce(params.SPECS[name], value)
    assert str(info.value).startswith(name)
    assert words in str(info.value)


def test_unknown_names_are_refused():
    with pytest.raises(ValueError, match='unknown parameter'):
        params.check_values({'lens.r3_mm': 1.0})


@pytest.mark.parametrize('path', sorted(CONFIG.glob('*.yaml')), ids=lambda p: p.name)
def test_config_files_load(path):
    if path.name.startswith('stereo'):      # stereo_node's params (issue 38)
        from mechdeconv_ros.schema.stereo_params import load_stereo_params_file, STEREO_SPECS
        assert set(load_stereo_params_file(path)) == set(STEREO_SPECS)
    else:
        values = params.load_params_file(path)
        assert set(values) == set(params.SPECS)
    text = path.read_text()
    assert text.lstrip().startswith('#'), 'config files record their source in a comment'


def test_params_yaml_round_trip(tmp_path):
    values = params.defaults()
    values['lens.surfaces.radius_mm'] = [10.0, -10.0]
    path = tmp_path / 'p.yaml'
    path.write_text(params.to_params_yaml(values))
    assert params.load_params_file(path) == values


def test_params_file_sections(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    lens: {r1_mm: 5.0}\n'
                    'correct_node:\n  ros__parameters:\n    lens: {r2_mm: -6.0}\n'
                    'other:\n  ros__parameters:\n    lens: {thickness_mm: 9.0}\n')
    values = params.load_params_file(path)
    assert (values['lens.r1_mm'], values['lens.r2_mm'], values['lens.thickness_mm']) == \
        (5.0, -6.0, 3.0)
    path.write_text('just: text\n')
    with pytest.raises(ValueError, match='ros__parameters'):
        params.load_params_file(path)


def test_integer_arrays_coerce_and_write_back():
    spec = params.SPECS['lens.zoom.surfaces']
    assert params.coerce(spec, [4, 9.0]) == [4, 9]
    for bad, words in (([4.5], 'expected an integer'), ([300], '300 is above the maximum'),
                       ([-1], '-1 is below the minimum'), (['4'], 'expected a number')):
        with pytest.raises(ValueError, match=r'lens\.zoom\.surfaces\[0\]: ' + words):
            params.coerce(spec, bad)
    text = params.to_params_yaml({'lens.zoom.surfaces': [4, 9]})
    assert yaml.safe_load(text)['/**']['ros__parameters']['lens']['zoom']['surfaces'] == [4, 9]
