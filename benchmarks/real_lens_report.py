# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The report of :mod:`benchmarks.real_lenses`: docs/real_lenses.md and config/lenses/*.yaml.

The page is generated from ``results/real_lenses.json``; everything after the line
:data:`READING_MARKER` is hand-written (the reading of the results) and kept across runs.
The params files hold the prescriptions that pass (no worse than the textbook model against
lensfun, centrally and over the frame, beyond the tie margin:
:func:`benchmarks.real_lenses.passes`) and whose source may be shipped
(:data:`benchmarks.real_lens_data.SHIPPABLE_SOURCES`); the sensor is left out.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any, Mapping

from benchmarks.real_lens_data import (lens_values, LENSES, LICENCES, RealLens,
                                       SHIPPABLE_SOURCES)
from benchmarks.report import markdown_table

#: Everything from this line on in docs/real_lenses.md is written by hand and kept.
READING_MARKER = '<!-- reading: kept by hand -->'
#: The zoom positions shipped as one params file (key prefix -> file name).
ZOOM_PREFIX = 'nikkor_z_14_30_'


def licence_of(source: str) -> str:
    """Return the licence of a prescription's source (by its repository prefix)."""
    return next(text for name, text in LICENCES.items() if source.startswith(name))


def _cell(e: Mapping[str, Any] | None) -> str:
    """Return 'max px (max %) / RMS px' of one error block."""
    if e is None:
        return 'n/a'
    return f"{e['max_px']:.1f} ({e['max_pct']:.2f} %) / {e['rms_px']:.1f}"


def _spread(result: Mapping[str, Any], field: str, pct_only: bool = False) -> str:
    cells = [s['errors'][field] for s in result['spread'] if s['errors'][field]]
    if not cells:
        return '-'
    worst = max(cells, key=lambda e: e['max_px'])
    if pct_only:
        return f"{worst['max_pct']:.2f}"
    return f"{worst['max_px']:.1f} ({worst['max_pct']:.2f} %)"


def _entry(result: Mapping[str, Any]) -> str:
    t = result['target']
    return f"{t['model']}, crop {t['crop']:g}, {t['type']}, {t['distortion']} @ {t['focal']:g}"


def _verdict(result: Mapping[str, Any], baseline: str) -> str:
    v = result['verdicts'][baseline]
    return f"{v['central']} / {v['frame']}"


def summary_table(doc: Mapping[str, Any]) -> list[str]:
    """Return the short table: max errors of ours and the baselines, and who beats whom."""
    rows = []
    for r in doc['lenses']:
        rows.append([
            r['name'], r['category'],
            f"{r['ours']['central']['max_pct']:.2f} / {r['ours']['frame']['max_pct']:.2f}",
            f"{r['textbook']['central']['max_pct']:.2f} / {r['textbook']['frame']['max_pct']:.2f}",
            f"{r['k1_fit']['central']['max_pct']:.2f} / {r['k1_fit']['frame']['max_pct']:.2f}",
            _spread(r, 'central', True) + ' / ' + _spread(r, 'frame', True),
            _verdict(r, 'textbook'), _verdict(r, 'k1_fit'), 'yes' if r['passes'] else 'no'])
    return markdown_table(
        ['lens', 'kind', 'traced patent, central / frame', 'textbook: nominal pinhole '
         '(fisheye: equisolid), central / frame', 'k1 fit to lensfun, central / frame',
         'lensfun spread, central / frame', 'traced vs textbook', 'traced vs k1 fit',
         'passes (no worse than the textbook)'], rows)


def verdict_counts(doc: Mapping[str, Any]) -> str:
    """Return one sentence: how often the traced patent beats each baseline, per field."""
    parts = []
    for baseline, label in (('textbook', 'the textbook model'), ('k1_fit', 'a k1 fit')):
        for field, where in (('central', 'centrally'), ('frame', 'over the frame')):
            got = [r['verdicts'][baseline][field] for r in doc['lenses']]
            parts.append(f"against {label} {where}: better {got.count('better')}, tie "
                         f"{got.count('tie')}, undecided {got.count('undecided')}, worse "
                         f"{got.count('worse')}")
    return f"Of {len(doc['lenses'])} positions, " + '; '.join(parts) + '.'


def full_table(doc: Mapping[str, Any]) -> list[str]:
    """Return the full table: max (%) / RMS in px, central field and whole frame."""
    rows = []
    for r in doc['lenses']:
        rows.append([r['name'], _entry(r), _cell(r['ours']['central']), _cell(r['ours']['frame']),
                     _cell(r['textbook']['central']), _cell(r['textbook']['frame']),
                     f"{r['k1']:+.4f}: " + _cell(r['k1_fit']['central']),
                     _cell(r['k1_fit']['frame']),
                     _spread(r, 'central') + ' / ' + _spread(r, 'frame')])
    return markdown_table(
        ['lens', 'lensfun entry (target)', 'ours, central', 'ours, whole frame',
         'textbook, central', 'textbook, whole frame', 'k1 fit, central',
         'k1 fit, whole frame', 'lensfun spread, central / frame (max)'], rows)


def focal_table(doc: Mapping[str, Any]) -> list[str]:
    """Return the focal lengths and focus distances, and the scale-literal comparison."""
    rows = []
    for r in doc['lenses']:
        ideal = r['ideal_focal_mm']
        rows.append([
            r['name'], f"{r['efl_mm']:.3f}", f"{r['nominal_focal_mm']:g}",
            f"{r['lensfun_focal_mm']:g}" + (' (real-focal)' if r['target']['real_focal'] else ''),
            f'{ideal:.3f}', f"{(r['efl_mm'] / r['nominal_focal_mm'] - 1) * 100:+.1f} %",
            f"{r['absolute']['central']['max_pct']:.2f} %",
            f"{r['corner_deg']['ours']:.1f} / {r['corner_deg']['lensfun']:.1f}",
            'infinity (patent)', 'not recorded by lensfun',
            f"{r['focus_check']['central']['max_pct']:.3f} / "
            f"{r['focus_check']['frame']['max_pct']:.2f}"])
    return markdown_table(
        ['lens', 'traced EFL [mm]', 'nominal f', 'lensfun f', 'ideal f (normalisation)',
         'EFL vs nominal', 'central max at equal angle, lensfun f literal',
         'field angle at the frame corner [deg], ours / lensfun literal', 'focus, ours',
         'focus, lensfun', 'ours focused at 3 m instead: change, max % central / frame'],
        rows)


def _sources(doc: Mapping[str, Any], page: Path) -> list[str]:
    by_key = {lens.key: lens for lens in LENSES}
    lines = []
    for r in doc['lenses']:
        lens = by_key[r['key']]
        fig = os.path.relpath(Path(page).resolve().parents[1] / r['figure'],
                              Path(page).resolve().parent)
        lines += [f"### {r['name']}", '',
                  f'* Prescription: {lens.patent}; transcription {lens.source}; licence '
                  f'{licence_of(lens.source)}.',
                  f'* lensfun: {_entry(r)}; other entries of the same optics: '
                  + (', '.join(s['entry'] for s in r['spread']) or 'none') + '.',
                  f"* Traced: EFL {r['efl_mm']:.3f} mm, back focus {r['back_focus_mm']:.3f} mm, "
                  f"chief rays traced to {r['max_field_deg']:.1f} deg (of 100 swept); focus at "
                  'infinity.']
        lines += [f'* Correction: {c}' for c in lens.corrections]
        if lens.notes:
            lines.append(f'* Note: {lens.notes}')
        lines += ['', f"![{r['name']}]({fig})", '']
    return lines


def _evidence(doc: Mapping[str, Any]) -> list[str]:
    ev = doc['evidence']
    d13 = ev['nikkor_d13']
    zoom = ev['zoom_focal']
    return [
        '## Corrections and checks, with the evidence', '',
        '* **AF DX Fisheye-Nikkor 10.5 mm, d13.** The transcription prints d13 (stop to '
        f"surface 14) = {d13['printed']['d13_mm']} mm. Traced with it, the lens has "
        f"EFL {d13['printed']['efl_mm']:.3f} mm and back focus "
        f"{d13['printed']['back_focus_mm']:.3f} mm, against the 10.5 mm of the product and "
        'the 41.1 mm back focus the same table lists (its last row). With d13 = '
        f"{d13['corrected']['d13_mm']} mm: EFL {d13['corrected']['efl_mm']:.3f} mm, back focus "
        f"{d13['corrected']['back_focus_mm']:.3f} mm, both as listed. The corrected value is "
        "used. (That 8.776 also contradicts the patent's condition (1) is reported with the "
        'correction; the patent text itself was not available to check here.)',
        '* **Nikkor Z 14-30, zoom positions.** The middle and tele air gaps (D1, D2, D3, D4, '
        "Bf of Table 1) give the table's focal lengths: "
        + ', '.join(f"{p} {z['traced_mm']:.3f} mm (table {z['table_mm']:g})"
                    for p, z in zoom.items()) + '.',
        "* **Takumar 50/1.4.** The transcription is at the patent's f = 100 mm; halved "
        '(all lengths x 0.5).',
        "* **lensfun's definitions.** Our evaluation of the ptlens model with radii "
        "normalised by half the shorter side of a 3:2 frame at the entry's crop agrees with "
        "lensfunpy's own correction map (Modifier, distortion only) to "
        f"{ev['lensfun_check_px']:.3f} px on a 3000 x 2000 frame.", '']


def docs_page(doc: Mapping[str, Any], out_dir: Path, page: Path) -> str:
    """
    Return docs/real_lenses.md: method, tables, sources, figures, evidence; reading kept.

    :param doc: the results document.
    :param out_dir: the results folder (figures are linked relative to the page).
    :param page: where the page goes.
    :return: the markdown.
    """
    head = [
        '# Real production lenses: patents traced against lensfun', '',
        '<!-- Generated by python -m benchmarks.real_lenses (make bench) down to the reading '
        'marker: do not edit above it. -->',
        f'Generated by `python -m benchmarks.real_lenses` (part of `make bench`); lensfun '
        f"database of lensfunpy {doc['lensfunpy']}. Method: the module docstring of "
        '`benchmarks/real_lenses.py`. In short: each patent prescription is traced (chief '
        "rays, scene at infinity, nothing fitted) and compared with the product's lensfun "
        "entry in lensfun's own coordinates (radius 1 = H, half the shorter side of the "
        "entry's 3:2 calibration frame; the ideal image's scale set by the model's own "
        'normalisation, Rd(1) = 1 for ptlens and poly3). Errors are those of a correction map '
        'over the raw frame: px of a 6000 x 4000 frame (H = 2000 px), % of H. Central field: '
        'within H of the centre (the circle touching the top and bottom edges); whole frame: '
        'to the corners (1.80 H). Textbook alternatives: the pinhole at the nominal focal '
        'length (fisheye: the equisolid projection), and the best one-parameter k1 fit '
        "(lensfun's poly3, least squares over the whole frame) to the entry itself.", '',
        '## Summary (max error, % of H)', '',
        'Verdicts, on the largest errors: the traced patent *ties* with a baseline within '
        f"{doc['tie_pct']:g} % of H (1 px); beyond that the verdict is *undecided* while the "
        "difference is within lensfun's own spread in that field (another entry of the same "
        'optics is that far from the target: the calibrations cannot tell), else *better* or '
        '*worse*. A lens *passes* (and may ship as a params file) when it is not *worse* than '
        'the textbook model centrally or over the frame: the physics gives at least what a '
        'user without a calibration has for free. The k1 fit is a calibration (fitted to the '
        'target itself): beating it is not required, and the table says where the trace does.',
        '',
        *summary_table(doc), '', verdict_counts(doc), '',
        '## Full table: max px (max %) / RMS px', '', *full_table(doc), '',
        '## Focal lengths and focus', '',
        "The patents' focal lengths are stated, never rescaled: the comparison above uses "
        "lensfun's normalisation (a straight-line calibration fixes the distortion's shape, "
        'not the scale). The column "at equal angle" takes lensfun\'s focal length literally '
        '(real-focal where the entry has one, else the nominal f) and compares image heights '
        'at the same field angle: what the focal-length mismatch alone would cost. Focus: '
        'the patents tabulate infinity; lensfun records no distance for distortion. The last '
        'column bounds what focus does to the traced curve: the same prescription focused at '
        '3 m from its front principal plane by moving the whole lens (unit focusing; these '
        'lenses mostly focus otherwise: internal or floating groups, not modelled here).', '',
        *focal_table(doc), '',
        *_evidence(doc),
        '## Lenses, sources and figures', '',
        "Each figure: top, the distortion Rd / Ru - 1 of lensfun's entry (black), the "
        'traced patent and the two textbook models over the raw radius; bottom, each '
        "model's error against lensfun in px (H = 2000 px). The grey line is the edge of the "
        'central field.', '', *_sources(doc, page)]
    reading = '\n' + READING_MARKER + '\n'
    try:
        text = page.read_text()
        at = text.find(READING_MARKER)
        if at >= 0:
            reading = '\n' + text[at:]
    except OSError:
        pass
    return '\n'.join(head) + '\n' + reading


# ----------------------------------------------------------------------------- params files

def _flow(values: list[Any]) -> str:
    return json.dumps([float(f'{v:.10g}') if isinstance(v, float) else v for v in values])


def _yaml_body(values: Mapping[str, Any], zoom: Mapping[str, Any] | None) -> list[str]:
    lines = ['/**:', '  ros__parameters:', '    lens:',
             f"      aperture_diameter_mm: {values['lens.aperture_diameter_mm']}",
             f"      stop_surface: {values['lens.stop_surface']}", '      surfaces:']
    for key in ('radius_mm', 'thickness_mm', 'refractive_index', 'glass', 'conic',
                'asphere_a4', 'asphere_a6', 'asphere_a8', 'asphere_a10', 'asphere_a12'):
        value = values.get(f'lens.surfaces.{key}')
        if value:
            lines.append(f'        {key}: {_flow(list(value))}')
    if zoom:
        lines += ['      zoom:', f"        joint: {zoom['joint']}",
                  f"        positions: {_flow(zoom['positions'])}",
                  f"        surfaces: {_flow(zoom['surfaces'])}",
                  f"        thickness_mm: {_flow(zoom['thickness_mm'])}"]
    lines += ['    scene:', '      distance_mm: 0.0', '      focus_distance_mm: 0.0']
    return lines


def _header(lens: RealLens, result: Mapping[str, Any], extra: list[str]) -> list[str]:
    c, f = result['ours']['central'], result['ours']['frame']
    return [
        '# Copyright 2026 The mechdeconv_ros Authors.',
        '# SPDX-License-Identifier: Apache-2.0 (this file); the prescription: see below.',
        '#',
        f"# {lens.name}: {lens.patent}, traced at the d line from the patent's nd / vd",
        f'# (MODEL:nd:vd glasses). Prescription copied from {lens.source};',
        f'# licence of that transcription: {licence_of(lens.source)} (full text:',
        "# config/lenses/LICENSES.md). Scene at infinity (the patent's focus). No clear",
        '# semi-diameters (the patent gives none): every surface is unlimited, the stop diameter',
        "# is the transcription's. Against lensfun (docs/real_lenses.md): max error",
        f"# {c['max_pct']:.2f} % of the half frame height centrally ({c['max_px']:.1f} px of a",
        f"# 4000 px high frame), {f['max_pct']:.2f} % over the frame; against the textbook",
        f"# model {_verdict(result, 'textbook')}, against a k1 fit to lensfun "
        f"{_verdict(result, 'k1_fit')}", '# (central / frame).', *extra,
        '# The sensor is yours to add: sensor.pixel_size_x_um, sensor.pixel_size_y_um,',
        '# sensor.width_px, sensor.height_px (docs/describe_your_lens.md).']


def write_configs(doc: Mapping[str, Any], folder: Path) -> list[Path]:
    """
    Write config/lenses/<key>.yaml for every passing lens of a shippable source.

    The three Nikkor Z 14-30 positions become one file with a zoom table (joint ``zoom``,
    position = Table 1's focal length in mm) when all three pass.

    :param doc: the results document.
    :param folder: the folder.
    :return: the files written.
    """
    folder.mkdir(parents=True, exist_ok=True)
    by_key = {lens.key: lens for lens in LENSES}
    results = {r['key']: r for r in doc['lenses']}
    written = []
    zoom_keys = [k for k in results if k.startswith(ZOOM_PREFIX)]
    for key, result in results.items():
        lens = by_key[key]
        if not result['passes'] or not lens.source.startswith(SHIPPABLE_SOURCES):
            continue
        if key in zoom_keys:
            continue
        values = lens_values(lens)
        text = _header(lens, result, []) + _yaml_body(values, None)
        path = folder / f'{key}.yaml'
        path.write_text('\n'.join(text) + '\n')
        written.append(path)
    if zoom_keys and all(results[k]['passes'] for k in zoom_keys):
        written.append(_zoom_config(doc, [by_key[k] for k in zoom_keys], folder))
    return written


def _zoom_config(doc: Mapping[str, Any], lenses: list[RealLens], folder: Path) -> Path:
    results = {r['key']: r for r in doc['lenses']}
    zoom = doc['evidence']['zoom_focal']
    gaps = sorted(k for k in lenses[0].gaps if k < len(lenses[0].rows) - 1)
    positions = [zoom[lens.key.rsplit('_', 1)[1]]['table_mm'] for lens in lenses]
    order = sorted(range(len(lenses)), key=lambda i: positions[i])
    table = {'joint': 'zoom', 'positions': [positions[i] for i in order], 'surfaces': gaps,
             'thickness_mm': [lenses[i].gaps[g] for i in order for g in gaps]}
    wide = lenses[order[0]]
    worst = max((results[lens.key] for lens in lenses),
                key=lambda r: r['ours']['central']['max_pct'])
    extra = ['# Zoom: joint "zoom" of sensor_msgs/JointState, position = the focal length in mm',
             '# of Table 1 (14.42, 20.0, 29.101); gaps D1, D2, D3, D4 tabled there (linear in',
             '# between). The surfaces arrays hold the wide end. The errors above are those of',
             '# the position with the largest central error.']
    named = dataclasses.replace(wide, name='Nikkor Z 14-30 f/4 S')
    text = _header(named, worst, extra) + _yaml_body(lens_values(wide), table)
    path = folder / 'nikkor_z_14_30.yaml'
    path.write_text('\n'.join(text) + '\n')
    return path
