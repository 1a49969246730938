#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Generate test/data/optiland_grids.json: ground truth for the robustness benchmark.

The accuracy benchmark (benchmarks/accuracy.py, the paper's section 4, Figs. 6-7) needs the
real sensor positions of ONE planar box grid in the scene, seen through a camera whose lens
changes: the aperture-stop offset m_a from 0 to 1 mm, the thickness t from 3 to 5 mm, and both
together. ``tools/make_optiland_reference.py`` gives each variant its own grid (95 % of the
sensor for that lens), so a thicker lens there looks at a smaller scene grid. This tool keeps
the scene fixed: the object points are those of the nominal Case 2 grid (20 x 18 points whose
pinhole images cover 95 % of the nominal sensor), and every variant lens traces exactly these
points with optiland, the package independent of ours. Our own tracer is not used here.

The lens builder, the chief-ray tracer (optiland's iterative aimer, tolerance 1e-11 mm at the
stop) and the JSON writer are those of ``tools/make_optiland_reference.py`` (imported, not
copied), so both files describe the lenses the same way. Install the pin of
``requirements-reference.txt`` and run::

    python tools/make_optiland_grids.py        # writes test/data/optiland_grids.json

Self-check: for the m_a variants that the reference file also holds (same focal length, so the
same object points), the positions must agree with the reference grids to 1e-9 mm.

Signs as in the reference file: ``object_*`` (shared by all variants) on the object plane, l
from the variant's own front principal plane, so ``tan = object / l`` and the pinhole image is
``v tan`` (v of the variant); ``real_*`` is the chief ray on the sensor as optiland gives it
(inverted image: opposite sign).
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUTPUT = REPO / 'test' / 'data' / 'optiland_grids.json'
REFERENCE_JSON = REPO / 'test' / 'data' / 'optiland_reference.json'

#: Case 2 of the paper (config/case2.yaml): n, r1, r2, t, m_a, stop diameter, l (mm).
NOMINAL = {'refractive_index': 1.5168, 'r1_mm': 4.0, 'r2_mm': -4.0, 'thickness_mm': 3.0,
           'stop_offset_mm': 0.2, 'aperture_diameter_mm': 1.0, 'distance_mm': 1000.0}
#: The sweeps: stop offset alone, thickness alone, both together (m_a = s, t = 3 + 2 s).
STOP_OFFSETS_MM = tuple(round(0.1 * i, 3) for i in range(11))
THICKNESSES_MM = tuple(round(3.0 + 0.25 * i, 3) for i in range(9))
BOTH = tuple((round(0.1 * i, 3), round(3.0 + 0.2 * i, 3)) for i in range(11))


def _load_reference_tool() -> Any:
    """Import tools/make_optiland_reference.py as a module (it is not a package)."""
    path = REPO / 'tools' / 'make_optiland_reference.py'
    spec = importlib.util.spec_from_file_location('make_optiland_reference', path)
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    return module


def variants() -> list[tuple[str, str, float, float]]:
    """Return ``(key, sweep, m_a, t)`` of every lens to trace (the nominal one once)."""
    out: list[tuple[str, str, float, float]] = []
    seen: set[tuple[float, float]] = set()
    rows = ([('stop_offset', m, NOMINAL['thickness_mm']) for m in STOP_OFFSETS_MM]
            + [('thickness', NOMINAL['stop_offset_mm'], t) for t in THICKNESSES_MM]
            + [('both', m, t) for m, t in BOTH])
    for sweep, m_a, t in rows:
        key = f'ma{m_a:.2f}_t{t:.2f}'
        if (m_a, t) not in seen:
            seen.add((m_a, t))
            out.append((key, sweep, m_a, t))
    return out


def scene_grid(ref: Any) -> dict[str, np.ndarray]:
    """
    Return the fixed scene grid: the nominal Case 2 box grid on the object plane, mm.

    Same construction as the reference tool's ``grid``: pinhole images at ``GRID_COVERAGE`` of
    the nominal sensor, ``GRID_NX`` x ``GRID_NY`` points, row-major (y outer, x inner).
    """
    sens = ref.sensor_info(ref.SENSOR_CASE2)
    cf = ref.thick_lens_closed_form(NOMINAL['refractive_index'], NOMINAL['r1_mm'],
                                    NOMINAL['r2_mm'], NOMINAL['thickness_mm'],
                                    NOMINAL['distance_mm'])
    v0 = cf['image_distance_mm']
    xs = np.linspace(-1.0, 1.0, ref.GRID_NX) * 0.5 * ref.GRID_COVERAGE * sens['width_mm']
    ys = np.linspace(-1.0, 1.0, ref.GRID_NY) * 0.5 * ref.GRID_COVERAGE * sens['height_mm']
    xi, yi = np.meshgrid(xs, ys)
    scale = NOMINAL['distance_mm'] / v0
    return {'object_x_mm': xi.ravel() * scale, 'object_y_mm': yi.ravel() * scale,
            'nominal_image_distance_mm': np.array(v0), 'sensor': sens}


def trace_variant(ref: Any, grid: dict[str, Any], m_a: float, t: float) -> dict[str, Any]:
    """Trace the fixed scene grid through the Case 2 lens with stop offset m_a, thickness t."""
    n, r1, r2 = NOMINAL['refractive_index'], NOMINAL['r1_mm'], NOMINAL['r2_mm']
    l_mm = NOMINAL['distance_mm']
    obj_x, obj_y = grid['object_x_mm'], grid['object_y_mm']
    sens = grid['sensor']
    cf = ref.thick_lens_closed_form(n, r1, r2, t, l_mm)
    field_max = ref.CURVE_REACH * sens['corner_radius_mm'] / cf['image_distance_mm'] * l_mm
    field_max = max(field_max, 1.05 * float(np.max(np.hypot(obj_x, obj_y))))
    lens, _rows, first_z, cf = ref.build_thick_lens(
        n, r1, r2, t, m_a, NOMINAL['aperture_diameter_mm'], l_mm, field_max)
    par = ref.paraxial_data(lens, first_z)
    v = par['image_distance_mm']
    traced = ref.trace_chief(lens, obj_x / field_max, obj_y / field_max, 'iterative')
    if not (np.allclose(traced['x0'], obj_x, rtol=1e-12, atol=1e-12)
            and np.allclose(traced['y0'], obj_y, rtol=1e-12, atol=1e-12)):
        raise RuntimeError(f'm_a {m_a}, t {t}: optiland launched other object points')
    stop_residual = float(np.max(np.hypot(traced['x_stop'], traced['y_stop'])))
    if not stop_residual < 1e-9:
        raise RuntimeError(f'm_a {m_a}, t {t}: chief rays missed the stop centre by '
                           f'{stop_residual:.2e} mm')
    return {
        'stop_offset_mm': m_a, 'thickness_mm': t,
        'efl_mm': par['efl_mm'], 'image_distance_mm': v,
        'front_principal_z_mm': par['front_principal_z_mm'],
        'stop_z_mm': cf['front_principal_z_mm'] - m_a,
        'real_x_mm': ref.lst(traced['x_img']), 'real_y_mm': ref.lst(traced['y_img']),
        'max_stop_residual_mm': stop_residual,
    }


def self_check(entries: dict[str, dict[str, Any]]) -> dict[str, float]:
    """Compare with the reference grids that share our object points (the m_a variants)."""
    if not REFERENCE_JSON.exists():
        return {}
    reference = json.loads(REFERENCE_JSON.read_text())['grids']
    out = {}
    for ref_key, m_a in (('case2', 0.2), ('case2_ma0.0', 0.0), ('case2_ma0.5', 0.5),
                         ('case2_ma1.0', 1.0)):
        mine = entries.get(f'ma{m_a:.2f}_t3.00')
        if ref_key not in reference or mine is None:
            continue
        diff = max(float(np.max(np.abs(np.subtract(mine[k], reference[ref_key][k]))))
                   for k in ('real_x_mm', 'real_y_mm'))
        if not diff < 1e-9:
            raise RuntimeError(f'{ref_key}: differs from the reference grid by {diff:.2e} mm')
        out[ref_key] = diff
    return out


def main(argv: list[str] | None = None) -> int:
    """Trace every variant and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('-o', '--output', type=Path, default=DEFAULT_OUTPUT,
                        help='output JSON (default: %(default)s)')
    args = parser.parse_args(argv)
    start = time.monotonic()
    ref = _load_reference_tool()
    import warnings
    warnings.filterwarnings('ignore', message='.*numba.*')
    grid = scene_grid(ref)
    entries: dict[str, dict[str, Any]] = {}
    sweeps: dict[str, list[str]] = {'stop_offset': [], 'thickness': [], 'both': []}
    for key, sweep, m_a, t in variants():
        entries[key] = trace_variant(ref, grid, m_a, t)
        print(f'[{time.monotonic() - start:5.1f} s] {key}: f = {entries[key]["efl_mm"]:.4f} mm',
              file=sys.stderr, flush=True)
    for sweep, m_a, t in ([('stop_offset', m, NOMINAL['thickness_mm']) for m in STOP_OFFSETS_MM]
                          + [('thickness', NOMINAL['stop_offset_mm'], t) for t in THICKNESSES_MM]
                          + [('both', m, t) for m, t in BOTH]):
        sweeps[sweep].append(f'ma{m_a:.2f}_t{t:.2f}')
    checks = self_check(entries)
    sens = grid['sensor']
    doc = {
        'provenance': {
            'generator': 'tools/make_optiland_grids.py',
            'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime(
                '%Y-%m-%dT%H:%M:%SZ'),
            'versions': ref.versions(),
            'runtime_s': round(time.monotonic() - start, 1),
            'self_check_vs_reference_max_abs_mm': checks,
        },
        'conventions': {
            'scene': 'one fixed planar grid of object points for every variant: the nominal '
                     'Case 2 box grid (pinhole images at coverage x the nominal sensor)',
            'object_distance': 'l from the front principal plane of each variant lens',
            'order': 'row-major: y (rows, ny) outer, x (columns, nx) inner',
            'tan': 'object_* / l; the pinhole (ideal) image is image_distance_mm * tan',
            'real': 'chief ray on the sensor plane as optiland gives it (inverted image)',
            'aiming': 'optiland iterative ray aiming, as tools/make_optiland_reference.py',
        },
        'nominal': NOMINAL,
        'sensor': sens,
        'wavelength_um': ref.WAVELENGTH_UM,
        'nx': ref.GRID_NX, 'ny': ref.GRID_NY, 'coverage': ref.GRID_COVERAGE,
        'nominal_image_distance_mm': float(grid['nominal_image_distance_mm']),
        'object_x_mm': ref.lst(grid['object_x_mm']),
        'object_y_mm': ref.lst(grid['object_y_mm']),
        'sweeps': sweeps,
        'variants': entries,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(ref.dumps(doc))
    print(f'wrote {args.output} ({args.output.stat().st_size / 1024:.0f} KiB) in '
          f'{time.monotonic() - start:.1f} s; self-check {checks}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
