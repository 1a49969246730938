# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The self-check on frames as real cameras send them (issue 36, item 4): verdict counts.

::

    python -m benchmarks.check_real_frames [--scenes 17] [--out results/check_real_frames.json]

Renders ``--scenes`` fisheye scenes (test/check_scenes.py: box rooms and grids at several
yaws and pitches, the axis 16 px right and 12 px down) through the TRUE description, at half
size (640 x 480, a 4 um pitch), sends each as every kind of :func:`check_scenes.as_sent`
(JPEG q80, demosaiced Bayer, 3 px motion blur, 10- and 12-bit ``mono16``, dim: mean 20
grey), and checks each frame alone (the hardest case: the node pools ``check.window``
frames) with the true description and with the nominal one (the axis centred). Prints and
writes the verdict counts per kind. Deterministic (fixed seeds); no timing.
"""

from __future__ import annotations

import argparse
from collections import Counter
import json
from pathlib import Path
import sys

REPO = Path(__file__).resolve().parents[1]
TEST = REPO / 'test'


def scenes(count: int) -> list[tuple[str, dict]]:
    """Return ``count`` scene recipes: box rooms and grids at several poses."""
    out = []
    for k in range(count):
        if k % 2 == 0:
            out.append(('room', {'yaw': -40.0 + 11.0 * k, 'pitch': -12.0 + 3.0 * (k % 5)}))
        else:
            out.append(('grid', {'yaw': -30.0 + 7.0 * k, 'pitch': -10.0 + 4.0 * (k % 4),
                                 'roll': 5.0 * k}))
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the frames and print the verdict counts."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', type=int, default=17)
    parser.add_argument('--out', default=str(REPO / 'results' / 'check_real_frames.json'))
    args = parser.parse_args(argv)
    sys.path.insert(0, str(TEST))
    from check_scenes import as_sent, box_room, grid, half_size, KINDS, Lens
    from mechdeconv_ros.imaging.plumb_check import check_images
    from mechdeconv_ros.model.model import build_model
    from test_check_frames import half_values, OFF

    lens = Lens('fisheye')
    models = {'true': build_model(half_values(OFF)),
              'nominal': build_model(half_values((0.0, 0.0)))}
    counts = {kind: {'true': Counter(), 'nominal': Counter()} for kind in KINDS}
    rms = {kind: [] for kind in KINDS}
    for k, (name, pose) in enumerate(scenes(args.scenes)):
        if name == 'room':
            frame = box_room(lens, OFF, pose['yaw'], pose['pitch'])
        else:
            frame = grid(lens, OFF, pose['yaw'], pose['pitch'], pose['roll'])
        frame = half_size(frame)
        for kind in KINDS:
            sent = as_sent(frame, kind, seed=k)
            for desc, model in models.items():
                result = check_images(model, [sent], 0.3)
                counts[kind][desc][result.verdict] += 1
                if desc == 'true' and result.straightness_rms_px is not None:
                    rms[kind].append(result.straightness_rms_px)
            print(f'{k:3d} {name:5s} {kind:13s} true {dict(counts[kind]["true"])} '
                  f'nominal {dict(counts[kind]["nominal"])}', flush=True)
    table = {kind: {'true': dict(counts[kind]['true']),
                    'nominal': dict(counts[kind]['nominal']),
                    'true_rms_px_median': (sorted(rms[kind])[len(rms[kind]) // 2]
                                           if rms[kind] else None)} for kind in KINDS}
    print('| kind | frames | true: ok | true: not_enough_edges | true: description_off '
          '| true: median RMS px | nominal: description_off | nominal: ok | nominal: '
          'not_enough_edges |')
    print('| --- | --- | --- | --- | --- | --- | --- | --- | --- |')
    for kind, row in table.items():
        t, n = row['true'], row['nominal']
        med = row['true_rms_px_median']
        print(f'| {kind} | {sum(t.values())} | {t.get("ok", 0)} | '
              f'{t.get("not_enough_edges", 0)} | {t.get("description_off", 0)} | '
              f'{"n/a" if med is None else f"{med:.3f}"} | {n.get("description_off", 0)} | '
              f'{n.get("ok", 0)} | {n.get("not_enough_edges", 0)} |')
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(table, indent=2) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
