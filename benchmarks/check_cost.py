# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
What the straight-edge check (issue 26) costs the node's frames: check.rate_hz 0 vs on.

One node per setting (``config/fisheye.yaml``, 1280x960 mono8 frames of a rendered grid from
test/check_scenes.py, the axis 16 px off so the check has work), the publisher in this process
paced at ``--rate`` Hz for ``--seconds``; latency = receive time - ``header.stamp`` (the
stamp set just before publishing, both in this process: one hop there and one back). Reports
per setting: frames delivered per second, latency p50 / p99 (ms), the node's own frame time
(``frame_time_ms_mean`` of /diagnostics) and, with the check on, its ``check_ms_last`` and
``checks``. Short and indicative on a shared machine; run with ``nice``::

    python -m benchmarks.check_cost [--rate 15] [--seconds 40] [--check-rate 0.2]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np

TEST = Path(__file__).resolve().parents[1] / 'test'


def measure(check_rate: float, rate: float, seconds: float, tmp: Path) -> dict[str, Any]:
    """Run one node with ``check.rate_hz`` = check_rate; return the measured figures."""
    sys.path.insert(0, str(TEST))
    from check_scenes import grid, Lens
    from diagnostic_msgs.msg import DiagnosticArray
    from ros_helpers import (BEST_EFFORT, make_image, next_domain_id, node_command, REPO,
                             running_node)
    from sensor_msgs.msg import Image
    lens = Lens('fisheye')
    frame = grid(lens, (16.0, 12.0), 0.0, 0.0, 10.0)
    argv = node_command(REPO / 'config' / 'fisheye.yaml', f'check.rate_hz:={check_rate}',
                        'lazy_subscription:=false')
    latencies: list[float] = []
    diags: list[dict[str, str]] = []
    with running_node(argv, next_domain_id(), tmp) as (_, client):
        node = client.node
        pub = node.create_publisher(Image, 'image_raw', BEST_EFFORT)

        def got(msg: Any) -> None:
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            latencies.append(time.time() - stamp)

        node.create_subscription(Image, 'image_rect', got, BEST_EFFORT)
        node.create_subscription(
            DiagnosticArray, '/diagnostics',
            lambda m: diags.append({kv.key: kv.value for kv in m.status[0].values}), 10)
        msg = make_image(frame, 'mono8')
        client.spin_for(2.0)
        start = time.monotonic()
        sent = 0
        warm = 5.0      # the first seconds build the maps: not measured
        while time.monotonic() - start < seconds + warm:
            if time.monotonic() - start >= warm and sent == 0:
                latencies.clear()
            now = time.time()
            msg.header.stamp.sec, msg.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
            pub.publish(msg)
            sent += time.monotonic() - start >= warm
            client.spin_until(lambda: False, 1.0 / rate)
        client.spin_for(1.0)
    lat = np.array(latencies) * 1e3
    last = diags[-1] if diags else {}
    return {'check_rate_hz': check_rate, 'sent': sent, 'delivered': int(lat.size),
            'delivered_fps': lat.size / seconds,
            'latency_p50_ms': float(np.percentile(lat, 50)) if lat.size else None,
            'latency_p99_ms': float(np.percentile(lat, 99)) if lat.size else None,
            'frame_time_ms_mean': last.get('frame_time_ms_mean'),
            'check_ms_last': last.get('check_ms_last'), 'checks': last.get('checks'),
            'verdict': last.get('verdict')}


def main() -> None:
    """Measure without and with the check; print JSON lines."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--rate', type=float, default=15.0)
    parser.add_argument('--seconds', type=float, default=40.0)
    parser.add_argument('--check-rate', type=float, default=0.2)
    parser.add_argument('--tmp', type=Path, default=Path('/tmp/mechdeconv_check_cost'))
    args = parser.parse_args()
    args.tmp.mkdir(parents=True, exist_ok=True)
    for check_rate in (0.0, args.check_rate):
        print(json.dumps(measure(check_rate, args.rate, args.seconds, args.tmp)), flush=True)


if __name__ == '__main__':
    main()
