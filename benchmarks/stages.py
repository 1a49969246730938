# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Where one frame's time goes: the relay, then correct_node's work added stage by stage.

One run, 30 Hz rgb8 frames at 1280x720 and 1920x1080, the shared-memory Fast DDS profile and
the Makefile's malloc settings in every process (a child benchmark process per run, as in
:mod:`benchmarks.node_latency`, whose publisher and probe it uses). For each frame size, in
interleaved rounds (the order of the rungs reverses every round), each rung of
:mod:`benchmarks.passthrough_node` (``relay``, ``copy``, ``remap``, ``info``, ``info_rect``:
each adds one of correct_node's stages, with the node's code), ``correct_node`` itself and
the side rung ``remap_fixed`` (``remap`` with fixed-point maps: the map form is chosen on
what it costs in a running relay, caches shared between frames) run one at a time between
the same publisher and probe, every process with
``MECHDECONV_STAGE_TIMES`` set (:mod:`mechdeconv_ros.node.stage_clock`):

* **receive** = callback entry - ``header.stamp`` (publisher's wall clock at publish): the
  publish, the transport, the executor's wait and take, rclpy's conversion;
* **read**, **model**, **copy** / **remap**, **publish_image**, **publish_info**,
  **publish_info_rect**, **bookkeeping**: the stage clock's marks in the callback (the node's
  ``model`` stage is the live model's reference read and the output pool);
* **out hop** = probe receive - the wall clock when ``publish(image)`` returned;
* **p50** = probe receive - stamp (two hops, as node_latency), median over the window;
* **CPU ms / frame** of the relay process per thread (``/proc/PID/task``): the executor
  (main) thread, the rebuild and summary threads (named by
  :func:`mechdeconv_ros.runtime.live_model.name_native_thread`), and every other thread (OpenCV's
  workers, Fast DDS's) over the window.

Stage values are medians over the window's frames (so the stages need not add up to the p50
exactly), taken in the round with the fewest cores used by other processes. The bare remap
is a plain ``cv2.remap`` of the same frame with the node's maps (``Rectifier.map1/map2``,
bilinear, the node's default threads), median of back-to-back calls in the child before the
ROS processes start, with ``Rectifier.correct`` interleaved for comparison.

Target (same run): node p50 <= relay p50 + 1.5 x bare remap.

::

    python -m benchmarks.stages [--quick] [--out results]
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

from benchmarks.common import LoadMonitor, log, RESULTS
from benchmarks.node_latency import (
    announcing_probe, latency_stats, node_argv, node_remap, Probe, publisher_argv, ros_env,
    start_child)
from benchmarks.report import (
    fmt_ms, fmt_num, machine_info, machine_line, markdown_table, verdict, write_json)
from mechdeconv_ros.node.process_env import Child, pick_domain_id
from mechdeconv_ros.node.stage_clock import ENV as STAGE_ENV

SIZES = ((1280, 720), (1920, 1080))
QUICK_SIZES = ((320, 240),)
RATE_HZ = 30.0
RUNGS = ('relay', 'copy', 'remap', 'info', 'info_rect', 'node', 'remap_fixed')
#: Column titles of the rungs.
RUNG_TITLES = {'relay': 'relay', 'copy': '+ read, copy', 'remap': '+ remap (no copy)',
               'info': '+ camera_info', 'info_rect': '+ camera_info_rect',
               'node': 'correct_node', 'remap_fixed': 'remap, fixed-point maps (side)',
               'baseline': 'baseline correct_node'}
#: Row order of the stages (a rung without a stage shows '-').
STAGES = ('receive', 'read', 'model', 'copy', 'remap', 'publish_image', 'out_hop',
          'publish_info', 'publish_info_rect', 'bookkeeping')
STAGE_TITLES = {'receive': 'receive (stamp -> callback)', 'read': 'read (pixels view)',
                'model': 'model + output message', 'copy': 'copy into the message',
                'remap': 'remap', 'publish_image': 'publish image_rect',
                'out_hop': 'out hop (publish -> probe)', 'publish_info': 'publish camera_info',
                'publish_info_rect': 'publish camera_info_rect',
                'bookkeeping': 'bookkeeping (counters, hints)'}
ROUNDS = 2
WINDOW_S = 4.0
WARMUP_S = 1.0
READY_TIMEOUT_S = 20.0
LATENCY_REMAP_FACTOR = 1.5
CHILD_TIMEOUT_S = 900.0


# ---------------------------------------------------------------------------------------------
# Measuring (the child process)
# ---------------------------------------------------------------------------------------------

def bare_remap(width: int, height: int, reps: int, idle_s: float = 1.0 / RATE_HZ
               ) -> dict[str, Any]:
    """
    Time a plain ``cv2.remap`` with the node's maps (and ``Rectifier.correct``), interleaved.

    Back to back at the node's default threads (the target's bare remap), and, to tell the
    in-situ remap's extra time apart, after ``idle_s`` of sleep (as between frames: OpenCV's
    workers asleep, caches shared with whatever ran meanwhile) at the default threads and at
    one thread, and back to back at one thread.

    :param width: frame width.
    :param height: frame height.
    :param reps: calls of each back-to-back variant (a third of that for the idle ones).
    :param idle_s: the sleep before each idle call, s.
    :return: ``{variant: {'median_ms', 'min_ms'}}``, and the default OpenCV threads.
    """
    import cv2

    rect, src, dst, remap, node_threads = node_remap(width, height)
    previous = cv2.getNumThreads()
    cv2.setNumThreads(node_threads)
    threads = cv2.getNumThreads()

    # (name, call, OpenCV threads, sleep before each call)
    variants = (('cv2_remap', remap, threads, 0.0),
                ('rectifier_correct', lambda: rect.correct(src, dst), threads, 0.0),
                ('cv2_remap_1t', remap, 1, 0.0),
                ('cv2_remap_idle', remap, threads, idle_s),
                ('cv2_remap_1t_idle', remap, 1, idle_s))
    samples: dict[str, list[float]] = {name: [] for name, *_ in variants}
    try:
        remap()
        for index in range(reps):
            for name, call, count, sleep_s in variants:
                if sleep_s and index % 3:
                    continue
                cv2.setNumThreads(count)
                if sleep_s:
                    time.sleep(sleep_s)
                else:
                    call()              # warm after the switch of variant
                start = time.perf_counter()
                call()
                samples[name].append((time.perf_counter() - start) * 1e3)
    finally:
        cv2.setNumThreads(previous)
    out: dict[str, Any] = {'threads': threads, 'reps': reps, 'idle_s': idle_s}
    for name, values_ms in samples.items():
        out[name] = {'median_ms': statistics.median(values_ms), 'min_ms': min(values_ms)}
    return out


def frame_traffic(width: int, height: int, reps: int = 5) -> dict[str, Any]:
    """
    Return the bytes each rung moves per output frame in its callback, and the DRAM floor.

    Counted on the Python side of the frame path (what the callback reads and writes; the
    transport's own copies, rclpy's conversions and Fast DDS's, are the relay's and every
    rung's alike): the source frame read, the output written, and the maps read, at their
    form in the rung (``remap``, ``info``, ``info_rect`` and ``correct_node``: the node's maps;
    ``remap_fixed``: CV_16SC2 + CV_16UC1, 6 bytes per output pixel). ``copy`` reads the frame
    and writes the message. The floor is those bytes at the cold copy bandwidth measured here
    (``np.copyto`` of a frame after a 64 MiB pass evicts the caches, median of ``reps``).

    :param width: frame width.
    :param height: frame height.
    :param reps: cold copies timed.
    :return: ``{'bytes': {rung: bytes}, 'map_bytes': {...}, 'cold_copy_gb_s', 'floor_ms'}``.
    """
    import cv2
    import numpy as np

    rect, src, dst, _, _ = node_remap(width, height)
    fixed = cv2.convertMaps(rect.map1, rect.map2, cv2.CV_16SC2)
    maps = {'node': rect.map1.nbytes + rect.map2.nbytes,
            'fixed': fixed[0].nbytes + fixed[1].nbytes}
    frame = src.nbytes + dst.nbytes
    flush = np.ones(64 << 20, np.uint8)
    times = []
    for _ in range(reps):
        flush += 1
        start = time.perf_counter()
        np.copyto(dst, src)
        times.append(time.perf_counter() - start)
    gb_s = frame / statistics.median(times) / 1e9
    moved = {'relay': 0, 'copy': frame, 'remap': frame + maps['node'],
             'info': frame + maps['node'], 'info_rect': frame + maps['node'],
             'node': frame + maps['node'], 'remap_fixed': frame + maps['fixed']}
    return {'bytes': moved, 'map_bytes': maps, 'frame_bytes': frame, 'cold_copy_gb_s': gb_s,
            'floor_ms': {rung: b / gb_s / 1e6 for rung, b in moved.items()}}


def thread_cpu_s(pid: int) -> dict[int, tuple[str, float]]:
    """
    Return ``{tid: (name, CPU seconds)}`` of a process's threads (``/proc/PID/task``).

    :param pid: the process.
    :return: the threads alive now (empty when the process is gone).
    """
    tick = os.sysconf('SC_CLK_TCK')
    out = {}
    try:
        tids = os.listdir(f'/proc/{pid}/task')
    except OSError:
        return out
    for tid in tids:
        try:
            with open(f'/proc/{pid}/task/{tid}/stat', encoding='ascii',
                      errors='replace') as stream:
                text = stream.read()
        except OSError:
            continue
        name = text[text.index('(') + 1:text.rindex(')')]
        fields = text[text.rindex(')') + 2:].split()
        out[int(tid)] = (name, (int(fields[11]) + int(fields[12])) / tick)
    return out


def thread_groups(pid: int, before: Mapping[int, tuple[str, float]],
                  after: Mapping[int, tuple[str, float]]) -> dict[str, float]:
    """
    Return the CPU seconds between two snapshots by group: main, rebuild/summary, others.

    :param pid: the process (its main thread's tid).
    :param before: :func:`thread_cpu_s` at the start.
    :param after: :func:`thread_cpu_s` at the end.
    :return: ``{'main': s, 'model threads': s, 'other threads': s}`` and per other name.
    """
    groups: dict[str, float] = {'main': 0.0, 'model threads': 0.0, 'other threads': 0.0}
    for tid, (name, cpu) in after.items():
        used = cpu - before.get(tid, (name, 0.0))[1]
        if tid == pid:
            groups['main'] += used
        elif name.startswith('mechdeconv'):
            groups['model threads'] += used
        else:
            groups['other threads'] += used
            key = f'thread {name}'
            groups[key] = groups.get(key, 0.0) + used
    return groups


def _rung_argv(rung: str, baseline: str = '') -> list[str]:
    if rung == 'node':
        return node_argv('node')
    if rung == 'baseline':
        # correct_node of another checkout (its path first on sys.path, before the cwd).
        return [sys.executable, '-c', f'import sys; sys.path.insert(0, {baseline!r}); '
                'from mechdeconv_ros.node.correct_node import main; main()'] \
            + node_argv('node')[3:]
    return [sys.executable, '-m', 'benchmarks.passthrough_node', '--upto', rung]


def _median(values: Sequence[float]) -> float:
    return statistics.median(values) if values else math.nan


def measure_rung(probe: Probe, rung: str, width: int, height: int, env: Mapping[str, str],
                 log_dir: Path, window_s: float, warmup_s: float, tag: str,
                 baseline: str = '', shared_pub: Child | None = None) -> dict[str, Any]:
    """
    Run one rung between the publisher and the probe for one window; return its figures.

    :param shared_pub: a running 30 Hz publisher of this size to use (and leave running);
        None: start one for this rung and stop it after the window.
    :return: p50 latency, fps, stage medians, CPU per frame by thread group, exit codes.
    """
    stage_file = log_dir / f'stages_{tag}.json'
    env = dict(env, **{STAGE_ENV: str(stage_file)})
    result: dict[str, Any] = {'rung': rung, 'size': f'{width}x{height}', 'errors': []}
    relay = start_child(_rung_argv(rung, baseline), env, log_dir, f'{rung}_{tag}')
    # The publisher starts while the relay does (its frames before the relay subscribes are
    # simply not received): the two start-ups overlap instead of adding up.
    pub = shared_pub or start_child(publisher_argv(width, height, RATE_HZ), env, log_dir,
                                    f'pub_{tag}')
    try:
        if not probe.ready(READY_TIMEOUT_S):
            result['errors'].append(f'{rung}: not ready: {relay.tail()}')
            return result
        probe.first_frame(6.0)
        probe.spin_for(warmup_s)
        cpu0 = thread_cpu_s(relay.pid)
        monitor = LoadMonitor(lambda: time.process_time() + relay.cpu_s() + pub.cpu_s())
        wall0, start_ns = time.monotonic(), time.time_ns()
        frames = probe.measure(window_s)
        wall = time.monotonic() - wall0
        end_ns = time.time_ns()
        cpu1 = thread_cpu_s(relay.pid)
        result.update(latency_stats(frames, window_s, (start_ns, end_ns)))
        result['others_cores'] = monitor.others_cores()
        result['wall_s'] = wall
        delivered = max(1, len(frames))
        result['cpu_ms_per_frame'] = {k: v * 1e3 / delivered
                                      for k, v in thread_groups(relay.pid, cpu0, cpu1).items()}
    finally:
        for proc in (pub, relay):
            if proc is not shared_pub:
                code = proc.stop()
                if code != 0 or proc.killed:
                    result['errors'].append(f'{proc.name} exited with {code}: {proc.tail()}')
    try:
        stage_frames = json.loads(stage_file.read_text())['frames']
    except (OSError, ValueError, KeyError):
        if rung != 'baseline':          # another checkout may predate the stage clock
            result['errors'].append(f'{rung}: no stage times written')
        stage_frames = []
    received = {stamp: recv for recv, stamp in frames}
    window = [f for f in stage_frames if f['stamp_ns'] in received]
    stages: dict[str, float] = {}
    for stage in STAGES:
        if stage == 'out_hop':     # may be < 0: the probe can wake before publish() returns
            values = [(received[f['stamp_ns']] - f['image_out_ns']) * 1e-6
                      for f in window if 'image_out_ns' in f]
        else:
            values = [f[stage] for f in window if stage in f]
        if values:
            stages[stage] = _median(values)
    result['stages'] = stages
    result['stage_frames'] = len(window)
    return result


def child_main(quick: bool, out_json: Path, baseline: str = '',
               only: Sequence[str] = RUNGS) -> int:
    """Measure the rungs at every size (this process has the shm profile)."""
    sizes = QUICK_SIZES if quick else SIZES
    rungs = tuple(only) + (('baseline',) if baseline else ())
    rounds, window_s, warmup_s = (1, 0.6, 0.2) if quick else (ROUNDS, WINDOW_S, WARMUP_S)
    env = dict(os.environ)
    doc: dict[str, Any] = {'bare_remap': {}, 'traffic': {}, 'runs': [], 'errors': []}
    log_dir = Path(tempfile.mkdtemp(prefix='mechdeconv_bench_stages_'))
    doc['log_dir'] = str(log_dir)
    # Quick: the probe first (its first seconds pass during the bare remap), announcing often
    # (node_latency.announcing_probe: each rung's start-up waited 0-3 s for discovery).
    early_probe = (announcing_probe(int(env['ROS_DOMAIN_ID']), log_dir, name='stage_probe')
                   if quick else None)
    for width, height in sizes:
        doc['bare_remap'][f'{width}x{height}'] = bare_remap(width, height, 6 if quick else 90)
        doc['traffic'][f'{width}x{height}'] = frame_traffic(width, height, 3 if quick else 15)
    probe = early_probe or Probe(int(env['ROS_DOMAIN_ID']), name='stage_probe')
    shared_pub: Child | None = None
    try:
        for width, height in sizes:
            if quick:
                # One publisher for every rung (the full run starts one per rung): a
                # start-up and a stop less per rung.
                shared_pub = start_child(publisher_argv(width, height, RATE_HZ), env,
                                         log_dir, f'pub_{width}x{height}')
            for index in range(rounds):
                order = rungs if index % 2 == 0 else tuple(reversed(rungs))
                for rung in order:
                    tag = f'{width}x{height}_{rung}_{index}'
                    result = measure_rung(probe, rung, width, height, env, log_dir, window_s,
                                          warmup_s, tag, baseline, shared_pub)
                    result['round'] = index
                    doc['runs'].append(result)
                    doc['errors'] += result['errors']
                    log(f"stages {result['size']} {rung:9s} round {index}: "
                        f"{result.get('fps', math.nan):.1f} fps, p50 "
                        f"{result.get('p50_ms', math.nan):.2f} ms, stages "
                        + ', '.join(f'{k} {v:.2f}' for k, v in result['stages'].items())
                        + f", others {result.get('others_cores', math.nan):.2f} cores")
            if shared_pub is not None:
                code = shared_pub.stop()
                if code != 0 or shared_pub.killed:
                    doc['errors'].append(f'{shared_pub.name} exited with {code}: '
                                         f'{shared_pub.tail()}')
                shared_pub = None
    finally:
        if shared_pub is not None:
            shared_pub.stop()
        probe.close()
        write_json(out_json, doc)
    return 0


# ---------------------------------------------------------------------------------------------
# The benchmark (parent)
# ---------------------------------------------------------------------------------------------

def best_runs(runs: Sequence[Mapping[str, Any]]) -> dict[tuple[str, str], Mapping[str, Any]]:
    """Return, per (size, rung), the round with the fewest cores used by others."""
    best: dict[tuple[str, str], Mapping[str, Any]] = {}
    for run in runs:
        if 'p50_ms' not in run:
            continue
        key = (run['size'], run['rung'])
        if key not in best or run['others_cores'] < best[key]['others_cores']:
            best[key] = run
    return best


def evaluate(doc: Mapping[str, Any]) -> dict[str, Any]:
    """Return, per size, the latency target and the node's excess over the relay by stage."""
    best = best_runs(doc['runs'])
    out: dict[str, Any] = {}
    for size, bare in doc['bare_remap'].items():
        relay, node = best.get((size, 'relay')), best.get((size, 'node'))
        remap_ms = bare['cv2_remap']['median_ms']
        entry: dict[str, Any] = {'bare_remap_ms': remap_ms,
                                 'rectifier_correct_ms': bare['rectifier_correct']['median_ms']}
        if relay and node:
            target = relay['p50_ms'] + LATENCY_REMAP_FACTOR * remap_ms
            entry.update({'relay_p50_ms': relay['p50_ms'], 'node_p50_ms': node['p50_ms'],
                          'latency_target_ms': target,
                          'latency_met': node['p50_ms'] <= target,
                          'node_over_relay_ms': node['p50_ms'] - relay['p50_ms'],
                          'excess_over_remap_ms': node['p50_ms'] - relay['p50_ms'] - remap_ms})
        out[size] = entry
    return out


def run(out_dir: Path = RESULTS, quick: bool = False, baseline: str = '',
        only: Sequence[str] = RUNGS) -> dict[str, Any]:
    """
    Run the stage benchmark in a child process; write ``stages.json`` into ``out_dir``.

    :param out_dir: results folder.
    :param quick: one small size, one round, 0.6 s windows, one publisher for every rung.
    :param baseline: a checkout of the repository whose correct_node runs as one more rung,
        ``baseline`` (before/after comparisons in one run; its stages are timed only if it
        has the stage clock).
    :param only: the rungs to run (default all).
    :return: the results document.
    """
    log_dir = Path(tempfile.mkdtemp(prefix='mechdeconv_bench_stages_parent_'))
    out_json = log_dir / 'stages_child.json'
    argv = [sys.executable, '-m', 'benchmarks.stages', '--child', '--out-json', str(out_json)]
    if quick:
        argv.append('--quick')
    if baseline:
        argv += ['--baseline', str(Path(baseline).resolve())]
    argv += ['--rungs', ','.join(only)]
    child = start_child(argv, ros_env(pick_domain_id('benchmarks', 91), 'shm'), log_dir,
                        'child_stages')
    start = time.monotonic()
    while child.running() and time.monotonic() - start < CHILD_TIMEOUT_S:
        time.sleep(0.2)
    code = child.stop()
    errors = [] if code == 0 else [f'stage child exited with {code}: {child.tail()}']
    measured: dict[str, Any] = {'bare_remap': {}, 'runs': [], 'errors': []}
    if out_json.exists():
        measured = json.loads(out_json.read_text())
    errors += measured.get('errors', [])
    sys.stderr.write(child.stderr())
    if not errors:
        shutil.rmtree(measured.get('log_dir', ''), ignore_errors=True)
        shutil.rmtree(log_dir, ignore_errors=True)
    doc = {'benchmark': 'stages', 'machine': machine_info(), 'method': __doc__,
           'load_average_1min': os.getloadavg()[0], 'rate_hz': RATE_HZ,
           'rungs': list(only) + (['baseline'] if baseline else []),
           'stages': list(STAGES), 'bare_remap': measured['bare_remap'],
           'traffic': measured.get('traffic', {}),
           'runs': measured['runs'], 'errors': errors}
    doc['targets'] = evaluate(doc)
    write_json(out_dir / 'stages.json', doc)
    return doc


# ---------------------------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------------------------

def tables(doc: Mapping[str, Any]) -> list[str]:
    """Return the markdown: one stage table per frame size, and the latency target."""
    best = best_runs(doc['runs'])
    rungs = [r for r in doc['rungs'] if any(k[1] == r for k in best)]
    lines = ["### Where a frame's time goes (stage by stage, 30 Hz rgb8, shm profile)", '',
             "Each column adds one of correct_node's stages to a Python relay (single-"
             'threaded executor, same QoS and profile), the last is correct_node itself; rows '
             'are median ms per frame of the stage clock (MECHDECONV_STAGE_TIMES), '
             '"receive" = callback entry - publish stamp, "out hop" = image publish -> '
             "probe receive; p50 = end to end (two hops); CPU = the relay process's CPU per "
             'delivered frame by thread. Of the rounds (rungs interleaved, order reversed '
             'each round) the one with the fewest cores used by other processes is shown.',
             '']
    for size in doc['bare_remap']:
        cols = [best.get((size, r)) for r in rungs]
        if not any(cols):
            continue
        relay = best.get((size, 'relay'))
        node = best.get((size, 'node'))
        rows = []
        for stage in doc['stages']:
            vals = [c['stages'].get(stage) if c else None for c in cols]
            if all(v is None for v in vals):
                continue
            diff = None
            if relay and node:
                diff = node['stages'].get(stage, 0.0) - relay['stages'].get(stage, 0.0)
            rows.append([STAGE_TITLES.get(stage, stage)] + [fmt_ms(v) for v in vals]
                        + [fmt_ms(diff)])

        def row(title: str, key: str, cpu: str | None = None) -> list[str]:
            vals = [(c['cpu_ms_per_frame'].get(cpu) if cpu else c.get(key)) if c else None
                    for c in cols]
            at = rungs.index('node') if 'node' in rungs else -1
            diff = (vals[at] - vals[0]) if (relay and node and vals[0] is not None
                                            and vals[at] is not None) else None
            return [title] + [fmt_ms(v) for v in vals] + [fmt_ms(diff)]

        rows.append(row('**latency p50** (end to end)', 'p50_ms'))
        rows.append(row('latency p99', 'p99_ms'))
        rows.append(row('CPU ms/frame, executor (main) thread', '', 'main'))
        rows.append(row('CPU ms/frame, rebuild + summary threads', '', 'model threads'))
        rows.append(row('CPU ms/frame, other threads (OpenCV, Fast DDS)', '', 'other threads'))
        traffic = doc.get('traffic', {}).get(size)
        if traffic:
            moved = [traffic['bytes'].get(r) for r in rungs]
            floor = [traffic['floor_ms'].get(r) for r in rungs]
            rows.append(['memory traffic, MB/frame (frame + maps, callback)']
                        + [fmt_num(b / 1e6 if b is not None else None, 1) for b in moved]
                        + ['-'])
            rows.append(['  at the cold copy bandwidth, ms'] + [fmt_ms(f) for f in floor]
                        + ['-'])
        rows.append(['delivered fps'] + [fmt_num(c.get('fps')) if c else '-' for c in cols]
                    + ['-'])
        rows.append(['others cores (machine load)'] + [fmt_num(c.get('others_cores'), 2)
                                                       if c else '-' for c in cols] + ['-'])
        bare = doc['bare_remap'][size]
        lines += [f"**{size}**: bare remap (plain cv2.remap with the node's maps, "
                  f"{bare['threads']} threads, back to back) "
                  f"{fmt_ms(bare['cv2_remap']['median_ms'])} ms median; Rectifier.correct "
                  f"{fmt_ms(bare['rectifier_correct']['median_ms'])} ms; 1 thread "
                  f"{fmt_ms(bare.get('cv2_remap_1t', {}).get('median_ms'))} ms; after "
                  f"{bare.get('idle_s', 0) * 1e3:.0f} ms idle (as between frames) "
                  f"{fmt_ms(bare.get('cv2_remap_idle', {}).get('median_ms'))} ms, at 1 "
                  f"thread {fmt_ms(bare.get('cv2_remap_1t_idle', {}).get('median_ms'))} ms."
                  + _traffic_note(doc.get('traffic', {}).get(size)), '']
        lines += markdown_table(['stage, ms'] + [RUNG_TITLES[r] for r in rungs]
                                + ['node - relay'], rows)
        lines.append('')
    rows = []
    for size, t in doc.get('targets', {}).items():
        if 'node_p50_ms' not in t:
            continue
        rows.append([size, fmt_ms(t['relay_p50_ms']), fmt_ms(t['bare_remap_ms']),
                     fmt_ms(t['node_p50_ms']),
                     f"<= {fmt_ms(t['latency_target_ms'])}: {verdict(t['latency_met'])}",
                     fmt_ms(t['excess_over_remap_ms'])])
    if rows:
        lines += ['Latency target, same run: node p50 <= relay p50 + '
                  f'{LATENCY_REMAP_FACTOR:g} x bare remap.', '']
        lines += markdown_table(['frame', 'relay p50 ms', 'bare remap ms', 'node p50 ms',
                                 'target', 'node - relay - remap ms'], rows)
    if doc.get('errors'):
        lines += ['', 'Errors: ' + '; '.join(e.splitlines()[0] for e in doc['errors'])]
    lines += ['', f"Machine: {machine_line(doc['machine'])}; 1-minute load average "
              f"{doc.get('load_average_1min', math.nan):.2f}.", '']
    return lines


def _traffic_note(traffic: Mapping[str, Any] | None) -> str:
    """Return the sentence on the frame's memory traffic (empty without the figures)."""
    if not traffic:
        return ''
    maps = traffic['map_bytes']
    return (f" Memory traffic: the frame in + out {traffic['frame_bytes'] / 1e6:.1f} MB, the "
            f"node's maps {maps['node'] / 1e6:.1f} MB (fixed point {maps['fixed'] / 1e6:.1f} "
            f"MB); cold copy bandwidth {traffic['cold_copy_gb_s']:.1f} GB/s, so the node's "
            f"remap cannot take less than {traffic['floor_ms']['node']:.2f} ms from memory.")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (or its child) and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--child', action='store_true', help='measure (in the shm env)')
    parser.add_argument('--out-json', type=Path)
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--out', type=Path, default=RESULTS, help='results folder')
    parser.add_argument('--baseline', default='',
                        help="another checkout's correct_node as one more rung")
    parser.add_argument('--rungs', default=','.join(RUNGS),
                        help='comma-separated subset of: ' + ', '.join(RUNGS))
    args = parser.parse_args(argv)
    only = tuple(r for r in args.rungs.split(',') if r)
    if any(r not in RUNGS for r in only):
        parser.error(f'unknown rung in {only}')
    if args.child:
        return child_main(args.quick, args.out_json, args.baseline, only)
    doc = run(args.out, quick=args.quick, baseline=args.baseline, only=only)
    print('\n'.join(tables(doc)))
    return 0 if not doc['errors'] else 1


if __name__ == '__main__':
    sys.exit(main())
