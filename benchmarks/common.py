# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Shared helpers of the benchmarks: load monitoring, interleaved timing, the command line.

(Tables, figures, JSON and machine facts: :mod:`benchmarks.report`.)

Timing method: on a shared machine the load of other processes comes in bursts of seconds,
so timing one variant after another would compare different loads. The variants of one
comparison run in *rounds*. Variants are grouped by their OpenCV thread count and an optional
group name; in every round each group runs in turn (``cv2.setNumThreads`` once per group),
each of its variants is called once to warm up, and then the group's variants are called in
turn, one call each, ``reps`` times over, so a burst of load from another process hits all of
them alike (call-level interleaving). The order of the groups and of the variants in a group
rotates from round to round. Before each round the machine is given up to ``quiet_wait_s`` to
become quiet, and how many cores *other* processes used during the round is recorded
(``others_cores``: busy time of the whole machine from ``/proc/stat`` minus this process's own
CPU time, over the wall time). A variant is summarised by its ``min`` over every call and the
``median`` of its per-round medians.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import os
from pathlib import Path
import statistics
import sys
import time
from typing import Any, Callable, Mapping, Sequence

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / 'results'
#: Per-sample data that the README does not need (ignored by git).
RAW = RESULTS / 'raw'

_TICK = os.sysconf('SC_CLK_TCK')


# ---------------------------------------------------------------------------------------------
# Load of the other processes
# ---------------------------------------------------------------------------------------------

def _machine_busy_s() -> float:
    """Return the CPU seconds all processes spent busy since boot (``/proc/stat``)."""
    with open('/proc/stat', encoding='ascii') as stream:
        fields = [int(x) for x in stream.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)
    guest = sum(fields[8:10]) if len(fields) > 9 else 0      # already counted in user/nice
    return (sum(fields) - idle - guest) / _TICK


class LoadMonitor:
    """
    Measure how many cores processes other than ours kept busy over an interval.

    ``own`` returns the CPU seconds of what counts as ours (default: this process, all its
    threads); the node benchmark adds its child processes.
    """

    def __init__(self, own: Callable[[], float] = time.process_time) -> None:
        """Start measuring now."""
        self._own = own
        self._t0 = time.monotonic()
        self._busy0 = _machine_busy_s()
        self._own0 = own()

    def others_cores(self) -> float:
        """Return the cores other processes used since the start (0 if nothing elapsed)."""
        wall = time.monotonic() - self._t0
        if wall <= 0.0:
            return 0.0
        busy = _machine_busy_s() - self._busy0
        own = self._own() - self._own0
        return max(0.0, (busy - own) / wall)

    def total_cores(self) -> float:
        """Return the cores the whole machine used since the start."""
        wall = time.monotonic() - self._t0
        return (_machine_busy_s() - self._busy0) / wall if wall > 0 else 0.0


def wait_for_quiet(max_wait_s: float, threshold_cores: float = 0.15,
                   window_s: float = 0.25) -> float:
    """
    Wait (up to ``max_wait_s``) until other processes use less than ``threshold_cores``.

    :return: the others' cores in the last window measured (0 when not waiting at all).
    """
    deadline = time.monotonic() + max_wait_s
    others = 0.0
    while time.monotonic() < deadline:
        monitor = LoadMonitor()
        time.sleep(window_s)
        others = monitor.others_cores()
        if others < threshold_cores:
            break
    return others


def wait_for_low_load(max_wait_s: float, threshold: float = 0.5, poll_s: float = 10.0,
                      log: Callable[[str], None] = print) -> float:
    """
    Wait (up to ``max_wait_s``) for the 1-minute load average to fall below ``threshold``.

    :return: the 1-minute load average when the wait ended.
    """
    deadline = time.monotonic() + max_wait_s
    load = os.getloadavg()[0]
    if load >= threshold and max_wait_s > 0:
        log(f'load average {load:.2f} >= {threshold}: waiting up to {max_wait_s:.0f} s')
    while load >= threshold and time.monotonic() < deadline:
        time.sleep(min(poll_s, max(0.0, deadline - time.monotonic())))
        load = os.getloadavg()[0]
    return load


# ---------------------------------------------------------------------------------------------
# Interleaved timing
# ---------------------------------------------------------------------------------------------

@dataclass
class Variant:
    """One thing to time: a call, and the OpenCV thread count to run it with (0 = leave)."""

    name: str
    call: Callable[[], Any]
    threads: int = 0
    info: dict[str, Any] = field(default_factory=dict)
    #: Variants of one group (and thread count) are interleaved call by call.
    group: str = ''


@dataclass
class Timing:
    """Timed calls of one variant, ms."""

    name: str
    samples: list[list[float]] = field(default_factory=list)      # per round
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def flat(self) -> list[float]:
        """Return every sample."""
        return [t for r in self.samples for t in r]

    @property
    def fastest(self) -> float:
        """Return the fastest call, ms."""
        return min(self.flat) if self.flat else math.nan

    @property
    def median(self) -> float:
        """Return the median of the per-round medians, ms."""
        meds = [statistics.median(r) for r in self.samples if r]
        return statistics.median(meds) if meds else math.nan

    def summary(self) -> dict[str, Any]:
        """Return min, median, count, and the info."""
        return {'min_ms': self.fastest, 'median_ms': self.median, 'calls': len(self.flat),
                **self.info}


def time_ms(call: Callable[[], Any], reps: int) -> list[float]:
    """Call ``reps`` times; return each call's wall time in ms."""
    out = []
    clock = time.perf_counter_ns
    for _ in range(reps):
        start = clock()
        call()
        out.append((clock() - start) * 1e-6)
    return out


def interleave(variants: Sequence[Variant], rounds: int, reps: int | Mapping[str, int],
               quiet_wait_s: float = 2.0) -> tuple[dict[str, Timing], list[float]]:
    """
    Time variants in interleaved rounds (see the module docstring).

    :param variants: what to time; a variant with ``threads > 0`` runs after
        ``cv2.setNumThreads(threads)``.
    :param rounds: rounds; the order of groups and variants rotates by one each round.
    :param reps: timed calls per variant and round (or per variant name).
    :param quiet_wait_s: the longest wait for a quiet machine before each round.
    :return: timings by name, and the others' cores of each round.
    """
    import cv2
    previous_threads = cv2.getNumThreads()
    timings = {v.name: Timing(v.name, info=dict(v.info, threads=v.threads)) for v in variants}
    groups: dict[tuple[int, str], list[Variant]] = {}
    for v in variants:
        groups.setdefault((v.threads, v.group), []).append(v)
    keys = list(groups)
    others = []
    clock = time.perf_counter_ns
    try:
        for r in range(rounds):
            wait_for_quiet(quiet_wait_s)
            monitor = LoadMonitor()
            for key in keys[r % len(keys):] + keys[:r % len(keys)]:
                group = groups[key]
                order = group[r % len(group):] + group[:r % len(group)]
                if key[0]:
                    cv2.setNumThreads(key[0])
                for v in order:
                    v.call()                                      # warm-up
                counts = {v.name: reps[v.name] if isinstance(reps, Mapping) else reps
                          for v in order}
                samples: dict[str, list[float]] = {v.name: [] for v in order}
                for i in range(max(counts.values())):
                    for v in order:
                        if i < counts[v.name]:
                            start = clock()
                            v.call()
                            samples[v.name].append((clock() - start) * 1e-6)
                for name, values in samples.items():
                    timings[name].samples.append(values)
            others.append(monitor.others_cores())
    finally:
        cv2.setNumThreads(previous_threads)
    return timings, others


# ---------------------------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------------------------

def log(message: str) -> None:
    """Print a progress line to stderr."""
    print(message, file=sys.stderr, flush=True)


def bench_main(description: str, run: Callable[..., dict[str, Any]],
               tables: Callable[[dict[str, Any]], list[str]], quick_help: str,
               argv: list[str] | None = None) -> int:
    """
    Run one benchmark from the command line (``--quick``, ``--out``) and print its tables.

    :param description: the benchmark module's docstring (its first paragraph is shown).
    :param run: ``run(out_dir, quick=...)`` returning the results document.
    :param tables: the document -> markdown lines.
    :param quick_help: what ``--quick`` does for this benchmark.
    :param argv: the arguments (default ``sys.argv[1:]``).
    :return: exit status 0.
    """
    import argparse
    parser = argparse.ArgumentParser(description=description.split('\n\n')[0].strip())
    parser.add_argument('--quick', action='store_true', help=quick_help)
    parser.add_argument('--out', type=Path, default=RESULTS, help='results folder')
    args = parser.parse_args(argv)
    doc = run(args.out, quick=args.quick)
    print('\n'.join(tables(doc)))
    return 0
