#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Generate test/data/optiland_ports.json: optiland's real chief rays through underwater ports.

For each case (a lens config, a port, the water, a wavelength, a scene distance) the scene
points of a 21 x 21 grid of directions (tx, ty) = (X/Z, Y/Z) at Z = ``scene.distance_mm``
from the lens's front principal plane (in air) are traced by optiland 0.6.3 (independent of
our tracer; iterative ray aiming to the stop centre, 1e-11 mm) through the port and the lens
to our sensor plane. The suite (test/test_underwater_reference.py) compares ``project``
(mechdeconv_ros.model.underwater.project_points) against them within 0.01 px.

What comes from our code (inputs, not the checked outputs): the surfaces of each lens (its
config), the indices at the wavelength (our glass module and the Quan & Fry water index,
both tested on their own), the sensor plane, the grid (21 x 21 directions spanning 95 % of
the raw image by the pinhole K of our model) and the starts of the wide lenses' aiming (our
3-D chief ray's slopes where we have one, else the symmetric port's: a start only, the
solution is where optiland's own ray meets the stop centre). Every direction of the grid is
traced: null only where optiland has no chief ray to the sensor (a tilted port's rays that
optiland reflects totally are aimed again with 0, 1/4, ... 1 of the tilt, optiland's optic
each time, so a start past the critical angle does not lose a ray optiland can trace). optiland
gets the port as surfaces: flat faces turned by rx / ry (radians, about each face's own axis
point; the outer face's axis point at z_i - t / cos(tilt) keeps the faces parallel) and dome
spheres displaced by dx / dy. The sign of optiland's rotations is checked geometrically here:
a positive ``port.tilt_x_deg`` must bring the face's y > 0 part closer to the lens (its ray
intersections there have larger z than the axis point).

Size: the 6 cases marked ``full`` keep the 21 x 21 grid; the others keep its 11 x 11
sub-grid (every second row and column, corners included): ``keep`` in each case.

Run (optiland from requirements-reference.txt)::

    python tools/make_optiland_ports.py      # writes test/data/optiland_ports.json
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
from pathlib import Path
import sys
import time
from typing import Any

from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.optics.ports import trace_scene_points
from mechdeconv_ros.schema.params import load_params_file
import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUTPUT = REPO / 'test' / 'data' / 'optiland_ports.json'
GRID = 21
COVERAGE = 0.95
LENSES = {'cooke': 'config/cooke_triplet.yaml', 'wide': 'config/wide_angle.yaml',
          'fisheye': 'config/fisheye.yaml'}
#: Dome inner radius per lens (mm): the lens fits inside with margin.
DOME_RADIUS = {'cooke': 40.0, 'wide': 45.0, 'fisheye': 60.0}
WAVELENGTHS = (486.13, 587.56, 656.27)
SEA = {'scene.medium': 'seawater', 'scene.salinity_psu': 35.0, 'scene.temperature_c': 15.0}
FRESH = {'scene.medium': 'water', 'scene.temperature_c': 20.0}


def cases() -> list[tuple[str, str, dict[str, Any], bool]]:
    """Return (key, lens, parameter overrides, full grid) of every case."""
    out = []
    for lens in LENSES:
        flat = {'port.type': 'flat', 'port.thickness_mm': 5.0, 'port.glass': 'PMMA',
                'port.distance_mm': 10.0, 'scene.distance_mm': 1000.0}
        for d in (5.0, 10.0, 20.0):
            out.append((f'{lens}_flat_d{d:g}', lens, {**flat, **SEA, 'port.distance_mm': d},
                        d == 10.0))
        for t in (3.0, 12.0):
            out.append((f'{lens}_flat_t{t:g}_bk7_fresh', lens,
                        {**flat, **FRESH, 'port.thickness_mm': t, 'port.glass': 'N-BK7'}, False))
        for dist in (300.0, 3000.0):
            out.append((f'{lens}_flat_l{dist:g}', lens,
                        {**flat, **SEA, 'scene.distance_mm': dist}, False))
        out.append((f'{lens}_flat_tilt_x1', lens, {**flat, **SEA, 'port.tilt_x_deg': 1.0},
                    False))
        out.append((f'{lens}_flat_tilt_y1', lens, {**flat, **SEA, 'port.tilt_y_deg': 1.0},
                    False))
        for wl in (WAVELENGTHS[0], WAVELENGTHS[2]):
            for name, water in (('sea', SEA), ('fresh', FRESH)):
                out.append((f'{lens}_flat_{name}_{wl:g}nm', lens,
                            {**flat, **water, 'lens.wavelength_nm': wl}, False))
        dome = {'port.type': 'dome', 'port.thickness_mm': 6.0, 'port.glass': 'N-BK7',
                'port.radius_mm': DOME_RADIUS[lens], 'scene.distance_mm': 1000.0}
        out.append((f'{lens}_dome_centred', lens, {**dome, **SEA}, True))
        out.append((f'{lens}_dome_off2', lens, {**dome, **SEA, 'port.center_offset_mm': 2.0},
                    False))
        out.append((f'{lens}_dome_dx1', lens, {**dome, **FRESH, 'port.decenter_x_mm': 1.0},
                    False))
        out.append((f'{lens}_dome_dy1', lens, {**dome, **SEA, 'port.decenter_y_mm': 1.0},
                    False))
        for wl in (WAVELENGTHS[0], WAVELENGTHS[2]):
            out.append((f'{lens}_dome_fresh_{wl:g}nm', lens,
                        {**dome, **FRESH, 'lens.wavelength_nm': wl}, False))
    return out


def lens_values(lens: str, overrides: dict[str, Any]) -> dict[str, Any]:
    """Return the checked values of a case (the lens config with the overrides)."""
    values = load_params_file(REPO / LENSES[lens])
    values.update(overrides)
    if lens == 'cooke':
        values['sensor.pixel_size_x_um'] = values['sensor.pixel_size_y_um'] = 5.0
    return values


def grid_directions(model: Any) -> tuple[np.ndarray, np.ndarray]:
    """Return the 21 x 21 directions whose pinhole images span COVERAGE of the raw image."""
    half_u = COVERAGE * (model.width - 1) / 2.0 / model.K[0, 0]
    half_v = COVERAGE * (model.height - 1) / 2.0 / model.K[1, 1]
    tx, ty = np.meshgrid(np.linspace(-half_u, half_u, GRID), np.linspace(-half_v, half_v, GRID))
    return tx.ravel(), ty.ravel()


def build_optic(source: Any, port: Any, sensor_z: float, object_gap: float, wl_um: float,
                rx_sign: float, field_max: float):
    """Build the port and the lens in optiland (the surfaces of our combined prescription)."""
    from optiland import optic
    from optiland.materials import IdealMaterial

    combined = source.combined
    lens = optic.Optic()
    lens.surfaces.add(index=0, radius=np.inf, thickness=object_gap,
                      material=IdealMaterial(source.medium_index))
    surfaces = combined.surfaces
    stop_index = None
    z = 0.0
    zs = []
    for s in surfaces:
        zs.append(z)
        z += s.thickness_mm
    # Our stop plane is a surface's vertex plane (the lens's stop_surface), + shift.
    for i, s in enumerate(surfaces):
        if abs(zs[i] - combined.stop_z_mm) < 1e-9 and i >= 2:
            stop_index = i + 1
    if stop_index is None:
        raise RuntimeError('no surface at the stop plane')
    for i, s in enumerate(surfaces, start=1):
        kwargs: dict[str, Any] = {
            'index': i, 'radius': s.radius_mm if s.radius_mm != 0.0 else np.inf,
            'thickness': (s.thickness_mm if i < len(surfaces)
                          else sensor_z - zs[-1]),
            'material': IdealMaterial(s.refractive_index), 'is_stop': i == stop_index}
        if s.conic != 0.0 or any(s.asphere):
            kwargs.update(surface_type='even_asphere', conic=s.conic,
                          coefficients=[0.0] + list(s.asphere) + [0.0] * (7 - len(s.asphere)))
        if i <= 2 and port is not None:
            if port.kind == 'flat':
                kwargs.update(rx=rx_sign * port.tilt_x_rad, ry=rx_sign * port.tilt_y_rad)
        lens.surfaces.add(**kwargs)
    lens.surfaces.add(index=len(surfaces) + 1)
    lens.set_aperture(aperture_type='float_by_stop_size', value=0.2)
    lens.fields.set_type(field_type='object_height')
    lens.fields.add(y=0.0)
    lens.fields.add(y=field_max)
    lens.wavelengths.add(value=wl_um, is_primary=True)
    lens.updater.update_paraxial()
    return lens


def decentre(optic: Any, port: Any) -> None:
    """Displace both dome spheres (optiland 0.6.3 has no paraxial model of a decentred one)."""
    for i in (1, 2):
        cs = optic.surfaces[i].geometry.cs
        cs.x = port.decenter_x_mm
        cs.y = port.decenter_y_mm


def aim_real(optic: Any, x0: np.ndarray, y0: np.ndarray, z0: float, slopes: np.ndarray,
             wl_um: float, with_slopes: bool = False) -> tuple[np.ndarray, ...]:
    """
    Aim chief rays with optiland's real-ray trace: a 2-D Newton on (L/N, M/N) to the stop centre.

    Used for the decentred domes, where optiland 0.6.3's aimers need a paraxial model it
    refuses to build. Every trace (intersection, refraction) is optiland's.

    :return: image x, y and the stop residual (mm).
    """
    from optiland.rays import RealRays

    stop = optic.surfaces.stop_index

    def trace(sl: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        norm = np.sqrt(1.0 + sl[:, 0] ** 2 + sl[:, 1] ** 2)
        rays = RealRays(x0.copy(), y0.copy(), np.full(x0.shape, z0), sl[:, 0] / norm,
                        sl[:, 1] / norm, 1.0 / norm, np.ones(x0.shape), np.full(x0.shape, wl_um))
        optic.surfaces.trace(rays)
        surfaces = list(optic.surfaces)
        get = lambda i, n: np.array(getattr(surfaces[i], n), dtype=float).reshape(-1)  # noqa
        return get(stop, 'x'), get(stop, 'y'), get(-1, 'x'), get(-1, 'y')

    sl = slopes.copy()
    eps = 1e-7
    for _ in range(30):
        sx, sy, _, _ = trace(sl)
        if np.nanmax(np.hypot(sx, sy)) < 1e-12:
            break
        ax, ay, _, _ = trace(sl + [eps, 0.0])
        bx, by, _, _ = trace(sl + [0.0, eps])
        j11, j21, j12, j22 = (ax - sx) / eps, (ay - sy) / eps, (bx - sx) / eps, (by - sy) / eps
        det = j11 * j22 - j12 * j21
        sl = sl - np.stack([(j22 * sx - j12 * sy) / det, (-j21 * sx + j11 * sy) / det], axis=1)
    sx, sy, ix, iy = trace(sl)
    if with_slopes:
        return ix, iy, np.hypot(sx, sy), sl
    return ix, iy, np.hypot(sx, sy)


def start_slopes(source: Any, pts: np.ndarray, tx: np.ndarray, ty: np.ndarray,
                 distance: float) -> np.ndarray:
    """
    Return the slopes that start optiland's aiming: our 3-D chief rays', else the symmetric's.

    Only a start: optiland's Newton finds where its own ray meets the stop centre.
    """
    symmetric = source.symmetric_slopes(tx, ty, distance)
    ours, slopes = trace_scene_points(
        source.lens.prescription, source.port, source.medium_index, pts,
        source.sensor_z_lens_frame(distance), symmetric, with_slopes=True)
    found = np.isfinite(ours).all(axis=1) & np.isfinite(slopes).all(axis=1)
    return np.where(found[:, None], slopes, symmetric)


def continued(source: Any, port: Any, sensor_z: float, gap: float, sign: float,
              field_max: float, x_obj: np.ndarray, y_obj: np.ndarray, z_object: float,
              slopes: np.ndarray, first: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """
    Aim again, with optiland, the rays its first aiming lost, by continuation in the tilt.

    A start whose ray optiland reflects totally (near the critical angle) is aimed through
    the port with 0, 1/4, ..., 1 of its tilt, each optic optiland's, each solution starting the
    next: what optiland traces does not depend on our tracer's start there.
    """
    import dataclasses

    x_img, y_img, residual = (np.array(a, dtype=float) for a in first)
    lost = ~(np.isfinite(x_img) & (residual < 1e-8))
    if not lost.any():
        return x_img, y_img, residual
    sl = slopes[lost].copy()
    for fraction in (0.0, 0.25, 0.5, 0.75, 1.0):
        part = dataclasses.replace(port, tilt_x_rad=fraction * port.tilt_x_rad,
                                   tilt_y_rad=fraction * port.tilt_y_rad)
        optic = _rebuilt(source, part, sensor_z, gap, sign, field_max)
        xi, yi, res, new = aim_real(optic, x_obj[lost], y_obj[lost], z_object, sl,
                                    source.wavelength_nm / 1000.0, with_slopes=True)
        good = np.isfinite(new).all(axis=1) & (res < 1e-8)
        sl[good] = new[good]
    x_img[lost], y_img[lost], residual[lost] = xi, yi, res
    return x_img, y_img, residual


def flat_outer_offset(port: Any) -> float:
    """Return how much further the tilted outer face's axis point is than the untilted one."""
    n_z = math.cos(port.tilt_x_rad) * math.cos(port.tilt_y_rad)
    return port.thickness_mm / n_z - port.thickness_mm


def trace_case(key: str, lens: str, overrides: dict[str, Any]) -> dict[str, Any]:
    """Trace one case with optiland; return its record."""
    values = lens_values(lens, overrides)
    model = build_model(values)
    source = model.source
    port = source.port
    distance = float(values['scene.distance_mm'])
    tx, ty = grid_directions(model)
    # The valid field of our model (radial) bounds the grid.
    z_h = source.first_order().front_principal_z_mm
    z_scene = z_h - distance + source.shift_mm      # combined frame
    sensor_z = source.image_plane(distance)[0]
    # The whole grid: optiland decides where a chief ray reaches the sensor (our model is
    # checked to have one wherever optiland has, and none where optiland has none).
    valid = np.ones(tx.shape, dtype=bool)
    tx_all, ty_all = tx, ty
    x_obj, y_obj = tx * distance, ty * distance
    field_max = float(np.max(np.hypot(x_obj, y_obj))) * 1.01
    tilted = port is not None and port.kind == 'flat' and not port.symmetric
    results = {}
    for sign in ((1.0, -1.0) if tilted else (1.0,)):
        if tilted:
            optic = _rebuilt(source, port, sensor_z, -z_scene, sign, field_max)
        else:
            optic = build_optic(source, port, sensor_z, -z_scene,
                                source.wavelength_nm / 1000.0, sign, field_max)
        aimer = 'iterative'
        try:
            if lens != 'cooke':
                raise ValueError('wide lenses: the real-ray Newton (robust takes minutes)')
            optic.ray_tracer.set_aiming(aimer, max_iter=50, tol=1e-11)
            rays = optic.trace_generic(x_obj / field_max, y_obj / field_max, 0 * tx, 0 * tx,
                                       source.wavelength_nm / 1000.0)
        except ValueError:
            aimer = 'real-ray Newton from our chief rays'
            rays = None
        surfaces = list(optic.surfaces)
        stop = optic.surfaces.stop_index

        def at(i: int, name: str) -> np.ndarray:
            return np.array(getattr(surfaces[i], name), dtype=float).reshape(-1)

        if rays is None:
            # optiland's aimers fail (iterative) or take minutes (robust) on the wide lenses:
            # optiland's own real-ray trace is aimed by a 2-D Newton (aim_real) from our chief
            # rays' directions; the solution is where optiland's ray meets the stop centre
            # (1e-12 mm), whatever the start.
            pts = np.stack([x_obj, y_obj, np.full(x_obj.shape, z_scene - source.shift_mm)],
                           axis=1)
            slopes = start_slopes(source, pts, tx, ty, distance)
            if port is not None and port.kind == 'dome' and not port.symmetric:
                decentre(optic, port)
            z_object = float(optic.surfaces[0].geometry.cs.z)     # optiland's frame
            x_img, y_img, residual = aim_real(optic, x_obj, y_obj, z_object, slopes,
                                              source.wavelength_nm / 1000.0)
            if tilted:
                x_img, y_img, residual = continued(
                    source, port, sensor_z, -z_scene, sign, field_max, x_obj, y_obj,
                    z_object, slopes, (x_img, y_img, residual))
        else:
            x_img, y_img = np.array(rays.x, dtype=float), np.array(rays.y, dtype=float)
            residual = np.hypot(at(stop, 'x'), at(stop, 'y'))
        if rays is not None and port is not None and port.kind == 'dome' \
                and not port.symmetric:
            # From the centred dome's chief rays (optiland's aimer), aim the decentred ones.
            n0 = at(0, 'N')
            slopes = np.stack([at(0, 'L') / n0, at(0, 'M') / n0], axis=1)
            decentre(optic, port)
            x_img, y_img, residual = aim_real(optic, at(0, 'x'), at(0, 'y'),
                                              float(at(0, 'z')[0]), slopes,
                                              source.wavelength_nm / 1000.0)
        if rays is None:
            surfaces = list(optic.surfaces)
        # The inner face (optiland surface 2): where the rays meet it, and its axis point.
        axis_z = float(surfaces[2].geometry.cs.z)
        results[sign] = (x_img, y_img, residual, at(2, 'x'), at(2, 'y'), at(2, 'z') - axis_z)
    sign = 1.0
    if tilted:
        # The geometric sign check (module docstring): a positive tilt_x brings the part of
        # the inner face at y > 0 closer to the lens (z above its axis point), tilt_y at x > 0.
        matches = []
        for s, (_, _, _, x2, y2, dz) in results.items():
            side = (y2 > 0.5) if port.tilt_x_rad > 0 else (x2 > 0.5)
            if side.any() and np.all(dz[side] > 0):
                matches.append(s)
        if len(matches) != 1:
            raise RuntimeError(f'{key}: the tilt sign check is ambiguous: {matches}')
        sign = matches[0]
    x_img, y_img, residual = results[sign][:3]
    ok = np.isfinite(x_img) & np.isfinite(y_img) & (residual < 1e-8)
    # Our read-out pixels of optiland's rays: the inverted image turned upright.
    px, py = model.pixel_mm
    u = np.full(tx_all.shape, np.nan)
    v = np.full(tx_all.shape, np.nan)
    u[valid] = np.where(ok, model.K[0, 2] - x_img / px, np.nan)
    v[valid] = np.where(ok, model.K[1, 2] - y_img / py, np.nan)
    ok_all = np.isfinite(u)
    return {'lens': lens, 'overrides': overrides, 'rx_sign': sign, 'aimer': aimer,
            'tx': tx_all.tolist(), 'ty': ty_all.tolist(),
            'u': [float(a) if k else None for a, k in zip(u, ok_all)],
            'v': [float(a) if k else None for a, k in zip(v, ok_all)],
            'max_stop_residual_mm': float(np.nanmax(np.where(ok, residual, np.nan)))
            if ok.any() else None,
            'medium_index': source.medium_index,
            'port_index': None if port is None else port.index}


def _rebuilt(source: Any, port: Any, sensor_z: float, gap: float, sign: float,
             field_max: float):
    """Build the optic with the tilted outer face's axis point t / cos(tilt) before the inner."""
    extra = flat_outer_offset(port)
    from optiland import optic as optic_module
    from optiland.materials import IdealMaterial

    combined = source.combined
    surfaces = combined.surfaces
    lens = optic_module.Optic()
    lens.surfaces.add(index=0, radius=np.inf, thickness=gap - extra,
                      material=IdealMaterial(source.medium_index))
    zs = np.concatenate(([0.0], np.cumsum([s.thickness_mm for s in surfaces[:-1]])))
    stop_index = 1 + int(np.flatnonzero(np.abs(zs - combined.stop_z_mm) < 1e-9)[-1])
    for i, s in enumerate(surfaces, start=1):
        thickness = s.thickness_mm if i < len(surfaces) else sensor_z - zs[-1]
        if i == 1:
            thickness += extra
        kwargs: dict[str, Any] = {
            'index': i, 'radius': s.radius_mm if s.radius_mm != 0.0 else np.inf,
            'thickness': thickness, 'material': IdealMaterial(s.refractive_index),
            'is_stop': i == stop_index}
        if s.conic != 0.0 or any(s.asphere):
            kwargs.update(surface_type='even_asphere', conic=s.conic,
                          coefficients=[0.0] + list(s.asphere) + [0.0] * (7 - len(s.asphere)))
        if i <= 2:
            kwargs.update(rx=sign * port.tilt_x_rad, ry=sign * port.tilt_y_rad)
        lens.surfaces.add(**kwargs)
    lens.surfaces.add(index=len(surfaces) + 1)
    lens.set_aperture(aperture_type='float_by_stop_size', value=0.2)
    lens.fields.set_type(field_type='object_height')
    lens.fields.add(y=0.0)
    lens.fields.add(y=field_max)
    lens.wavelengths.add(value=source.wavelength_nm / 1000.0, is_primary=True)
    lens.updater.update_paraxial()
    return lens


def main(argv: list[str] | None = None) -> int:
    """Trace every case and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('-o', '--output', type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument('--only', default='', help='trace only keys containing this')
    args = parser.parse_args(argv)
    import warnings
    warnings.filterwarnings('ignore')
    import importlib.metadata
    start = time.monotonic()
    out: dict[str, Any] = {}
    keep_sub = [i * GRID + j for i in range(0, GRID, 2) for j in range(0, GRID, 2)]
    for key, lens, overrides, full in cases():
        if args.only and args.only not in key:
            continue
        record = trace_case(key, lens, overrides)
        keep = list(range(GRID * GRID)) if full else keep_sub
        for name in ('u', 'v'):
            record[name] = [None if record[name][i] is None else round(record[name][i], 5)
                            for i in keep]
        record['keep'] = 'full 21 x 21' if full else '11 x 11 sub-grid (every second)'
        # The directions as their grid: tx = linspace(-half_tx, half_tx, n)[::step].
        record['grid'] = {'half_tx': float(np.max(np.abs(record.pop('tx')))),
                          'half_ty': float(np.max(np.abs(record.pop('ty')))), 'n': GRID,
                          'step': 1 if full else 2}
        out[key] = record
        rays = sum(u is not None for u in record['u'])
        print(f'[{time.monotonic() - start:6.1f} s] {key}: {rays}'
              f' rays, stop residual {record["max_stop_residual_mm"]}', file=sys.stderr,
              flush=True)
    doc = {'provenance': {'generator': 'tools/make_optiland_ports.py',
                          'optiland': importlib.metadata.version('optiland'),
                          'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime(
                              '%Y-%m-%dT%H:%M:%SZ'),
                          'runtime_s': round(time.monotonic() - start, 1)},
           'conventions': {'grid': f'{GRID} x {GRID} directions tx = X/Z, ty = Y/Z spanning '
                                   f'{COVERAGE} of the raw image (pinhole K of our model), '
                                   'row-major (ty outer); stored as grid: half_tx, half_ty, '
                                   'n and step (1: the full grid, 2: every second row and '
                                   'column); tx = linspace(-half_tx, half_tx, n)[::step]',
                           'u_v': "optiland's chief ray on our sensor plane as a raw pixel "
                                  '(K principal point, inverted image turned upright); null '
                                  'where optiland fails or misses the stop by > 1e-8 mm'},
           'cases': out}
    args.output.write_text(json.dumps(doc, separators=(',', ':')) + '\n')
    print(f'wrote {args.output} ({args.output.stat().st_size / 1024:.0f} KiB)', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
