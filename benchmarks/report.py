# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The reporting side of every benchmark: machine facts, JSON, markdown tables and figures.

The benchmark modules measure and return a results document (a JSON-ready dict); everything
that turns such a document into text or pictures lives here, so the tables of ``make bench``
(``docs/benchmarks.md``) and the figures (``results/*.png``) share one style: times in ms with
3 significant digits (:func:`fmt_ms`), ``-`` for a missing value, one machine line per run
(:func:`machine_line`), PNGs written by :func:`save_figure`.

* generic: :func:`machine_info`, :func:`machine_line`, :func:`write_json`, :func:`fmt_ms`,
  :func:`fmt_ratio`, :func:`fmt_num`, :func:`fmt_pct`, :func:`markdown_table`,
  :func:`save_figure`;
* :mod:`benchmarks.accuracy`: :func:`accuracy_tables`, :func:`accuracy_plots`,
  :func:`accuracy_grid_figure`;
* :mod:`benchmarks.speed`: :func:`speed_tables`, :func:`speed_plots`;
* :mod:`benchmarks.node_latency`: :func:`node_tables`, :func:`node_plot`;
* :mod:`benchmarks.soak`: :func:`soak_report`, :func:`soak_plot`.

This module never imports a benchmark module (they import it): what a table or figure needs
beyond the measurements (a target, a rate, a label) travels in the results document, and the
two helpers the benchmarks and the tables share, :func:`best_variant` and :func:`find_run`,
live here.
"""

from __future__ import annotations

import datetime
import json
import math
import os
from pathlib import Path
import platform
import subprocess
import sys
from typing import Any, Iterable, Mapping, Sequence

REPO = Path(__file__).resolve().parents[1]
#: Titles and figure files of the accuracy sweeps.
SWEEP_TITLES = {'stop_offset': 'aperture-stop offset m_a (t = 3 mm)',
                'thickness': 'lens thickness t (m_a = 0.2 mm)',
                'both': 'both: m_a = s mm, t = 3 + 2 s mm'}
FIGURES = {'stop_offset': 'accuracy_stop_offset.png', 'thickness': 'accuracy_thickness.png',
           'both': 'accuracy_both.png'}


# ---------------------------------------------------------------------------------------------
# Machine facts, JSON, formatting
# ---------------------------------------------------------------------------------------------

def _lscpu_model() -> str:
    try:
        out = subprocess.run(['lscpu'], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        out = ''
    for line in out.splitlines():
        if line.startswith('Model name:'):
            return line.split(':', 1)[1].strip()
    return platform.processor() or 'unknown'


def _version(module: str) -> str | None:
    try:
        imported = __import__(module)
    except ImportError:
        return None
    return str(getattr(imported, '__version__', 'unknown'))


def _git_commit() -> str | None:
    try:
        out = subprocess.run(['git', '-C', str(REPO), 'rev-parse', 'HEAD'], capture_output=True,
                             text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None


def machine_info() -> dict[str, Any]:
    """
    Return the facts that every results JSON carries.

    :return: CPU model (lscpu), core count, memory, load, OS, Python/numpy/OpenCV versions.
    """
    import cv2
    import numpy as np
    try:
        with open('/proc/meminfo', encoding='ascii') as stream:
            mem_kib = int(stream.readline().split()[1])
    except (OSError, ValueError, IndexError):
        mem_kib = 0
    return {
        'cpu_model': _lscpu_model(),
        'nproc': os.cpu_count(),
        'memory_gib': round(mem_kib / 2 ** 20, 1),
        'loadavg_1_5_15': list(os.getloadavg()),
        'platform': platform.platform(),
        'python': platform.python_version(),
        'numpy': np.__version__,
        'opencv': cv2.__version__,
        'opencv_default_threads': cv2.getNumThreads(),
        'lensfunpy': _version('lensfunpy'),
        'git_commit': _git_commit(),
        'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ'),
        'executable': sys.executable,
    }


def machine_line(info: Mapping[str, Any]) -> str:
    """Return a one-line description of the machine for the tables."""
    return (f"{info['cpu_model']}, {info['nproc']} vCPUs, {info['memory_gib']} GiB; "
            f"Python {info['python']}, numpy {info['numpy']}, OpenCV {info['opencv']}")


def _clean(value: Any) -> Any:
    """Make a value JSON-ready: NaN/inf -> None, numpy scalars -> Python."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if hasattr(value, 'tolist') and not isinstance(value, (str, bytes)):
        return _clean(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(path: Path, doc: Mapping[str, Any]) -> Path:
    """Write ``doc`` (NaN -> null) as indented JSON; create the folder."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_clean(doc), indent=1) + '\n')
    return path


def fmt_ms(value: float | None) -> str:
    """Format a time in ms with 3 significant digits (``-`` when missing)."""
    if value is None or not math.isfinite(value):
        return '-'
    if value >= 100:
        return f'{value:.0f}'
    if value >= 10:
        return f'{value:.1f}'
    if value >= 1:
        return f'{value:.2f}'
    return f'{value:.3f}'


def fmt_ratio(value: float | None) -> str:
    """Format a ratio (``x``) with 2 decimals."""
    if value is None or not math.isfinite(value):
        return '-'
    return f'{value:.2f}'


def fmt_num(value: Any, digits: int = 1) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return '-'
    return f'{value:.{digits}f}'


def fmt_pct(value: float | None) -> str:
    if value is None or not math.isfinite(value):
        return '-'
    if value >= 0.1:
        return f'{value:.2f}'
    return f'{value:.1e}'


def verdict(met: bool | None) -> str:
    """Return ``met`` or ``missed`` for a target."""
    return 'met' if met else 'missed'


def best_variant(variants: Mapping[str, Mapping[str, Any]], kind: str, stat: str,
                 threads: int | None = None) -> tuple[str, float]:
    """Return the name and ``stat`` of the fastest variant of a kind (and thread count)."""
    best = ('', math.inf)
    for name, v in variants.items():
        if v['kind'] == kind and (threads is None or v['threads'] == threads):
            if v[stat] < best[1]:
                best = (name, v[stat])
    return best


def find_run(runs: Sequence[Mapping[str, Any]], **match: Any) -> Mapping[str, Any] | None:
    """Return the first run whose fields equal ``match`` (None when there is none)."""
    return next((r for r in runs if all(r.get(k) == v for k, v in match.items())), None)


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> list[str]:
    """Return the lines of a GitHub markdown table."""
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(str(c) for c in row) + ' |' for row in rows]
    return lines


def save_figure(fig: Any, out_dir: Path, filename: str, dpi: int = 100) -> str:
    """
    Lay out, write and close a matplotlib figure in the results folder.

    :param fig: the figure.
    :param out_dir: the results folder.
    :param filename: the PNG's name (may include a subfolder).
    :param dpi: resolution.
    :return: the path relative to the results folder's parent, as the README links it.
    """
    import matplotlib.pyplot as plt
    fig.tight_layout()
    path = out_dir / filename
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return str(path.relative_to(out_dir.parent))


# ---------------------------------------------------------------------------------------------
# Accuracy
# ---------------------------------------------------------------------------------------------

def _sweep_x(name: str, row: Mapping[str, Any]) -> float:
    return row['thickness_mm'] if name == 'thickness' else row['stop_offset_mm']


def accuracy_plots(doc: Mapping[str, Any], out_dir: Path) -> dict[str, str]:
    """Write one figure per sweep (radii mean error vs the parameter, like Figs. 6 and 7)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out = {}
    nominal = doc['nominal']
    for name, rows in doc['sweeps'].items():
        if not rows:
            continue
        x = [_sweep_x(name, r) for r in rows]
        mech = [r['mechanistic']['radii_mean_error_percent'] for r in rows]
        brown = [r['brown']['radii_mean_error_percent'] for r in rows]
        refit = [r['brown']['radii_mean_error_percent_focal_refit'] for r in rows]
        fig, ax = plt.subplots(figsize=(7.5, 4.8))
        ax.semilogy(x, brown, 'o-', color='tab:red',
                    label='conventional: Brown K1 K2 P1 P2, calibrated once at nominal')
        ax.semilogy(x, refit, 's:', color='tab:orange', ms=4,
                    label='conventional with its focal length re-fitted')
        ax.semilogy(x, mech, 'o-', color='tab:blue',
                    label='mechanistic: rebuilt from the lens parameters')
        ax.axhline(doc['target_percent'], color='grey', ls='--', lw=0.8, label='target 0.1 %')
        ax.axhspan(*doc['paper']['conventional_degraded_percent'], color='tab:red', alpha=0.08,
                   label='paper: calibrated model degraded to 9.6-22 %')
        if name == 'stop_offset':
            ax.axvline(nominal['stop_offset_mm'], color='k', lw=0.6, ls='-.')
            ax.set_xlabel('aperture-stop offset m_a [mm] (t = 3 mm; calibrated at 0.2 mm)')
        elif name == 'thickness':
            ax.axvline(nominal['thickness_mm'], color='k', lw=0.6, ls='-.')
            ax.set_xlabel('lens thickness t [mm] (m_a = 0.2 mm; calibrated at 3 mm)')
        else:
            ax.set_xlabel('s: m_a = s mm and t = 3 + 2 s mm together (calibrated at m_a 0.2, '
                          't 3)')
        ax.set_ylabel('radii mean error [%] (eq. 35-37)')
        ax.set_title(f'Case 2 lens, {SWEEP_TITLES[name]}: optiland ground truth')
        ax.grid(True, which='both', alpha=0.3)
        ax.legend(fontsize=7.5, loc='center right')
        out[name] = save_figure(fig, out_dir, FIGURES[name], dpi=110)
    return out


def accuracy_grid_figure(panels: Mapping[str, Mapping[str, Any]], out_dir: Path) -> str:
    """
    Write the grid before and after correction (like the paper's Fig. 4).

    Each panel shows, for one lens, the pinhole positions of the scene grid, the raw points
    the camera records, and both corrections of the raw points, in pixels of the changed
    raw camera (not magnified: the conventional model's errors are tens of pixels, the
    mechanistic model's are below 1e-5 px).
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(6.5 * len(panels), 5.4), squeeze=False)
    for ax, panel in zip(axes[0], panels.values()):
        f = panel['to_px']
        ideal, raw = panel['ideal'] * f, panel['raw'] * f
        ax.plot(raw[:, 0], raw[:, 1], '.', color='0.6', ms=4, label='raw (what the camera sees)')
        ax.plot(ideal[:, 0], ideal[:, 1], '+', color='k', ms=6, label='ideal pinhole position')
        for key, color, marker, label in (
                ('brown', 'tab:red', 'x', 'conventional (calibrated at nominal)'),
                ('mechanistic', 'tab:blue', 'o', 'mechanistic (rebuilt)')):
            shown = panel[key] * f
            ax.plot(shown[:, 0], shown[:, 1], marker, color=color, ms=5, mfc='none',
                    label=label)
        ax.set_title(panel['title'])
        ax.set_aspect('equal')
        ax.invert_yaxis()
        ax.set_xlabel('x from the principal point [px]')
        ax.set_ylabel('y [px]')
        ax.grid(alpha=0.3)
    axes[0][-1].legend(fontsize=7.5, loc='lower right', framealpha=0.9)
    fig.suptitle('Case 2 grid, corrected by both models (optiland ground truth)')
    return save_figure(fig, out_dir, 'accuracy_grid.png')


def accuracy_tables(doc: Mapping[str, Any]) -> list[str]:
    """Return the markdown lines of the accuracy section."""
    cal = doc['brown_calibration']
    lines = [
        '### Accuracy and robustness (paper section 4, Figs. 6-7)',
        '',
        f"Ground truth: optiland ({doc['ground_truth']['source']}, "
        f"{doc['ground_truth']['note']}); Case 2 lens and 640x480 sensor, 20 x 18 box grid "
        "1 m away. Radii mean error (eq. 35-37) of each model's corrected grid against the "
        'pinhole image of the changed camera. Conventional = Brown K1 K2 P1 P2 + focal lengths '
        'and centre, Gauss-Newton, calibrated once at m_a 0.2 mm / t 3 mm '

        f"({cal['iterations']} iterations, residual {cal['residual_rms_px']:.1e} px RMS, "
        f"{fmt_ms(cal['time_ms_min'])} ms); mechanistic = rebuilt from the changed lens "
        'parameters, no calibration.',
        '',
    ]
    rows = []
    for name, entries in doc['sweeps'].items():
        # Every other variant (first and last always) keeps the table short; the JSON and the
        # figures have them all.
        shown = [r for i, r in enumerate(entries) if i % 2 == 0 or i == len(entries) - 1]
        for r in shown:
            m, b = r['mechanistic'], r['brown']
            rows.append([
                name.replace('_', ' '), f"{r['stop_offset_mm']:.1f}",
                f"{r['thickness_mm']:.2f}", f"{r['efl_model_mm']:.3f}",
                fmt_pct(m['radii_mean_error_percent']), f"{m['max_position_error_px']:.1e}",
                fmt_pct(b['radii_mean_error_percent']), f"{b['max_position_error_px']:.2f}",
                fmt_pct(b['radii_mean_error_percent_focal_refit']),
                fmt_ms(r['mechanistic_build_ms'])])
    lines += markdown_table(
        ['sweep', 'm_a mm', 't mm', 'f mm', 'mechanistic %', 'mech. max err px',
         'Brown (calibrated at nominal) %', 'Brown max err px', 'Brown, f re-fitted %',
         'mech. build ms'], rows)
    c1 = doc.get('case1_nominal') or {}
    nominal_row = next((r for r in doc['sweeps'].get('stop_offset', [])
                        if r['stop_offset_mm'] == doc['nominal']['stop_offset_mm']), None)
    lines += ['', 'At the nominal parameters (paper: mechanistic 0.8 % for Case 1, 2.5 % for '
              'Case 2):', '']
    nominal_rows = []
    if c1:
        nominal_rows.append(['Case 1 (1600x1200, 4.4 um)', '0.8',
                             fmt_pct(c1['mechanistic']['radii_mean_error_percent']),
                             fmt_pct(c1['brown']['radii_mean_error_percent']),
                             fmt_ms(c1['build_ms'])])
    if nominal_row:
        nominal_rows.append(['Case 2 (640x480, 4.06 x 4.44 um)', '2.5',
                             fmt_pct(nominal_row['mechanistic']['radii_mean_error_percent']),
                             fmt_pct(nominal_row['brown']['radii_mean_error_percent']),
                             fmt_ms(nominal_row['mechanistic_build_ms'])])
    lines += markdown_table(['case', 'paper %', 'mechanistic %',
                             'Brown calibrated on it %', 'mech. build ms'], nominal_rows)
    lines += ['', f"Target mechanistic <= {doc['target_percent']} % everywhere: "
              f"{verdict(doc['target_met'])} "
              f"(worst {fmt_pct(doc['mechanistic_worst_percent'])} %).", '']
    for name, path in (doc.get('figures') or {}).items():
        if name == 'grid':
            lines.append(f'![grid corrected by both models]({path}) The grid at the nominal '
                         'lens and at m_a 1 mm + t 5 mm: raw points, pinhole positions, and '
                         'both corrections.')
        else:
            lines.append(f'![radii mean error vs {SWEEP_TITLES[name]}]({path}) '
                         f'Radii mean error vs {SWEEP_TITLES[name]}.')
    lines += ['', f"Machine: {machine_line(doc['machine'])}.", '']
    return lines


# ---------------------------------------------------------------------------------------------
# Speed
# ---------------------------------------------------------------------------------------------

def speed_plots(doc: Mapping[str, Any], out_dir: Path) -> dict[str, str]:
    """Write the per-frame figure (rgb8 and mono8) and the rebuild figure."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    import numpy as np

    out = {}
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True)
    series = (('copy', 'copy (np.copyto)', 'tab:gray'),
              ('ours', 'ours (Rectifier.correct)', 'tab:blue'),
              ('opencv', 'best OpenCV remap', 'tab:green'),
              ('lensfunpy', 'lensfunpy map + remap', 'tab:purple'),
              ('image_geometry', 'image_geometry way (maps + cubic per call)', 'tab:red'))
    encodings = list(dict.fromkeys(v['encoding'] for v in doc['per_frame'].values()))
    for ax, encoding in zip(axes, encodings):
        entries = [(k, v) for k, v in doc['per_frame'].items() if v['encoding'] == encoding]
        labels = [v['size'] for _, v in entries]
        x = np.arange(len(entries))
        width = 0.16
        for i, (kind, label, color) in enumerate(series):
            mins = [best_variant(v['variants'], kind, 'min_ms')[1] for _, v in entries]
            meds = [best_variant(v['variants'], kind, 'median_ms')[1] for _, v in entries]
            if not all(math.isfinite(m) for m in mins):
                continue
            pos = x + (i - 2) * width
            ax.bar(pos, meds, width, color=color, alpha=0.45)
            ax.bar(pos, mins, width, color=color, label=label)
        ax.set_yscale('log')
        ax.set_xticks(x, labels)
        ax.set_title(f'{encoding}: per-frame time (solid: min, light: median)')
        ax.grid(axis='y', which='both', alpha=0.3)
    axes[0].set_ylabel('ms per frame')
    axes[0].legend(fontsize=8)
    out['per_frame'] = save_figure(fig, out_dir, 'speed_per_frame.png')

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    sizes = list(doc['rebuild'])
    pixels = [int(s.split('x')[0]) * int(s.split('x')[1]) / 1e6 for s in sizes]
    for name, label, color, style in (
            ('ours build_model+Rectifier 1t', 'ours: build_model + Rectifier, 1 thread',
             'tab:blue', 'o-'),
            ('ours build_model+Rectifier 2t', 'ours, 2 threads', 'tab:blue', 'o:'),
            ('ours build_model 1t', 'ours: build_model only (trace + fit)', 'tab:cyan', 's--'),
            ('cv initUndistortRectifyMap 16SC2 1t', 'cv2.initUndistortRectifyMap, 1 thread',
             'tab:green', 'o-'),
            ('cv initUndistortRectifyMap 16SC2 2t', 'cv2.initUndistortRectifyMap, 2 threads',
             'tab:green', 'o:'),
            ('lensfunpy map 1t', 'lensfunpy apply_geometry_distortion', 'tab:purple', 'o-')):
        ys = [doc['rebuild'][s]['variants'].get(name, {}).get('median_ms', math.nan)
              for s in sizes]
        if any(math.isfinite(y) for y in ys):
            ax.loglog(pixels, ys, style, color=color, label=label)
    target = doc['rebuild'].get('1920x1080', {}).get('target_ms')
    if target:
        ax.plot([1920 * 1080 / 1e6], [target], 'r*', ms=12,
                label=f'target at 1080p: {target:g} ms')
    ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    ax.set_xticks(pixels, sizes)
    ax.set_xlabel('frame')
    ax.set_ylabel('ms (median)')
    ax.set_title('Model + map rebuild after a parameter change')
    ax.grid(which='both', alpha=0.3)
    ax.legend(fontsize=8)
    out['rebuild'] = save_figure(fig, out_dir, 'speed_rebuild.png')
    return out


def _min_median(v: Mapping[str, Any] | None) -> str:
    if not v:
        return '-'
    return f"{fmt_ms(v['min_ms'])} / {fmt_ms(v['median_ms'])}"


def speed_tables(doc: Mapping[str, Any]) -> list[str]:
    """Return the markdown lines of the speed section."""
    lines = ['### Per-frame correction (ms, min / median; ratios min / median)', '',
             'Same frames, same run, interleaved rounds; bilinear unless noted; output into a '
             'preallocated array. Best OpenCV = fastest of cv2.remap with 2 x CV_32FC1, '
             'CV_32FC2 and CV_16SC2 + CV_16UC1 maps (from our equivalent K, D, K_new) at 1 '
             'and 2 threads. image_geometry way = its Python rectifyImage: maps rebuilt every '
             'call + INTER_CUBIC. lensfunpy way = its apply_geometry_distortion map + '
             'cv2.remap bilinear.', '']
    rows = []
    for key, f in doc['per_frame'].items():
        r_min, r_med = f['ratios']['min'], f['ratios']['median']
        v = f['variants']
        ours_name = r_min['ours_best']
        cv_name = r_min['opencv_best']
        lf = best_variant(v, 'lensfunpy', 'min_ms')[0]
        ig = best_variant(v, 'image_geometry', 'min_ms')[0]
        rows.append([
            key, _min_median(v['copy']), f'{_min_median(v[ours_name])} ({ours_name.split()[-1]})',
            f'{_min_median(v[cv_name])} ({cv_name[3:]})',
            f"{fmt_ratio(r_min['ours_over_opencv_best'])} / "
            f"{fmt_ratio(r_med['ours_over_opencv_best'])}",
            f"{fmt_ratio(r_min['ours_1t_over_opencv_best_1t'])} / "
            f"{fmt_ratio(r_med['ours_1t_over_opencv_best_1t'])}",
            f"{r_min['ours_over_copy']:.0f} / {r_med['ours_over_copy']:.0f}",
            _min_median(v.get(ig)), _min_median(v.get(lf)) if lf else 'skipped',
            f"{max(f['others_cores']):.2f}"])
    lines += markdown_table(
        ['frame', 'copy', 'ours (threads)', 'best OpenCV (maps, threads)',
         'ours / best OpenCV', 'at 1 thread', 'ours / copy', 'image_geometry way',
         'lensfunpy way', 'others cores (max)'], rows)
    met = [f['ratios']['target_met'] for f in doc['per_frame'].values()]
    lines += ['', f"Target 'no slower than the best OpenCV configuration' (within "
              f"{doc['noise_band']:.0%} noise, judged on the minima): "
              f'{verdict(all(met))} ({sum(met)} of {len(met)} frame types '
              'within the band).', '']
    lines += ['### Model + map rebuild (ms, min / median)', '']
    rows = []
    for size, b in doc['rebuild'].items():
        v = b['variants']
        rows.append([size, _min_median(v['ours build_model+Rectifier 1t']),
                     _min_median(v['ours build_model+Rectifier 2t']),
                     _min_median(v['ours build_model 1t']),
                     _min_median(v['cv initUndistortRectifyMap 16SC2 1t']),
                     _min_median(v['cv initUndistortRectifyMap 16SC2 2t']),
                     _min_median(v['lensfunpy map 1t']) if 'lensfunpy map 1t' in v
                     else 'skipped',
                     fmt_ratio(b['ours_1t_over_cv_1t_median'])])
    lines += markdown_table(
        ['frame', 'ours build_model + Rectifier, 1 thread', '2 threads',
         'build_model only', 'cv2.initUndistortRectifyMap 1 thread', '2 threads',
         'lensfunpy map build', 'ours / OpenCV (1 thread, median)'], rows)
    hd = doc['rebuild'].get('1920x1080')
    if hd:
        lines += ['', f"Target rebuild <= {hd['target_ms']:g} ms at 1920x1080: "
                  f"{verdict(hd['target_met_1t'])} at 1 thread (median "
                  f"{fmt_ms(hd['ours_ms_median_1t'])} ms), "
                  f"{verdict(hd['target_met_2t'])} at 2 threads "
                  f"({fmt_ms(hd['ours_ms_median_2t'])} ms; the node default uses all "
                  'cores).']
    for note in doc['notes']:
        lines.append(f'Note: {note}.')
    lines.append('')
    figs = doc.get('figures') or {}
    if 'per_frame' in figs:
        lines.append(f"![per-frame time]({figs['per_frame']}) Per-frame time of ours, the "
                     'best OpenCV remap, a copy and the peers, rgb8 and mono8.')
    if 'rebuild' in figs:
        lines.append(f"![rebuild time]({figs['rebuild']}) Model + map rebuild time vs "
                     'frame size, against OpenCV and lensfunpy map builds.')
    lines += ['', f"Machine: {machine_line(doc['machine'])}.", '']
    return lines


# ---------------------------------------------------------------------------------------------
# The node end to end
# ---------------------------------------------------------------------------------------------

class _NodeConstants:
    """The node benchmark's settings, as its results document states them."""

    def __init__(self, doc: Mapping[str, Any]) -> None:
        constants = doc.get('constants', {})
        self.rate_hz = float(doc.get('rate_hz', 30.0))
        self.target_rate = str(constants.get('target_rate_label', 'target rate'))
        self.set_target_periods = float(constants.get('set_target_periods', 2))
        self.busy_others_cores = float(constants.get('busy_others_cores', 0.3))


def node_plot(doc: Mapping[str, Any], out_dir: Path) -> str:
    """Write throughput, latency, what the shm profile buys, and parameter-set reaction."""
    nl = _NodeConstants(doc)
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(2, 2, figsize=(13, 9))
    runs = [r for child in doc['children'].values() for r in child['runs']]
    sizes = sorted({r['size'] for r in runs}, key=lambda s: int(s.split('x')[0]))
    x = np.arange(len(sizes))

    def bars(ax: Any, series: Sequence[tuple[str, str, str, str, str]], metric: str) -> None:
        width = 0.8 / len(series)
        for i, (kind, transport, rate, label, color) in enumerate(series):
            vals, p99 = [], []
            for size in sizes:
                run = find_run(runs, kind=kind, size=size, rate=rate, transport=transport)
                vals.append(run.get(metric, math.nan) if run else math.nan)
                p99.append(run.get('p99_ms', math.nan) if run else math.nan)
            if all(not math.isfinite(v) for v in vals):
                continue
            pos = x + (i - (len(series) - 1) / 2) * width
            ax.bar(pos, np.nan_to_num(vals), width, color=color, label=label)
            if metric == 'p50_ms':
                ax.plot(pos, p99, '_', color='k', ms=14)
        ax.set_xticks(x, sizes)
        ax.grid(axis='y', alpha=0.3)

    def targets(ax: Any, key: str, style: str, label: str) -> None:
        for j, size in enumerate(sizes):
            value = doc['targets'].get(size, {}).get(key)
            if value:
                ax.plot([j - 0.4, j + 0.4], [value, value], style, lw=1.2,
                        label=label if j == 0 else None)

    ax = axes[0, 0]
    bars(ax, (('passthrough', 'shm', 'flat out', 'pass-through, publisher flat out',
               'tab:gray'),
              ('node', 'shm', 'flat out', 'correct_node, publisher flat out', 'lightsteelblue'),
              ('node', 'shm', nl.target_rate, 'correct_node, camera paced at the bound',
               'tab:blue')), 'fps')
    targets(ax, 'serial_bound_fps', 'r--', 'target: serial bound 1/(1/pass-through + remap)')
    ax.set_title('throughput, shm profile [fps delivered]', fontsize=10)
    ax = axes[0, 1]
    bars(ax, (('passthrough', 'shm', f'{nl.rate_hz:g} Hz', 'pass-through', 'tab:gray'),
              ('node', 'shm', f'{nl.rate_hz:g} Hz', 'correct_node', 'tab:blue')), 'p50_ms')
    targets(ax, 'latency_target_ms', 'r--', 'target: pass-through p50 + 1.5 x remap')
    ax.set_title(f'latency at {nl.rate_hz:g} Hz, shm profile: p50 (bar), p99 (tick) [ms]',
                 fontsize=10)
    ax = axes[1, 0]
    bars(ax, (('passthrough', 'shm', f'{nl.rate_hz:g} Hz', 'pass-through, shm profile',
               'tab:gray'),
              ('node', 'shm', f'{nl.rate_hz:g} Hz', 'correct_node, shm profile', 'tab:blue'),
              ('passthrough', 'default', f'{nl.rate_hz:g} Hz', 'pass-through, default transports',
               'silver'),
              ('node', 'default', f'{nl.rate_hz:g} Hz', 'correct_node, default transports',
               'lightsteelblue')), 'fps')
    ax.axhline(nl.rate_hz, color='k', lw=0.8, ls=':', label=f'published: {nl.rate_hz:g} fps')
    ax.set_title(f'frames delivered of a {nl.rate_hz:g} Hz best-effort stream [fps]', fontsize=10)
    ax = axes[1, 1]
    sets = [r for r in doc['children'].get('shm', {}).get('set_parameters', [])
            if 'reply_to_first_new_frame_ms' in r]
    for j, size in enumerate(sizes):
        vals = [r['reply_to_first_new_frame_ms'] for r in sets if r['size'] == size]
        ax.plot([j - 0.08] * len(vals), vals, 'o', color='tab:blue', alpha=0.7,
                label='from the reply' if j == 0 else None)
        vals = [r['send_to_first_new_frame_ms'] for r in sets if r['size'] == size]
        ax.plot([j + 0.08] * len(vals), vals, 'o', mfc='none', color='tab:purple', alpha=0.7,
                label='from the request' if j == 0 else None)
    ax.axhline(nl.set_target_periods * 1000.0 / nl.rate_hz, color='r', ls='--', lw=1,
               label='target: 2 frame periods at 30 fps')
    ax.set_xticks(range(len(sizes)), sizes)
    ax.set_xlim(-0.5, len(sizes) - 0.5)
    ax.grid(axis='y', alpha=0.3)
    ax.set_title('set_parameters -> first frame of the new model [ms]', fontsize=10)
    for ax in axes.ravel():
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    return save_figure(fig, out_dir, 'node_latency.png')


def _set_cell(t: Mapping[str, Any]) -> str:
    if 'set_to_new_frame_target_ms' not in t:
        return '-'
    met = ('met' if t.get('set_met_all') else
           'median met' if t.get('set_met_median') else 'missed')
    cell = (f"{fmt_num(t.get('set_to_new_frame_median_ms'))} / "
            f"{fmt_num(t.get('set_to_new_frame_max_ms'))} vs <= "
            f"{fmt_num(t.get('set_to_new_frame_target_ms'))}: {met}")
    if 'request_to_new_frame_median_ms' in t:
        cell += (f" (from the request: {fmt_num(t.get('request_to_new_frame_median_ms'))} / "
                 f"{fmt_num(t.get('request_to_new_frame_max_ms'))})")
    return cell


def _flat_out_cell(t: Mapping[str, Any], doc: Mapping[str, Any]) -> str:
    if 'node_flat_out_fps' not in t:
        return '-'
    constants = doc.get('constants', {})
    share = float(constants.get('flat_out_share', 0.9))
    cell = (f"{fmt_num(t['node_flat_out_fps'])} of {fmt_num(share * t['serial_bound_fps'])} "
            f"({fmt_num(t['node_flat_out_over_serial_bound'], 2)} x)")
    if t.get('flat_out_met') is None:
        return f"{cell}: not measurable here, {t.get('cores', '?')} cores"
    return f"{cell}: {verdict(t['flat_out_met'])}"


def node_tables(doc: Mapping[str, Any]) -> list[str]:
    """Return the markdown lines of the node section."""
    nl = _NodeConstants(doc)
    lines = ['### The node end to end (publisher -> node -> subscriber, rgb8, best effort)', '',
             'Three processes on the 2 vCPUs; latency = subscriber receive time - stamp set '
             f'by the publisher (two hops), at {nl.rate_hz:g} Hz; throughput with the publisher '
             'flat out. Pass-through = subscribe + republish (same QoS, same transport). '
             'shm = config/fastdds_shm.xml in every process; default = Fast DDS builtin '
             'transports. All with the Makefile MALLOC_* settings. Relay CPU ms/frame = the '
             "relay process's CPU time per delivered frame; node callback = correct_node's "
             'own per-frame time from its /diagnostics; others cores = CPU used by processes '
             'outside the measurement (a window with more than '
             f'{nl.busy_others_cores:g} was measured once more and the less disturbed one kept).',
             '']
    rows = []
    for transport, child in doc['children'].items():
        for run in child['runs']:
            rows.append([run['size'], transport, run['kind'], run['rate'],
                         fmt_num(run.get('published_fps')), fmt_num(run['fps']),
                         fmt_num(run.get('p50_ms')), fmt_num(run.get('p99_ms')),
                         fmt_num(run['node_cores'], 2), fmt_num(run.get('node_cpu_ms_per_frame')),
                         fmt_num(run.get('node_callback_ms')),
                         fmt_num(run.get('longest_gap_ms'), 0), fmt_num(run['others_cores'], 2)])
    lines += markdown_table(['frame', 'transport', 'relay', 'publisher', 'published fps',
                             'delivered fps', 'latency p50 ms', 'p99 ms', 'relay cores',
                             'relay CPU ms/frame', 'node callback ms', 'longest gap ms',
                             'others cores'], rows)
    lines += ['', 'Targets (shm profile, same run): a Python relay cannot overlap the remap '
              "with rclpy's per-frame work, so the node is held to the serial bound "
              '1 / (1 / pass-through fps + bare remap time) (the most a relay forwards when '
              "it does the pass-through's work and then the remap, one frame at a time; "
              'measured with the camera paced at that rate) and to a latency of pass-through '
              'p50 + 1.5 x bare remap time.', '']
    rows = []
    for size, t in doc['targets'].items():
        rows.append([
            size, fmt_ms(t['bare_remap_ms']),
            f"{fmt_num(t.get('node_fps'))} of {fmt_num(t.get('serial_bound_fps'))}: "
            f"{verdict(t.get('throughput_met'))} (flooding publisher: "
            f"{fmt_num(t.get('node_flat_out_fps'))})"
            if 'node_fps' in t else '-',
            f"{fmt_num(t.get('node_p50_ms'))} vs <= {fmt_num(t.get('latency_target_ms'))}: "
            f"{verdict(t.get('latency_met'))}"
            if 'node_p50_ms' in t else '-',
            _flat_out_cell(t, doc), _set_cell(t), fmt_num(t.get('node_rebuild_ms_median'))])
    lines += markdown_table(['frame', 'bare remap ms (median; node default threads)',
                             'node fps delivered of a camera at the serial bound',
                             'node p50 ms vs pass-through p50 + 1.5 x remap',
                             'flat out vs 0.9 x serial bound (>= 4 cores)',
                             'param set reply -> first new frame ms (median / max)',
                             'node rebuild ms (its diagnostics)'], rows)
    if doc['errors']:
        lines += ['', 'Errors: ' + '; '.join(e.splitlines()[0] for e in doc['errors'])]
    figs = doc.get('figures') or {}
    if 'node' in figs:
        lines += ['', f"![node throughput and latency]({figs['node']}) Node throughput and "
                  'latency against the pass-through, frames delivered with and without the '
                  'shared-memory profile, and the parameter-set reaction.']
    lines += ['', f"Machine: {machine_line(doc['machine'])}.", '']
    return lines


def stereo_tables(doc: Mapping[str, Any]) -> list[str]:
    """
    Return the markdown of the stereo benchmark (:mod:`benchmarks.stereo_latency`).

    :param doc: its results document.
    :return: lines.
    """
    child = doc.get('child') or {}
    targets = doc.get('targets') or {}
    remaps = (child.get('bare_two_remaps_ms') or {}).get('median')
    names = {'relay': 'relay of two streams', 'stereo': 'stereo_node',
             'stereo_check': f"stereo_node, check at {doc.get('check_rate_hz', 1.0):g} Hz"}
    lines = [f"### stereo_node: 2 x {child.get('size', '?')} rgb8 at "
             f"{doc.get('rate_hz', 30):g} Hz", '',
             f'Two bare remaps (the pair, median): {fmt_ms(remaps)} ms.', '']
    rows = [[names.get(r.get('kind'), r.get('kind')), fmt_num(r.get('pairs_per_s')),
             fmt_ms(r.get('p50_ms')), fmt_ms(r.get('p90_ms')), fmt_ms(r.get('p99_ms')),
             fmt_ms(r.get('longest_gap_ms')),
             r.get('checks', '-') if r.get('kind') == 'stereo_check' else '-']
            for r in child.get('runs', [])]
    lines += markdown_table(['process', 'pairs/s', 'p50 ms', 'p90 ms', 'p99 ms',
                             'longest gap ms', 'checks done'], rows)
    if 'latency_ratio' in targets:
        lines += ['', f"Target p50 <= relay p50 + {targets['target_remaps']:g} x two remaps "
                  f"({fmt_ms(targets['p50_budget_ms'])} ms): (node - relay) / two remaps = "
                  f"{fmt_ratio(targets['latency_ratio'])}, "
                  f"{verdict(targets['latency_met'])}."]
    if 'check_pairs_share' in targets:
        lines += [f"The check at {doc.get('check_rate_hz', 1.0):g} Hz: "
                  f"{fmt_ratio(targets['check_pairs_share'])} x the pairs "
                  f"per second without it, p50 {targets['check_p50_delta_ms']:+.2f} ms."]
    if 'latency_ratio_check' in targets:
        lines += ['With the check on: (node - relay) / two remaps = '
                  f"{fmt_ratio(targets['latency_ratio_check'])}, "
                  f"{verdict(targets['latency_met_check'])}; pairs delivered "
                  f"{100 * targets.get('delivered_stereo_check', float('nan')):.0f} % "
                  f"(check off: {100 * targets.get('delivered_stereo', float('nan')):.0f} %)."]
    if doc.get('errors'):
        lines += ['', 'Errors: ' + '; '.join(e.splitlines()[0] for e in doc['errors'])]
    if doc.get('machine'):
        lines += ['', f"Machine: {machine_line(doc['machine'])}."]
    return lines + ['']


#: A check A/B run is marked as loaded when, in a window with the check off, processes other
#: than the graph's used more than this many cores (the load average counts the benchmark's
#: own camera, node and probe: about 1.5 on 2 vCPUs at the serial bound).
LOADED_AB = 0.25


def _ab_window_row(size: str, window: Mapping[str, Any]) -> list[str]:
    """Return one window's row of the check A/B table."""
    return [size, window['camera'], fmt_num(window.get('rate_hz')), window['state'],
            fmt_num(window['fps']), fmt_num(window.get('p50_ms')), fmt_num(window.get('p99_ms')),
            fmt_num(window['checks'], 0) if window['state'] == 'on' else '-',
            fmt_num(window.get('check_cpu_s')),
            f"{fmt_num(window.get('check_deferred'), 0)} / "
            f"{fmt_num(window.get('check_pauses'), 0)}",
            fmt_num(window['others_cores'], 2), fmt_num(window.get('load_1min'), 2)]


def check_ab_tables(doc: Mapping[str, Any]) -> list[str]:
    """Return the markdown lines of the check's A/B (issue 36, ``benchmarks/check_ab.py``)."""
    target = doc['target']
    windows = doc['windows_s']
    lines = ['### The self-check against the frame path (check off and on, interleaved)', '',
             'One correct_node per size with its default parameters (config/case2.yaml); its '
             f"check.rate_hz set to 0 (off) and to {doc['on_rate_hz']:g} Hz (on) through its "
             'parameter service for the windows off, on, off, on at each camera rate (30 Hz, '
             'then paced at the serial bound 1 / (1 / pass-through flat-out fps + bare remap)'
             f"); windows of {', '.join(f'{v:g} s ({k})' for k, v in windows.items())}, each "
             f"{doc['settle_s']:g} s after its set (and, off, after the check's process ended). "
             'Latency = probe receive - publisher stamp (two hops). Checks = completed in the '
             "window (the node's /diagnostics); check CPU = the check process's CPU seconds "
             'in the window; gate = checks deferred / paused by the CPU gate in the window; '
             'load = 1-minute load average.'
             + (f" Extra node parameters: `{doc['node_params']}`." if doc.get('node_params')
                else ''), '']
    rows = [_ab_window_row(size, w) for size, entry in doc['sizes'].items()
            for w in entry['windows']]
    lines += markdown_table(['frame', 'camera', 'Hz', 'check', 'delivered fps', 'p50 ms',
                             'p99 ms', 'checks completed', 'check CPU s', 'gate deferred / paused',
                             'others cores', 'load'], rows)
    lines += ['', f"Target (issue 36): p50 on <= p50 off x {1 + target['p50_share']:g} + "
              f"{target['p50_margin_ms']:g} ms, delivered on >= {1 - target['delivered_share']:g} "
              'x off (means of the two windows of each), and at 30 Hz a check completed in '
              "every 'on' window.", '']
    rows = []
    for v in doc['verdicts'].values():
        checks = ', '.join(str(c) for c in v['checks_per_on_window'])
        rows.append([v['size'], v['camera'],
                     f"{fmt_num(v['p50_off_ms'])} / {fmt_num(v['p50_on_ms'])} "
                     f"(<= {fmt_num(v['p50_limit_ms'])}): {verdict(v['p50_met'])}",
                     f"{fmt_num(v['fps_off'])} / {fmt_num(v['fps_on'])} "
                     f"(>= {fmt_num(v['fps_limit'])}): {verdict(v['fps_met'])}",
                     checks + ('' if v['checks_met'] is None
                               else f": {verdict(v['checks_met'])}"),
                     verdict(v['met'])])
    lines += markdown_table(['frame', 'camera', 'p50 ms off / on (limit)',
                             'delivered fps off / on (limit)', "checks per 'on' window",
                             'verdict'], rows)
    if doc['errors']:
        lines += ['', 'Errors: ' + '; '.join(e.splitlines()[0] for e in doc['errors'])]
    lines += ['', f"Machine: {machine_line(doc['machine'])}; 1-minute load average "
              f"{fmt_num(doc['load_before'], 2)} at the start, {fmt_num(doc['load_after'], 2)} "
              'at the end.', '']
    others = max((w['others_cores'] for entry in doc['sizes'].values()
                  for w in entry['windows'] if w['state'] == 'off'), default=0.0)
    if others > LOADED_AB:
        lines += [f'**Measured on a loaded machine** (other processes used up to {others:.2f} '
                  'cores with the check off: their work is in every window, and the gate holds '
                  'checks back while the machine is busier than check.max_load): these numbers '
                  'say nothing of the check; rerun `python -m benchmarks.check_cost --ab` on a '
                  'quiet one.', '']
    return lines


# ---------------------------------------------------------------------------------------------
# Soak
# ---------------------------------------------------------------------------------------------

def soak_plot(doc: dict[str, Any], path: Path) -> Path:
    """Draw RSS (and output fps) over time with the second-half fit; return the path."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    samples = doc['samples']
    t = [s['t_s'] / 60.0 for s in samples]
    rss = [s['rss_mib'] for s in samples]
    memory = doc['summary']['memory_second_half']
    fig, ax = plt.subplots(figsize=(10, 5))
    ax.plot(t, rss, color='tab:blue', linewidth=1.0, label='node RSS (1 s samples)')
    lo, hi = memory['window_s']
    fit_t = [lo / 60.0, hi / 60.0]
    ax.plot(fit_t, [memory['intercept_mib'] + memory['slope_mib_per_min'] * x for x in fit_t],
            color='tab:red', linewidth=2.0,
            label=f"fit over the second half: {memory['slope_mib_per_min']:+.4f} MiB/min "
                  f"(+/- {memory['slope_se_mib_per_min']:.4f})")
    ax.axvspan(0, lo / 60.0, color='0.92', label='first half (warm-up)')
    for entry in doc['sets']:
        ax.axvline(entry['t_s'] / 60.0, color='0.6', linewidth=0.5, linestyle=':')
    ax.set_xlabel('time [min]')
    ax.set_ylabel('resident memory [MiB]')
    span = max(rss) - min(rss)
    ax.set_ylim(min(rss) - max(5.0, 0.2 * span), max(rss) + max(5.0, 0.2 * span))
    ax2 = ax.twinx()
    ax2.plot(t, [s['fps_out'] for s in samples], color='tab:green', linewidth=0.6, alpha=0.6)
    ax2.set_ylabel('image_rect received [fps]', color='tab:green')
    ax2.set_ylim(0, max(doc['rate_hz'] * 1.5, max(s['fps_out'] for s in samples) + 1))
    ax.set_title(f"correct_node, {doc['width']}x{doc['height']} rgb8 at {doc['rate_hz']:g} Hz "
                 f"for {doc['minutes']:g} min; stop offset set every {doc['set_every_s']:g} s "
                 '(dotted)', fontsize=10)
    ax.legend(loc='lower right', fontsize=8)
    fig.text(0.01, 0.01, machine_line(doc['machine']), fontsize=7, color='0.4')
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def soak_report(doc: dict[str, Any]) -> str:
    """Return the human-readable summary of a run."""
    if 'summary' not in doc:
        return 'soak: no summary; errors: ' + '; '.join(doc['errors'])
    s = doc['summary']
    m = s['memory_second_half']
    lines = [
        f"soak: {s['seconds'] / 60:.1f} min of {doc['width']}x{doc['height']} rgb8 at "
        f"{doc['rate_hz']:g} Hz: received {s['fps_out_mean']:.1f} fps mean "
        f"(min {s['fps_out_min']} in a second), latency p50 {doc['latency_ms']['p50']:.1f} ms, "
        f"p99 {doc['latency_ms']['p99']:.1f} ms; node {s['node_cores_mean']:.2f} cores; other "
        f"processes {doc.get('others_cores', math.nan):.2f} cores",
        f"RSS: {s['rss_mib']['first']:.1f} MiB at start, {s['rss_mib']['after_1_min']:.1f} after "
        f"1 min, {s['rss_mib']['at_half']:.1f} at half, {s['rss_mib']['end']:.1f} at the end, "
        f"max {s['rss_mib']['max']:.1f}",
        f"second half: slope {m['slope_mib_per_min']:+.4f} MiB/min (SE "
        f"{m['slope_se_mib_per_min']:.4f}), residual sd {m['residual_std_mib']:.3f} MiB, "
        f"predicted growth {m['growth_over_window_mib']:+.2f} MiB over the half (allowed "
        f"{m['allowed_growth_mib']:.2f}): {'FLAT' if m['flat'] else 'GROWING'}",
        f"threads {s['threads']['min']}-{s['threads']['max']}, open descriptors "
        f"{s['fds']['min']}-{s['fds']['max']}; parameter sets {s['sets']}, reaching the frames "
        f"{s['sets_reaching_frames']}; exit codes {doc['exit_codes']}",
    ]
    if doc['errors']:
        lines.append('errors: ' + '; '.join(doc['errors']))
    return '\n'.join(lines)
