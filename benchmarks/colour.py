# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Cost of colour: lateral colour correction and Bayer input (issue #20).

Everything runs in one process, in interleaved rounds (:func:`benchmarks.common.interleave`),
one OpenCV thread, on the Case 2 thick lens in SCHOTT N-BK7 (``config/case2.yaml`` with
``lens.glass``; about 1 px of lateral colour at the raw corner), the sensor size from the
frame.

* **Per frame**, 1280x720 and 1920x1080 rgb8: ``Rectifier.correct`` with one map (the
  reference, ``output.lateral_color_correction`` false) and with a map per channel (true: the
  folded remap of :mod:`mechdeconv_ros.imaging.channel_remap`). Target: lateral / single <= 1.3.
* **Bayer**, same sizes, ``bayer_rggb8``: demosaicing (:class:`mechdeconv_ros.imaging.debayer.
  Demosaicer`, each ``debayer`` method) plus the correction, against the rgb8 correction of
  the same frame size. Target: demosaic + correction / correction <= 1.5.
* The same two (rgb8 correction; ``vng`` + correction) again at the node's default thread
  count (``remap_threads`` 0: OpenCV's default, every core), where the remap runs on every core
  and VNG in as many stripes (:mod:`mechdeconv_ros.imaging.debayer`); like with like, both ratios.
* **Rebuild** at 1920x1080: ``build_model`` + ``Rectifier`` without and with lateral colour
  (three channel traces and three maps), and the traces alone (``trace_ms``).
"""

from __future__ import annotations

import os
from pathlib import Path
import sys
from typing import Any, Mapping

from benchmarks.common import bench_main, interleave, log, RESULTS, Variant
from benchmarks.report import machine_info, markdown_table, write_json
from benchmarks.speed import case2_values
from mechdeconv_ros.imaging.debayer import Demosaicer
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import DEBAYER_METHODS
import numpy as np

FRAME_SIZES = ((1280, 720), (1920, 1080))
REBUILD_SIZE = (1920, 1080)
GLASS = 'SCHOTT:N-BK7'
#: lateral / single remap; demosaic + correction / rgb8 correction (per frame).
LATERAL_RATIO_TARGET = 1.3
BAYER_RATIO_TARGET = 1.5


def glass_values() -> dict[str, Any]:
    """Return Case 2 in N-BK7 focused at 550 nm, the sensor size from the frames."""
    values = case2_values()
    values.update({'lens.glass': GLASS, 'lens.wavelength_nm': 550.0})
    return values


def frames(rounds: int, reps: int, quiet: float, sizes=FRAME_SIZES) -> dict[str, Any]:
    """Time the single remap, the lateral remap and the Bayer paths per frame, interleaved."""
    values = glass_values()
    out: dict[str, Any] = {}
    rng = np.random.default_rng(0)
    default = os.cpu_count() or 1          # what cv2.setNumThreads(-1) gives, as the node
    for width, height in sizes:
        model = build_model(dict(values, **{'output.lateral_color_correction': True}),
                            width, height)
        single = Rectifier(model, lateral=False)
        lateral = Rectifier(model)
        lateral.prepare_colours((0, 1, 2))
        src = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
        mosaic = rng.integers(0, 256, (height, width), dtype=np.uint8)
        dst = np.empty(single.out_shape + (3,), np.uint8)
        demosaicers = {m: Demosaicer() for m in DEBAYER_METHODS}

        def bayer(method: str, lat: bool) -> Any:
            def call() -> Any:
                rgb, _ = demosaicers[method].demosaic(mosaic, 'rggb', method)
                if lat:
                    return lateral.correct(rgb, dst, colours=(0, 1, 2))
                return single.correct(rgb, dst)
            return call

        variants = [
            Variant('single', lambda: single.correct(src, dst), 1),
            Variant('lateral', lambda: lateral.correct(src, dst, colours=(0, 1, 2)), 1),
            *(Variant(f'bayer {m}', bayer(m, False), 1) for m in DEBAYER_METHODS),
            Variant('bayer bilinear + lateral', bayer('bilinear', True), 1),
            Variant('single, default threads', lambda: single.correct(src, dst), default),
            Variant('bayer vng, default threads', bayer('vng', False), default),
        ]
        timings, others = interleave(variants, rounds, reps, quiet)
        result: dict[str, Any] = {name: t.summary() for name, t in timings.items()}
        base = result['single']['median_ms']
        result['lateral_over_single'] = result['lateral']['median_ms'] / base
        result['lateral_target_met'] = bool(result['lateral_over_single'] <= LATERAL_RATIO_TARGET)
        result['bayer_over_rgb8'] = {m: result[f'bayer {m}']['median_ms'] / base
                                     for m in DEBAYER_METHODS}
        result['bayer_target_met'] = {m: bool(r <= BAYER_RATIO_TARGET)
                                      for m, r in result['bayer_over_rgb8'].items()}
        result['default_threads'] = {
            'threads': default,
            'bayer_vng_over_rgb8': (result['bayer vng, default threads']['median_ms']
                                    / result['single, default threads']['median_ms'])}
        result['others_cores'] = others
        key = f'{width}x{height}'
        out[key] = result
        bayer_text = ', '.join(f'bayer {m} x{r:.2f}' for m, r in result['bayer_over_rgb8'].items())
        lateral = result['lateral']['median_ms']
        log(f'colour: {key}: single {base:.3g} ms, lateral {lateral:.3g} ms '
            f"(x{result['lateral_over_single']:.2f}), {bayer_text}; {default} threads: "
            f"bayer vng x{result['default_threads']['bayer_vng_over_rgb8']:.2f}")
    return out


def rebuilds(rounds: int, reps: int, quiet: float) -> dict[str, Any]:
    """Time the rebuild without and with lateral colour, interleaved."""
    width, height = REBUILD_SIZE
    values = glass_values()
    on = dict(values, **{'output.lateral_color_correction': True})
    variants = [
        Variant('without', lambda: Rectifier(build_model(values, width, height)), 1),
        Variant('with', lambda: Rectifier(build_model(on, width, height)), 1),
        Variant('traces only', lambda: build_model(on, width, height).lateral_color(), 1),
    ]
    timings, others = interleave(variants, rounds, reps, quiet)
    result: dict[str, Any] = {name: t.summary() for name, t in timings.items()}
    model = build_model(on, width, height)
    traces = model.lateral_color()
    result.update({
        'size': f'{width}x{height}', 'others_cores': others,
        'with_over_without': result['with']['median_ms'] / result['without']['median_ms'],
        'trace_ms': traces.trace_ms,
        'max_rb_separation_px': traces.max_rb_separation_px})
    log(f"colour: rebuild {result['without']['median_ms']:.3g} -> "
        f"{result['with']['median_ms']:.3g} ms (three traces {traces.trace_ms:.3g} ms)")
    return result


def run(out_dir: Path = RESULTS, quick: bool = False) -> dict[str, Any]:
    """
    Run the colour benchmark; write ``colour.json`` into ``out_dir``.

    :param out_dir: results folder.
    :param quick: one round, one call, small frames (smoke test).
    :return: the results document.
    """
    quiet = 0.0 if quick else 2.0
    doc = {
        'benchmark': 'colour',
        'machine': machine_info(),
        'method': __doc__,
        'per_frame': frames(1 if quick else 5, 1 if quick else 10, quiet,
                            ((320, 240),) if quick else FRAME_SIZES),
        'rebuild': rebuilds(1 if quick else 5, 1 if quick else 3, quiet),
    }
    write_json(Path(out_dir) / 'colour.json', doc)
    return doc


def tables(doc: Mapping[str, Any]) -> list[str]:
    """Return the markdown tables of a results document."""
    lines = ['Per frame, rgb8 and bayer_rggb8 (median ms, 1 thread, Case 2 in N-BK7):', '']
    rows = []
    for key, r in doc['per_frame'].items():
        rows.append((key, f"{r['single']['median_ms']:.3g}", f"{r['lateral']['median_ms']:.3g}",
                     f"{r['lateral_over_single']:.2f}",
                     *(f"{r['bayer_over_rgb8'][m]:.2f}" for m in DEBAYER_METHODS)))
    lines += markdown_table(('frame', 'one map', 'map per channel', 'ratio (target 1.3)',
                             *(f'Bayer {m} / rgb8 (target 1.5)' for m in DEBAYER_METHODS)),
                            rows)
    lines += ['', "At the node's default threads (remap on every core, VNG in stripes):", '']
    rows = []
    for key, r in doc['per_frame'].items():
        d = r.get('default_threads')
        if d:
            rows.append((key, d['threads'], f"{r['single, default threads']['median_ms']:.3g}",
                         f"{r['bayer vng, default threads']['median_ms']:.3g}",
                         f"{d['bayer_vng_over_rgb8']:.2f}"))
    lines += markdown_table(('frame', 'threads', 'rgb8 correction', 'Bayer vng + correction',
                             'ratio (target 1.5)'), rows)
    rebuild = doc['rebuild']
    lines += ['', f"Rebuild at {rebuild['size']} (median ms, 1 thread):", '']
    lines += markdown_table(
        ('without', 'with lateral colour', 'with / without', 'three traces',
         'R-B separation at the raw corner [px]'),
        [(f"{rebuild['without']['median_ms']:.3g}", f"{rebuild['with']['median_ms']:.3g}",
          f"{rebuild['with_over_without']:.2f}", f"{rebuild['trace_ms']:.3g}",
          f"{rebuild['max_rb_separation_px']:.3g}")])
    return lines


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark alone and print its tables."""
    return bench_main(__doc__ or '', run, tables, 'one round, tiny frames', argv)


if __name__ == '__main__':
    sys.exit(main())
