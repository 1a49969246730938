#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Generate test/data/optiland_assembly.json: optiland's chief rays on decentred, tilted sensors.

The reference of issue 25 (test/test_reference_assembly.py): for a thick lens (config/
case2.yaml), the Cooke triplet, the 160-deg wide angle and the 170-deg fisheye (config/), and
for sensor poses with axis offsets up to 0.2 mm and tilts up to 1 deg in both axes, the raw
pixel where optiland's real chief ray of each of 21 x 21 scene directions meets the sensor.
optiland is a reference-only dependency (requirements-reference.txt); run::

    .venv/bin/pip install -r requirements-reference.txt
    .venv/bin/python tools/make_optiland_assembly.py       # about 2 min

Frames (docs/design.md section 2.16). A scene direction is ``(tx, ty) = (X / Z, Y / Z)`` in the
camera's optical frame (X right, Y down, Z forward, from H). optiland's frame has z along the
light (from the scene towards the sensor): ``(x, y, z) = (X, -Y, -Z)`` (a half turn about X).
The sensor is built here from the issue's words, in optiland's frame, not from our model:

- the lens axis meets the sensor plane at ``O = (0, 0, z_s)`` (z_s: optiland's paraxial image
  plane of the scene); untilted, the rows run along ``e_u = (-1, 0, 0)`` (u grows: the image is
  inverted, a scene point at +X lands at -x) and the columns along ``e_v = (0, 1, 0)``;
- tilt_x (alpha) turns the plane about its row line through O so that rows of larger v come
  closer to the lens: ``e_v' = (0, cos a, -sin a)``; the plane's normal becomes
  ``n' = (0, sin a, cos a)``;
- tilt_y (beta) then turns it about its own (turned) column line so that columns of larger u
  come closer: ``e_u' = cos b e_u - sin b n'`` (z component ``-sin b cos a``);
- the axis is at pixel ``((W - 1) / 2 + dx / p_x, (H - 1) / 2 + dy / p_y)``, so the sensor
  centre, optiland's image-surface vertex, is at ``O - dx e_u' - dy e_v'``.

optiland places its image surface by ``x, y, z`` and ``rx, ry, rz`` (``globalize``: rotate
about x, then y, then z, then translate: global = Rz Ry Rx local). Its local axes are
``x_l = -e_u'``, ``y_l = e_v'``, ``z_l = x_l x y_l``; the angles come from that matrix
(scipy's extrinsic 'xyz' Euler angles, the same order) and are CHECKED here by globalizing
optiland's own local unit vectors, and by the hand-computed case of the issue (tilt_x > 0: the
local point (0, +1) -- a row of larger v -- lies closer to the lens). A hit at optiland local
``(x_l, y_l)`` is the pixel ``u = (W - 1) / 2 - x_l / p_x``, ``v = (H - 1) / 2 + y_l / p_y``.

Chief rays: each direction's field angle theta is traced in the meridional plane (optiland's
y field: object height ``l tan(theta)`` for a finite scene, angle for infinity; the 1-D field
passes 90 deg, where optiland refuses a 2-D angle field), aimed at the stop centre
(``iterative`` aimer for the thick lens and the triplet, ``robust`` for the wide designs,
stop residual < 1e-9 mm), and turned about the axis to the direction's azimuth (the lens is
rotationally symmetric: exact). The turned image-space rays meet optiland's tilted image
surface (its own localize and intersection). As a self-check, directions that a 2-D angle
field can express are also traced through the whole lens with the tilted image surface in
place; the two agree to ``SELF_CHECK_PX``.

The directions: a 21 x 21 grid of raw pixels from edge to edge of the sensor (pixel -0.5 to
W - 0.5), turned into scene directions through our centred model (only to choose inputs that
reach the whole sensor; optiland decides where they land), those under 90 deg.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import math
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUTPUT = REPO / 'test' / 'data' / 'optiland_assembly.json'
GRID = 21
#: Sensor poses: (axis_offset_x_mm, axis_offset_y_mm, tilt_x_deg, tilt_y_deg).
POSES = ((0.0, 0.0, 0.0, 0.0), (0.2, -0.15, 1.0, -0.7), (-0.12, 0.2, -0.6, 1.0),
         (0.05, 0.0, 0.0, 1.0), (0.0, -0.2, 1.0, 0.0))
LENSES = (('thick_lens', 'case2.yaml'), ('cooke_triplet', 'cooke_triplet.yaml'),
          ('wide_angle', 'wide_angle.yaml'), ('fisheye', 'fisheye.yaml'))
SELF_CHECK_PX = 1e-6
STOP_RESIDUAL_MM = 1e-9


def provenance(ref: Any, generator: str, start: float) -> dict[str, Any]:
    """Return the provenance entry of a reference file (generator, date, versions, runtime)."""
    return {'generator': generator,
            'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime(
                '%Y-%m-%dT%H:%M:%SZ'),
            'versions': ref.versions(), 'runtime_s': round(time.monotonic() - start, 1)}


def _load(name: str) -> Any:
    path = REPO / 'tools' / f'{name}.py'
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    return module


def sensor_axes(tilt_x_deg: float, tilt_y_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(e_u', e_v')`` in optiland's frame (module docstring)."""
    a, b = math.radians(tilt_x_deg), math.radians(tilt_y_deg)
    e_u = np.array([-1.0, 0.0, 0.0])
    e_v = np.array([0.0, math.cos(a), -math.sin(a)])
    normal = np.array([0.0, math.sin(a), math.cos(a)])
    return math.cos(b) * e_u - math.sin(b) * normal, e_v


def place_image_surface(surface: Any, z_s: float, pose: tuple[float, ...]) -> np.ndarray:
    """
    Put optiland's image surface at the pose; check optiland's rotation convention.

    :return: the local-to-global rotation (columns x_l, y_l, z_l).
    """
    from optiland.coordinate_system import CoordinateSystem
    from optiland.rays import RealRays
    from scipy.spatial.transform import Rotation

    dx, dy, tilt_x, tilt_y = pose
    e_u, e_v = sensor_axes(tilt_x, tilt_y)
    x_l, y_l = -e_u, e_v
    matrix = np.stack([x_l, y_l, np.cross(x_l, y_l)], axis=1)
    rx, ry, rz = Rotation.from_matrix(matrix).as_euler('xyz')
    vertex = np.array([0.0, 0.0, z_s]) - dx * e_u - dy * e_v
    cs = CoordinateSystem(x=float(vertex[0]), y=float(vertex[1]), z=float(vertex[2]),
                          rx=float(rx), ry=float(ry), rz=float(rz))
    surface.geometry.cs = cs
    # optiland's own globalize of its local unit vectors (directions) must give the axes.
    probe = RealRays(np.zeros(3), np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0]),
                     np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.ones(3),
                     np.full(3, 0.55))
    cs.globalize(probe)
    got = np.stack([np.asarray(probe.L), np.asarray(probe.M), np.asarray(probe.N)], axis=0)
    if not np.allclose(got, matrix, atol=1e-14):
        raise RuntimeError(f'optiland rotates its surface otherwise than assumed: {got}')
    if tilt_x > 0 and tilt_y == 0:
        # The words: a row of larger v (local y_l > 0) comes closer to the lens.
        point = RealRays(np.zeros(1), np.ones(1), np.zeros(1), np.zeros(1), np.zeros(1),
                         np.ones(1), np.ones(1), np.full(1, 0.55))
        cs.globalize(point)
        if not float(np.asarray(point.z)[0]) < vertex[2]:
            raise RuntimeError('tilt_x > 0 must bring the rows of larger v closer')
        expected = vertex[2] - math.sin(math.radians(tilt_x))
        if abs(float(np.asarray(point.z)[0]) - expected) > 1e-12:
            raise RuntimeError('optiland tilt differs from the hand-computed one')
    return matrix


def local_hits(surface: Any, rays: dict[str, np.ndarray], wavelength_um: float) -> np.ndarray:
    """Intersect global image-space rays with optiland's (placed) image surface: local x, y."""
    from optiland.rays import RealRays

    n = rays['x'].size
    real = RealRays(rays['x'].copy(), rays['y'].copy(), rays['z'].copy(), rays['L'].copy(),
                    rays['M'].copy(), rays['N'].copy(), np.ones(n), np.full(n, wavelength_um))
    surface.geometry.localize(real)
    real = surface._trace_real(real)
    return np.stack([np.asarray(real.x, dtype=float), np.asarray(real.y, dtype=float)], axis=1)


def turn(rays: dict[str, np.ndarray], angle: np.ndarray) -> dict[str, np.ndarray]:
    """Turn rays about optiland's z axis by ``angle`` (rad, per ray)."""
    c, s = np.cos(angle), np.sin(angle)
    return {'x': c * rays['x'] - s * rays['y'], 'y': s * rays['x'] + c * rays['y'],
            'z': rays['z'], 'L': c * rays['L'] - s * rays['M'],
            'M': s * rays['L'] + c * rays['M'], 'N': rays['N']}


def meridional_rays(ref: Any, lens: Any, theta: np.ndarray, finite: bool, l_mm: float,
                    field_max: float, mode: str, wavelength_um: float) -> dict[str, np.ndarray]:
    """
    Trace the chief ray of each field angle in optiland's y-z plane, camera azimuth 90 deg.

    The camera direction (0, tan theta) (down in the image) is the optiland object point
    (0, -l tan theta) (finite) or the angle field -theta (the ray travels towards -y... it
    arrives from +y at infinity): see the module docstring's frame.
    """
    out = {k: np.full(theta.size, np.nan) for k in ('x', 'y', 'z', 'L', 'M', 'N', 'stop')}
    batch = mode == 'iterative'
    groups = [np.arange(theta.size)] if batch else [np.array([i]) for i in range(theta.size)]
    for idx in groups:
        if finite:
            hy = -l_mm * np.tan(theta[idx]) / field_max
        else:
            # optiland's angle field f travels along (0, tan f, 1): the scene direction
            # (0, +tan theta) in the camera frame is optiland's (0, -tan theta, -1) side, whose
            # rays travel towards +y: f = +theta.
            hy = np.degrees(theta[idx]) / field_max
        try:
            r = ref.trace_chief(lens, np.zeros(idx.size), hy, mode, wavelength_um)
        except Exception:                            # optiland refuses or cannot aim
            continue
        last = list(lens.surfaces)[-1]
        for key in ('x', 'y', 'z', 'L', 'M', 'N'):
            out[key][idx] = np.asarray(getattr(last, key), dtype=float).reshape(-1)
        out['stop'][idx] = np.hypot(r['x_stop'], r['y_stop'])
        bad = ~(np.abs(out['stop'][idx]) < STOP_RESIDUAL_MM) | (r['min_step_mm'] < -1e-9)
        for key in ('x', 'y', 'z', 'L', 'M', 'N'):
            out[key][idx[bad]] = np.nan
    return out


def build(ref: Any, values: dict[str, Any], field_max_deg: float) -> tuple[Any, bool, float,
                                                                           float, float]:
    """Return (optic, finite, l from H, optiland field max, optiland z of our z = 0)."""
    distance = float(values['scene.distance_mm'])
    if not values['lens.surfaces.radius_mm']:
        n, r1, r2 = (float(values[k]) for k in ('lens.refractive_index', 'lens.r1_mm',
                                                'lens.r2_mm'))
        t, m_a = float(values['lens.thickness_mm']), float(values['lens.stop_offset_mm'])
        field_max = distance * math.tan(math.radians(field_max_deg))
        lens, _rows, first_z, _cf = ref.build_thick_lens(
            n, r1, r2, t, m_a, float(values['lens.aperture_diameter_mm']), distance, field_max)
        return lens, True, distance, field_max, first_z
    rows = []
    for i, radius in enumerate(values['lens.surfaces.radius_mm']):
        conic = values['lens.surfaces.conic'][i] if values['lens.surfaces.conic'] else 0.0
        asphere = tuple(values[f'lens.surfaces.asphere_a{p}'][i]
                        if values[f'lens.surfaces.asphere_a{p}'] else 0.0
                        for p in (4, 6, 8, 10, 12, 14, 16))
        rows.append(ref._row(radius, values['lens.surfaces.thickness_mm'][i],
                             values['lens.surfaces.refractive_index'][i],
                             i == int(values['lens.stop_surface']), conic, asphere))
    wavelength_um = float(values['lens.wavelength_nm']) * 1e-3
    lens = ref.build_wide_optic(rows, wavelength_um,
                                ('float_by_stop_size', float(values['lens.aperture_diameter_mm'])),
                                field_max_deg)
    lens.image_solve()
    lens.updater.update_paraxial()
    return lens, False, math.inf, field_max_deg, 0.0


def lens_entry(ref: Any, key: str, config: str) -> dict[str, Any]:
    """Trace one lens for every pose."""
    from mechdeconv_ros.model.assembly import unproject
    from mechdeconv_ros.model.model import build_model
    from mechdeconv_ros.schema.params import load_params_file

    from mechdeconv_ros.lenses.lens_params import with_glass_indices

    # Named glasses as the indices our catalogue gives at lens.wavelength_nm (a config's
    # refractive_index column is rounded to 6 decimals: 2.5e-3 px at the triplet's corner).
    values = with_glass_indices(load_params_file(REPO / 'config' / config))
    w, h = int(values['sensor.width_px']), int(values['sensor.height_px'])
    px, py = (float(values[f'sensor.pixel_size_{a}_um']) * 1e-3 for a in 'xy')
    ours = build_model(values)
    us, vs = np.meshgrid(np.linspace(-0.5, w - 0.5, GRID), np.linspace(-0.5, h - 0.5, GRID))
    tx, ty = unproject(ours, us.ravel(), vs.ravel())
    keep = np.isfinite(tx) & np.isfinite(ty)
    tx, ty = tx[keep], ty[keep]
    theta = np.arctan(np.hypot(tx, ty))
    azimuth = np.arctan2(ty, tx)
    wavelength_um = float(values['lens.wavelength_nm']) * 1e-3
    lens, finite, l_mm, field_max, first_z = build(
        ref, values, min(89.0, math.degrees(float(theta.max())) + 1.0))
    mode = 'iterative' if key in ('thick_lens', 'cooke_triplet') else 'robust'
    rays = meridional_rays(ref, lens, theta, finite, l_mm, field_max, mode, wavelength_um)
    # The meridional ray of camera azimuth 90 deg turned to the direction's azimuth: a turn
    # by delta about the camera's Z is a turn by -delta about optiland's z (y is flipped).
    turned = turn(rays, -(azimuth - 0.5 * math.pi))
    surface = list(lens.surfaces)[-1]
    z_s = float(surface.geometry.cs.z)
    poses = []
    for pose in POSES:
        place_image_surface(surface, z_s, pose)
        local = local_hits(surface, turned, wavelength_um)
        u = (w - 1) / 2.0 - local[:, 0] / px
        v = (h - 1) / 2.0 + local[:, 1] / py
        poses.append({'axis_offset_x_mm': pose[0], 'axis_offset_y_mm': pose[1],
                      'tilt_x_deg': pose[2], 'tilt_y_deg': pose[3],
                      'u': _lst(u), 'v': _lst(v),
                      'self_check_px': self_check(ref, lens, surface, z_s, pose, tx, ty, u, v,
                                                  finite, l_mm, field_max, mode, w, h, px, py,
                                                  wavelength_um)})
        place_image_surface(surface, z_s, (0.0, 0.0, 0.0, 0.0))
    return {'config': f'config/{config}', 'width_px': w, 'height_px': h,
            'pixel_mm': [px, py], 'scene_distance_mm': None if not finite else l_mm,
            'aiming': mode, 'sensor_z_mm': z_s - first_z,
            'max_stop_residual_mm': float(np.nanmax(rays['stop'])),
            'tx': _lst(tx), 'ty': _lst(ty), 'poses': poses}


def self_check(ref: Any, lens: Any, surface: Any, z_s: float, pose: tuple[float, ...],
               tx: np.ndarray, ty: np.ndarray, u: np.ndarray, v: np.ndarray, finite: bool,
               l_mm: float, field_max: float, mode: str, w: int, h: int, px: float, py: float,
               wavelength_um: float) -> float | None:
    """Trace a few directions through the whole lens with the tilted surface in place."""
    from optiland.rays import RealRays

    pick = np.unique(np.linspace(0, tx.size - 1, 9).round().astype(int))
    if finite:
        hx, hy = l_mm * tx[pick] / field_max, -l_mm * ty[pick] / field_max
    else:
        # Travel direction (-tx, ty, 1) (module docstring): tan f_x = -tx, tan f_y = ty.
        fx, fy = np.degrees(np.arctan(-tx[pick])), np.degrees(np.arctan(ty[pick]))
        ok = np.hypot(fx, fy) < 89.0
        pick, fx, fy = pick[ok], fx[ok], fy[ok]
        hx, hy = fx / field_max, fy / field_max
    worst = 0.0
    for i, (a, b) in zip(pick, zip(hx, hy)):
        try:
            ref.trace_chief(lens, np.array([a]), np.array([b]), mode, wavelength_um)
        except Exception:
            continue
        point = RealRays(np.asarray(surface.x, dtype=float), np.asarray(surface.y, dtype=float),
                         np.asarray(surface.z, dtype=float), np.zeros(1), np.zeros(1),
                         np.ones(1), np.ones(1), np.full(1, wavelength_um))
        surface.geometry.localize(point)
        uu = (w - 1) / 2.0 - float(np.asarray(point.x)[0]) / px
        vv = (h - 1) / 2.0 + float(np.asarray(point.y)[0]) / py
        if np.isfinite(u[i]) and np.isfinite(uu):
            worst = max(worst, abs(uu - u[i]), abs(vv - v[i]))
    if worst > SELF_CHECK_PX:
        raise RuntimeError(f'pose {pose}: the turned meridional rays differ from the direct '
                           f'2-D trace by {worst:.3g} px')
    return worst


def _lst(a: np.ndarray) -> list[float | None]:
    return [None if not np.isfinite(x) else float(x) for x in np.asarray(a, dtype=float)]


def main(argv: list[str] | None = None) -> int:
    """Trace every lens and pose and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('-o', '--output', type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument('--only', help='trace one lens key, keep the others of the output')
    args = parser.parse_args(argv)
    import warnings
    warnings.filterwarnings('ignore')
    ref = _load('make_optiland_reference')
    start = time.monotonic()
    lenses = {}
    if args.only and args.output.exists():
        lenses = json.loads(args.output.read_text())['lenses']
    for key, config in LENSES:
        if args.only and key != args.only:
            continue
        lenses[key] = lens_entry(ref, key, config)
        print(f'[{time.monotonic() - start:5.1f} s] {key}: {len(lenses[key]["tx"])} directions',
              file=sys.stderr, flush=True)
    doc = {
        'provenance': provenance(ref, 'tools/make_optiland_assembly.py', start),
        'conventions': {
            'directions': 'tx = X / Z, ty = Y / Z in the camera optical frame (X right, Y down, '
                          'Z forward from H); the point on the plane at scene.distance_mm',
            'pixels': 'u, v raw pixels where the chief ray meets the sensor (null: no ray)',
            'pose': 'the issue 25 definition, built in optiland frame (module docstring)'},
        'lenses': lenses,
    }
    args.output.write_text(json.dumps(doc, indent=1) + '\n')
    print(f'wrote {args.output}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
