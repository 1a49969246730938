# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A moving zoom (issue 19): per-frame accuracy and latency while the lens sweeps its range.

Lens: config/zoom.yaml (Nikon patent S53-131852, 17-row zoom cam) at 1920x1080 with 12.5 um
pixels (the same 24 x 13.5 mm sensor); ``zoom`` sweeps its whole range, 0 -> 1 in 2 s and back
(a triangle wave of period 4 s), frames at 30 Hz.

1. **Strategy** (no ROS): the cost of the two ways to correct a frame of a moving lens, in
   the same process: a full model and its maps per frame (``build_model`` + ``Rectifier``)
   against the precomputed grid (:mod:`mechdeconv_ros.imaging.moving_maps`: grid build time and
   memory once; per frame the blend and the one ``cv2.resize``); and the bare remap.
2. **Accuracy** (no ROS): for every frame of one 2 s sweep (61 frames), the lens state at its
   stamp from a :class:`~mechdeconv_ros.imaging.lens_state.LensStateHistory` fed as the node feeds
   it (JointState at 100 Hz and one with each frame's stamp), the grid's map of that state
   against the EXACT model of the true state at the stamp (``build_model`` + float maps):
   the largest displacement over the output image (px). Target: >= 95 % of frames within
   0.1 px, and no frame's state more than one table step from the true one.
3. **Node** (ROS, three processes as :mod:`benchmarks.node_latency`): the publisher process
   sends JointState (``lens_state``) at 100 Hz and before each frame one stamped like it, and
   1920x1080 rgb8 frames at 30 Hz; the node is correct_node with the zoom lens, the baselines
   the pass-through relay and the same node with the zoom joint off (a still lens: what the
   moving lens adds). The node's own frame time is its /diagnostics ``frame_time_ms_mean``.
   Latency p50 = probe receive - stamp. The state each frame was corrected with is read
   back from its ``camera_info_rect`` (K_new[0][0] is monotonic in the zoom: the grid's
   inverse gives the position). Target: node p50 <= relay p50 + 2 x the
   bare remap time (a plain ``cv2.remap`` of a 1080p rgb8 frame with the node's map, same
   run), and every frame's state within one table step of the state at its stamp.

Quick (the suite's smoke run): a 320x180 frame and the table's first QUICK_ROWS rows (the zoom
sweeps 0 -> 0.125 and back: a 5-state grid of the same density instead of 33; the node builds
it at its start-up too), one timed full-model build, short windows.

The machine is shared: the numbers are as loaded as it was (the run records the load).
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path
import signal
import statistics
import struct
import sys
import tempfile
import time
from typing import Any, Sequence

from benchmarks.common import log, RESULTS
from benchmarks.node_latency import latency_stats, start_child
from benchmarks.report import machine_info, write_json
from mechdeconv_ros.node.process_env import graph_env, pick_domain_id

REPO = Path(__file__).resolve().parents[1]
ZOOM_YAML = REPO / 'config' / 'zoom.yaml'
SIZE = (1920, 1080)
QUICK_SIZE = (320, 180)
#: Pixel pitch that keeps the config's 24 x 13.5 mm sensor at SIZE, um.
SENSOR_MM = (24.0, 13.5)
RATE_HZ = 30.0
STATE_RATE_HZ = 100.0
SWEEP_S = 2.0
ACCURACY_PX = 0.1
ACCURACY_SHARE = 0.95
LATENCY_REMAP_FACTOR = 2.0
WINDOW_S = 6.0
READY_TIMEOUT_S = 120.0
#: Zoom table rows of the quick run (the same row spacing, an eighth of the range).
QUICK_ROWS = 3


def sweep(t: float, span: float = 1.0) -> float:
    """Return the zoom position at time ``t`` (s): 0 -> span in SWEEP_S, back, and so on."""
    phase = (t / SWEEP_S) % 2.0
    return span * (phase if phase <= 1.0 else 2.0 - phase)


def zoom_values(width: int, height: int, rows: int = 0) -> dict[str, Any]:
    """
    Return config/zoom.yaml at a frame size, the pixel pitch keeping the sensor size.

    :param width: frame width, px.
    :param height: frame height, px.
    :param rows: keep only the zoom table's first ``rows`` rows (0: all).
    :return: the checked values.
    """
    from mechdeconv_ros.schema.params import check_values, load_params_file
    values = dict(load_params_file(ZOOM_YAML))
    values.update({'sensor.width_px': width, 'sensor.height_px': height,
                   'sensor.pixel_size_x_um': SENSOR_MM[0] / width * 1e3,
                   'sensor.pixel_size_y_um': SENSOR_MM[1] / height * 1e3})
    if rows:
        gaps = len(values['lens.zoom.surfaces'])
        values['lens.zoom.positions'] = list(values['lens.zoom.positions'][:rows])
        values['lens.zoom.thickness_mm'] = list(values['lens.zoom.thickness_mm'][:rows * gaps])
    return check_values(values)


def span_of(values: dict[str, Any]) -> float:
    """Return the zoom range the sweep covers: the table's last position."""
    return float(values['lens.zoom.positions'][-1])


def _params_file(width: int, height: int, rows: int, folder: Path) -> Path:
    """Write the node's params file: the zoom lens at this size (and table rows)."""
    from mechdeconv_ros.schema.params import load_params_file, to_params_yaml
    values = zoom_values(width, height, rows)
    # The config's own names (with the sensor's): the node's defaults do the rest.
    names = sorted(set(load_params_file(ZOOM_YAML)) | {
        'sensor.width_px', 'sensor.height_px', 'sensor.pixel_size_x_um', 'sensor.pixel_size_y_um'})
    path = folder / 'zoom_bench.yaml'
    path.write_text(to_params_yaml(values, names=names))
    return path


# ---------------------------------------------------------------------------------------------
# 1 and 2: strategy and accuracy (no ROS)
# ---------------------------------------------------------------------------------------------

def _grid(values: dict[str, Any]) -> Any:
    from mechdeconv_ros.imaging.moving_maps import moving_rectifier
    from mechdeconv_ros.model.model import build_model
    model = build_model(values)
    return moving_rectifier(model, build_model)


def strategy_and_accuracy(width: int, height: int, frames: int, reps: int,
                          rows: int = 0) -> dict[str, Any]:
    """Measure the two strategies' costs and the per-frame accuracy over one sweep."""
    import cv2
    import numpy as np
    from tqdm import tqdm

    from benchmarks.common import time_ms
    from mechdeconv_ros.imaging.lens_state import LensStateHistory
    from mechdeconv_ros.imaging.remap import build_float_maps, Rectifier
    from mechdeconv_ros.lenses.lens_table import mechanisms, values_at
    from mechdeconv_ros.model.model import build_model

    values = zoom_values(width, height, rows)
    span = span_of(values)
    (zoom,) = mechanisms(values)
    start = time.perf_counter()
    rectifier = _grid(values)
    grid_s = time.perf_counter() - start
    grid = rectifier.grid
    src = np.random.default_rng(0).integers(0, 256, (height, width, 3), dtype=np.uint8)
    dst = np.empty_like(src)
    states = iter(np.linspace(0.0, span, 997).tolist() * 100)
    per_frame = time_ms(lambda: rectifier.prepare({'zoom': next(states)}), reps)
    bare = time_ms(lambda: cv2.remap(src, rectifier._map, None, cv2.INTER_LINEAR, dst=dst,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=0), reps)
    full_model = time_ms(lambda: Rectifier(build_model(values_at(values, {'zoom': 0.37 * span}))),
                         max(1, reps // 10))
    # One sweep, states as the node receives them.
    history = LensStateHistory({'zoom': zoom.joint})
    period_ns = int(1e9 / STATE_RATE_HZ)
    frame_ns = [int(i * 1e9 / RATE_HZ) for i in range(frames)]
    # In time order, as they arrive: a sample far older than the newest is a jump back in time
    # (a rosbag loop), which clears the history.
    # Stamps start at 1 s: a stamp of 0 means "unstamped" (the newest state).
    t0 = 1_000_000_000
    for t in sorted({*range(0, frame_ns[-1] + period_ns, period_ns), *frame_ns}):
        history.add(t0 + t, [zoom.joint], [sweep(t * 1e-9, span)])
    rows = []
    for t in tqdm(frame_ns, desc='zoom accuracy', unit='frame'):
        true = sweep(t * 1e-9, span)
        used = history.at(t0 + t).positions['zoom']
        _, full = grid.at({'zoom': used})
        exact = build_model(values_at(values, {'zoom': true}))
        mx, my = build_float_maps(exact)
        valid = (mx > -100.0)
        error = np.hypot(full[..., 0] - mx, full[..., 1] - my)[valid]
        rows.append({'t_s': t * 1e-9, 'true': true, 'used': used,
                     'max_px': float(error.max()), 'p99_px': float(np.percentile(error, 99)),
                     'state_steps': abs(used - true) / zoom.step})
    within = sum(r['max_px'] <= ACCURACY_PX for r in rows) / len(rows)
    return {
        'size': f'{width}x{height}',
        'grid': {'states': len(grid.cameras), 'build_s': grid_s,
                 'memory_mb': grid.memory_bytes / 1e6,
                 'frame_map_mb': grid.frame_map_bytes / 1e6},
        'per_frame_map_ms': statistics.median(per_frame),
        'full_model_per_frame_ms': statistics.median(full_model),
        'bare_remap_ms': statistics.median(bare),
        'frames': rows,
        'share_within_px': within,
        'largest_px': max(r['max_px'] for r in rows),
        'largest_state_steps': max(r['state_steps'] for r in rows),
        'accuracy_met': within >= ACCURACY_SHARE and
        max(r['state_steps'] for r in rows) <= 1.0,
        '_grid': grid,          # for the node part (not written)
    }


# ---------------------------------------------------------------------------------------------
# 3: the node (ROS)
# ---------------------------------------------------------------------------------------------

def publisher_main(width: int, height: int, seconds: float, span: float = 1.0) -> int:
    """Publish lens_state at 100 Hz and frames at 30 Hz (each after its own state) until SIGINT."""
    import threading

    import numpy as np
    import rclpy
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import Image, JointState

    from mechdeconv_ros.node.frame_input import sensor_qos
    from mechdeconv_ros.node.image_msgs import new_output_image

    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Node('bench_zoom_camera')
    frames = node.create_publisher(Image, 'image_raw', sensor_qos())
    states = node.create_publisher(JointState, 'lens_state', 10)
    out = new_output_image(width, height, 'rgb8')
    out.pixels[...] = np.random.default_rng(0).integers(0, 256, out.pixels.shape, np.uint8)
    lock = threading.Lock()
    t0 = time.time_ns()

    def state_at(now_ns: int) -> None:
        msg = JointState(name=['zoom'], position=[sweep((now_ns - t0) * 1e-9, span)])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now_ns, 1_000_000_000)
        with lock:
            states.publish(msg)

    def state_loop() -> None:
        while not stop.wait(1.0 / STATE_RATE_HZ):
            state_at(time.time_ns())

    thread = threading.Thread(target=state_loop, daemon=True)
    thread.start()
    count = 0
    next_t = time.monotonic()
    while not stop.is_set():
        delay = next_t - time.monotonic()
        if delay > 0 and stop.wait(delay):
            break
        next_t += 1.0 / RATE_HZ
        now = time.time_ns()
        state_at(now)           # the camera reports the lens with each frame
        out.msg.header.stamp.sec, out.msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
        frames.publish(out.msg)
        count += 1
    print(json.dumps({'published': count, 't0_ns': t0}), flush=True)
    thread.join(timeout=1.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


class ZoomProbe:
    """image_rect (stamp only) and camera_info_rect (stamp, K_new[0][0]) on a domain."""

    def __init__(self, domain_id: int) -> None:
        """Create the context, the node and the subscriptions."""
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import CameraInfo, Image

        self._rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node('bench_zoom_probe', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                         reliability=ReliabilityPolicy.BEST_EFFORT)
        self.node.create_subscription(Image, 'image_rect', self._on_image, qos, raw=True)
        self.node.create_subscription(CameraInfo, 'camera_info_rect', self._on_info, qos)
        from diagnostic_msgs.msg import DiagnosticArray
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 10)
        self.frame_ms: list[float] = []
        self.frames: list[tuple[int, int]] = []
        self.focal: dict[int, float] = {}
        self.recording = False

    def _on_image(self, data: bytes) -> None:
        if self.recording:
            now = time.time_ns()
            little = data[1] == 1
            sec, nsec = struct.unpack_from('<iI' if little else '>iI', data, 4)
            self.frames.append((now, sec * 1_000_000_000 + nsec))

    def _on_info(self, msg: Any) -> None:
        if self.recording:
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            self.focal[stamp] = float(msg.k[0])

    def _on_diag(self, msg: Any) -> None:
        if self.recording:
            for status in msg.status:
                for kv in status.values:
                    if kv.key == 'frame_time_ms_mean':
                        try:
                            value = float(kv.value)
                        except ValueError:
                            continue
                        if math.isfinite(value):
                            self.frame_ms.append(value)

    def spin_until(self, predicate: Any, timeout: float) -> bool:
        """Spin until ``predicate()`` or the timeout."""
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def record(self, seconds: float) -> None:
        """Record for a while."""
        self.frames.clear()
        self.focal.clear()
        self.frame_ms.clear()
        self.recording = True
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)
        self.recording = False

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        self.executor.shutdown()
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.context)


def _node_argv(kind: str, params: Path) -> list[str]:
    if kind in ('node', 'still'):
        # 'still': the same lens with its zoom joint off (the first rows, no lens_state).
        still = ['-p', 'lens.zoom.joint:=""'] if kind == 'still' else []
        return [sys.executable, '-m', 'mechdeconv_ros.node.entry', '--ros-args',
                '--params-file', str(params)] + still
    return [sys.executable, '-m', 'benchmarks.passthrough_node']


def node_run(width: int, height: int, seconds: float, grid: Any, warmup_s: float = 1.0,
             kinds: Sequence[str] = ('passthrough', 'still', 'node'),
             rows: int = 0) -> dict[str, Any]:
    """Run the relay and the node under the sweeping publisher; latency and states used."""
    import numpy as np

    domain = pick_domain_id('benchmarks', 91)
    env = graph_env(domain, shm_profile=True)
    log_dir = Path(tempfile.mkdtemp(prefix='mechdeconv_bench_zoom_'))
    params = _params_file(width, height, rows, log_dir)
    span = span_of(zoom_values(width, height, rows))
    probe = ZoomProbe(domain)
    out: dict[str, Any] = {'errors': []}
    # K_new[0][0] -> zoom position, by the grid (monotonic over the table).
    positions = np.linspace(0.0, span, 2001)
    focals = np.array([grid.camera_at({'zoom': p}).K_new[0, 0] for p in positions])
    monotonic = bool(np.all(np.diff(focals) > 0))
    out['focal_monotonic'] = monotonic
    try:
        for kind in kinds:
            proc = start_child(_node_argv(kind, params), env, log_dir, kind)
            # The publisher starts with the node (their start-ups overlap; the sweep's time
            # origin is the publisher's, whenever the node starts taking frames).
            pub = start_child([sys.executable, '-m', 'benchmarks.zoom', '--role',
                               'publisher', '--width', str(width), '--height',
                               str(height), '--span', str(span)], env, log_dir,
                              f'publisher_{kind}')
            try:
                ready = probe.spin_until(
                    lambda: probe.node.count_subscribers('/image_raw') > 0 and
                    probe.node.count_publishers('/image_rect') > 0, READY_TIMEOUT_S)
                # The first frame (the node's grid is built at start-up: fixed sensor size),
                # then the warm-up.
                probe.frames.clear()
                probe.recording = True
                first = probe.spin_until(lambda: len(probe.frames) > 0, READY_TIMEOUT_S)
                probe.spin_until(lambda: False, warmup_s)
                probe.recording = False
                if not first:
                    out['errors'].append(f'{kind}: no frame within {READY_TIMEOUT_S} s')
                probe.record(seconds)
                stats = latency_stats(probe.frames, seconds)
                stats['ready'] = ready
                if probe.frame_ms:
                    stats['node_frame_ms'] = statistics.median(probe.frame_ms)
                if kind == 'node':
                    stats.update(_states(probe, pub, positions, focals, grid, span))
                out[kind] = stats
                log(f'zoom [{kind}] {width}x{height}: {stats["fps"]:.1f} fps, p50 '
                    f'{stats.get("p50_ms", math.nan):.1f} ms')
            finally:
                if pub is not None and pub.running():
                    pub.stop()
                code = proc.stop()
                if code != 0 or proc.killed:
                    out['errors'].append(f'{kind} exited with {code}: {proc.tail()}')
    finally:
        probe.close()
    return out


def _states(probe: ZoomProbe, pub: Any, positions: Any, focals: Any,
            grid: Any, span: float) -> dict[str, Any]:
    """Return how far each frame's state (from its camera_info_rect) is from its stamp's."""
    import numpy as np
    # The publisher prints its sweep's time origin when it stops.
    pub.stop()
    try:
        t0 = json.loads(pub.stdout().strip().splitlines()[-1])['t0_ns']
    except (ValueError, IndexError, KeyError):
        return {'state_error': 'no t0 from the publisher'}
    (zoom,) = grid.mechanisms
    steps = []
    for stamp, focal in probe.focal.items():
        used = float(np.interp(focal, focals, positions))
        true = sweep((stamp - t0) * 1e-9, span)
        steps.append(abs(used - true) / zoom.step)
    if not steps:
        return {'state_error': 'no camera_info_rect'}
    return {'frames_checked': len(steps), 'largest_state_steps': max(steps),
            'median_state_steps': statistics.median(steps)}


# ---------------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------------

def run(out_dir: Path = RESULTS, quick: bool = False, ros: bool = True) -> dict[str, Any]:
    """
    Run the zoom benchmark; write ``zoom.json`` into ``out_dir``.

    :param out_dir: results folder.
    :param quick: a small frame, a few frames, short windows (proves it runs).
    :param ros: also run the node part.
    :return: the results document.
    """
    width, height = QUICK_SIZE if quick else SIZE
    frames = 7 if quick else int(SWEEP_S * RATE_HZ) + 1
    rows = QUICK_ROWS if quick else 0
    core = strategy_and_accuracy(width, height, frames, 5 if quick else 30, rows)
    grid = core.pop('_grid')
    log(f"zoom: grid {core['grid']['states']} states in {core['grid']['build_s']:.1f} s, "
        f"{core['grid']['memory_mb']:.1f} MB + {core['grid']['frame_map_mb']:.1f} MB map; per "
        f"frame {core['per_frame_map_ms']:.2f} ms vs full model "
        f"{core['full_model_per_frame_ms']:.0f} ms; {core['share_within_px'] * 100:.0f} % "
        f"within {ACCURACY_PX} px (largest {core['largest_px']:.3f} px)")
    doc: dict[str, Any] = {'benchmark': 'zoom', 'machine': machine_info(), 'method': __doc__,
                           'load_1min': os.getloadavg()[0], 'core': core, 'errors': []}
    if ros:
        # Quick: no 'still' run (the same node and loop as 'node', with the joint off).
        node = node_run(width, height, 0.6 if quick else WINDOW_S, grid, 0.3 if quick else 1.0,
                        ('passthrough', 'node') if quick else ('passthrough', 'still', 'node'),
                        rows)
        doc['node'] = node
        doc['errors'] += node.get('errors', [])
        relay, ours = node.get('passthrough', {}), node.get('node', {})
        bound = relay.get('p50_ms', math.nan) + LATENCY_REMAP_FACTOR * core['bare_remap_ms']
        doc['targets'] = {
            'accuracy': core['accuracy_met'],
            'latency_bound_ms': bound,
            'latency_p50_ms': ours.get('p50_ms', math.nan),
            'latency_met': ours.get('p50_ms', math.inf) <= bound,
            'node_state_steps': ours.get('largest_state_steps', math.nan),
            'node_states_met': ours.get('largest_state_steps', math.inf) <= 1.0,
        }
    write_json(out_dir / 'zoom.json', doc)
    return doc


def tables(doc: dict[str, Any]) -> list[str]:
    """Return the markdown lines of the zoom benchmark."""
    core = doc['core']
    grid = core['grid']
    lines = ['### Moving zoom (config/zoom.yaml, sweep 0 -> 1 in 2 s, 30 Hz)', '',
             '| quantity | value |', '| --- | --- |',
             f"| size | {core['size']} |",
             f"| grid | {grid['states']} states, built in {grid['build_s']:.1f} s, "
             f"{grid['memory_mb']:.1f} MB + {grid['frame_map_mb']:.1f} MB per-frame map |",
             f"| per-frame map (blend + resize) | {core['per_frame_map_ms']:.2f} ms |",
             '| full model + maps per frame (the alternative) | '
             f"{core['full_model_per_frame_ms']:.0f} ms |",
             f"| bare remap | {core['bare_remap_ms']:.2f} ms |",
             f'| frames within {ACCURACY_PX} px of the exact model | '
             f"{core['share_within_px'] * 100:.0f} % (largest {core['largest_px']:.3f} px) |",
             f"| largest state error | {core['largest_state_steps']:.3f} table steps |"]
    targets = doc.get('targets')
    if targets:
        node = doc['node']
        still = node.get('still', {})
        still_p50 = still.get('p50_ms', math.nan)
        still_ms = still.get('node_frame_ms', math.nan)
        lines += [f"| relay p50 | {node.get('passthrough', {}).get('p50_ms', math.nan):.1f}"
                  ' ms |',
                  '| node, zoom joint off (still lens): p50, frame time | '
                  f'{still_p50:.1f} ms, {still_ms:.1f} ms |',
                  '| node p50 (bound relay + 2 x remap), frame time | '
                  f"{targets['latency_p50_ms']:.1f} ms "
                  f"({targets['latency_bound_ms']:.1f} ms): "
                  f"{'met' if targets['latency_met'] else 'missed'}, "
                  f"{node.get('node', {}).get('node_frame_ms', math.nan):.1f} ms |",
                  '| node: largest state error of a frame | '
                  f"{targets['node_state_steps']:.3f} table steps |"]
    return lines + ['']


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, or the publisher process."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--role', choices=('benchmark', 'publisher'), default='benchmark')
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--no-ros', action='store_true', help='only the core measurements')
    parser.add_argument('--out', type=Path, default=RESULTS)
    parser.add_argument('--width', type=int, default=SIZE[0])
    parser.add_argument('--height', type=int, default=SIZE[1])
    parser.add_argument('--span', type=float, default=1.0, help='publisher: the zoom range')
    args = parser.parse_args(argv)
    if args.role == 'publisher':
        return publisher_main(args.width, args.height, 0.0, args.span)
    doc = run(args.out, quick=args.quick, ros=not args.no_ros)
    print('\n'.join(tables(doc)))
    return 0 if not doc['errors'] else 1


if __name__ == '__main__':
    sys.exit(main())
