# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Real production lenses: their patents traced by this project against lensfun's calibrations.

For every lens of :mod:`benchmarks.real_lens_data` the patent prescription is traced (chief
rays, scene at infinity, d-line indices of the patent's nd) and compared with the lensfun
entry of the product (lensfunpy 1.18.0's bundled database, a reference-only dependency in
requirements-bench.txt), with no parameter fitted. lensfun's definitions, as its library
applies them (checked against ``lensfunpy.Modifier`` in :func:`check_lensfun_convention`):

* radii are normalised to half the shorter side of the calibration frame, a 3:2 frame of the
  entry's crop factor c: H = 12 mm / c (r = 1 at the top edge, the corner at r = 1.803);
* models, Ru ideal and Rd real (distorted) radius: ptlens Rd = Ru (a Ru^3 + b Ru^2 + c Ru +
  1 - a - b - c), poly3 Rd = Ru (1 - k1 + k1 Ru^2), poly5 Rd = Ru (1 + k1 Ru^2 + k2 Ru^4);
* the ideal image is the entry's projection (rectilinear: f tan(theta); fisheye:
  f theta; equisolid: 2 f sin(theta / 2)) with f the entry's ``real-focal`` where it has one,
  else the nominal focal length.

A rectilinear calibration from straight lines fixes the distortion's shape but not the
ideal image's scale: ptlens and poly3 are normalised by Rd(1) = 1, poly5 by Rd'(0) = 1, and
a rectilinear correction does not depend on f. So a rectilinear curve (ours, or another
entry's) is compared in the entry's normalised coordinates with its ideal scale set by the
same normalisation (ours then passes through Rd(1) = 1 too; the f this implies is reported,
against the patent's and the nominal one: a focal-length mismatch is stated, never hidden
in the comparison). A fisheye entry fixes the field angle of every radius through its f
(and real-focal, measured from a panorama), so there the comparison is at equal field angle.

Errors are taken over the raw (distorted) frame, a 121 x 81 grid of points: for each point
the lensfun entry gives its ideal radius, the candidate the real radius it puts that ray at,
and the difference is the error of a correction map there. Central field: points within
half the frame height of the centre (r <= 1); whole frame: to the corners. Pixels are those
of a 24 MP 6000 x 4000 frame of the entry's crop (H = 2000 px); % are of H, half the frame
height. The two textbook alternatives: the nominal-f pinhole (fisheye: equisolid), and the
best one-parameter fit (lensfun's poly3 k1, least squares over the whole frame) to the entry.

Verdicts (:func:`verdicts`): per lens, centrally and over the frame, the traced patent is
better than, worse than, tied with (within 1 px) or undecided against (within lensfun's own
spread) each of the two. A lens passes (:func:`passes`: it may ship as a params file) when it
is not worse than its own textbook model in either field: a criterion its textbook model
cannot meet by itself (until issue 37: within 0.5 % of H centrally, which the nominal
pinhole met in 7 of 10 rows).

::

    python -m benchmarks.real_lenses [--out results] [--docs docs/real_lenses.md]
    python -m benchmarks.real_lenses --from-json   # judge results/real_lenses.json anew
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any, Mapping

from benchmarks.common import log, RESULTS
from benchmarks.real_lens_data import lens_values, LENSES, RealLens, SAME_OPTICS
from benchmarks.report import save_figure, write_json
from mechdeconv_ros.lenses.lens_params import make_prescription
from mechdeconv_ros.optics.raytrace import image_plane, paraxial, trace_field_angles
import numpy as np

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / 'docs' / 'real_lenses.md'
CONFIGS = REPO / 'config' / 'lenses'
#: Half the shorter side of the full-frame 3:2 calibration frame (36 x 24 mm), mm.
FULL_FRAME_HALF_HEIGHT_MM = 12.0
#: lensfun's default aspect ratio of a calibration frame.
ASPECT = 1.5
#: Pixels in half the frame height (a 6000 x 4000 frame).
HALF_HEIGHT_PX = 2000.0
#: Grid of raw-frame points the errors are taken over (a quarter frame suffices: radial).
GRID = (121, 81)
#: The finite focus distance (mm from H) of the focus check: how much focusing there changes
#: the traced curve (unit focusing), against the infinity focus the patents tabulate.
FOCUS_CHECK_MM = 3000.0
#: Two largest errors tie within this much of H (1 px of the 2000 px half height).
TIE_PCT = 0.05
#: The baselines the traced patent is judged against: what a user without a calibration
#: would take (the nominal-f pinhole; fisheye: equisolid), and one who calibrated k1.
BASELINES = ('textbook', 'k1_fit')
FIELDS = ('central', 'frame')
INF = math.inf


# ----------------------------------------------------------------------------- lensfun side

def lensfun_entries(model: str, focal: float) -> list[dict[str, Any]]:
    """
    Return the lensfun entries of a lens model with a distortion calibration at ``focal``.

    :param model: lensfun's model name (exact).
    :param focal: the calibrated focal length, mm.
    :return: dicts with model, crop, type, distortion model, terms, real focal, comment.
    """
    import lensfunpy
    db = lensfunpy.Database()
    real = _real_focals()
    found = []
    for lens in db.lenses:
        if lens.model != model:
            continue
        for calib in lens.calib_distortion:
            if abs(calib.focal - focal) > 1e-6:
                continue
            kind = {lensfunpy.LensType.RECTILINEAR: 'rectilinear',
                    lensfunpy.LensType.FISHEYE: 'fisheye',
                    lensfunpy.LensType.FISHEYE_EQUISOLID: 'equisolid'}[lens.type]
            crop = round(float(lens.crop_factor), 4)
            found.append({
                'model': model, 'crop': crop, 'type': kind,
                'distortion': calib.model.name.lower(),
                'terms': [round(float(t), 7) for t in calib.terms],
                'focal': float(calib.focal),
                'real_focal': real.get((model, crop, float(calib.focal))),
                'half_height_mm': FULL_FRAME_HALF_HEIGHT_MM / crop})
            break
    found.sort(key=lambda e: e['crop'])
    return found


def _real_focals() -> dict[tuple[str, float, float], float]:
    """Return {(model, crop, focal): real focal} from lensfunpy's bundled XML (not exposed)."""
    import xml.etree.ElementTree as ET

    import lensfunpy
    out = {}
    for path in sorted((Path(lensfunpy.__file__).parent / 'db_files').glob('*.xml')):
        for lens in ET.parse(path).getroot().iter('lens'):
            rf = lens.findall('calibration/real-focal-length')
            if not rf:
                continue
            model = lens.findtext('model')
            crop = round(float(lens.findtext('cropfactor') or 1.0), 4)
            for r in rf:
                out[(model, crop, float(r.get('focal')))] = float(r.get('real-focal'))
    return out


def lensfun_rd(entry: Mapping[str, Any], ru: np.ndarray) -> np.ndarray:
    """Return lensfun's distorted radius Rd of the ideal radius Ru (normalised units)."""
    t = entry['terms']
    model = entry['distortion']
    if model == 'ptlens':
        a, b, c = t[:3]
        return ru * (a * ru ** 3 + b * ru ** 2 + c * ru + 1.0 - a - b - c)
    if model == 'poly3':
        return ru * (1.0 - t[0] + t[0] * ru ** 2)
    if model == 'poly5':
        return ru * (1.0 + t[0] * ru ** 2 + t[1] * ru ** 4)
    raise ValueError(f'lensfun model {model} is not one of ptlens, poly3, poly5')


def projection(kind: str, theta: np.ndarray) -> np.ndarray:
    """Return the ideal projection P(theta) of a lensfun lens type (image height / f)."""
    if kind == 'rectilinear':
        return np.tan(theta)
    if kind == 'fisheye':
        return theta
    if kind == 'equisolid':
        return 2.0 * np.sin(theta / 2.0)
    raise ValueError(kind)


def entry_focal(entry: Mapping[str, Any]) -> float:
    """Return the focal length lensfun uses for the entry's projection (real-focal first)."""
    return float(entry['real_focal'] or entry['focal'])


def entry_height(entry: Mapping[str, Any], theta: np.ndarray) -> np.ndarray:
    """Return the real image height (mm) lensfun's entry gives to the field angle theta."""
    h = entry['half_height_mm']
    return h * lensfun_rd(entry, entry_focal(entry) * projection(entry['type'], theta) / h)


def check_lensfun_convention(entry: Mapping[str, Any]) -> float:
    """
    Return the largest difference (px) between :func:`lensfun_rd` and lensfunpy's own map.

    A 3:2 frame of 3000 x 2000 px at the entry's crop, lensfunpy's Modifier with distortion
    only: the source position of each corrected pixel along the middle row must be Rd(Ru)
    with radii normalised by half the frame height.

    :param entry: a rectilinear lensfun entry.
    :return: the largest difference in pixels.
    """
    import lensfunpy
    db = lensfunpy.Database()
    lens = next(x for x in db.lenses if x.model == entry['model']
                and abs(x.crop_factor - entry['crop']) < 1e-3)
    width, height = 3000, 2000
    mod = lensfunpy.Modifier(lens, lens.crop_factor, width, height)
    mod.initialize(entry['focal'], 8.0, 1000.0, 1.0, lens.type,
                   flags=lensfunpy.ModifyFlags.DISTORTION)
    coords = mod.apply_geometry_distortion()
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    x = np.arange(width // 2 + 1, width)
    ru = (x - cx) / (height / 2.0)
    rd = (coords[int(cy), x, 0] - cx) / (height / 2.0)
    return float(np.max(np.abs(rd - lensfun_rd(entry, ru))) * height / 2.0)


# ----------------------------------------------------------------------------- our side

def traced(lens: RealLens, samples: int = 2001, theta_max_deg: float = 100.0,
           distance_mm: float = INF) -> dict[str, Any]:
    """
    Trace the chief rays of a lens at infinity: image height against field angle.

    :param lens: the lens.
    :param samples: field angles, uniform from 0 to ``theta_max_deg``.
    :param theta_max_deg: the largest field angle tried.
    :param distance_mm: the scene's distance from the front principal plane; a finite one
        is focused by moving the whole lens (unit focusing: the sensor at its image plane),
        which is not how most of these lenses focus.
    :return: theta (rad), height (mm, NaN past the valid field), efl and the back focus.
    """
    prescription = make_prescription(lens_values(lens))
    sensor_z, _ = image_plane(prescription, distance_mm)
    par = paraxial(prescription)
    theta = np.radians(np.linspace(0.0, theta_max_deg, samples))
    height = -trace_field_angles(prescription, distance_mm, sensor_z, theta)
    bad = ~np.isfinite(height)
    if bad.any():
        height[np.argmax(bad):] = np.nan
    grow = np.diff(height) > 0
    if not grow[np.isfinite(height[1:])].all():
        stop = int(np.argmin(grow | ~np.isfinite(height[1:]))) + 1
        height[stop:] = np.nan
    return {'theta': theta, 'height': height, 'efl_mm': par.efl_mm,
            'back_focus_mm': sensor_z - par.last_vertex_z_mm}


# ----------------------------------------------------------------------------- comparison

def _raw_grid(entry: Mapping[str, Any]) -> np.ndarray:
    """Return the normalised radii of the raw-frame grid points (a quarter frame)."""
    x = np.linspace(0.0, ASPECT, GRID[0])
    y = np.linspace(0.0, 1.0, GRID[1])
    return np.hypot(*np.meshgrid(x, y)).ravel()


def _inverse(x: np.ndarray, y: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Interpolate x at y = query on a monotone (increasing) curve; NaN outside."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    return np.interp(query, y, x, left=np.nan, right=np.nan)


def normalised_curve(theta: np.ndarray, height_mm: np.ndarray, target: Mapping[str, Any]
                     ) -> tuple[np.ndarray, np.ndarray, float]:
    """
    Put a physical curve h(theta) into the target entry's coordinates (Ru, Rd).

    Ru = f P(theta) / H with P the target's projection and the ideal scale f set by the
    target model's own normalisation: Rd(1) = 1 for ptlens and poly3, Rd'(0) = 1 for poly5.

    :param theta: field angles, rad.
    :param height_mm: image heights, mm (NaN past the valid field).
    :param target: the lensfun entry whose coordinates are used.
    :return: (Ru, Rd, f) with f, mm, the ideal image's focal length the normalisation implies.
    """
    h = target['half_height_mm']
    proj = projection(target['type'], theta)
    if target['type'] == 'rectilinear':
        proj = np.where(theta < math.radians(89.0), proj, np.nan)
    rd = _monotone(np.where(np.isfinite(proj), height_mm / h, np.nan))
    if target['distortion'] == 'poly5':
        scale = float(height_mm[1] / proj[1])
    else:
        theta1 = _inverse(theta, rd, np.array([1.0]))[0]
        scale = float(h / projection(target['type'], np.array([theta1]))[0])
    return scale * proj / h, rd, scale


def _monotone(y: np.ndarray) -> np.ndarray:
    """Return y with NaN from its first non-increase or NaN on (its increasing prefix)."""
    y = np.array(y, dtype=float)
    step = np.diff(y)
    bad = ~(np.isfinite(y[1:]) & (step > 0))
    if bad.any():
        y[int(np.argmax(bad)) + 1:] = np.nan
    return y


def errors(candidate: tuple[np.ndarray, ...], target: Mapping[str, Any],
           x_target: tuple[np.ndarray, ...]) -> dict[str, Any]:
    """
    Return the candidate's errors against the target over the raw frame.

    :param candidate: the candidate's (x, Rd) curve in the target's coordinates.
    :param target: the lensfun entry.
    :param x_target: the target's own (x, Rd) curve.
    :return: max and RMS in px and % of H, central field and whole frame, and the covered
        fraction of the frame (points the candidate's trace reaches).
    """
    rd = _raw_grid(target)
    x = _inverse(x_target[0], x_target[1], rd)
    cx, cy = candidate[:2]
    ok = np.isfinite(cx) & np.isfinite(cy)
    pred = np.interp(x, cx[ok], cy[ok], left=np.nan, right=np.nan)
    diff = pred - rd
    out: dict[str, Any] = {'covered': float(np.mean(np.isfinite(diff)))}
    for name, mask in (('central', rd <= 1.0), ('frame', np.ones_like(rd, bool))):
        d = diff[mask & np.isfinite(diff)]
        if not d.size:
            out[name] = None
            continue
        out[name] = {'max_pct': float(np.max(np.abs(d)) * 100.0),
                     'rms_pct': float(np.sqrt(np.mean(d ** 2)) * 100.0),
                     'max_px': float(np.max(np.abs(d)) * HALF_HEIGHT_PX),
                     'rms_px': float(np.sqrt(np.mean(d ** 2)) * HALF_HEIGHT_PX)}
    return out


def compare(lens: RealLens, trace: Mapping[str, Any], entries: list[dict[str, Any]],
            others: list[dict[str, Any]]) -> dict[str, Any]:
    """
    Compare the traced curve, the two textbook models and other entries with the target.

    The target is the entry of the largest frame (the smallest crop factor).

    :param lens: the lens.
    :param trace: :func:`traced` output.
    :param entries: the lensfun entries of the product at the patent's focal position.
    :param others: entries of the same optics under another name (part of the spread).
    :return: the comparison document of this lens.
    """
    target = next(e for e in entries if abs(e['crop'] - lens.lensfun_crop) < 1e-3)
    corner = target['half_height_mm'] * math.hypot(1.0, ASPECT)
    theta = trace['theta']
    mine = normalised_curve(theta, trace['height'], target)
    own_h = entry_height(target, theta)
    own = normalised_curve(theta, own_h, target)
    fisheye = target['type'] != 'rectilinear'
    textbook = lens.nominal_focal * projection('equisolid' if fisheye else 'rectilinear', theta)
    ideal = normalised_curve(theta, textbook, target)
    # At equal field angle, lensfun's ideal image at its own focal length (real-focal or
    # nominal): what the entry says when its scale is taken literally.
    h = target['half_height_mm']
    absolute = errors((theta, _monotone(trace['height'] / h)), target,
                      (theta, _monotone(own_h / h)))
    rd = _raw_grid(target)
    x = _inverse(own[0], own[1], rd)
    u = np.interp(x, ideal[0], ideal[1])
    ok = np.isfinite(u)
    g = u[ok] * (u[ok] ** 2 - 1.0)
    k1 = float(np.sum((rd[ok] - u[ok]) * g) / np.sum(g ** 2))
    k1_curve = (ideal[0], _monotone(ideal[1] * (1.0 - k1 + k1 * ideal[1] ** 2)))
    spread = []
    for other in [e for e in entries if e is not target] + others:
        # Only where the other calibration's frame reaches (it says nothing beyond).
        limit = other['half_height_mm'] * math.hypot(1.0, ASPECT)
        h = entry_height(other, theta)
        h = np.where(h <= limit, h, np.nan)
        spread.append({'entry': f"{other['model']} (crop {other['crop']:g})",
                       'errors': errors(normalised_curve(theta, h, target), target, own)})
    return {
        'key': lens.key, 'name': lens.name, 'category': lens.category,
        'patent': lens.patent, 'source': lens.source, 'corrections': list(lens.corrections),
        'notes': lens.notes, 'target': target, 'entries': entries, 'others': others,
        'efl_mm': trace['efl_mm'], 'back_focus_mm': trace['back_focus_mm'],
        'nominal_focal_mm': lens.nominal_focal, 'ideal_focal_mm': mine[2],
        'max_field_deg': float(np.degrees(theta[np.isfinite(trace['height'])][-1])),
        'ours': errors(mine, target, own), 'textbook': errors(ideal, target, own),
        'absolute': absolute, 'lensfun_focal_mm': entry_focal(target),
        'corner_deg': {
            name: float(np.degrees(_inverse(theta, _monotone(height), np.array([corner]))[0]))
            for name, height in (('ours', trace['height']), ('lensfun', own_h))},
        'k1': k1, 'k1_fit': errors(k1_curve, target, own), 'spread': spread,
        'curves': _curves(target, own, mine, ideal, k1_curve)}


def _curves(target: Mapping[str, Any], own: Any, mine: Any, ideal: Any, k1: Any
            ) -> dict[str, list[float]]:
    """Return the curves of the figure: Rd over the raw radius, per candidate."""
    r = np.linspace(0.0, math.hypot(1.0, ASPECT), 161)
    x = _inverse(own[0], own[1], r)
    out = {'r': r.tolist()}
    for name, curve in (('ours', mine), ('textbook', ideal), ('k1', k1)):
        cx, cy = curve[:2]
        ok = np.isfinite(cx) & np.isfinite(cy)
        out[name] = np.interp(x, cx[ok], cy[ok], left=np.nan, right=np.nan).tolist()
    out['ideal'] = np.interp(x, ideal[0], ideal[1]).tolist()
    return out


# ----------------------------------------------------------------------------- evidence

def evidence() -> dict[str, Any]:
    """
    Return the checks behind the corrections and the zoom positions, and the lensfun check.

    * Nikkor 10.5: the traced focal length and back focus with d13 as printed and corrected
      (the patent lists Bf = 41.1 mm);
    * Nikkor Z 14-30: the traced focal length at each position against Table 1;
    * lensfun: :func:`lensfun_rd` against lensfunpy's own map of one entry (px).
    """
    import dataclasses

    from benchmarks.real_lens_data import (NIKKOR105_PRINTED_D13, Z1430_TABLE_FOCAL)
    fisheye = next(lens for lens in LENSES if lens.key == 'nikkor_10_5_fisheye')
    rows = list(fisheye.rows)
    rows[fisheye.stop] = (0.0, NIKKOR105_PRINTED_D13, 1.0, 0.0)
    out: dict[str, Any] = {'nikkor_d13': {}}
    for label, lens in (('printed', dataclasses.replace(fisheye, rows=tuple(rows))),
                        ('corrected', fisheye)):
        t = traced(lens, samples=2)
        out['nikkor_d13'][label] = {'d13_mm': lens.rows[lens.stop][1], 'efl_mm': t['efl_mm'],
                                    'back_focus_mm': t['back_focus_mm']}
    out['zoom_focal'] = {}
    for lens in LENSES:
        if lens.key.startswith('nikkor_z_14_30_'):
            position = lens.key.rsplit('_', 1)[1]
            out['zoom_focal'][position] = {'table_mm': Z1430_TABLE_FOCAL[position],
                                           'traced_mm': traced(lens, samples=2)['efl_mm']}
    probe = lensfun_entries('Canon EF 50mm f/1.8 MkII', 50.0)
    out['lensfun_check_px'] = max(check_lensfun_convention(e) for e in probe)
    return out


# ----------------------------------------------------------------------------- run

def spread_pct(result: Mapping[str, Any], field: str) -> float:
    """Return lensfun's own spread in ``field``: how far another entry is from the target."""
    spread = [s['errors'][field]['max_pct'] for s in result['spread'] if s['errors'][field]]
    return max(spread, default=0.0)


def verdicts(result: Mapping[str, Any]) -> dict[str, dict[str, str]]:
    """
    Return whether the traced patent beats each baseline, centrally and over the frame.

    On the largest errors against lensfun: ``tie`` within :data:`TIE_PCT`; beyond it
    ``undecided`` while the difference is within lensfun's own spread in that field (two
    calibrations of the same optics disagree by more), else ``better`` / ``worse``; ``n/a``
    where the trace does not cover the field.

    :param result: one lens of the results document.
    :return: baseline -> field -> verdict.
    """
    out: dict[str, dict[str, str]] = {}
    for baseline in BASELINES:
        out[baseline] = {}
        for field in FIELDS:
            ours, theirs = result['ours'][field], result[baseline][field]
            if ours is None or theirs is None or result['ours']['covered'] < 0.999:
                out[baseline][field] = 'n/a'
                continue
            gap = theirs['max_pct'] - ours['max_pct']
            if abs(gap) <= TIE_PCT:
                verdict = 'tie'
            elif abs(gap) <= spread_pct(result, field):
                verdict = 'undecided'
            else:
                verdict = 'better' if gap > 0 else 'worse'
            out[baseline][field] = verdict
    return out


def passes(result: Mapping[str, Any]) -> bool:
    """
    Return whether the traced patent is worth shipping: no worse than the textbook model.

    That is, centrally and over the frame its largest error against lensfun is not larger
    than the nominal-f pinhole's (fisheye: equisolid) beyond the tie margin and lensfun's own
    spread (no verdict ``worse``): the physics gives at least what a user without a
    calibration has for free, as far as the calibrations can tell.

    :param result: one lens of the results document (with its ``verdicts``).
    :return: True when it passes.
    """
    textbook = verdicts(result)['textbook']
    return all(textbook[field] in ('better', 'tie', 'undecided') for field in FIELDS)


def rejudge(doc: dict[str, Any]) -> dict[str, Any]:
    """Set every lens's ``verdicts`` and ``passes`` (and the document's ``tie_pct``) anew."""
    for result in doc['lenses']:
        result['verdicts'] = verdicts(result)
        result['passes'] = passes(result)
    doc.pop('pass_pct', None)
    doc['tie_pct'] = TIE_PCT
    return doc


def figure(result: Mapping[str, Any], out_dir: Path) -> str:
    """Plot one lens: the distortion (Rd/Ru - 1) of every curve, and the errors in px."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    c = result['curves']
    r = np.array(c['r'])
    ideal = np.array(c['ideal'])
    with np.errstate(invalid='ignore', divide='ignore'):
        fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6.5), sharex=True)
        top.plot(r, (r / ideal - 1) * 100, 'k-', lw=2.5, label='lensfun')
        styles = (('ours', 'traced patent (ours)', 'tab:red', '-'),
                  ('textbook', 'equisolid, nominal f' if result['target']['type'] != 'rectilinear'
                   else 'pinhole, nominal f', 'tab:blue', ':'),
                  ('k1', f"k1 fit ({result['k1']:+.4f})", 'tab:green', '--'))
        for key, label, colour, style in styles:
            y = np.array(c[key], dtype=float)
            top.plot(r, (y / ideal - 1) * 100, color=colour, ls=style, label=label)
            bottom.plot(r, (y - r) * HALF_HEIGHT_PX, color=colour, ls=style, label=label)
    for ax in (top, bottom):
        ax.axvline(1.0, color='grey', lw=0.8)
        ax.grid(alpha=0.3)
    t = result['target']
    top.set_ylabel('distortion Rd / Ru - 1 [%]')
    top.set_title(f"{result['name']}\nlensfun '{t['model']}' (crop {t['crop']:g}, "
                  f"{t['type']}, {t['distortion']})", fontsize=9)
    top.legend(fontsize=8)
    bottom.set_ylabel('error vs lensfun [px, H = 2000 px]')
    bottom.set_xlabel('raw radius r / H (1 = top edge, 1.80 = corner)')
    fig.tight_layout()
    return save_figure(fig, out_dir, f"real_lens_{result['key']}.png")


def run(out_dir: Path = RESULTS, quick: bool = False, docs: Path | None = DOCS,
        configs: Path | None = CONFIGS) -> dict[str, Any]:
    """
    Trace and compare every lens; write ``real_lenses.json``, a PNG per lens, the docs page.

    Skips (with a note) when lensfunpy is not installed (it is a reference-only dependency).

    :param out_dir: results folder.
    :param quick: fewer field angles (the numbers then mean less); writes no docs page and
        no params files.
    :param docs: the page to write (None: none).
    :param configs: where the passing prescriptions go as params files (None: nowhere).
    :return: the results document.
    """
    if quick:
        docs = configs = None
    try:
        import lensfunpy
    except ImportError:
        log('real_lenses: lensfunpy is not installed (pip install -r requirements-bench.txt)'
            ': skipped')
        return {'skipped': 'lensfunpy not installed', 'lenses': []}
    samples = 401 if quick else 4001
    results = []
    for lens in LENSES:
        trace = traced(lens, samples=samples)
        entries = lensfun_entries(lens.lensfun_model, lens.lensfun_focal)
        others = [e for m in SAME_OPTICS.get(lens.lensfun_model, ())
                  for e in lensfun_entries(m, lens.lensfun_focal)]
        result = compare(lens, trace, entries, others)
        near = traced(lens, samples=samples, distance_mm=FOCUS_CHECK_MM)
        result['focus_check'] = errors(
            normalised_curve(near['theta'], near['height'], result['target']),
            result['target'], normalised_curve(trace['theta'], trace['height'],
                                               result['target']))
        result['verdicts'] = verdicts(result)
        result['passes'] = passes(result)
        result['figure'] = figure(result, out_dir)
        results.append(result)
        o = result['ours']['central']
        log(f"{lens.key}: f {trace['efl_mm']:.3f} mm, central max {o['max_pct']:.3f} % "
            f"(pinhole {result['textbook']['central']['max_pct']:.3f} %), "
            f"{'passes' if result['passes'] else 'fails'}")
    doc = {'lensfunpy': lensfunpy.__version__, 'half_height_px': HALF_HEIGHT_PX,
           'tie_pct': TIE_PCT, 'evidence': evidence(), 'lenses': results}
    write_json(out_dir / 'real_lenses.json', doc)
    return report(doc, out_dir, docs, configs)


def report(doc: dict[str, Any], out_dir: Path, docs: Path | None,
           configs: Path | None) -> dict[str, Any]:
    """
    Write the params files of the passing lenses and the docs page of a results document.

    :param doc: the results document.
    :param out_dir: the results folder.
    :param docs: the page to write (None: none).
    :param configs: where the passing prescriptions go (None: nowhere).
    :return: the document.
    """
    if configs is not None:
        from benchmarks.real_lens_report import write_configs
        write_configs(doc, configs)
    if docs is not None:
        from benchmarks.real_lens_report import docs_page
        docs.write_text(docs_page(doc, out_dir, docs))
    return doc


def tables(doc: Mapping[str, Any]) -> list[str]:
    """Return the summary table for docs/benchmarks.md (the full page: docs/real_lenses.md)."""
    from benchmarks.real_lens_report import summary_table
    if not doc.get('lenses'):
        return ['### Real production lenses', '', f"Skipped: {doc.get('skipped')}.", '']
    return ['### Real production lenses (patents against lensfun)', '',
            *summary_table(doc), '', 'Full table, figures and sources: docs/real_lenses.md.', '']


def main(argv: list[str] | None = None) -> int:
    """Command line: run and write everything."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, default=RESULTS)
    parser.add_argument('--docs', type=Path, default=DOCS)
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--from-json', action='store_true',
                        help='no trace and no lensfunpy: judge results/real_lenses.json anew '
                             '(verdicts, passes) and rewrite it, the docs page and the params '
                             'files')
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.from_json:
        doc = rejudge(json.loads((args.out / 'real_lenses.json').read_text()))
        write_json(args.out / 'real_lenses.json', doc)
        doc = report(doc, args.out, args.docs, CONFIGS)
    else:
        doc = run(args.out, args.quick, args.docs, CONFIGS)
    print('\n'.join(tables(doc)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
