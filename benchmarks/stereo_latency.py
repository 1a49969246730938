# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
stereo_node end to end: pair latency at 30 Hz against a relay of two streams (issue 38, item 8).

Processes (all with :func:`mechdeconv_ros.node.process_env.graph_env`, the package's Fast DDS
profile, a private ``ROS_DOMAIN_ID``; the measuring child is a process of its own because
Fast DDS reads its profile once per process):

* a **publisher** (``--role publisher``): two prebuilt rgb8 Images, ``left/image_raw`` and
  ``right/image_raw``, stamped with the same wall-clock time just before each pair, paced at
  30 Hz;
* under test, in turn: the **relay** (``python -m benchmarks.passthrough_node --stereo``:
  both streams republished as received, same QoS, one process), **stereo_node** with
  config/stereo.yaml (2 x 1280x720, the check off: ``stereo_check.rate_hz`` 0) and
  **stereo_node with its check** at its default rate (``stereo_check.rate_hz`` 0.2, the
  idle-time child);
* the **probe** in the measuring child: ``left/image_rect`` and ``right/image_rect`` as raw CDR
  (only the stamp is read). A pair's latency is the later of its two receive times minus the
  stamp.

The bare remap time is ``StereoRectifier.rectify`` of the pair (two ``cv2.remap``, bilinear,
float maps, OpenCV's default threads) into preallocated outputs, median of back-to-back
calls, in the child before the ROS processes start.

Target (the single node's, doubled): stereo_node's p50 <= the relay's p50 + 1.5 x the two bare
remaps (:func:`evaluate`: the ratio ``(p50_node - p50_relay) / two_remaps`` <= 1.5), all from
one run. The check "never costs a frame": the pairs per second delivered with the check at
its default rate against without it (share of the published pairs), and the p50 difference.
Timings are only meaningful on a quiet machine.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import shutil
import signal
import statistics
import struct
import sys
import tempfile
import time
from typing import Any, Sequence

from benchmarks.common import log, RESULTS
from benchmarks.node_latency import latency_stats, paced_publish, ros_env, start_child
from benchmarks.report import machine_info, stereo_tables, write_json
from mechdeconv_ros.node.process_env import Child, pick_domain_id
from mechdeconv_ros.schema.stereo_params import stereo_defaults

REPO = Path(__file__).resolve().parents[1]
STEREO_YAML = REPO / 'config' / 'stereo.yaml'
SIZE = (1280, 720)
QUICK_SIZE = (320, 240)
RATE_HZ = 30.0
WINDOW_S = 6.0
#: The stereo check's rate in the 'with its check' run: the default a user gets.
CHECK_RATE_HZ = float(stereo_defaults()['stereo_check.rate_hz'])
QUICK_WINDOW_S = 1.0
WARMUP_S = 1.5
READY_TIMEOUT_S = 90.0
CHILD_TIMEOUT_S = 600.0
#: The latency target: p50 within the relay's + this many times the two bare remaps.
TARGET_REMAPS = 1.5
#: The kinds measured, in order.
KINDS = ('relay', 'stereo', 'stereo_check')
#: What the probe reads of the node's check from /diagnostics.
CHECK_KEYS = ('stereo_checks', 'stereo_check_ms_last', 'verdict', 'matches')


def node_argv(kind: str, size: tuple[int, int]) -> list[str]:
    """
    Return the command of the process under test.

    :param kind: one of :data:`KINDS`.
    :param size: the raw frames' size (both cameras).
    :return: argv.
    """
    if kind == 'relay':
        return [sys.executable, '-m', 'benchmarks.passthrough_node', '--stereo']
    argv = [sys.executable, '-c', 'from mechdeconv_ros.node.entry import stereo_node; '
            'stereo_node()', '--ros-args', '--params-file', str(STEREO_YAML),
            '-p', f"stereo_check.rate_hz:={CHECK_RATE_HZ if kind == 'stereo_check' else 0.0}"]
    if size != SIZE:
        for side in ('left', 'right'):
            argv += ['-p', f'{side}.sensor.width_px:={size[0]}',
                     '-p', f'{side}.sensor.height_px:={size[1]}']
    return argv


def publisher_main(width: int, height: int, rate_hz: float) -> int:
    """Publish a prebuilt rgb8 pair on ``left/`` and ``right/image_raw`` until SIGINT."""
    import threading

    import numpy as np
    import rclpy
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import Image

    from mechdeconv_ros.node.frame_input import sensor_qos
    from mechdeconv_ros.node.image_msgs import new_output_image

    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Node('bench_stereo_camera')
    import cv2
    # A textured scene (blurred noise), the right view shifted by 8 px: the check finds
    # thousands of matches, so its cost on the frames is a real one.
    rng = np.random.default_rng(0)
    texture = cv2.GaussianBlur(rng.integers(0, 256, (height, width + 8, 3), dtype=np.uint8),
                               (0, 0), 1.5)
    sides = []
    for k, side in enumerate(('left', 'right')):
        out = new_output_image(width, height, 'rgb8')
        out.pixels[...] = texture[:, 8 * k:8 * k + width]
        out.msg.header.frame_id = f'bench_{side}_optical_frame'
        sides.append((node.create_publisher(Image, f'{side}/image_raw', sensor_qos()), out.msg))

    class Both:
        """Publish the pair with one stamp (the left message's)."""

        def publish(self, _: Any) -> None:
            sides[1][1].header.stamp = sides[0][1].header.stamp
            for pub, msg in sides:
                pub.publish(msg)

    count, seconds = paced_publish(Both(), sides[0][1], rate_hz, stop)
    print(json.dumps({'published': count, 'seconds': seconds}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


class PairProbe:
    """Subscriber of both rectified images on the benchmark's domain."""

    def __init__(self, domain_id: int) -> None:
        """Create the context, the node and both raw subscriptions."""
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Image

        self._rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node('bench_stereo_probe', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                         reliability=ReliabilityPolicy.BEST_EFFORT)
        self.received: dict[str, dict[int, int]] = {'left': {}, 'right': {}}
        #: The node's last /diagnostics values of the check (:data:`CHECK_KEYS`).
        self.check: dict[str, str] = {}
        from diagnostic_msgs.msg import DiagnosticArray
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        for side in ('left', 'right'):
            self.node.create_subscription(Image, f'{side}/image_rect',
                                          lambda data, s=side: self._on(s, data), qos, raw=True)

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values if kv.key in CHECK_KEYS}
            if values:
                self.check = values

    def checks(self) -> int:
        """Return how many checks the node reported so far (0 before any)."""
        return int(self.check.get('stereo_checks', '0') or 0)

    def _on(self, side: str, data: bytes) -> None:
        now = time.time_ns()
        little = data[1] == 1
        sec, nsec = struct.unpack_from('<iI' if little else '>iI', data, 4)
        self.received[side][sec * 1_000_000_000 + nsec] = now

    def spin_for(self, seconds: float) -> None:
        """Spin for a while."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=min(0.02, max(0.0, deadline - time.monotonic())))

    def pairs(self, since_ns: int = 0) -> list[tuple[int, int]]:
        """
        Return ``(later receive ns, stamp ns)`` of every pair of which both sides came.

        :param since_ns: only pairs stamped from then on (wall clock, ns).
        :return: the pairs.
        """
        left, right = self.received['left'], self.received['right']
        return [(max(left[s], right[s]), s) for s in left.keys() & right.keys()
                if s >= since_ns]

    def clear(self) -> None:
        """Forget what was received."""
        for side in self.received.values():
            side.clear()

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        self.executor.shutdown()
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.context)


def bare_remaps_ms(size: tuple[int, int], reps: int) -> dict[str, float]:
    """
    Return the median and minimum time of rectifying one rgb8 pair (two bare remaps).

    :param size: the raw and rectified size.
    :param reps: back-to-back calls.
    :return: ``{'median', 'min'}`` in ms.
    """
    import numpy as np

    from mechdeconv_ros.imaging.stereo_remap import StereoRectifier
    from mechdeconv_ros.model.stereo import build_stereo
    from mechdeconv_ros.schema.stereo_params import load_stereo_params_file
    values = load_stereo_params_file(STEREO_YAML)
    for side in ('left', 'right'):
        values[f'{side}.sensor.width_px'], values[f'{side}.sensor.height_px'] = size
    rectifier = StereoRectifier(build_stereo(values, size, size))
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8) for _ in range(2)]
    outs = tuple(np.empty_like(f) for f in frames)
    rectifier.rectify(*frames, dst=outs)
    times = []
    for _ in range(reps):
        start = time.perf_counter()
        rectifier.rectify(*frames, dst=outs)
        times.append((time.perf_counter() - start) * 1e3)
    return {'median': statistics.median(times), 'min': min(times)}


def _measure(kind: str, size: tuple[int, int], env: dict[str, str], probe: PairProbe,
             log_dir: Path, window_s: float, doc: dict[str, Any]) -> dict[str, Any]:
    """Start the process under test and the publisher, measure one window, stop both."""
    proc = start_child(node_argv(kind, size), env, log_dir, kind)
    pub: Child | None = None
    try:
        # Pairs of the run before may still be in flight: only this publisher's count.
        started = time.time_ns()
        pub = start_child([sys.executable, '-m', 'benchmarks.stereo_latency', '--role',
                           'publisher', '--width', str(size[0]), '--height', str(size[1]),
                           '--rate', str(RATE_HZ)], env, log_dir, f'publisher_{kind}')
        deadline = time.monotonic() + READY_TIMEOUT_S
        while not probe.pairs(started) and time.monotonic() < deadline:
            probe.spin_for(0.1)
        if not probe.pairs(started):
            doc['errors'].append(f'{kind}: no pair within {READY_TIMEOUT_S} s: {proc.tail()}')
            return {'kind': kind}
        probe.spin_for(WARMUP_S if window_s > QUICK_WINDOW_S else 0.2)
        probe.clear()
        probe.check = {}
        start_ns = time.time_ns()
        probe.spin_for(window_s)
        checks_before = probe.checks()
        stats = latency_stats(probe.pairs(start_ns), window_s, (start_ns, time.time_ns()))
        stats['pairs_per_s'] = stats.pop('fps')
        stats['kind'] = kind
        # The checks done by the end of the window (the count since the node started: what
        # the check cost the frames is only measured if it ran).
        stats['checks'] = checks_before
        stats['check_ms_last'] = probe.check.get('stereo_check_ms_last')
        return stats
    finally:
        for child in (pub, proc):
            if child is not None:
                code = child.stop()
                doc['exit_codes'].append({'process': child.name, 'exit_code': code})
                if code != 0:
                    doc['errors'].append(f'{child.name} exited with {code}: {child.tail()}')


def child_main(quick: bool, out_json: Path) -> int:
    """Measure every kind in this process (its Fast DDS profile is fixed by its environment)."""
    size = QUICK_SIZE if quick else SIZE
    env = dict(os.environ)
    doc: dict[str, Any] = {'size': f'{size[0]}x{size[1]}', 'runs': [], 'errors': [],
                           'exit_codes': []}
    log_dir = Path(tempfile.mkdtemp(prefix='mechdeconv_bench_stereo_'))
    doc['log_dir'] = str(log_dir)
    probe = PairProbe(int(env['ROS_DOMAIN_ID']))
    doc['bare_two_remaps_ms'] = bare_remaps_ms(size, 5 if quick else 40)
    try:
        for kind in KINDS:
            log(f'stereo_latency: {kind} at {doc["size"]}')
            doc['runs'].append(_measure(kind, size, env, probe, log_dir,
                                        QUICK_WINDOW_S if quick else WINDOW_S, doc))
    finally:
        probe.close()
    out_json.write_text(json.dumps(doc))
    return 0


def evaluate(child: dict[str, Any]) -> dict[str, Any]:
    """
    Return the targets from one run: the latency ratio and the check's cost.

    :param child: the measuring child's document.
    :return: ``latency_ratio`` ((p50 node - p50 relay) / two bare remaps), ``latency_met``
        (<= :data:`TARGET_REMAPS`), ``check_pairs_share`` (pairs/s with the check over
        without) and ``check_p50_delta_ms``.
    """
    runs = {r['kind']: r for r in child.get('runs', [])}
    remaps = child.get('bare_two_remaps_ms', {}).get('median', float('nan'))
    out: dict[str, Any] = {'target_remaps': TARGET_REMAPS}
    if 'p50_ms' in runs.get('relay', {}) and 'p50_ms' in runs.get('stereo', {}):
        ratio = (runs['stereo']['p50_ms'] - runs['relay']['p50_ms']) / remaps
        out.update({'latency_ratio': ratio, 'latency_met': bool(ratio <= TARGET_REMAPS),
                    'p50_budget_ms': runs['relay']['p50_ms'] + TARGET_REMAPS * remaps})
    if 'p50_ms' in runs.get('stereo', {}) and 'p50_ms' in runs.get('stereo_check', {}):
        out['check_pairs_share'] = (runs['stereo_check']['pairs_per_s']
                                    / max(runs['stereo']['pairs_per_s'], 1e-9))
        out['check_p50_delta_ms'] = runs['stereo_check']['p50_ms'] - runs['stereo']['p50_ms']
        if 'p50_ms' in runs.get('relay', {}):
            # The single check's measure (benchmarks/check_cost.py): the same latency target
            # with the check on, and the pairs delivered of those published.
            ratio = (runs['stereo_check']['p50_ms'] - runs['relay']['p50_ms']) / remaps
            out.update({'latency_ratio_check': ratio,
                        'latency_met_check': bool(ratio <= TARGET_REMAPS)})
    for kind in ('stereo', 'stereo_check'):
        if 'pairs_per_s' in runs.get(kind, {}):
            out[f'delivered_{kind}'] = runs[kind]['pairs_per_s'] / RATE_HZ
    return out


def run(out_dir: Path = RESULTS, quick: bool = False) -> dict[str, Any]:
    """
    Run the stereo benchmark; write ``stereo_latency.json`` into ``out_dir``.

    :param out_dir: results folder.
    :param quick: 320x240, one-second windows (proves the pipeline runs).
    :return: the results document.
    """
    log_dir = Path(tempfile.mkdtemp(prefix='mechdeconv_bench_stereo_child_'))
    out_json = log_dir / 'child.json'
    argv = [sys.executable, '-m', 'benchmarks.stereo_latency', '--child', '--out-json',
            str(out_json)] + (['--quick'] if quick else [])
    child = start_child(argv, ros_env(pick_domain_id('benchmarks', 53), 'shm'), log_dir,
                        'child')
    start = time.monotonic()
    while child.running() and time.monotonic() - start < CHILD_TIMEOUT_S:
        time.sleep(0.2)
    code = child.stop()
    errors = [] if code == 0 else [f'child exited with {code}: {child.tail()}']
    measured = json.loads(out_json.read_text()) if out_json.exists() else {}
    errors += measured.get('errors', [])
    if not errors:
        shutil.rmtree(measured.get('log_dir', ''), ignore_errors=True)
        shutil.rmtree(log_dir, ignore_errors=True)
    doc = {'benchmark': 'stereo_latency', 'machine': machine_info(), 'method': __doc__,
           'rate_hz': RATE_HZ, 'check_rate_hz': CHECK_RATE_HZ, 'quick': quick, 'child': measured,
           'targets': evaluate(measured), 'errors': errors}
    write_json(Path(out_dir) / 'stereo_latency.json', doc)
    return doc


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch: the benchmark, its measuring child, or the publisher."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--role', choices=('benchmark', 'publisher'), default='benchmark')
    parser.add_argument('--child', action='store_true')
    parser.add_argument('--out-json', type=Path)
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--out', type=Path, default=RESULTS)
    parser.add_argument('--width', type=int, default=SIZE[0])
    parser.add_argument('--height', type=int, default=SIZE[1])
    parser.add_argument('--rate', type=float, default=RATE_HZ)
    args = parser.parse_args(argv)
    if args.role == 'publisher':
        return publisher_main(args.width, args.height, args.rate)
    if args.child:
        return child_main(args.quick, args.out_json)
    doc = run(args.out, quick=args.quick)
    print('\n'.join(stereo_tables(doc)))
    return 0 if not doc['errors'] else 1


if __name__ == '__main__':
    sys.exit(main())
