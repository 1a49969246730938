# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Imported lens files: agreement with an independent tracer, and what an import costs.

For every real ``.zmx`` file of ``test/data/zmx`` with a reference in
``test/data/zmx_reference.json`` (optiland 0.6.3 read the same file, aimed each chief ray at the
stop centre and traced it at the file's primary wavelength: ``tools/make_zmx_reference.py``):

* **geometry**: the file imported with optiland's own indices, traced by this package to the
  file's image surface; the largest difference of the real image height over the reference's
  field, in pixels of the reference's pitch, and the relative difference of the effective
  focal length. This isolates the reader and the tracer from the glass data.
* **with our glass**: the file imported as a user imports it (the bundled catalogs at the
  file's wavelength); the same two numbers. Differences here are glass data (catalog
  revisions), or the import refuses the file (the reason is shown).
* **cost**: ``import_zmx`` (read, convert, resolve glasses) and ``build_model`` of the imported
  lens at 1920x1080, median ms.

Heights are signed as the raw image (inverted); the comparison is of magnitudes' differences.

::

    python -m benchmarks.lens_import [--quick] [--out results]
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from benchmarks.common import bench_main, interleave, log, RESULTS, Variant
from benchmarks.report import machine_info, write_json
from mechdeconv_ros.lenses.lens_import import import_zmx, Medium
from mechdeconv_ros.lenses.lens_params import make_prescription
from mechdeconv_ros.lenses.zmx import LensImportError
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.optics.prescription import paraxial, vertex_z
from mechdeconv_ros.optics.raytrace import trace_field_angles
from mechdeconv_ros.schema.params import check_values
import numpy as np

REPO = Path(__file__).resolve().parents[1]
REFERENCE = REPO / 'test' / 'data' / 'zmx_reference.json'
SIZE = (1920, 1080)


def _optiland_indices(ref: dict[str, Any]) -> Any:
    """Return a resolver that gives each medium optiland's index (file surface n)."""
    def resolve(lens: Any, surface: Any, wavelength_nm: float) -> Medium:
        return Medium('', ref['media'][surface.number]['index'])
    return resolve


def _agreement(values: dict[str, Any], ref: dict[str, Any]) -> tuple[float, float]:
    """Return (largest height difference px, relative EFL difference) against the reference."""
    vals = check_values(values)
    lens = make_prescription(vals)
    sensor_z = float(vertex_z(lens)[-1]) + float(vals['lens.image_distance_mm'])
    theta = np.radians(np.asarray(ref['field_deg'], dtype=float))
    ours = -trace_field_angles(lens, math.inf, sensor_z, theta)
    pixel_mm = float(ref['tolerance_pixel_um']) * 1e-3
    worst = float(np.max(np.abs(ours - np.asarray(ref['real_height_mm'], dtype=float))))
    efl = paraxial(lens).efl_mm
    return worst / pixel_mm, abs(efl / float(ref['efl_mm']) - 1.0)


def run(out_dir: Path = RESULTS, quick: bool = False) -> dict[str, Any]:
    """
    Compare and time every referenced file; write ``lens_import.json`` into ``out_dir``.

    :param out_dir: results folder.
    :param quick: one round of one call, no wait for a quiet machine (proves it runs; the
        timings mean little).
    :return: the results document.
    """
    rounds, reps = (1, 1) if quick else (3, 5)
    lenses = json.loads(REFERENCE.read_text(encoding='utf-8'))['lenses']
    results: dict[str, Any] = {}
    for key, ref in lenses.items():
        path = REPO / ref['file']
        log(f'lens_import: {key}')
        geometry = import_zmx(path, resolve=_optiland_indices(ref)).values
        row: dict[str, Any] = {'file': ref['file'], 'note': ref.get('note', ''),
                               'field_deg': float(max(ref['field_deg'])),
                               'pixel_um': float(ref['tolerance_pixel_um'])}
        row['geometry_px'], row['geometry_efl_rel'] = _agreement(geometry, ref)
        # optiland gives a glass it cannot find Zemax's 1.5 / 40 placeholder: its reference
        # is then not the designed lens, and 'with our glass' compares with that placeholder.
        row['reference_placeholder'] = any(
            m['kind'] == 'AbbeMaterial' and abs(m['index'] - 1.5) < 1e-12 for m in ref['media'])
        try:
            ours = import_zmx(path).values
        except LensImportError as err:
            row['refused'] = str(err).splitlines()[0]
            ours = None
        if ours is not None:
            row['glass_px'], row['glass_efl_rel'] = _agreement(ours, ref)
        sized = {**(ours or geometry), 'sensor.pixel_size_x_um': row['pixel_um'],
                 'sensor.pixel_size_y_um': row['pixel_um']}
        variants = [Variant('import', lambda p=path, r=ref: import_zmx(
                        p, resolve=_optiland_indices(r)))]
        try:
            build_model(sized, *SIZE)
            variants.append(Variant('model', lambda v=sized: build_model(v, *SIZE)))
        except ValueError as err:   # the sensor we chose is larger than the lens's field
            row['model_error'] = str(err)
        timings, _ = interleave(variants, rounds, reps, quiet_wait_s=0.0 if quick else 2.0)
        row['import_ms'] = timings['import'].median
        if 'model' in timings:
            row['model_ms'] = timings['model'].median
        results[key] = row
    doc = {'machine': machine_info(), 'size': list(SIZE), 'rounds': rounds, 'reps': reps,
           'lenses': results}
    write_json(out_dir / 'lens_import.json', doc)
    return doc


def tables(doc: dict[str, Any]) -> list[str]:
    """Return the markdown table of a results document."""
    lines = ['### Imported lens files against optiland', '',
             'Real `.zmx` files from the rayoptics distribution (test/data/zmx); largest '
             'real-height difference over the field in pixels of the pitch shown, relative '
             'focal-length difference; import and build_model '
             f"({doc['size'][0]}x{doc['size'][1]}) median ms.", '',
             '| file | field | pitch | geometry px / EFL | with our glass px / EFL | '
             'import ms | model ms |',
             '|---|---:|---:|---|---|---:|---:|']
    for key, r in doc['lenses'].items():
        glass = (f"{r['glass_px']:.2g} / {r['glass_efl_rel']:.1e}" if 'glass_px' in r
                 else f"refused: {r['refused'].split(': ', 1)[-1][:60]}")
        if r.get('reference_placeholder') and 'glass_px' in r:
            glass += ' (optiland used a 1.5 / 40 placeholder glass)'
        model = f"{r['model_ms']:.1f}" if 'model_ms' in r else '-'
        lines.append(f"| {key} | {r['field_deg']:.0f} deg | {r['pixel_um']:g} um | "
                     f"{r['geometry_px']:.2g} / {r['geometry_efl_rel']:.1e} | {glass} | "
                     f"{r['import_ms']:.1f} | {model} |")
    return lines + ['']


def main(argv: list[str] | None = None) -> int:
    """Run from the command line."""
    return bench_main(__doc__ or '', run, tables, 'one round of one call', argv)


if __name__ == '__main__':
    raise SystemExit(main())
