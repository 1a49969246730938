# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
What the live self-check costs the frame path: check off / on windows interleaved in ONE run.

Issue 36, item 1: with the default parameters, at 1280x720 and 1920x1080 rgb8, a camera at
30 Hz and one paced at the serial bound, correct_node's p50 latency with the check on must be
within 5 % + 0.5 ms of the same node with the check off (``check.rate_hz`` 0), its delivered
frames within 1 %, and checks must complete in every 'on' window at 30 Hz (a check the gate
always holds back is not free, it is off).

One run, per size (the processes of :mod:`benchmarks.node_latency`: its publisher, its
pass-through relay, correct_node with ``config/case2.yaml`` and the sensor size from the
frames, its probe, the shm profile, a private domain):

1. the bare remap (a plain ``cv2.remap`` with the node's maps, median) and the pass-through
   with the publisher flat out give the serial bound ``1 / (1 / relay fps + remap)``
   (:func:`benchmarks.node_latency.serial_bound_fps`);
2. ONE node runs with its defaults; for a camera at 30 Hz, then one paced at the serial
   bound, its ``check.rate_hz`` is set (through its ``set_parameters`` service, as
   ``ros2 param set`` does) to 0 (off) and back to its default (on) for the windows
   ``off, on, off, on``. Each window starts :data:`SETTLE_S` after the set (after an 'off'
   set, also after the check's process has ended: a check in progress finishes first) and
   lasts :data:`WINDOW_S` (30 Hz: long enough for checks to complete at the default rate).

Per window: delivered fps, latency p50 / p99 (probe receive time - the publisher's stamp, two
hops), checks completed in it (the node's ``checks`` in /diagnostics at the window's end minus
at its start, both read half a second later: /diagnostics comes every second, so a check is
counted in the window it most likely ended in), the CPU seconds the check's process used in
it, what the gate did (``check_deferred``, ``check_pauses``) and the cores other processes
kept busy. The
verdict per size and camera compares the mean of the two 'on' windows with the mean of the
two 'off' windows: p50 on <= p50 off x 1.05 + 0.5 ms, delivered on >= 0.99 x delivered off,
and (30 Hz) at least one check completed in each 'on' window.

Timings from a shared machine mean little: the 1-minute load average is recorded at the start
and end. About 5 minutes on 2 vCPUs::

    python -m benchmarks.check_cost --ab [--quick] [--out results] [--no-docs]
        [--node-params 'name:=value ...']

writes ``results/check_ab.json`` and regenerates the tables (``docs/benchmarks.md``,
``results/README_tables.md``); also part of ``make bench`` (:mod:`benchmarks.run_all`).
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path
import shutil
import statistics
import sys
import tempfile
import time
from typing import Any, Mapping, Sequence

from benchmarks import node_latency as nl
from benchmarks.common import log, RESULTS
from benchmarks.report import machine_info, write_json
from mechdeconv_ros.node.process_env import pick_domain_id

SIZES = ((1280, 720), (1920, 1080))
QUICK_SIZES = ((320, 240),)
#: The order of the windows of each camera rate.
WINDOWS = ('off', 'on', 'off', 'on')
#: Window length (s) per camera: at 30 Hz long enough for checks to complete at 0.2 Hz with
#: the child held during frames (a first check, with the child's start, took 2 to 4 s of CPU
#: at 720p on the loaded machine); at the serial bound the gate holds checks back.
WINDOW_S = {'30 Hz': 22.0, 'serial bound': 10.0}
QUICK_WINDOW_S = 1.0
#: Seconds after a set before its window starts (the set's own work, a check's first frame).
SETTLE_S = 2.0
QUICK_SETTLE_S = 0.3
#: Longest wait (s) after an 'off' set for the check's process to end (a check in progress
#: finishes first).
OFF_WAIT_S = 20.0
#: Seconds of the pass-through's flat-out window (the serial bound's relay rate).
FLAT_OUT_S = 3.0
#: The target (issue 36): p50 on <= p50 off x (1 + P50_SHARE) + P50_MARGIN_MS; delivered on
#: >= (1 - DELIVERED_SHARE) x delivered off.
P50_SHARE = 0.05
P50_MARGIN_MS = 0.5
DELIVERED_SHARE = 0.01
RATE_PARAM = 'check.rate_hz'
#: Half the node's /diagnostics period (s): how late, on average, a count there is.
DIAGNOSTICS_LAG_S = 0.5
CHILD_TIMEOUT_S = 600.0


# ---------------------------------------------------------------------------------------------
# The measuring child process (one ROS domain, the shm profile)
# ---------------------------------------------------------------------------------------------

def check_children(pid: int) -> list[int]:
    """Return the pids of a process's check worker children (Linux ``/proc``)."""
    out = []
    try:
        tasks = os.listdir(f'/proc/{pid}/task')
    except OSError:
        return out
    for task in tasks:
        try:
            children = Path(f'/proc/{pid}/task/{task}/children').read_text().split()
        except OSError:
            continue
        for child in children:
            try:
                cmd = Path(f'/proc/{child}/cmdline').read_bytes()
            except OSError:
                continue
            if b'check_worker' in cmd:
                out.append(int(child))
    return out


def cpu_s(pids: Sequence[int]) -> float:
    """Return the user + system CPU seconds of processes (those gone count 0)."""
    total = 0.0
    for pid in pids:
        try:
            fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    return total


class CheckCpu:
    """The CPU seconds the node's check processes used (they come and go with the check)."""

    def __init__(self, node_pid: int) -> None:
        """Start counting."""
        self._pid, self._seen = node_pid, {}

    def poll(self) -> float:
        """Read the children now; return their total CPU seconds since counting began."""
        for child in check_children(self._pid):
            self._seen[child] = max(self._seen.get(child, 0.0), cpu_s([child]))
        return sum(self._seen.values())


def set_parameter(probe: nl.Probe, name: str, value: float, timeout: float = 5.0) -> str:
    """Set a double parameter on the node as ``ros2 param set`` does; return '' or the error."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    if not probe.set_client.wait_for_service(timeout_sec=timeout):
        return 'set_parameters service not available'
    future = probe.set_client.call_async(SetParameters.Request(
        parameters=[Parameter(name, value=float(value)).to_parameter_msg()]))
    if not probe.spin_until(future.done, timeout):
        return 'no reply'
    result = future.result().results[0]
    return '' if result.successful else f'rejected: {result.reason}'


def last_before(probe: nl.Probe, key: str, at: float) -> float:
    """Return the node's last reported ``key`` received before ``at`` (0: none)."""
    seen = [v[key] for t, v in probe.diagnostics if t < at and key in v]
    return seen[-1] if seen else 0.0


def measure_window(probe: nl.Probe, node: Any, pub: Any, seconds: float,
                   check_cpu: CheckCpu) -> dict[str, Any]:
    """Measure one window; add the checks completed, the check's CPU and the gate's counts."""
    cpu0, t0 = check_cpu.poll(), time.monotonic()
    load0 = os.getloadavg()[0]
    stats = nl._measure_once(probe, node, pub, seconds)
    t1 = time.monotonic()
    stats['check_cpu_s'] = check_cpu.poll() - cpu0
    stats.pop('check', None)
    # /diagnostics reports a count up to a period after it changed: both ends are read half a
    # period later (a check is counted in the window it most likely ended in).
    probe.spin_for(DIAGNOSTICS_LAG_S + 0.1)
    for key in nl.CHECK_KEYS:
        stats[key] = (last_before(probe, key, t1 + DIAGNOSTICS_LAG_S)
                      - last_before(probe, key, t0 + DIAGNOSTICS_LAG_S))
    stats['load_1min'] = (load0 + os.getloadavg()[0]) / 2.0
    stats['seconds'] = t1 - t0
    return stats


def settle(probe: nl.Probe, node: Any, state: str, quick: bool) -> float:
    """Wait after a set: an 'off' window also waits for the check's process to end."""
    start = time.monotonic()
    settle_s = QUICK_SETTLE_S if quick else SETTLE_S
    if state == 'on':
        probe.spin_for(settle_s)
        return time.monotonic() - start
    # Off: no check process for settle_s in a row (one still starting counts too).
    deadline, quiet_since = start + (2.0 if quick else OFF_WAIT_S), start
    while time.monotonic() < deadline and time.monotonic() - quiet_since < settle_s:
        probe.spin_for(0.1)
        if check_children(node.pid):
            quiet_since = time.monotonic()
    return time.monotonic() - start


def flat_out_fps(probe: nl.Probe, env: Mapping[str, str], log_dir: Path, width: int,
                 height: int, seconds: float, doc: dict[str, Any]) -> float:
    """Return the pass-through's delivered fps with the publisher flat out."""
    relay = nl.start_child(nl.node_argv('passthrough'), env, log_dir, f'relay_{width}')
    pub = None
    try:
        if not probe.ready(nl.READY_TIMEOUT_S):
            doc['errors'].append(f'relay {width}x{height} not ready: {relay.tail()}')
        pub = nl.start_child(nl.publisher_argv(width, height, 0.0), env, log_dir,
                             f'publisher_flat_{width}')
        probe.first_frame(nl.FIRST_FRAME_TIMEOUT_S)
        probe.spin_for(0.5)
        return len(probe.measure(seconds)) / seconds
    finally:
        for proc in (pub, relay):
            if proc is not None:
                _stop(proc, doc)


def _stop(proc: Any, doc: dict[str, Any]) -> None:
    """Stop a process; record a non-zero exit as an error."""
    code = proc.stop()
    if code != 0 or proc.killed:
        doc['errors'].append(f'{proc.name} exited with {code}: {proc.tail()}')


def measure_size(probe_domain: int, env: Mapping[str, str], log_dir: Path, width: int,
                 height: int, on_rate: float, quick: bool, doc: dict[str, Any]) -> None:
    """Measure one size: the serial bound, then the interleaved windows of one node."""
    size = f'{width}x{height}'
    remap = nl.bare_remap_ms(width, height, 5 if quick else 40)
    # A flood leaves a probe's shared-memory transport stalling: a fresh probe after it.
    probe = nl.Probe(probe_domain, name=f'ab_probe_flat_{width}')
    try:
        relay_fps = flat_out_fps(probe, env, log_dir, width, height,
                                 0.6 if quick else FLAT_OUT_S, doc)
    finally:
        probe.close()
    serial = nl.serial_bound_fps(relay_fps, remap['median_ms'])
    entry: dict[str, Any] = {'bare_remap': remap, 'passthrough_flat_out_fps': relay_fps,
                             'serial_bound_fps': serial, 'windows': []}
    doc['sizes'][size] = entry
    log(f'check_ab {size}: bare remap {remap["median_ms"]:.2f} ms, relay flat out '
        f'{relay_fps:.1f} fps, serial bound {serial:.1f} fps')
    probe = nl.Probe(probe_domain, name=f'ab_probe_{width}')
    node = nl.start_child(nl.node_argv('node'), env, log_dir, f'node_{width}')
    try:
        if not probe.ready(nl.READY_TIMEOUT_S):
            doc['errors'].append(f'node {size} not ready: {node.tail()}')
        check_cpu = CheckCpu(node.pid)
        cameras = [('30 Hz', nl.RATE_HZ)]
        if math.isfinite(serial) and not quick:
            cameras.append(('serial bound', serial))
        for camera, rate in cameras:
            pub = nl.start_child(nl.publisher_argv(width, height, rate), env, log_dir,
                                 f'publisher_{width}_{camera.replace(" ", "_")}')
            try:
                probe.first_frame(nl.FIRST_FRAME_TIMEOUT_S)
                for state in WINDOWS:
                    error = set_parameter(probe, RATE_PARAM, on_rate if state == 'on' else 0.0)
                    if error:
                        doc['errors'].append(f'{size} {camera} {state}: {error}')
                    waited = settle(probe, node, state, quick)
                    stats = measure_window(probe, node, pub, QUICK_WINDOW_S if quick
                                           else WINDOW_S[camera], check_cpu)
                    stats.update({'camera': camera, 'rate_hz': rate, 'state': state,
                                  'settled_s': waited})
                    entry['windows'].append(stats)
                    log(f'check_ab {size} {camera:12s} {state:3s}: {stats["fps"]:.1f} fps, p50 '
                        f'{stats.get("p50_ms", math.nan):.1f} ms, p99 '
                        f'{stats.get("p99_ms", math.nan):.1f} ms, checks {stats["checks"]:.0f}, '
                        f'check CPU {stats["check_cpu_s"]:.1f} s, deferred '
                        f'{stats["check_deferred"]:.0f}, pauses {stats["check_pauses"]:.0f}, '
                        f'others {stats["others_cores"]:.2f} cores, load '
                        f'{stats["load_1min"]:.2f}')
            finally:
                _stop(pub, doc)
    finally:
        _stop(node, doc)
        probe.close()


def child_main(quick: bool, out_json: Path, on_rate: float,
               sizes: Sequence[tuple[int, int]] | None = None) -> int:
    """Measure every size in this process's domain; write the raw document."""
    env = dict(os.environ)
    domain = int(env['ROS_DOMAIN_ID'])
    doc: dict[str, Any] = {'sizes': {}, 'errors': [], 'on_rate_hz': on_rate,
                           'node_params': env.get(nl.NODE_PARAMS_ENV, '')}
    log_dir = Path(tempfile.mkdtemp(prefix='mechdeconv_check_ab_'))
    doc['log_dir'] = str(log_dir)
    try:
        for width, height in sizes or (QUICK_SIZES if quick else SIZES):
            measure_size(domain, env, log_dir, width, height, on_rate, quick, doc)
    except Exception as err:    # noqa: B902 - record it; the parent reports it
        doc['errors'].append(f'{err!r}')
    finally:
        write_json(out_json, doc)
    if not doc['errors']:
        shutil.rmtree(log_dir, ignore_errors=True)
    return 0


# ---------------------------------------------------------------------------------------------
# The parent: the child, the verdicts, the results file
# ---------------------------------------------------------------------------------------------

def _mean(values: Sequence[float]) -> float:
    """Return the mean (NaN when empty)."""
    values = [v for v in values if v is not None and math.isfinite(v)]
    return statistics.fmean(values) if values else math.nan


def evaluate(sizes: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """
    Return the verdict per size and camera (module docstring).

    :param sizes: size -> its entry (``windows``: the measured windows, in order).
    :return: ``'<size> <camera>'`` -> p50 and fps off / on, their limits, checks, met.
    """
    out: dict[str, Any] = {}
    for size, entry in sizes.items():
        for camera in dict.fromkeys(w['camera'] for w in entry['windows']):
            windows = [w for w in entry['windows'] if w['camera'] == camera]
            off = [w for w in windows if w['state'] == 'off']
            on = [w for w in windows if w['state'] == 'on']
            p50_off, p50_on = (_mean([w.get('p50_ms') for w in ws]) for ws in (off, on))
            fps_off, fps_on = (_mean([w['fps'] for w in ws]) for ws in (off, on))
            p50_limit = p50_off * (1.0 + P50_SHARE) + P50_MARGIN_MS
            fps_limit = fps_off * (1.0 - DELIVERED_SHARE)
            checks = [int(w['checks']) for w in on]
            checks_met = all(c >= 1 for c in checks) if camera == '30 Hz' else None
            p50_met, fps_met = p50_on <= p50_limit, fps_on >= fps_limit
            out[f'{size} {camera}'] = {
                'size': size, 'camera': camera, 'p50_off_ms': p50_off, 'p50_on_ms': p50_on,
                'p50_limit_ms': p50_limit, 'p50_met': p50_met, 'fps_off': fps_off,
                'fps_on': fps_on, 'fps_limit': fps_limit, 'fps_met': fps_met,
                'checks_per_on_window': checks, 'checks_met': checks_met,
                'met': bool(p50_met and fps_met and checks_met is not False)}
    return out


def run(out_dir: Path = RESULTS, quick: bool = False, on_rate: float | None = None,
        node_params: str | None = None, sizes: str | None = None) -> dict[str, Any]:
    """
    Run the A/B in a child process; write ``check_ab.json`` into ``out_dir``.

    :param out_dir: results folder.
    :param quick: one tiny size, 30 Hz only, 1 s windows (proves it runs; numbers mean
        nothing).
    :param on_rate: ``check.rate_hz`` of the 'on' windows (None: the schema's default).
    :param node_params: extra node parameters (``name:=value`` ...; None: the environment's
        :data:`benchmarks.node_latency.NODE_PARAMS_ENV`).
    :param sizes: ``WxH,WxH`` (None: :data:`SIZES`; a development aid: the table then lacks
        the other size).
    :return: the results document.
    """
    from mechdeconv_ros.schema.params import SPECS
    rate = float(SPECS[RATE_PARAM].default) if on_rate is None else float(on_rate)
    log_dir = Path(tempfile.mkdtemp(prefix='mechdeconv_check_ab_parent_'))
    out_json = log_dir / 'child.json'
    env = nl.ros_env(pick_domain_id('benchmarks', 53), 'shm')
    if node_params is not None:
        env[nl.NODE_PARAMS_ENV] = node_params
    argv = [sys.executable, '-m', 'benchmarks.check_ab', '--child', '--out-json',
            str(out_json), '--check-rate', str(rate)] + (['--quick'] if quick else []) + (
                ['--sizes', sizes] if sizes else [])
    load_before = os.getloadavg()[0]
    child = nl.start_child(argv, env, log_dir, 'child')
    start = time.monotonic()
    while child.running() and time.monotonic() - start < CHILD_TIMEOUT_S:
        time.sleep(0.2)
    code = child.stop()
    sys.stderr.write(child.stderr())
    raw = json.loads(out_json.read_text()) if out_json.exists() else {'sizes': {}, 'errors': []}
    errors = list(raw['errors']) + ([f'child exited with {code}: {child.tail()}'] if code
                                    else [])
    doc = {'benchmark': 'check_ab', 'machine': machine_info(), 'method': __doc__,
           'quick': quick, 'load_before': load_before, 'load_after': os.getloadavg()[0],
           'on_rate_hz': rate, 'node_params': raw.get('node_params', ''),
           'windows_s': {'quick': QUICK_WINDOW_S} if quick else WINDOW_S,
           'settle_s': QUICK_SETTLE_S if quick else SETTLE_S,
           'target': {'p50_share': P50_SHARE, 'p50_margin_ms': P50_MARGIN_MS,
                      'delivered_share': DELIVERED_SHARE},
           'sizes': raw['sizes'], 'verdicts': evaluate(raw['sizes']), 'errors': errors}
    if not errors:
        shutil.rmtree(log_dir, ignore_errors=True)
    write_json(Path(out_dir) / 'check_ab.json', doc)
    return doc


def main(argv: list[str] | None = None) -> int:
    """Run the A/B (or, with ``--child``, measure); print the tables; regenerate the docs."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--child', action='store_true', help='measure (internal)')
    parser.add_argument('--out-json', type=Path)
    parser.add_argument('--quick', action='store_true', help='tiny size, 1 s windows')
    parser.add_argument('--check-rate', type=float, default=None,
                        help="check.rate_hz of the 'on' windows (default: the schema's)")
    parser.add_argument('--node-params', default=None,
                        help="extra node parameters, 'name:=value ...'")
    parser.add_argument('--sizes', default=None, help='WxH,WxH (default: both sizes)')
    parser.add_argument('--out', type=Path, default=RESULTS, help='results folder')
    parser.add_argument('--no-docs', action='store_true',
                        help='do not regenerate docs/benchmarks.md and the README tables')
    args = parser.parse_args(argv)
    if args.child:
        sizes = [tuple(int(v) for v in s.split('x')) for s in args.sizes.split(',')
                 ] if args.sizes else None
        return child_main(args.quick, args.out_json, args.check_rate, sizes)
    doc = run(args.out, quick=args.quick, on_rate=args.check_rate, node_params=args.node_params,
              sizes=args.sizes)
    from benchmarks.report import check_ab_tables
    print('\n'.join(check_ab_tables(doc)))
    if not args.quick and not args.no_docs and Path(args.out).resolve() == RESULTS.resolve():
        from benchmarks.regenerate import regenerate, REPO
        regenerate(args.out, REPO / 'docs' / 'benchmarks.md')
    return 0 if not doc['errors'] else 1


if __name__ == '__main__':
    sys.exit(main())
