# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The demo's story of a moving lens (issue 19): the camera sweeps its joints, each frame corrected.

:func:`sweep_scenario` is what ``python -m mechdeconv_ros.tools.demo`` runs when a
``lens.m.joint`` of the params file is set: ``demo_camera`` sweeps the lens and publishes
``lens_state`` with each frame, ``correct_node`` corrects each frame at the state of its
stamp. The demo prints the model at the tables' first rows and the node's diagnostics,
measures throughput and latency while the lens sweeps, then takes two raw / corrected pairs
of one stamp each, with the lens state, f and the largest displacement of the model at that
state (:func:`mechdeconv_ros.lenses.sources.source_for` at the state), and writes
``raw_<i>.png``, ``corrected_<i>.png`` and ``summary.png``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import time
from typing import Any

from mechdeconv_ros.node.process_env import Child
from mechdeconv_ros.tools.demo_report import (
    diagnostics_lines, measure, newest_rect, say, stamp_ns, stop_children, to_bgr, wait_for,
    write_png)

#: A moving lens: the node and the camera first build their grids of lens states.
MOVING_STARTUP_TIMEOUT_S = 180.0


def sweep_scenario(args: argparse.Namespace, children: list[Child], monitor: Any, model: Any,
                   params_file: Path, out: Path) -> int:
    """Tell the moving lens's story (issue 19): the camera sweeps, each frame corrected."""
    import numpy as np

    from mechdeconv_ros.lenses.sources import source_for
    from mechdeconv_ros.model.model import build_model
    from mechdeconv_ros.tools.cli import format_report
    from mechdeconv_ros.tools.demo_report import caption

    joints = ', '.join(f'lens.{m.name}.joint {m.joint!r} ({m.positions[0]:g} to '
                       f'{m.positions[-1]:g})' for m in model.source.moving)
    say(f'the lens moves: {joints}; demo_camera sweeps it and publishes lens_state with each '
        'frame, correct_node corrects each frame at the state of its stamp')
    say('waiting for the first corrected frame (both first build their grid of lens states) ...')
    wait_for(lambda: monitor.last_rect is not None, MOVING_STARTUP_TIMEOUT_S,
             'corrected frame on image_rect', children)
    say('first corrected frame received')
    print(f'\nmodel at the first rows ({params_file.name}, {model.width}x{model.height}):\n  '
          + format_report(model.report()).replace('\n', '\n  '), flush=True)
    wait_for(lambda: bool(monitor.diag.get('lens_grid_states')), 10.0,
             'diagnostics of the moving lens', children)
    print(diagnostics_lines(monitor.diag, monitor.diag_message), flush=True)
    measure(monitor, args.seconds, 'lens sweeping', args.rate, children)
    frames = []
    for _ in range(2):
        # The pair of one stamp: the camera renders each frame at the state it publishes.
        rect = newest_rect(monitor)
        stamp = stamp_ns(rect.header.stamp)
        raw = monitor.grab_raw(5.0)
        while stamp_ns(raw.header.stamp) < stamp:
            raw = monitor.grab_raw(5.0)
        joints = monitor.lens_state_at(stamp_ns(raw.header.stamp)) or {}
        state = {m.name: float(joints.get(m.joint, m.positions[0]))
                 for m in model.source.moving}
        rect = next((r for r in monitor.recent_rects() if
                     stamp_ns(r.header.stamp) == stamp_ns(raw.header.stamp)), None)
        if rect is None:        # its correction did not arrive (best effort): the newest
            rect = newest_rect(monitor)
        at = build_model(model.values, model.width, model.height,
                         source=source_for(model.source.table_values, state))
        text = ', '.join(f'{k} = {v:.3f}' for k, v in state.items())
        frames.append((to_bgr(raw), to_bgr(rect),
                       f'{text}, f = {at.focal_length_mm:.1f} mm, max displacement '
                       f'{at.max_displacement_px:.1f} px'))
        say('  lens state ' + text +
            f", lens_state_lag_ms {monitor.diag.get('lens_state_lag_ms')}, "
            f"lens_states_ignored {monitor.diag.get('lens_states_ignored')}")
        time.sleep(1.3)
    for i, (raw, corrected, _) in enumerate(frames):
        write_png(out / f'raw_{i}.png', raw)
        write_png(out / f'corrected_{i}.png', corrected)
    write_png(out / 'summary.png', np.vstack([
        np.hstack([caption(raw, f'image_raw: {text}'),
                   caption(corrected, 'image_rect at the lens state of its stamp')])
        for raw, corrected, text in frames]))
    stop_children(children)
    say(f'done: see {out}/summary.png')
    return 0
