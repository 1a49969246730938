# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Run every benchmark (``make bench``) and write the README tables.

::

    python -m benchmarks.run_all [--quick] [--only accuracy,speed,node] [--wait-load 600]

Waits (up to ``--wait-load`` seconds, default 600) for the 1-minute load average to drop
below 0.5, so the timings are taken on a quiet machine; then runs :mod:`benchmarks.accuracy`,
:mod:`benchmarks.speed` and :mod:`benchmarks.node_latency`, each writing its
``results/<name>.json`` and figures, and finally prints the markdown tables and writes them to
``results/README_tables.md``. About five minutes on 2 cores.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
import time
from typing import Any, Callable

from benchmarks import accuracy, node_latency, speed
from benchmarks.common import (
    log, machine_info, machine_line, RESULTS, wait_for_low_load, write_json)

BENCHMARKS: dict[str, tuple[Callable[..., Any], Callable[[Any], list[str]]]] = {
    'accuracy': (accuracy.run, accuracy.tables),
    'speed': (speed.run, speed.tables),
    'node': (node_latency.run, node_latency.tables),
}


def run_all(out_dir: Path = RESULTS, quick: bool = False,
            only: tuple[str, ...] = tuple(BENCHMARKS), wait_load_s: float = 600.0
            ) -> tuple[list[str], dict[str, Any]]:
    """
    Run the selected benchmarks; write their results and ``README_tables.md``.

    :param out_dir: results folder.
    :param quick: tiny sizes and repeats (the smoke test).
    :param only: which benchmarks to run, by name.
    :param wait_load_s: longest wait for a load average below 0.5 before starting.
    :return: the markdown lines, and a summary (durations, load, targets).
    """
    load = wait_for_low_load(wait_load_s, log=log)
    summary: dict[str, Any] = {'machine': machine_info(), 'load_at_start': load,
                               'quick': quick, 'durations_s': {}}
    lines = ['## Benchmarks', '',
             'Measured by `make bench` (`python -m benchmarks.run_all`) on '
             f"{machine_line(summary['machine'])}; 1-minute load average at the start "
             f'{load:.2f}. Every number below comes from that run (results/*.json).', '']
    for name in only:
        bench, tables = BENCHMARKS[name]
        start = time.monotonic()
        log(f'== {name} ==')
        doc = bench(out_dir, quick=quick)
        summary['durations_s'][name] = round(time.monotonic() - start, 1)
        lines += tables(doc)
    total = sum(summary['durations_s'].values())
    lines.append(f'Benchmark run time: {total:.0f} s ('
                 + ', '.join(f'{k} {v:.0f} s' for k, v in summary['durations_s'].items())
                 + ').')
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / 'README_tables.md').write_text('\n'.join(lines) + '\n')
    write_json(out_dir / 'run_all.json', summary)
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
    args = parser.parse_args(argv)
    only = tuple(n.strip() for n in args.only.split(',') if n.strip())
    unknown = [n for n in only if n not in BENCHMARKS]
    if unknown:
        parser.error(f'unknown benchmark(s) {unknown}')
    lines, _ = run_all(args.out, quick=args.quick, only=only, wait_load_s=args.wait_load)
    print('\n'.join(lines))
    return 0


if __name__ == '__main__':
    sys.exit(main())
