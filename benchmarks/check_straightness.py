# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The check's straightness against whole lines from known positions (issue 36, item 2).

::

    python -m benchmarks.check_straightness [--lens fisheye|wide]

Renders one grid, a turned grid and the box room (test/check_scenes.py) through a sensor
whose axis is off (test/test_check.py ``OFFSET_PX``), gives every detected edge point its
known scene line (:func:`check_scenes.assign_to_lines`) and compares the whole-line RMS of
that grouping (:func:`check_scenes.whole_line_rms`) with the check's
``straightness_rms_px`` for four descriptions: true, nominal (centred), half the offset and
its negative. Prints markdown rows (docs/design.md section 2.17). No timing.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    """Print the comparison rows of one lens."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--lens', default='fisheye', choices=['fisheye', 'wide'])
    args = parser.parse_args(argv)
    sys.path.insert(0, str(REPO / 'test'))
    from check_scenes import (assign_to_lines, box_room, grid, grid_lines, Lens, room_lines,
                              whole_line_rms)
    from mechdeconv_ros.imaging.plumb_check import check_chains
    from mechdeconv_ros.imaging.straight_edges import detect_chains
    from mechdeconv_ros.model.model import build_model
    import numpy as np
    from test_check import OFFSET_PX, values

    lens = Lens(args.lens)
    off = OFFSET_PX[args.lens]
    scenes = {'grid': (grid(lens, off, 0.0, 0.0, 10.0), grid_lines(0.0, 0.0, 10.0)),
              'turned grid': (grid(lens, off, 35.0, -10.0, -25.0),
                              grid_lines(35.0, -10.0, -25.0)),
              'room': (box_room(lens, off), room_lines())}
    descriptions = {'true': off, 'nominal': (0.0, 0.0), 'half': (off[0] / 2, off[1] / 2),
                    'opposite': (-off[0], -off[1])}
    models = {name: build_model(values(args.lens, o)) for name, o in descriptions.items()}
    for scene, (frame, lines) in scenes.items():
        chains = detect_chains(frame)
        points = np.concatenate(chains)
        label = assign_to_lines(lens, off, points, lines)
        known = len(np.unique(label[label >= 0]))
        for name, model in models.items():
            truth = whole_line_rms(model, points, label)
            result = check_chains(model, chains, 0.3)
            print(f'| {args.lens} | {scene} | {name} | {truth:.3f} | '
                  f'{result.straightness_rms_px:.3f} | '
                  f'{result.straightness_rms_px / truth:.2f} | {result.lines} ({known}) | '
                  f'{result.verdict} |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
