# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``mechdeconv check``: the straightness of raw images and the assembly that straightens them.

Prints either one JSON object (``--json``: the keys of
:meth:`~mechdeconv_ros.imaging.plumb_check.CheckResult.as_dict`) or a short table. Exit status
0 whatever the verdict (a verdict is a measurement, not a failure); 2 for bad input.
"""

from __future__ import annotations

import json
import math
from typing import Any, Mapping, TextIO

from mechdeconv_ros.imaging.plumb_check import check_images, CheckResult
import numpy as np


def run_check(model: Any, images: list[np.ndarray], values: Mapping[str, Any], as_json: bool,
              out: TextIO) -> int:
    """
    Check raw images against a model and print the result.

    :param model: the lens model of the description.
    :param images: raw frames (all of the model's size).
    :param values: the parameter values (``check.max_rms_px``).
    :param as_json: print JSON.
    :param out: where to print.
    :return: exit status 0.
    """
    result = check_images(model, images, float(values.get('check.max_rms_px', 0.3)))
    if as_json:
        out.write(json.dumps(_json_safe(result.as_dict()), indent=2) + '\n')
    else:
        out.write(format_table(result))
    return 0


def _json_safe(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def format_table(result: CheckResult) -> str:
    """
    Return the result as a short human-readable table.

    :param result: the check.
    :return: text ending in a newline.
    """
    def px(value: float | None) -> str:
        return 'n/a' if value is None or not math.isfinite(value) else f'{value:.3f} px'

    lines = [f'verdict: {result.verdict}',
             f'edges: {result.edges} on {result.lines} scene lines ({result.points} points, '
             f'{result.rejected_edges} rejected), field coverage '
             f'{100.0 * result.field_coverage:.0f} %',
             f'straightness of whole lines with the description: rms '
             f'{px(result.straightness_rms_px)}, '
             f'max {px(result.straightness_max_px)}']
    if result.estimate:
        lines.append(f'straightness after the estimate: rms '
                     f'{px(result.straightness_rms_px_after)}, max '
                     f'{px(result.straightness_max_px_after)}')
        lines.append(f'{"parameter":34} {"estimate":>12} {"sigma":>10} {"tolerance":>10}')
        for name, est in result.estimate.items():
            seen = '' if est['sigma'] <= est['tolerance'] else '  (not seen by these edges)'
            lines.append(f'{name:34} {est["value"]:12.5f} {est["sigma"]:10.5f} '
                         f'{est["tolerance"]:10.5f}{seen}')
    return '\n'.join(lines) + '\n'
