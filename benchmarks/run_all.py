# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Run every benchmark (``make bench``) and write the full measured tables.

::

    python -m benchmarks.run_all [--quick] [--only accuracy,speed,node] [--wait-load 600]
                                 [--out results] [--docs docs/benchmarks.md]

Waits (up to ``--wait-load`` seconds, default 600) for the 1-minute load average to drop
below 0.5, so the timings are taken on a quiet machine; then runs :mod:`benchmarks.accuracy`,
:mod:`benchmarks.speed`, :mod:`benchmarks.node_latency`, :mod:`benchmarks.stages`,
:mod:`benchmarks.wide`, :mod:`benchmarks.vignetting`, :mod:`benchmarks.colour`,
:mod:`benchmarks.compressed_input`, :mod:`benchmarks.zoom` (a moving zoom lens),
:mod:`benchmarks.lens_import` (imported lens files against optiland) and
:mod:`benchmarks.real_lenses` (production lenses' patents against lensfun; it also writes
docs/real_lenses.md and config/lenses), :mod:`benchmarks.stereo_latency` (stereo_node
against a relay of two streams) and :mod:`benchmarks.check_ab` (the self-check's cost:
check off / on windows interleaved, issue 36), each writing its
``results/<name>.json`` and figures, and finally prints the markdown tables (made by
:mod:`benchmarks.report`) and writes them to ``results/README_tables.md`` and to
``docs/benchmarks.md`` (a generated file: the machine line at the top, figure links relative
to it). ``--quick`` (tiny sizes, one repetition: proves the pipeline runs, its numbers mean
nothing) writes no ``docs/benchmarks.md`` unless ``--docs`` names one. About fifteen minutes on
2 cores.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
import time
from typing import Any, Callable

from benchmarks import (
    accuracy, check_ab, colour, compressed_input, lens_import, node_latency, real_lenses,
    regenerate, speed, stages, stereo_latency, vignetting, wide, zoom)
from benchmarks.common import log, RESULTS, wait_for_low_load
from benchmarks.regenerate import DOCS_PAGE, docs_page, tables_header
from benchmarks.report import machine_info, machine_line, write_json

#: Benchmark name -> (its run, its tables: :data:`benchmarks.regenerate.TABLES`).
BENCHMARKS: dict[str, tuple[Callable[..., Any], Callable[[Any], list[str]]]] = {
    name: (run, regenerate.TABLES[name]) for name, run in (
        ('accuracy', accuracy.run), ('speed', speed.run), ('node', node_latency.run),
        ('stages', stages.run), ('wide', wide.run), ('vignetting', vignetting.run),
        ('colour', colour.run), ('compressed', compressed_input.run), ('zoom', zoom.run),
        ('lens_import', lens_import.run), ('real_lenses', real_lenses.run),
        ('stereo', stereo_latency.run),
        ('check_ab', check_ab.run))}


def run_all(out_dir: Path = RESULTS, quick: bool = False,
            only: tuple[str, ...] = tuple(BENCHMARKS), wait_load_s: float = 600.0,
            docs: Path | None = None) -> tuple[list[str], dict[str, Any]]:
    """
    Run the selected benchmarks; write their results, ``README_tables.md`` and the docs page.

    :param out_dir: results folder.
    :param quick: tiny sizes and repeats (the smoke test).
    :param only: which benchmarks to run, by name.
    :param wait_load_s: longest wait for a load average below 0.5 before starting.
    :param docs: where to write the generated page of full tables (None: nowhere).
    :return: the markdown lines, and a summary (durations, load, targets).
    """
    load = wait_for_low_load(wait_load_s, log=log)
    summary: dict[str, Any] = {'machine': machine_info(), 'load_at_start': load,
                               'quick': quick, 'durations_s': {}}
    lines = tables_header(machine_line(summary['machine']), load)
    for name in only:
        bench, _ = BENCHMARKS[name]
        start = time.monotonic()
        log(f'== {name} ==')
        bench(out_dir, quick=quick)
        summary['durations_s'][name] = round(time.monotonic() - start, 1)
    # Every block from its results file, named with the run that wrote it (a benchmark not
    # run now keeps its earlier file, and says so).
    body = regenerate.blocks(regenerate.load(out_dir), summary)
    lines += body
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / 'README_tables.md').write_text('\n'.join(lines) + '\n')
    write_json(out_dir / 'run_all.json', summary)
    if docs is not None:
        docs.parent.mkdir(parents=True, exist_ok=True)
        docs.write_text(docs_page(body, machine_line(summary['machine']), load, out_dir, docs))
        log(f'wrote {docs}')
    return lines, summary


def main(argv: list[str] | None = None) -> int:
    """Run, print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--quick', action='store_true', help='tiny sizes and repeats')
    parser.add_argument('--only', default=','.join(BENCHMARKS),
                        help='comma-separated subset of: ' + ', '.join(BENCHMARKS))
    parser.add_argument('--wait-load', type=float, default=600.0,
                        help='seconds to wait for a load average below 0.5 (default 600)')
    parser.add_argument('--out', type=Path, default=RESULTS, help='results folder')
    parser.add_argument('--docs', type=Path, default=None,
                        help='the generated page of full tables (default docs/benchmarks.md; '
                             'none with --quick)')
    args = parser.parse_args(argv)
    only = tuple(n.strip() for n in args.only.split(',') if n.strip())
    unknown = [n for n in only if n not in BENCHMARKS]
    if unknown:
        parser.error(f'unknown benchmark(s) {unknown}')
    docs = args.docs or (None if args.quick else DOCS_PAGE)
    lines, _ = run_all(args.out, quick=args.quick, only=only, wait_load_s=args.wait_load,
                       docs=docs)
    print('\n'.join(lines))
    return 0


if __name__ == '__main__':
    sys.exit(main())
