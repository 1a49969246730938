# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
What the straight-edge check (issue 26) costs the node's frames: check.rate_hz 0 vs on.

Per frame size (``--sizes``, default 1280x960 and 1920x1080), the fisheye config
(``config/fisheye.yaml``, sensor size set to the frame's) corrects mono8 frames of a rendered
grid (test/check_scenes.py, the axis 16 px off so that the check has edges and work), the
publisher in this process paced at ``--rate`` Hz (an absolute schedule) for ``--seconds``.
Three processes are measured one after the other: the **relay**
(:mod:`benchmarks.passthrough_node`, the same transport and QoS, no correction), the node
with ``check.rate_hz`` 0 (**off**) and with ``--check-rate`` (**on**). Latency = receive time
- ``header.stamp`` (the stamp set just before publishing, both in this process: one hop there
and one back). Reported per run: frames sent and delivered (%), latency p50 / p99 (ms), the
node's RSS and its check child's (MiB, the largest of samples every second: psutil), the
node's own frame time (``frame_time_ms_mean`` of /diagnostics) and, with the check on, its
``check_ms_last`` and ``checks``.

The targets are :mod:`benchmarks.node_latency`'s, restated for this run: p50 <= relay p50 +
1.5 x the bare remap (a plain ``cv2.remap`` of the same frame with the node's maps at its
default threads, median of back-to-back calls, measured here before the runs), and >= 97 %
of the paced frames delivered. Each is reported met or missed with the check off and on, and
the load of the machine (1-minute load average) before and after. Short and indicative on a
shared machine; run with ``nice``; writes ``results/check_cost.json``::

    python -m benchmarks.check_cost [--rate 30] [--seconds 30] [--check-rate 0.2]
        [--sizes 1280x960,1920x1080]

With ``--ab`` it runs :mod:`benchmarks.check_ab` instead (issue 36: the node with its defaults
at 1280x720 and 1920x1080 rgb8, check off / on windows interleaved in one run, the verdict
against the target; part of ``make bench``): ``python -m benchmarks.check_cost --ab``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path
import statistics
import sys
import time
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TEST = REPO / 'test'
#: Latency target margin: relay p50 + LATENCY_REMAPS x the bare remap (node_latency's).
LATENCY_REMAPS = 1.5
#: Delivered fraction target of a paced camera (node_latency's).
DELIVERED_MIN = 0.97
#: An off phase of the phased run starts after WINDOW_S without CPU time of the check.
WINDOW_S = 0.3


def frame_and_remap(width: int, height: int) -> tuple[np.ndarray, dict[str, float]]:
    """Return the grid frame at a size and the bare remap time of the node's maps (ms)."""
    import cv2

    from benchmarks.common import time_ms
    from mechdeconv_ros.imaging.remap import Rectifier
    from mechdeconv_ros.model.model import build_model
    from mechdeconv_ros.schema.params import defaults, load_params_file, SPECS
    sys.path.insert(0, str(TEST))
    from check_scenes import grid, Lens
    lens = Lens('fisheye')
    lens.width, lens.height = width, height
    frame = grid(lens, (16.0, 12.0), 0.0, 0.0, 10.0)
    values = defaults()
    values.update(load_params_file(REPO / 'config' / 'fisheye.yaml'))
    values.update({'sensor.width_px': width, 'sensor.height_px': height})
    rect = Rectifier(build_model(values))
    dst = np.empty_like(frame)
    default = int(SPECS['remap_threads'].default)
    previous = cv2.getNumThreads()
    cv2.setNumThreads(default if default > 0 else -1)     # as correct_node does
    threads = cv2.getNumThreads()
    try:
        def remap() -> None:
            cv2.remap(frame, rect.map1, rect.map2, cv2.INTER_LINEAR, dst=dst,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        remap()
        samples = time_ms(remap, 100)
    finally:
        cv2.setNumThreads(previous)
    return frame, {'median_ms': statistics.median(samples), 'threads': threads}


def _rss_mib(pid: int) -> tuple[float, float | None]:
    """Return the RSS of a process and of its check child (None: none), MiB."""
    import psutil
    proc = psutil.Process(pid)
    child = [c for c in proc.children() if 'check_worker' in ' '.join(c.cmdline())]
    return (proc.memory_info().rss / 2 ** 20,
            child[0].memory_info().rss / 2 ** 20 if child else None)


def _check_stat(node_pid: int) -> Path | None:
    """
    Return the /proc stat file of what runs the checks (None: nothing).

    The check child, else the node's nice-19 thread (a node whose check is a thread).
    """
    import psutil
    for child in psutil.Process(node_pid).children():
        if 'check_worker' in ' '.join(child.cmdline()):
            return Path(f'/proc/{child.pid}/stat')
    for task in Path(f'/proc/{node_pid}/task').iterdir():
        stat = task / 'stat'
        if int(stat.read_text().rsplit(')', 1)[1].split()[16]) == 19:
            return stat
    return None


def _cpu_s(stat: Path | None) -> float | None:
    """Return the user + system CPU seconds of a /proc stat file (None: none or gone)."""
    try:
        fields = stat.read_text().rsplit(')', 1)[1].split()
    except (AttributeError, OSError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def _node_argv(kind: str, width: int, height: int, check_rate: float) -> list[str]:
    """Return the command of the relay or of the node."""
    sys.path.insert(0, str(TEST))
    from ros_helpers import node_command
    if kind == 'relay':     # named correct_node so that the test client talks to it
        return [sys.executable, '-m', 'benchmarks.passthrough_node', '--ros-args',
                '-r', '__node:=correct_node']
    return node_command(REPO / 'config' / 'fisheye.yaml', f'check.rate_hz:={check_rate}',
                        f'sensor.width_px:={width}', f'sensor.height_px:={height}',
                        'lazy_subscription:=false')


def _percentiles(lat_ms: np.ndarray) -> dict[str, float | None]:
    """Return p50 / p99 of latencies (ms)."""
    return {'latency_p50_ms': float(np.percentile(lat_ms, 50)) if lat_ms.size else None,
            'latency_p99_ms': float(np.percentile(lat_ms, 99)) if lat_ms.size else None}


def measure(kind: str, frame: np.ndarray, check_rate: float, rate: float, seconds: float,
            tmp: Path, phase_s: float = 0.0) -> dict[str, Any]:
    """
    Run one relay or node; return the measured figures.

    With ``phase_s`` > 0 (kind ``phases``), the node alternates ``check.rate_hz`` between 0
    and ``check_rate`` every ``phase_s`` seconds (10: checks back to back), so that frames
    with and without checks share the machine's load of the moment (:func:`_split_by_phase`;
    splitting by the check's CPU time instead selects the quiet moments, when a nice-19 check
    gets a core).
    """
    sys.path.insert(0, str(TEST))
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.parameter import Parameter
    from ros_helpers import BEST_EFFORT, make_image, next_domain_id, running_node
    from sensor_msgs.msg import Image
    height, width = frame.shape[:2]
    argv = _node_argv(kind, width, height, 0.0 if phase_s else check_rate)
    received: list[tuple[float, float]] = []     # (stamp, latency) in s
    diags: list[dict[str, str]] = []
    diag_times: list[float] = []
    rss: list[tuple[float, float | None]] = []
    switches: list[tuple[float, bool]] = []
    cpu: list[tuple[float, float | None]] = []     # (wall time, check CPU s) per publish
    stat = None
    with running_node(argv, next_domain_id(), tmp) as (proc, client):
        node, executor = client.node, client.executor
        pub = node.create_publisher(Image, 'image_raw', BEST_EFFORT)

        def got(msg: Any) -> None:
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            received.append((stamp, time.time() - stamp))

        node.create_subscription(Image, 'image_rect', got, BEST_EFFORT)
        node.create_subscription(
            DiagnosticArray, '/diagnostics',
            lambda m: (diag_times.append(time.time()),
                       diags.append({kv.key: kv.value for kv in m.status[0].values})), 10)
        msg = make_image(frame, 'mono8')
        client.spin_for(2.0)
        warm, period = 5.0, 1.0 / rate     # the first seconds build the maps: not measured
        start = next_t = next_rss = next_switch = time.monotonic() + warm
        sent = 0
        while next_t - start < seconds:
            while (now := time.monotonic()) < next_t:
                executor.spin_once(timeout_sec=next_t - now)
            wall = time.time_ns()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(wall, 10 ** 9)
            cpu.append((wall * 1e-9, _cpu_s(stat)))
            pub.publish(msg)
            sent += now >= start
            next_t = max(next_t + period, time.monotonic() - period)   # no bursts
            if now >= next_rss and now >= start:
                rss.append(_rss_mib(proc.pid))
                stat = _check_stat(proc.pid) if kind != 'relay' else None
                next_rss = now + 1.0
            if phase_s and now >= next_switch:
                on = not (switches and switches[-1][1])
                switches.append((time.time(), on))
                client.set_parameters_async(
                    Parameter('check.rate_hz', Parameter.Type.DOUBLE, check_rate if on else 0.0))
                next_switch = now + phase_s
        client.spin_for(1.0)
    first = time.time() - (time.monotonic() - start)    # wall time of the measurement start
    lat = np.array([r[1] for r in received if r[0] >= first - 0.5 * period]) * 1e3
    child = [r[1] for r in rss if r[1] is not None]
    last = diags[-1] if diags else {}
    out = {'kind': kind, 'width': width, 'height': height, 'check_rate_hz': check_rate,
           'rate_hz': rate, 'seconds': seconds, 'sent': sent, 'delivered': int(lat.size),
           'delivered_pct': 100.0 * lat.size / max(sent, 1), **_percentiles(lat),
           'node_rss_mib': max(r[0] for r in rss) if rss else None,
           'child_rss_mib': max(child) if child else None,
           'frame_time_ms_mean': last.get('frame_time_ms_mean'),
           'check_ms_last': last.get('check_ms_last'), 'checks': last.get('checks'),
           'verdict': last.get('verdict')}
    if phase_s:
        frame_ms = [(t - 0.5, float(d.get('frame_time_ms_mean', 'nan')))     # a 1 s mean
                    for t, d in zip(diag_times, diags)]
        out.update(_split_by_phase(received, cpu, switches, frame_ms))
    return out


def _split_by_phase(received: list[tuple[float, float]], cpu: list[tuple[float, float | None]],
                    switches: list[tuple[float, bool]],
                    frame_ms: list[tuple[float, float]]) -> dict[str, Any]:
    """
    Split the frames of a phased run into the on phases and the off phases (see measure).

    On: from 1 s after the switch on (the next check starts) to the switch off. Off: from
    the end of the check in progress at the switch off (the first ``WINDOW_S`` without CPU
    time of what runs checks) to the next switch on. Also the node's own frame time in each
    (the median of its 1 s means in /diagnostics, ``frame_ms`` = (mid time, mean ms)).
    """
    times = np.array([c[0] for c in cpu])
    used = np.array([np.nan if c[1] is None else c[1] for c in cpu])
    during, without, during_ms, without_ms = [], [], [], []
    ends = [s[0] for s in switches[1:]] + [float('inf')]
    for (t0, on), t1 in zip(switches, ends):
        lo = t0 + 1.0
        if not on:      # after the check in progress
            k = int(np.searchsorted(times, t0))
            while k < times.size:
                j = int(np.searchsorted(times, times[k] + WINDOW_S))
                if j >= times.size or used[j] == used[k]:
                    break
                k += 1
            lo = times[k] if k < times.size else float('inf')
        (during if on else without).extend(r[1] for r in received if lo <= r[0] < t1)
        (during_ms if on else without_ms).extend(
            ms for t, ms in frame_ms if lo + 0.5 <= t < t1 - 0.5 and math.isfinite(ms))
    out = {f'{name}_{key}': value
           for name, lat in (('during', during), ('without', without))
           for key, value in {'frames': len(lat),
                              **_percentiles(np.array(lat) * 1e3)}.items()}
    out['during_frame_time_ms'] = statistics.median(during_ms) if during_ms else None
    out['without_frame_time_ms'] = statistics.median(without_ms) if without_ms else None
    return out


def targets(runs: dict[str, dict[str, Any]], remap_ms: float) -> dict[str, Any]:
    """Return node_latency's targets for the runs of one size (met / missed)."""
    bound = runs['relay']['latency_p50_ms'] + LATENCY_REMAPS * remap_ms
    out: dict[str, Any] = {'p50_bound_ms': bound}
    for kind, key in (('off', ''), ('on', ''), ('phases', 'during_'), ('phases', 'without_')):
        run = runs.get(kind)
        if run is None or run.get(f'{key}latency_p50_ms') is None:
            continue
        name = f'{kind}_{key}'.rstrip('_')
        out[f'latency_{name}'] = 'met' if run[f'{key}latency_p50_ms'] <= bound else 'missed'
        if not key:
            out[f'delivered_{name}'] = ('met' if run['delivered_pct'] >= 100.0 * DELIVERED_MIN
                                        else 'missed')
    return out


def main() -> None:
    """Measure the relay and the node without and with the check; print JSON lines."""
    if '--ab' in sys.argv[1:]:      # the interleaved A/B of issue 36 (benchmarks.check_ab)
        from benchmarks import check_ab
        sys.exit(check_ab.main([a for a in sys.argv[1:] if a != '--ab']))
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--rate', type=float, default=30.0)
    parser.add_argument('--seconds', type=float, default=30.0)
    parser.add_argument('--check-rate', type=float, default=0.2)
    parser.add_argument('--sizes', default='1280x960,1920x1080')
    parser.add_argument('--kinds', default='relay,off,on,phases',
                        help='the runs (comma-separated)')
    parser.add_argument('--phase', type=float, default=8.0,
                        help='seconds of each state of the phased run')
    parser.add_argument('--phase-check-rate', type=float, default=10.0,
                        help='check.rate_hz in the on phases (10: checks back to back)')
    parser.add_argument('--tmp', type=Path, default=Path('/tmp/mechdeconv_check_cost'))
    parser.add_argument('--out', type=Path, default=REPO / 'results' / 'check_cost.json')
    args = parser.parse_args()
    args.tmp.mkdir(parents=True, exist_ok=True)
    doc: dict[str, Any] = {'date': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()),
                           'load_before': os.getloadavg()[0], 'cpus': os.cpu_count(),
                           'sizes': {}}
    for size in args.sizes.split(','):
        width, height = (int(v) for v in size.split('x'))
        frame, remap = frame_and_remap(width, height)
        plan = {'relay': (0.0, 0.0), 'off': (0.0, 0.0), 'on': (args.check_rate, 0.0),
                'phases': (args.phase_check_rate, args.phase)}
        runs = {kind: measure(kind, frame, check_rate, args.rate, args.seconds, args.tmp, phase)
                for kind, (check_rate, phase) in plan.items() if kind in args.kinds.split(',')}
        for run in runs.values():
            print(json.dumps(run), flush=True)
        doc['sizes'][size] = {'bare_remap': remap, 'runs': runs}
        if 'relay' in runs:
            doc['sizes'][size]['targets'] = targets(runs, remap['median_ms'])
            print(json.dumps({size: doc['sizes'][size]['targets']}), flush=True)
    doc['load_after'] = os.getloadavg()[0]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + '\n')


if __name__ == '__main__':
    main()
