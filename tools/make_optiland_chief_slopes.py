#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Generate test/data/optiland_chief_slopes.json: optiland's chief rays as lines in image space.

test/data/optiland_wide_reference.json holds, for the 160-deg wide angle and the 170-deg
fisheye (config/wide_angle.yaml, config/fisheye.yaml), the real height of each chief ray on
the paraxial image plane only. A tilted sensor meets each chief ray off that plane, so the
test renderer of the self-check (test/check_scenes.py) also needs the ray's direction there.
This script traces the same designs the same way (tools/make_optiland_reference.py:
``WIDE_DESIGNS``, ``build_wide_optic``, the image surface put on the paraxial image plane by
optiland's ``image_solve``, each chief ray aimed alone by optiland's robust aimer, stop
residual < 1e-9 mm), at the same field angles as that file's curve, and writes per angle:

- ``height_mm``: ``rho(z_s)``, the chief ray's distance from the axis on the image plane
  ``z_s`` (equal to the reference file's ``real_height_abs_mm``; the script checks it);
- ``slope``: ``s = d rho / dz``, z along the light (from the lens towards the sensor), the
  ray's direction in the meridional plane (``M / N`` with the sign of the height: ``s > 0``
  when the ray moves away from the axis as it travels on);
- ``height_minus_mm``, ``height_plus_mm``: ``rho`` on the planes ``z_s -+ PLANE_STEP_MM``,
  where optiland's own intersection meets the ray with its image surface moved there
  (tools/make_optiland_assembly.py ``place_image_surface``, ``local_hits``): the check of
  the line, ``rho(z_s) + s (z - z_s)`` (agreement to 1e-12 mm).

optiland is a reference-only dependency (requirements-reference.txt); run::

    .venv/bin/pip install -r requirements-reference.txt
    .venv/bin/python tools/make_optiland_chief_slopes.py       # about 5 min
"""

from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUTPUT = REPO / 'test' / 'data' / 'optiland_chief_slopes.json'
WIDE_REFERENCE = REPO / 'test' / 'data' / 'optiland_wide_reference.json'
LENSES = ('wide_angle_160', 'fisheye_170')
#: Distance of the two check planes from the image plane, mm.
PLANE_STEP_MM = 0.05
#: The traced heights must equal the reference file's to this, mm.
HEIGHT_AGREEMENT_MM = 1e-9


def _assembly_tool() -> Any:
    """Return tools/make_optiland_assembly.py as a module (it loads its sibling tools)."""
    spec = importlib.util.spec_from_file_location(
        'make_optiland_assembly', REPO / 'tools' / 'make_optiland_assembly.py')
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    return module


def _image_ray(lens: Any) -> dict[str, float]:
    """Return the last traced ray at optiland's image surface (one ray)."""
    last = list(lens.surfaces)[-1]
    return {k: float(np.asarray(getattr(last, k), dtype=float).reshape(-1)[0])
            for k in ('x', 'y', 'z', 'L', 'M', 'N')}


def _height_on_plane(asm: Any, surface: Any, ray: dict[str, float], z: float,
                     wavelength_um: float) -> float:
    """Return rho where the ray meets optiland's image surface moved to ``z`` (its own trace)."""
    asm.place_image_surface(surface, z, (0.0, 0.0, 0.0, 0.0))
    hit = asm.local_hits(surface, {k: np.array([v]) for k, v in ray.items()}, wavelength_um)
    return float(np.hypot(hit[0, 0], hit[0, 1]))


def lens_entry(ref: Any, asm: Any, key: str, reference: dict[str, Any]) -> dict[str, Any]:
    """Trace the chief rays of one design at the reference curve's field angles."""
    spec = next(s for s in ref.WIDE_DESIGNS if s[0] == key)
    _key, _desc, builder, wavelength_um, _sensor, config = spec
    rows, _glasses, aperture, design_deg = builder(wavelength_um)
    lens = ref.build_wide_optic(rows, wavelength_um, aperture,
                                design_deg + ref.REACH_MARGIN_DEG)
    lens.updater.image_solve()
    lens.updater.update_paraxial()
    surface = list(lens.surfaces)[-1]
    z_s = float(surface.geometry.cs.z)
    curve = reference['curve']
    angles = np.asarray(curve['field_angle_deg'], dtype=float)
    out = {k: np.full(angles.size, np.nan) for k in ('h', 's', 'hm', 'hp', 'stop')}
    for i, angle in enumerate(angles):
        trace, why = ref._trace_why(lens, float(angle), wavelength_um)
        if trace is None:
            raise RuntimeError(f'{key}: optiland fails at {angle:.3f} deg: {why}')
        ray = _image_ray(lens)
        if abs(ray['z'] - z_s) > 1e-12 or abs(ray['x']) > 1e-12 or abs(ray['L']) > 1e-12:
            raise RuntimeError(f'{key}: the chief ray at {angle:.3f} deg is not meridional '
                               'on the image plane')
        sign = 1.0 if ray['y'] >= 0.0 else -1.0
        out['h'][i] = abs(ray['y'])
        out['s'][i] = sign * ray['M'] / ray['N'] if angle > 0.0 else 0.0
        for name, dz in (('hm', -PLANE_STEP_MM), ('hp', PLANE_STEP_MM)):
            out[name][i] = _height_on_plane(asm, surface, ray, z_s + dz, wavelength_um)
        asm.place_image_surface(surface, z_s, (0.0, 0.0, 0.0, 0.0))
        out['stop'][i] = abs(float(trace['y_stop'][0]))
    expected = np.asarray(curve['real_height_abs_mm'], dtype=float)
    height_error = float(np.max(np.abs(out['h'] - expected)))
    if height_error > HEIGHT_AGREEMENT_MM:
        raise RuntimeError(f'{key}: heights differ from {WIDE_REFERENCE.name} by '
                           f'{height_error:.3g} mm')
    line = np.concatenate([out['h'] - out['s'] * PLANE_STEP_MM - out['hm'],
                           out['h'] + out['s'] * PLANE_STEP_MM - out['hp']])
    # Near the axis rho(z) is |h + s dz| (the ray may cross the axis): compare there too.
    line_error = float(np.max(np.abs(line[np.isfinite(line)])))
    if line_error > 1e-12:
        raise RuntimeError(f'{key}: optiland intersections depart from the line by '
                           f'{line_error:.3g} mm')
    return {'config': config, 'wavelength_um': wavelength_um, 'image_plane_z_mm': z_s,
            'plane_step_mm': PLANE_STEP_MM,
            'max_stop_residual_mm': float(np.max(out['stop'])),
            'max_height_minus_reference_mm': height_error,
            'max_line_residual_mm': line_error,
            'field_angle_deg': _lst(angles), 'height_mm': _lst(out['h']),
            'slope': _lst(out['s']), 'height_minus_mm': _lst(out['hm']),
            'height_plus_mm': _lst(out['hp'])}


def _lst(a: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(a, dtype=float)]


def main(argv: list[str] | None = None) -> int:
    """Trace both designs and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('-o', '--output', type=Path, default=DEFAULT_OUTPUT)
    args = parser.parse_args(argv)
    import warnings
    warnings.filterwarnings('ignore')
    asm = _assembly_tool()
    ref = asm._load('make_optiland_reference')
    reference = json.loads(WIDE_REFERENCE.read_text())['lenses']
    start = time.monotonic()
    lenses = {}
    for key in LENSES:
        lenses[key] = lens_entry(ref, asm, key, reference[key])
        print(f'[{time.monotonic() - start:5.1f} s] {key}: '
              f'{len(lenses[key]["field_angle_deg"])} chief rays, slope at the edge '
              f'{lenses[key]["slope"][-1]:.4f}', file=sys.stderr, flush=True)
    doc = {
        'provenance': asm.provenance(ref, 'tools/make_optiland_chief_slopes.py', start),
        'conventions': {
            'field_angle_deg': 'the chief ray of this field angle (scene at infinity), the '
                               f'angles of {WIDE_REFERENCE.name} curve',
            'height_mm': 'rho(z_s): distance from the axis on the paraxial image plane',
            'slope': 'd rho / dz, z along the light (towards the sensor)',
            'height_minus_mm': f'rho on the plane z_s - {PLANE_STEP_MM} mm (optiland '
                               'propagation)',
            'height_plus_mm': f'rho on the plane z_s + {PLANE_STEP_MM} mm'},
        'lenses': lenses,
    }
    args.output.write_text(json.dumps(doc, indent=1) + '\n')
    print(f'wrote {args.output}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
