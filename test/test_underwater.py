# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Underwater ports and water (issue 27, docs/underwater.md): the core, without ROS.

- refusals name their parameter (port geometry, water outside the formula, a datasheet lens);
- the 3-D trace through a port (optics/ports.py) equals the meridional trace of the same
  symmetric port to 1e-6 px, and the tilted/decentred ports' maps (radial + a splined 3-D
  residual) stay within 0.05 px of the exact per-point trace (the interpolation error);
- physics: a flat port multiplies the focal length by about n_w, seawater scales the image
  by about 0.5 % against fresh water, the water's dispersion gives lateral colour, a dome
  centred on the entrance pupil is nearly central and a flat port is not.

The agreement with optiland is test/test_underwater_reference.py.
"""

from __future__ import annotations

from pathlib import Path

from mechdeconv_ros.imaging.remap import build_float_maps
from mechdeconv_ros.lenses.lens_errors import ModelError
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.model.underwater import noncentral_errors, project_points, spline_weights
from mechdeconv_ros.schema.params import load_params_file
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SEA = {'scene.medium': 'seawater', 'scene.distance_mm': 1000.0}
FLAT = {**SEA, 'port.type': 'flat', 'port.glass': 'PMMA', 'port.distance_mm': 10.0,
        'port.thickness_mm': 5.0}
DOME = {**SEA, 'port.type': 'dome', 'port.glass': 'N-BK7', 'port.radius_mm': 40.0,
        'port.thickness_mm': 6.0}


def cooke(**overrides: object) -> dict:
    values = load_params_file(ROOT / 'config' / 'cooke_triplet.yaml')
    values.update({'scene.distance_mm': 1000.0, 'sensor.pixel_size_x_um': 5.0,
                   'sensor.pixel_size_y_um': 5.0})
    values.update(overrides)
    return values


@pytest.mark.parametrize('overrides,name', [
    ({**FLAT, 'port.thickness_mm': 0.0}, 'port.thickness_mm'),
    ({**FLAT, 'port.distance_mm': 0.0}, 'port.distance_mm'),
    ({**FLAT, 'port.distance_mm': 0.5, 'port.tilt_x_deg': 30.0}, 'port.distance_mm'),  # cuts
    ({**DOME, 'port.radius_mm': 10.0}, 'port.radius_mm'),          # the lens does not fit
    ({**DOME, 'port.radius_mm': 0.0}, 'port.radius_mm'),
    ({**FLAT, 'port.glass': 'UNOBTAINIUM'}, 'port.glass'),
    ({**FLAT, 'scene.medium_index': 0.9}, 'scene.medium_index'),
    ({**FLAT, 'scene.temperature_c': 31.0}, 'scene.temperature_c'),
    ({**FLAT, 'scene.salinity_psu': 36.0}, 'scene.salinity_psu'),
    ({**FLAT, 'lens.wavelength_nm': 800.0}, 'lens.wavelength_nm'),
    ({**FLAT, 'scene.distance_mm': 20.0}, 'scene.distance_mm'),      # inside the housing
])
def test_refusals_name_the_parameter(overrides: dict, name: str) -> None:
    with pytest.raises(ModelError) as err:
        build_model(cooke(**overrides))
    assert err.value.parameter == name, str(err.value)


def test_a_port_on_a_datasheet_lens_is_refused() -> None:
    values = load_params_file(ROOT / 'config' / 'case2.yaml')
    values.update({'lens.focal_length_mm': 4.0, 'lens.datasheet.field_angle_deg': [0.0, 20.0],
                   'lens.datasheet.image_height_mm': [0.0, 1.4], 'port.type': 'flat'})
    with pytest.raises(ModelError, match='datasheet') as err:
        build_model(values)
    assert err.value.parameter == 'port.type'


def test_water_outside_its_range_only_matters_in_water() -> None:
    # In air the water's temperature is not used (no refusal).
    build_model(cooke(**{'scene.temperature_c': 40.0}))


def test_flat_port_scales_the_focal_length_by_the_water_index() -> None:
    air = build_model(cooke())
    flat = build_model(cooke(**FLAT))
    n_w = flat.source.medium_index
    assert 1.33 < n_w < 1.35
    # A thin flat port close to the lens: f_water ~ n_w f_air (to a few percent).
    assert flat.K[0, 0] / air.K[0, 0] == pytest.approx(n_w, rel=0.03)
    fresh = build_model(cooke(**{**FLAT, 'scene.medium': 'water'}))
    # Fresh to 35 PSU: about 0.5 % in scale (Quan & Fry: 1.3339 -> 1.3402 at 550 nm).
    assert flat.K[0, 0] / fresh.K[0, 0] == pytest.approx(1.0047, abs=0.0015)
    # camera_info's equivalent is chosen and its error reported.
    assert flat.distortion_model in ('plumb_bob', 'rational_polynomial', 'equidistant')
    assert np.isfinite(flat.equivalent_max_error_px)


@pytest.mark.parametrize('port', [FLAT, DOME, {**DOME, 'port.center_offset_mm': 2.0}])
def test_the_3d_trace_equals_the_meridional_one_for_a_symmetric_port(port: dict) -> None:
    model = build_model(cooke(**port))
    tx, ty = np.meshgrid(np.linspace(-0.07, 0.07, 7), np.linspace(-0.04, 0.04, 5))
    u, v = project_points(model, tx, ty)           # the traced lines (assembly.project)
    a, b = model.source.sensor_points(tx, ty, 1000.0)
    u3 = model.K[0, 2] + a / model.pixel_mm[0]
    v3 = model.K[1, 2] + b / model.pixel_mm[1]
    assert np.all(np.isfinite(u3))
    assert np.max(np.hypot(u3 - u, v3 - v)) < 1e-5


def test_tilt_and_decentre_signs() -> None:
    # tilt_x > 0 brings the port part seen at larger v closer: the image of the axis moves.
    base = build_model(cooke(**FLAT))
    tilted = build_model(cooke(**{**FLAT, 'port.tilt_x_deg': 1.0}))
    u0, v0 = project_points(base, 0.0, 0.0)
    u1, v1 = project_points(tilted, 0.0, 0.0)
    assert abs(float(u1 - u0)) < 1e-6 < abs(float(v1 - v0))
    tilted_y = build_model(cooke(**{**FLAT, 'port.tilt_y_deg': 1.0}))
    u2, v2 = project_points(tilted_y, 0.0, 0.0)
    assert abs(float(v2 - v0)) < 1e-6 < abs(float(u2 - u0))
    # A plate turned by a: the axis ray refracts into the water by about (1 - 1/n) a. By
    # value: the water ray along the axis leaves the plate turned away from its normal, which
    # tilts toward -y (the y > 0 part came closer), so into +y in the air: the lens images
    # it as a direction above the axis, at a smaller v; tilt_y likewise at a smaller u.
    # (test/test_underwater_ports.py checks the whole image against the plate's closed form.)
    shift = (1.0 - 1.0 / tilted.source.medium_index) * np.radians(1.0) * tilted.K[1, 1]
    assert float(v1 - v0) == pytest.approx(-shift, rel=0.1)
    assert float(u2 - u0) == pytest.approx(-shift * tilted.K[0, 0] / tilted.K[1, 1], rel=0.1)


def test_spline_weights_reproduce_cubics_inside() -> None:
    nodes = np.arange(9.0)
    q = np.linspace(0.0, 8.0, 101)
    w = spline_weights(9, q)
    assert np.allclose(w @ (2.0 * nodes + 1.0), 2.0 * q + 1.0)
    assert np.allclose(w.sum(axis=1), 1.0)


@pytest.mark.parametrize('port', [
    {**FLAT, 'port.tilt_x_deg': 1.0, 'port.tilt_y_deg': -0.5},
    {**DOME, 'port.decenter_x_mm': 1.0, 'port.decenter_y_mm': -1.0}])
def test_remap_of_a_non_symmetric_port_within_0_05_px(port: dict) -> None:
    model = build_model(cooke(**port, **{'sensor.width_px': 1920, 'sensor.height_px': 1080}))
    map_x, map_y = build_float_maps(model)
    rng = np.random.default_rng(7)
    u = rng.integers(0, model.out_width, 400)
    v = rng.integers(0, model.out_height, 400)
    xn = (u - model.K_new[0, 2]) / model.K_new[0, 0]
    yn = (v - model.K_new[1, 2]) / model.K_new[1, 1]
    eu, ev = project_points(model, xn, yn)
    err = np.hypot(map_x[v, u] - eu, map_y[v, u] - ev)
    assert np.all(np.isfinite(err))
    assert np.max(err) < 0.05
    # ... and the residual really matters (the symmetric maps alone would be off).
    assert np.max(np.hypot(*model.raw_from_rect(np.stack([u, v], 1)).T - np.stack([eu, ev]))) \
        > 1.0


def test_noncentral_error() -> None:
    flat = noncentral_errors(build_model(cooke(**FLAT)))
    dome = noncentral_errors(build_model(cooke(**DOME)))
    assert flat['noncentral_error_px_half'] > 0.1
    assert flat['noncentral_error_px_half'] > 1.5 * flat['noncentral_error_px_twice'] > 0
    assert dome['noncentral_error_px_half'] < 0.5 * flat['noncentral_error_px_half']
    # In air without a port: not reported.
    assert noncentral_errors(build_model(cooke())) == dict.fromkeys(
        ('noncentral_error_px_half', 'noncentral_error_px_twice'))
    report = build_model(cooke(**FLAT)).report()
    assert report['noncentral_error_px_half'] == pytest.approx(flat['noncentral_error_px_half'])


def test_water_dispersion_gives_lateral_colour() -> None:
    # The wide-angle config has fixed glass indices (no dispersion of its own): in water the
    # channels separate by the water's and the port's dispersion alone.
    values = load_params_file(ROOT / 'config' / 'wide_angle.yaml')
    values.update({**FLAT, 'output.lateral_color_correction': True})
    model = build_model(values)
    assert model.lateral_color().max_rb_separation_px > 1.0


def test_zmx_object_in_water(tmp_path: Path) -> None:
    from mechdeconv_ros.lenses.lens_import import import_zmx
    from mechdeconv_ros.lenses.zmx import LensImportError
    from mechdeconv_ros.optics.water import water_index

    text = (ROOT / 'test' / 'data' / 'zmx' / 'edmund_55278.zmx').read_text('utf-16')
    for glass, salinity in (('WATER', 0.0), ('SEAWATER', 35.0)):
        path = tmp_path / f'{glass}.zmx'
        path.write_text(text.replace('SURF 0\n', f'SURF 0\n  GLAS {glass} 0 0 1.333 55.0\n',
                                     1), 'utf-8')
        imported = import_zmx(path, 550.0)
        assert imported.values['scene.medium_index'] == pytest.approx(
            water_index(550.0, 20.0, salinity))
        assert any('object space is' in w for w in imported.warnings)
    path = tmp_path / 'oil.zmx'
    path.write_text(text.replace('SURF 0\n', 'SURF 0\n  GLAS N-BK7 0 0 1.5 60.0\n', 1),
                    'utf-8')
    with pytest.raises(LensImportError, match='water glass it can name'):
        import_zmx(path, 550.0)


def test_the_shipped_example(tmp_path: Path) -> None:
    import json
    import subprocess
    import sys

    values = load_params_file(ROOT / 'config' / 'underwater_flat.yaml')
    model = build_model(values)
    errors = noncentral_errors(model)
    # docs/underwater.md quotes these: 0.22 px at 1 m, 0.11 px at 4 m.
    assert errors['noncentral_error_px_half'] == pytest.approx(0.223, abs=0.01)
    assert errors['noncentral_error_px_twice'] == pytest.approx(0.112, abs=0.01)
    # `mechdeconv project` (the CLI) through the port: the axis lands on the principal point.
    csv = tmp_path / 'dirs.csv'
    csv.write_text('0.0,0.0\n0.02,-0.01\n')
    out = subprocess.run([sys.executable, '-m', 'mechdeconv_ros.tools.cli', 'project',
                          '--params', str(ROOT / 'config' / 'underwater_flat.yaml'), str(csv)],
                         capture_output=True, text=True, check=True).stdout.split()
    first = [float(x) for x in out[0].split(',')]
    assert first[2:] == pytest.approx([model.K[0, 2], model.K[1, 2]], abs=1e-6)
    u, v = project_points(model, 0.02, -0.01)
    assert [float(x) for x in out[1].split(',')][2:] == pytest.approx([float(u), float(v)])
    report = json.loads(subprocess.run(
        [sys.executable, '-m', 'mechdeconv_ros.tools.cli', 'info', '--json', '--params',
         str(ROOT / 'config' / 'underwater_flat.yaml')], capture_output=True, text=True,
        check=True).stdout)
    assert report['noncentral_error_px_half'] == pytest.approx(
        errors['noncentral_error_px_half'])
