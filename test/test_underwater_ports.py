# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Ports at the edges of their use (issue 37): infinity, air written out, the housing, 90 deg.

- a scene at infinity (``scene.distance_mm`` 0) behind a tilted flat port or a decentred dome
  is traced exactly: a direction at infinity has an exact image through any port (parallel
  rays in the water, the one through the stop centre); against a closed form for the flat
  port (a plane-parallel plate turns a parallel beam as one water-air face would, so the
  ported lens images the water direction d where the lens in air images d' = Snell(d) at
  the plate's normal, the normal built here from the parameter's documented geometry, not
  from the package), and as the limit of far scenes for the dome; on every route (info,
  correct, the remap; the node in test/test_node_underwater.py);
- ``scene.medium_index`` 1.0 is air: no port path, the relative illumination traced, a zoom
  lens accepted, the same pixels as air;
- a scene point in the housing (behind the port's outer face off the axis) has no pixel;
- the remap of a non-symmetric port takes no residual from a clamped angle, and masks the
  grid cells a node without an exact ray touches.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path
import re

import cv2
from mechdeconv_ros.imaging.remap import build_float_maps
from mechdeconv_ros.lenses.port_source import PortedSource
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.model.projection import pixels_of
from mechdeconv_ros.model.underwater import ideal_directions, project_points, residual_nodes
from mechdeconv_ros.optics.ports import trace_scene_points
from mechdeconv_ros.schema.params import (
    load_params_file, scene_distance, scene_in_air, to_params_yaml)
from mechdeconv_ros.tools import cli
import numpy as np
import numpy.testing as npt
import pytest

ROOT = Path(__file__).resolve().parents[1]
SEA = {'scene.medium': 'seawater', 'scene.salinity_psu': 35.0, 'scene.temperature_c': 15.0}
FLAT = {**SEA, 'port.type': 'flat', 'port.glass': 'PMMA', 'port.distance_mm': 10.0,
        'port.thickness_mm': 5.0}
DOME = {**SEA, 'port.type': 'dome', 'port.glass': 'N-BK7', 'port.radius_mm': 45.0,
        'port.thickness_mm': 6.0}


def config(name: str, **overrides: object) -> dict:
    values = load_params_file(ROOT / 'config' / f'{name}.yaml')
    values.update(overrides)
    return values


def plate_normal(tilt_x_deg: float, tilt_y_deg: float) -> np.ndarray:
    """
    Return the flat port's unit normal toward the lens from the parameters' documented words.

    One tilt at a time: tilt_x > 0 brings the part of the window at y > 0 closer to the lens
    (the plane holds the x axis and (0, cos a, sin a)); tilt_y > 0 the part at x > 0 (the
    plane holds the y axis and (cos b, 0, sin b)). Lens frame, light along +z.
    """
    a, b = math.radians(tilt_x_deg), math.radians(tilt_y_deg)
    assert a == 0.0 or b == 0.0
    if b == 0.0:
        u, w = np.array([1.0, 0.0, 0.0]), np.array([0.0, math.cos(a), math.sin(a)])
    else:
        u, w = np.array([math.cos(b), 0.0, math.sin(b)]), np.array([0.0, 1.0, 0.0])
    n = np.cross(u, w)
    return n / np.linalg.norm(n) * np.sign(n[2])


def snell(k: np.ndarray, n: np.ndarray, n0: float, n1: float) -> np.ndarray:
    """Return unit directions k (N, 3) refracted at the unit normal n (along the light)."""
    mu = n0 / n1
    cos_i = k @ n
    cos_t = np.sqrt(1.0 - mu * mu * (1.0 - cos_i * cos_i))
    return mu * k + (cos_t - mu * cos_i)[:, None] * n


DIRECTIONS = np.array([[0.0, 0.0, 1.0], [0.08, 0.0, 1.0], [0.0, 0.08, 1.0], [-0.06, 0.05, 1.0],
                       [0.1, -0.07, 1.0], [-0.12, -0.03, 1.0]])


@pytest.mark.parametrize('tilt', [(1.0, 0.0), (-2.0, 0.0), (0.0, 1.0), (0.0, -1.5)],
                         ids=['tilt-x+1', 'tilt-x-2', 'tilt-y+1', 'tilt-y-1.5'])
def test_infinity_through_a_tilted_flat_port_is_the_plate_closed_form(tilt: tuple) -> None:
    ported = build_model(config('cooke_triplet', **FLAT, **{
        'scene.distance_mm': 0.0, 'port.tilt_x_deg': tilt[0], 'port.tilt_y_deg': tilt[1]}))
    air = build_model(config('cooke_triplet', **{'scene.distance_mm': 0.0}))
    n_w = ported.source.medium_index
    d = DIRECTIONS / np.linalg.norm(DIRECTIONS, axis=1, keepdims=True)
    # Optical frame (X right, Y down, Z ahead) to the ray's direction (lens frame, toward the
    # lens): k = (-X, -Y, Z); through the plate as through one water-air face.
    k = snell(np.stack([-d[:, 0], -d[:, 1], d[:, 2]], axis=1), plate_normal(*tilt), n_w, 1.0)
    d_air = np.stack([-k[:, 0], -k[:, 1], k[:, 2]], axis=1)
    # A plate is afocal: the paraxial image of infinity, so the sensor, is where it is in air.
    npt.assert_allclose(ported.K[:, 2], air.K[:, 2], atol=1e-12)
    npt.assert_allclose(pixels_of(ported, d), pixels_of(air, d_air), atol=2e-3)
    # The axis direction moves by tens of px (the sign by value is in the line above).
    assert np.hypot(*(pixels_of(ported, d[:1]) - pixels_of(air, d[:1]))[0]) > 10.0


@pytest.mark.parametrize('lens,port', [
    ('cooke_triplet', {**DOME, 'port.radius_mm': 40.0, 'port.decenter_x_mm': 1.0}),
    ('wide_angle', {**DOME, 'port.decenter_y_mm': -1.0}),
    ('wide_angle', {**FLAT, 'port.tilt_x_deg': 1.0, 'port.tilt_y_deg': 0.5}),
], ids=['cooke-dome-dx', 'wide-dome-dy', 'wide-flat-tilt-xy'])
def test_infinity_is_the_limit_of_far_scenes(lens: str, port: dict) -> None:
    inf = build_model(config(lens, **port, **{'scene.distance_mm': 0.0}))
    half = 0.6 * inf.width / inf.K[0, 0]
    d = np.concatenate([DIRECTIONS[:, :2] * half / 0.12, np.ones((6, 1))], axis=1)
    p_inf = pixels_of(inf, d)
    assert np.all(np.isfinite(p_inf))
    # A point at l sees the pupil's millimetres under 1/l: the gap to infinity falls as 1/l.
    gaps = []
    for distance in (1.0e4, 1.0e5, 1.0e6):
        far = build_model(config(lens, **port, **{'scene.distance_mm': distance}))
        gaps.append(float(np.max(np.hypot(*(pixels_of(far, d) - p_inf).T))))
    assert gaps[2] < 0.1
    npt.assert_allclose(np.array(gaps[:2]) / np.array(gaps[1:]), 10.0, rtol=0.05)


@pytest.mark.parametrize('port', [{**FLAT, 'port.tilt_x_deg': 1.0},
                                  {**DOME, 'port.radius_mm': 40.0, 'port.decenter_x_mm': 1.0}],
                         ids=['flat-tilted', 'dome-decentred'])
def test_infinity_behind_any_port_on_every_route(port: dict, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture) -> None:
    values = config('cooke_triplet', **port, **{'scene.distance_mm': 0.0,
                                                'sensor.width_px': 160, 'sensor.height_px': 120,
                                                'sensor.pixel_size_x_um': 60.0,
                                                'sensor.pixel_size_y_um': 60.0})
    params = tmp_path / 'params.yaml'
    params.write_text(to_params_yaml(values))
    assert cli.main(['info', '--params', str(params)]) == 0
    image = tmp_path / 'in.png'
    cv2.imwrite(str(image), np.full((120, 160), 128, np.uint8))
    assert cli.main(['correct', '--params', str(params), str(image),
                     str(tmp_path / 'out.png')]) == 0, capsys.readouterr().err
    assert cv2.imread(str(tmp_path / 'out.png')).shape[:2] == (120, 160)
    model = build_model(values)
    map_x, map_y = build_float_maps(model)[:2]
    assert np.all(np.isfinite(map_x)) and np.mean(map_x > -1.0) > 0.9


def test_medium_index_one_is_air() -> None:
    air = build_model(config('cooke_triplet'))
    written = build_model(config('cooke_triplet', **{'scene.medium_index': 1.0}))
    assert not isinstance(written.source, PortedSource)
    assert written.illumination(with_fraction=False) is not None
    tx, ty = np.meshgrid(np.linspace(-0.15, 0.15, 5), np.linspace(-0.1, 0.1, 4))
    npt.assert_allclose(np.stack(project_points(written, tx, ty)),
                        np.stack(project_points(air, tx, ty)), atol=1e-9)
    npt.assert_allclose(written.K, air.K, rtol=1e-12)
    # A zoom lens (a port path refuses moving groups) is accepted with air written out.
    zoom = build_model(config('zoom', **{'scene.medium_index': 1.0}))
    assert not isinstance(zoom.source, PortedSource)
    # Any other index is a medium, below 1 still refused.
    assert isinstance(build_model(config('cooke_triplet', **{'scene.medium_index': 1.33}))
                      .source, PortedSource)


def test_a_scene_point_in_the_housing_has_no_pixel() -> None:
    # A flat port turned 10 deg about x: its y < 0 part moves toward the scene. The scene
    # plane 1 mm in front of the outer face on the axis passes behind that face at y = -10 mm
    # (10 tan 10 deg = 1.76 mm): the point there is in the housing, not in the water.
    port = {**FLAT, 'port.tilt_x_deg': 10.0}
    probe = build_model(config('wide_angle', **port, **{'scene.distance_mm': 1000.0}))
    z_h = probe.source.first_order().front_principal_z_mm
    distance = z_h + 10.0 + 5.0 + 1.0
    model = build_model(config('wide_angle', **port, **{'scene.distance_mm': distance}))
    tx = np.array([0.0, 0.0, 0.0])
    ty = np.array([-10.0, -3.0, 10.0]) / distance
    u, v = project_points(model, tx, ty)
    # y = -10: in the housing (the face reaches 1.76 mm, the plane is 1 mm in front); y = -3
    # (0.53 mm) and y = +10 (the face recedes): in the water, traced.
    assert np.isnan(u[0]) and np.isnan(v[0])
    assert np.all(np.isfinite(u[1:])) and np.all(np.isfinite(v[1:]))


def test_a_dome_scene_point_inside_the_outer_sphere_has_no_pixel() -> None:
    # A scene plane in front of the dome's vertex is outside its sphere everywhere, but the
    # 3-D trace takes any points: one 0.5 mm inside the outer sphere off the axis (x = 20 mm)
    # is in the dome, not in the water (it was traced backwards to the sphere).
    model = build_model(config('wide_angle', **DOME, **{'port.decenter_x_mm': 1.0}))
    source = model.source
    port = source.port
    outer = port.radius_mm + port.thickness_mm
    surface_z = port.center_z_mm - math.sqrt(outer ** 2 - (20.0 - 1.0) ** 2)
    points = np.array([[20.0, 0.0, surface_z + 0.5], [20.0, 0.0, surface_z - 0.5]])
    out = trace_scene_points(source.lens.prescription, port, source.medium_index, points,
                             source.sensor_z_lens_frame(1000.0))
    assert np.all(np.isnan(out[0])) and np.all(np.isfinite(out[1]))


@pytest.fixture(scope='module')
def fisheye_decentred() -> object:
    # The fisheye (equidistant output past 90 deg with alpha 1) behind a decentred dome, the
    # scene at 1 m: a plane, so no scene point past 90 deg.
    return build_model(config('fisheye', **{
        **DOME, 'port.radius_mm': 60.0, 'port.decenter_x_mm': 1.0, 'scene.distance_mm': 1000.0,
        'output.alpha': 1.0}))


def test_no_clamped_angle_feeds_the_residual(fisheye_decentred: object) -> None:
    model = fisheye_decentred
    u_nodes, v_nodes, du, dv = residual_nodes(model)
    xn = (u_nodes[None, :] - model.K_new[0, 2]) / model.K_new[0, 0]
    yn = (v_nodes[:, None] - model.K_new[1, 2]) / model.K_new[1, 1]
    xn, yn = np.broadcast_arrays(xn, yn)
    theta = np.hypot(xn, yn)                       # equidistant output
    past = theta > 1.55                           # past 88.8 deg (the old clamp)
    assert past.any()
    # Past 90 deg the scene plane has no point: no residual. Between 88.8 and 90 deg the
    # residual is that of the node's own direction.
    assert np.all(np.isnan(du[theta > 0.5 * math.pi]))
    d = ideal_directions(model, xn, yn)
    exact = pixels_of(model, d)
    radial = model.raw_from_rect(np.stack([u_nodes[None, :] + 0.0 * yn,
                                           v_nodes[:, None] + 0.0 * xn], axis=-1))
    npt.assert_allclose(du[past], (exact[..., 0] - radial[..., 0])[past], atol=1e-9)
    npt.assert_allclose(dv[past], (exact[..., 1] - radial[..., 1])[past], atol=1e-9)


def test_cells_without_an_exact_ray_are_masked(fisheye_decentred: object) -> None:
    map_x, map_y = build_float_maps(fisheye_decentred)[:2]
    assert np.all(np.isfinite(map_x)) and np.all(np.isfinite(map_y))
    _, _, du, _ = residual_nodes(fisheye_decentred)
    assert np.isnan(du).any()
    # Every node without a ray: the pixels at it are outside (the remap's -1000).
    cols, rows = du.shape[1], du.shape[0]
    r, c = np.nonzero(np.isnan(du))
    px = np.round(c * (fisheye_decentred.out_width - 1) / (cols - 1)).astype(int)
    py = np.round(r * (fisheye_decentred.out_height - 1) / (rows - 1)).astype(int)
    assert np.all(map_x[py, px] < -999.0)


def test_the_page_quotes_the_script() -> None:
    # docs/underwater.md's numbers of the water, the tilt and the shipped example are those
    # tools/underwater_numbers.py prints (its slower sections: run it by hand).
    spec = importlib.util.spec_from_file_location(
        'underwater_numbers', ROOT / 'tools' / 'underwater_numbers.py')
    numbers = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(numbers)
    page = (ROOT / 'docs' / 'underwater.md').read_text()
    for section in (numbers.water, numbers.tilt, numbers.shipped):
        for line in section():
            for token in re.findall(r'[-+]?\d+\.\d+(?:e[-+]\d+)?', line):
                value = float(token)
                quoted = {token, f'{value:g}', f'{value:.1e}'.replace('e-0', 'e-')}
                assert any(q in page for q in quoted), f'{token} ({line}) is not on the page'


@pytest.mark.parametrize('values,distance,air', [
    ({'scene.distance_mm': 0.0}, math.inf, True),
    ({'scene.distance_mm': 1500.0, 'scene.medium_index': 1.0}, 1500.0, True),
    ({'scene.distance_mm': 1500.0, 'scene.medium': 'water', 'scene.medium_index': 1.0},
     1500.0, True),
    ({'scene.distance_mm': 20.0, 'scene.medium': 'water'}, 20.0, False),
    ({'scene.distance_mm': 20.0, 'scene.medium_index': 1.0001}, 20.0, False),
], ids=['infinity-air', 'index-1', 'index-1-over-water', 'water', 'index-above-1'])
def test_the_one_reading_of_distance_and_air(values: dict, distance: float, air: bool) -> None:
    assert scene_distance(values) == distance
    assert scene_in_air(values) is air
