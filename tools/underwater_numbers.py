#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Print every number docs/underwater.md quotes, each computed here from the package's API.

Sections (the page's order): the water (Quan & Fry against IAPWS R9-97), a tilted port's
effect on the axis pixel, the shipped example (config/underwater_flat.yaml), the non-central
error of a flat port, a dome and the wide-angle lens, the agreement with optiland
(test/data/optiland_ports.json, written by tools/make_optiland_ports.py) and the remap of a
non-symmetric port against the exact per-point trace. Deterministic (seeded pixels); the
numbers do not depend on the machine's load.

Run::

    python tools/underwater_numbers.py            # about a minute
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
import sys
from typing import Any

from mechdeconv_ros.imaging.remap import build_float_maps
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.model.underwater import noncentral_errors, project_points, RESIDUAL_GRID
from mechdeconv_ros.optics.water import iapws_water_index, water_index
from mechdeconv_ros.schema.params import load_params_file
import numpy as np

REPO = Path(__file__).resolve().parents[1]
SEA = {'scene.medium': 'seawater', 'scene.salinity_psu': 35.0, 'scene.temperature_c': 15.0}
FLAT = {**SEA, 'port.type': 'flat', 'port.glass': 'PMMA', 'port.distance_mm': 10.0,
        'port.thickness_mm': 5.0}
DOME = {**SEA, 'port.type': 'dome', 'port.glass': 'N-BK7', 'port.radius_mm': 40.0,
        'port.thickness_mm': 6.0}
NO_PORT = {'port.type': 'none', 'scene.medium': 'air'}


def config(name: str, **overrides: Any) -> dict[str, Any]:
    """Return a shipped config's values with overrides."""
    values = load_params_file(REPO / 'config' / f'{name}.yaml')
    values.update(overrides)
    return values


def water() -> list[str]:
    """Return the water's lines: the index at 550 nm, 25 degC, and IAPWS's agreement."""
    fresh, sea = water_index(550.0, 25.0, 0.0), water_index(550.0, 25.0, 35.0)
    worst = max(abs(water_index(lam, t) - iapws_water_index(lam, t))
                for lam in np.linspace(400.0, 700.0, 31) for t in np.linspace(0.0, 30.0, 31))
    return [f'water 550 nm 25 degC: fresh {fresh:.4f}, 35 PSU {sea:.4f} '
            f'({(sea / fresh - 1.0) * 100:.2f} % in scale)',
            f'Quan & Fry vs IAPWS R9-97 (400-700 nm, 0-30 degC, pure water): {worst:.1e}']


def shipped() -> list[str]:
    """Return the shipped example's lines (config/underwater_flat.yaml)."""
    model = build_model(config('underwater_flat'))
    air = build_model(config('underwater_flat', **NO_PORT))
    fresh = build_model(config('underwater_flat', **{'scene.medium': 'water'}))
    errors = noncentral_errors(model)
    fits = {fit.distortion_model: fit.max_error_px for fit in model.equivalent_fits}
    return [f'underwater_flat.yaml: noncentral half {errors["noncentral_error_px_half"]:.2f} px, '
            f'twice {errors["noncentral_error_px_twice"]:.2f} px',
            f'  focal length in water {model.K[0, 0]:.0f} px, in air {air.K[0, 0]:.0f} px '
            f'(x {model.K[0, 0] / air.K[0, 0]:.2f}); plumb_bob max error '
            f'{fits.get("plumb_bob", math.nan):.1e} px',
            f'  fresh -> sea water (15 degC): focal length x {model.K[0, 0] / fresh.K[0, 0]:.4f} '
            f'({model.K[0, 0] - fresh.K[0, 0]:.0f} px)']


def tilt() -> list[str]:
    """Return how far 1 deg of flat-port tilt moves the axis direction's pixel (Cooke)."""
    base = build_model(config('underwater_flat', **{'scene.distance_mm': 1000.0}))
    tilted = build_model(config('underwater_flat', **{'scene.distance_mm': 1000.0,
                                                      'port.tilt_x_deg': 1.0}))
    u0, v0 = project_points(base, 0.0, 0.0)
    u1, v1 = project_points(tilted, 0.0, 0.0)
    return [f'1 deg of port.tilt_x_deg (underwater_flat.yaml at 1 m): the axis direction '
            f'moves {float(v1 - v0):+.1f} px in v, {float(u1 - u0):+.1e} px in u']


def noncentral() -> list[str]:
    """Return the non-central errors at 1 m in seawater: flat, dome, wide angle."""
    lines = []
    at = {'scene.distance_mm': 1000.0}
    for label, values in (
            ('Cooke, flat PMMA 10 mm in front, 5 mm thick',
             config('underwater_flat', **FLAT, **at)),
            ('Cooke, N-BK7 dome R = 40 mm, 6 mm, centred on the entrance pupil',
             config('underwater_flat', **{**NO_PORT, **DOME, **at})),
            ('wide angle, the same flat port', config('wide_angle', **FLAT, **at))):
        errors = noncentral_errors(build_model(values))
        lines.append(f'{label} (scene at 1 m): {errors["noncentral_error_px_half"]:.2g} px at '
                     f'0.5 m, {errors["noncentral_error_px_twice"]:.2g} px at 2 m')
    return lines


def reference() -> list[str]:
    """Return the optiland table: per lens and port kind, cases, rays and the max error."""
    data = json.loads((REPO / 'test' / 'data' / 'optiland_ports.json').read_text())
    configs = {'cooke': 'cooke_triplet', 'wide': 'wide_angle', 'fisheye': 'fisheye'}
    groups: dict[tuple[str, str], list[float]] = {}
    missing = 0
    for case in data['cases'].values():
        values = config(configs[case['lens']], **case['overrides'])
        if case['lens'] == 'cooke':
            values['sensor.pixel_size_x_um'] = values['sensor.pixel_size_y_um'] = 5.0
        model = build_model(values)
        grid = case['grid']
        tx, ty = np.meshgrid(
            np.linspace(-grid['half_tx'], grid['half_tx'], grid['n'])[::grid['step']],
            np.linspace(-grid['half_ty'], grid['half_ty'], grid['n'])[::grid['step']])
        u_ref = np.array([np.nan if u is None else u for u in case['u']])
        v_ref = np.array([np.nan if v is None else v for v in case['v']])
        u, v = project_points(model, tx.ravel(), ty.ravel())
        has = np.isfinite(u_ref)
        missing += int(np.sum(has != np.isfinite(u)))
        key = (case['lens'], case['overrides']['port.type'])
        group = groups.setdefault(key, [0, 0, 0.0, 0])
        group[0] += 1
        group[1] += int(has.sum())
        group[2] = max(group[2], float(np.max(np.hypot(u - u_ref, v - v_ref)[has])))
        group[3] += int(u_ref.size)
    lines = [f'{len(data["cases"])} cases (optiland {data["provenance"]["optiland"]}); '
             f'directions where one of optiland and project has a ray and the other none: '
             f'{missing}', '| lens, port | cases | directions | rays | max error (px) |',
             '| --- | --- | --- | --- | --- |']
    names = {'cooke': 'Cooke triplet', 'wide': 'wide angle', 'fisheye': 'fisheye'}
    for (lens, kind), (cases, rays, worst, total) in groups.items():
        lines.append(f'| {names[lens]}, {kind} | {cases} | {total} | {rays} | {worst:.1e} |')
    return lines


def remap() -> list[str]:
    """Return the maps (radial + splined residual) against the exact trace, 400 pixels."""
    lines = [f'residual grid: {RESIDUAL_GRID[0]} x {RESIDUAL_GRID[1]} nodes']
    hd = {'sensor.width_px': 1920, 'sensor.height_px': 1080}
    cooke = {'sensor.pixel_size_x_um': 5.0, 'sensor.pixel_size_y_um': 5.0, **hd,
             'scene.distance_mm': 1000.0}
    for label, values in (
            ('Cooke, flat port tilted 1 deg in x, -0.5 deg in y',
             config('cooke_triplet', **FLAT, **cooke,
                    **{'port.tilt_x_deg': 1.0, 'port.tilt_y_deg': -0.5})),
            ('Cooke, dome decentred 1 mm in x, -1 mm in y',
             config('cooke_triplet', **DOME, **cooke,
                    **{'port.decenter_x_mm': 1.0, 'port.decenter_y_mm': -1.0})),
            ('wide angle, dome R = 45 mm decentred 1 mm in x',
             config('wide_angle', **{**DOME, 'port.radius_mm': 45.0,
                                     'port.decenter_x_mm': 1.0, 'scene.distance_mm': 1000.0})),
            ('wide angle, the same dome centred (the radial curve alone)',
             config('wide_angle', **{**DOME, 'port.radius_mm': 45.0,
                                     'scene.distance_mm': 1000.0}))):
        model = build_model(values)
        map_x, map_y = build_float_maps(model)
        rng = np.random.default_rng(7)
        u = rng.integers(0, model.out_width, 400)
        v = rng.integers(0, model.out_height, 400)
        xn = (u - model.K_new[0, 2]) / model.K_new[0, 0]
        yn = (v - model.K_new[1, 2]) / model.K_new[1, 1]
        eu, ev = project_points(model, xn, yn)
        inside = map_x[v, u] > -999.0
        err = np.hypot(map_x[v, u] - eu, map_y[v, u] - ev)[inside]
        lines.append(f'{label}: max {np.max(err):.1e} px over {int(inside.sum())} of 400 '
                     'random output pixels')
    return lines


def main(argv: list[str] | None = None) -> int:
    """Print the numbers, section by section."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.parse_args(argv)
    for title, section in (('The water', water), ('A tilted port', tilt),
                           ('The shipped example', shipped),
                           ('Non-central error', noncentral),
                           ('Accuracy against optiland', reference),
                           ('The remap of a non-symmetric port', remap)):
        print(f'## {title}')
        for line in section():
            print(line)
        print()
        sys.stdout.flush()
    return 0


if __name__ == '__main__':
    sys.exit(main())
