# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Compressed input (``image_transport:=compressed``) next to raw input, in the same run.

For 1280x720 and 1920x1080, a publisher paced at 30 Hz sends the same picture either as a
raw rgb8 ``image_raw`` (sensor_msgs/Image) or as a JPEG of quality 90 on
``image_raw/compressed`` (sensor_msgs/CompressedImage, format ``"rgb8; jpeg compressed bgr8"``,
as image_transport's compressed plugin writes it), to ``correct_node`` (case2.yaml, sensor size
from the frames) with ``image_transport`` raw or compressed. The probe of
:mod:`benchmarks.node_latency` receives ``image_rect`` and the node's ``/diagnostics``.

Per row: the delivered ``image_rect`` fps, latency p50/p99 (probe receive time minus the
publisher's ``header.stamp``: publisher -> node -> probe), the node's CPU use, its own per
frame time and decode time (means of its 1 Hz diagnostics, medians over the window), and the
bare decode time of the same JPEG in this process (:func:`mechdeconv_ros.node.compressed.decode`,
median), which is what the compressed path adds to the node's work per frame. The picture is
the demo camera's chart (grid lines on coloured cells), a camera-like JPEG load.

Every process runs with :func:`mechdeconv_ros.node.process_env.graph_env` (shared-memory Fast DDS
profile, ``MALLOC_*``, localhost discovery) on a private domain of the benchmarks' range; the
machine is shared, so windows that others disturbed are measured again as in node_latency.

``python -m benchmarks.compressed_input [--quick] [--seconds S]`` writes
``results/compressed_input.json`` and prints the table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import signal
import statistics
import sys
import time
from typing import Any, Sequence

from benchmarks.common import log, RESULTS
from benchmarks.node_latency import (
    _run_window, CASE2_YAML, paced_publish, Probe, READY_TIMEOUT_S, start_child)
from benchmarks.report import machine_info
from mechdeconv_ros.node.process_env import graph_env, pick_domain_id

SIZES = ((1280, 720), (1920, 1080))
QUICK_SIZES = ((320, 240),)
RATE_HZ = 30.0
JPEG_QUALITY = 90
WINDOW_S = 5.0
TRANSPORTS = ('raw', 'compressed')
DECODE_REPS = 30


def picture(width: int, height: int) -> Any:
    """Return the benchmark picture: the demo camera's chart, RGB uint8."""
    from mechdeconv_ros.tools.demo_camera import chart_texture
    return chart_texture(width, height)


def jpeg_of(width: int, height: int) -> tuple[str, bytes]:
    """Return ``(format, data)`` of the picture as image_transport would send it (q 90)."""
    from mechdeconv_ros.node.compressed import encode
    return encode(picture(width, height), 'rgb8', 'jpeg', jpeg_quality=JPEG_QUALITY)


def bare_decode_ms(width: int, height: int, reps: int = DECODE_REPS) -> dict[str, float]:
    """Time :func:`mechdeconv_ros.node.compressed.decode` of the picture's JPEG in this process."""
    from benchmarks.common import time_ms
    from mechdeconv_ros.node.compressed import decode
    fmt, data = jpeg_of(width, height)
    decode(fmt, data)
    samples = time_ms(lambda: decode(fmt, data), reps)
    return {'median_ms': statistics.median(samples), 'min_ms': min(samples), 'reps': reps,
            'jpeg_bytes': len(data), 'raw_bytes': width * height * 3}


# ---------------------------------------------------------------------------------------------
# The publisher process
# ---------------------------------------------------------------------------------------------

def publisher_main(width: int, height: int, rate_hz: float, transport: str) -> int:
    """Publish the picture (raw rgb8 or JPEG) at ``rate_hz`` until SIGINT; print counts."""
    import array
    import threading

    import numpy as np
    import rclpy
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import CompressedImage

    from mechdeconv_ros.node.frame_input import sensor_qos
    from mechdeconv_ros.node.image_msgs import new_output_image

    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Node('bench_camera')
    if transport == 'compressed':
        msg = CompressedImage()
        msg.format, data = jpeg_of(width, height)
        msg.data = array.array('B', data)
        topic = node.resolve_topic_name('image_raw') + '/compressed'
    else:
        out = new_output_image(width, height, 'rgb8')
        np.copyto(out.pixels, picture(width, height))
        msg, topic = out.msg, 'image_raw'
    msg.header.frame_id = 'bench_optical_frame'
    pub = node.create_publisher(type(msg), topic, sensor_qos())
    count, seconds = paced_publish(pub, msg, rate_hz, stop)
    print(json.dumps({'published': count, 'seconds': seconds}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


# ---------------------------------------------------------------------------------------------
# Measurement
# ---------------------------------------------------------------------------------------------

def measure(width: int, height: int, transport: str, seconds: float, log_dir: Path,
            salt: int) -> dict[str, Any]:
    """Run node + publisher for one size and transport; return the window's figures."""
    domain = pick_domain_id('benchmarks', salt)
    env = graph_env(domain, shm_profile=True)
    node_cmd = [sys.executable, '-m', 'mechdeconv_ros.node.entry', '--ros-args',
                '--params-file', str(CASE2_YAML), '-p', 'sensor.width_px:=0',
                '-p', 'sensor.height_px:=0', '-p', f'image_transport:={transport}']
    pub_cmd = [sys.executable, '-m', 'benchmarks.compressed_input', '--role', 'publisher',
               '--width', str(width), '--height', str(height), '--transport', transport]
    name = f'{width}x{height}_{transport}'
    from mechdeconv_ros.node.process_env import configure_this_process
    configure_this_process(env)
    probe = Probe(domain, name='bench_probe_' + transport)
    node = start_child(node_cmd, env, log_dir, f'node_{name}')
    pub = start_child(pub_cmd, env, log_dir, f'publisher_{name}')
    input_topic = '/image_raw' + ('/compressed' if transport == 'compressed' else '')
    try:
        ready = probe.spin_until(
            lambda: probe.node.count_subscribers(input_topic) > 0
            and probe.node.count_publishers('/image_rect') > 0, READY_TIMEOUT_S)
        if not ready:
            return {'error': 'node not ready', 'log': node.output()[-2000:]}
        stats = _run_window(probe, node, pub, seconds)
        start = time.monotonic() - seconds
        for key in ('frame_time_ms_mean', 'decode_time_ms_mean'):
            values = probe.diagnostics_since(start, key)
            if values:
                stats[f'node_{key}'] = statistics.median(values)
        return stats
    finally:
        probe.close()
        codes = {'node': node.stop(signal.SIGINT), 'publisher': pub.stop(signal.SIGINT)}
        if any(codes.values()):
            log(f'  {name}: exit codes {codes}')


def run(out_dir: Path = RESULTS, quick: bool = False, seconds: float = WINDOW_S) -> dict:
    """Measure every size and transport; write ``compressed_input.json``; return the doc."""
    import tempfile

    sizes = QUICK_SIZES if quick else SIZES
    doc: dict[str, Any] = {'machine': machine_info(), 'rate_hz': RATE_HZ,
                           'jpeg_quality': JPEG_QUALITY, 'window_s': seconds, 'rows': []}
    with tempfile.TemporaryDirectory(prefix='mechdeconv_compressed_') as tmp:
        salt = 0
        for width, height in sizes:
            decode_ms = bare_decode_ms(width, height)
            log(f'{width}x{height}: bare JPEG decode {decode_ms["median_ms"]:.2f} ms '
                f'({decode_ms["jpeg_bytes"] / 1e3:.0f} kB vs {decode_ms["raw_bytes"] / 1e6:.2f} '
                'MB raw)')
            for transport in TRANSPORTS:
                log(f'{width}x{height} {transport} at {RATE_HZ:g} Hz ...')
                salt += 1
                stats = measure(width, height, transport, seconds, Path(tmp), salt)
                row = {'size': f'{width}x{height}', 'transport': transport, **stats}
                if transport == 'compressed':
                    row['bare_decode'] = decode_ms
                doc['rows'].append(row)
                log('  ' + row_text(row))
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / 'compressed_input.json').write_text(json.dumps(doc, indent=1, default=float))
    print(table(doc))
    return doc


def _fmt(value: Any, spec: str = '.1f') -> str:
    return '-' if value is None else format(value, spec)


def row_text(row: dict[str, Any]) -> str:
    """Return one line of figures for the log."""
    if 'error' in row:
        return f"{row['size']} {row['transport']}: {row['error']}"
    return (f"{row['fps']:.1f} fps, p50 {_fmt(row.get('p50_ms'))} ms, p99 "
            f"{_fmt(row.get('p99_ms'))} ms, node {row['node_cores']:.2f} cores, "
            f"node frame {_fmt(row.get('node_frame_time_ms_mean'))} ms, decode "
            f"{_fmt(row.get('node_decode_time_ms_mean'))} ms")


def table(doc: dict[str, Any]) -> str:
    """Return the results as a Markdown table."""
    lines = ['| size | input | bare decode ms | node decode ms | node frame ms | '
             'image_rect fps (30 Hz in) | latency p50 ms | p99 ms | node cores |',
             '|---|---|---|---|---|---|---|---|---|']
    for row in doc['rows']:
        if 'error' in row:
            lines.append(f"| {row['size']} | {row['transport']} | {row['error']} |")
            continue
        bare = row.get('bare_decode', {}).get('median_ms')
        label = 'raw rgb8' if row['transport'] == 'raw' else f'JPEG q{JPEG_QUALITY}'
        lines.append(
            f"| {row['size']} | {label} | {_fmt(bare, '.2f')} | "
            f"{_fmt(row.get('node_decode_time_ms_mean'), '.2f')} | "
            f"{_fmt(row.get('node_frame_time_ms_mean'), '.2f')} | {row['fps']:.1f} | "
            f"{_fmt(row.get('p50_ms'))} | {_fmt(row.get('p99_ms'))} | "
            f"{row['node_cores']:.2f} |")
    return '\n'.join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: the benchmark, or (``--role publisher``) its publisher process."""
    parser = argparse.ArgumentParser(prog='python -m benchmarks.compressed_input')
    parser.add_argument('--role', choices=('benchmark', 'publisher'), default='benchmark')
    parser.add_argument('--quick', action='store_true', help='one small size, short window')
    parser.add_argument('--seconds', type=float, default=WINDOW_S)
    parser.add_argument('--out', type=Path, default=RESULTS)
    parser.add_argument('--width', type=int, default=1280)
    parser.add_argument('--height', type=int, default=720)
    parser.add_argument('--transport', choices=TRANSPORTS, default='raw')
    args = parser.parse_args(argv)
    if args.role == 'publisher':
        return publisher_main(args.width, args.height, RATE_HZ, args.transport)
    run(args.out, args.quick, 2.0 if args.quick else args.seconds)
    return 0


if __name__ == '__main__':
    sys.exit(main())
