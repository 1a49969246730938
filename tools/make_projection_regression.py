#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Generate test/data/projection_regression.json: the projection's results before issue 37.

A regression reference, NOT an independent one (the independent references are optiland's:
test/test_reference_assembly.py, test/test_underwater_reference.py): it records what the code
of commit 0a30dce (before the projection had one owner, model/projection.py) computed, so
test/test_projection.py can show the single path gives the same numbers. Run it with that
commit's tree first on the path::

    git archive 0a30dce | tar -x -C /tmp/before
    PYTHONPATH=/tmp/before .venv/bin/python tools/make_projection_regression.py

For every shipped config (centred, and with the sensor offset and tilted where the config
allows it; the flat port also tilted about one axis), on a 7 x 7 grid of raw pixels from edge
to edge: ``directions_of`` (raw pixel -> unit direction), ``pixels_of`` of those directions,
``underwater.project_points`` (what ``mechdeconv project`` ran) of their tangents, and the
self-check's ``ChiefLines.directions_and_scales`` under a pose with a defocus.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
OUTPUT = REPO / 'test' / 'data' / 'projection_regression.json'
CONFIGS = ('case1', 'case2', 'cooke_triplet', 'edmund_55278', 'fisheye', 'wide_angle',
           'underwater_flat', 'zoom')
#: (name, extra values, the self-check's pose (dx, dy, alpha, beta, dz)).
POSES = (('centred', {}, (0.0, 0.0, 0.0, 0.0, 0.0)),
         ('tilted', {'sensor.axis_offset_x_mm': 0.2, 'sensor.axis_offset_y_mm': -0.15,
                     'sensor.tilt_x_deg': 1.0, 'sensor.tilt_y_deg': -0.7},
          (0.2, -0.15, 1.0, -0.7, 0.01)))
PORT_POSE = ('port_tilt_y', {'port.tilt_y_deg': 0.7}, (0.0, 0.0, 0.0, 0.0, 0.0))
GRID = 7
#: The commit whose code is recorded (run with its tree first on the path).
BEFORE = '0a30dce'


def _list(array: np.ndarray) -> list:
    return [None if not np.isfinite(x) else float(x) for x in np.asarray(array).ravel()]


def case(values: dict) -> dict:
    """Return the recorded results of one model."""
    from mechdeconv_ros.imaging.plumb_lines import ChiefLines
    from mechdeconv_ros.model.model import build_model
    from mechdeconv_ros.model.projection import directions_of, pixels_of
    from mechdeconv_ros.model.underwater import project_points

    model = build_model(values)
    us = np.linspace(-0.5, model.width - 0.5, GRID)
    vs = np.linspace(-0.5, model.height - 0.5, GRID)
    pixels = np.stack(np.meshgrid(us, vs), axis=-1).reshape(-1, 2)
    dirs = directions_of(model, pixels)
    ok = np.all(np.isfinite(dirs), axis=1)
    forward = pixels_of(model, dirs[ok])
    front = ok & (dirs[:, 2] > 0.1)
    tangents = dirs[front, :2] / dirs[front, 2:]
    u, v = project_points(model, tangents[:, 0], tangents[:, 1])
    return {'pixels': _list(pixels), 'directions': _list(dirs),
            'forward_directions': _list(dirs[ok]), 'forward_pixels': _list(forward),
            'tangents': _list(tangents), 'tangent_pixels': _list(np.stack([u, v], axis=1)),
            'chief_lines': ChiefLines.from_model(model)}


def run() -> None:
    """Write the reference (see the module docstring)."""
    from mechdeconv_ros.lenses.lens_errors import ModelError
    from mechdeconv_ros.schema.params import load_params_file

    import mechdeconv_ros
    code = Path(mechdeconv_ros.__file__).resolve().parents[1]
    out: dict = {'code': str(code), 'commit': BEFORE,
                 'generated_by': 'tools/make_projection_regression.py', 'cases': {}}
    for config in CONFIGS:
        base = load_params_file(REPO / 'config' / f'{config}.yaml')
        poses = POSES + ((PORT_POSE,) if config == 'underwater_flat' else ())
        for name, extra, check_pose in poses:
            values = {**base, **extra}
            try:
                entry = case(values)
            except ModelError as err:
                print(f'{config} {name}: refused ({err})')
                continue
            lines = entry.pop('chief_lines')
            points = np.array(entry['pixels']).reshape(-1, 2)
            dirs, radial, tangential = lines.directions_and_scales(points, np.array(check_pose))
            entry.update(values=extra, config=f'config/{config}.yaml',
                         check_pose=list(check_pose), check_directions=_list(dirs),
                         check_radial=_list(radial), check_tangential=_list(tangential))
            out['cases'][f'{config}/{name}'] = entry
            print(f'{config} {name}: done')
    OUTPUT.write_text(json.dumps(out, indent=None, separators=(',', ':')) + '\n')


if __name__ == '__main__':
    run()
