# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``mechdeconv stereo-check``: the rig's rotation measured from raw pairs, and the verdict.

    mechdeconv stereo-check --params STEREO.yaml [-p NAME=VALUE ...] [--json]
        LEFT1.png RIGHT1.png [LEFT2.png RIGHT2.png ...]

The pairs are pooled (as stereo_node pools ``stereo_check.window`` pairs) and checked against
the description (:mod:`mechdeconv_ros.imaging.stereo_check`). Prints one JSON object
(``--json``: ``verdict``, ``matches``, ``matches_total``, ``pairs``,
``vertical_disparity_rms_px``, ``vertical_disparity_rms_px_after``, ``residual_rms_px``,
``estimate``: ``{full parameter name: {value, sigma, tolerance}}``, empty without an
estimate; non-finite numbers as null) or a short table. Exit status 0 whatever the verdict (a
verdict is a measurement); 2 with one line naming the parameter or file for bad input.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any, Sequence, TextIO

import cv2
from mechdeconv_ros.imaging.stereo_check import check_pairs, StereoCheckResult
from mechdeconv_ros.model.stereo import build_stereo
import numpy as np


def add_stereo_check_parser(sub: Any) -> argparse.ArgumentParser:
    """
    Add the ``stereo-check`` sub-command's parser.

    :param sub: the ``mechdeconv`` command's sub-parsers.
    :return: the new parser (the caller sets its ``func``).
    """
    parser = sub.add_parser(
        'stereo-check', help="measure the rig's rotation from raw stereo pairs",
        description='Match features between the left and right raw images of each pair, fit '
                    "the rig's rotation (and the offsets their tolerances free) to the "
                    'epipolar constraint through both lenses, and say whether the '
                    "description's rows line up (ok, rig_off, not_enough_matches).")
    parser.add_argument('--params', metavar='STEREO.yaml', required=True,
                        help='ROS 2 params file of stereo_node (e.g. config/stereo.yaml)')
    parser.add_argument('-p', '--param', action='append', metavar='NAME=VALUE',
                        help='override one pair parameter, e.g. -p rig.rotation_x_deg=0.1')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('images', nargs='+', metavar='IMAGE',
                        help='raw pairs: LEFT1 RIGHT1 [LEFT2 RIGHT2 ...]')
    return parser


def grey(image: np.ndarray) -> np.ndarray:
    """
    Return an 8-bit grey copy of an image as cv2.imread gives it (BGR, BGRA or mono).

    :param image: the image.
    :return: ``(h, w)`` uint8.
    """
    if image.ndim == 3:
        image = cv2.cvtColor(image[..., :3], cv2.COLOR_BGR2GRAY)
    if image.dtype != np.uint8:
        image = cv2.convertScaleAbs(image, alpha=255.0 / max(float(image.max()), 1.0))
    return image


def run_stereo_check(values: dict[str, Any], images: Sequence[np.ndarray],
                     names: Sequence[str]) -> StereoCheckResult:
    """
    Check raw pairs against a pair's description.

    :param values: the checked pair values.
    :param images: ``LEFT1, RIGHT1, LEFT2, ...`` as read.
    :param names: their file names (for refusals).
    :return: the check.
    :raises ValueError: an odd number of images or a size that is not its camera's (naming
        the file); ModelError naming the parameter of a refused pair.
    """
    if len(images) % 2:
        raise ValueError(f'{names[-1]}: the images come in LEFT RIGHT pairs '
                         f'({len(images)} given)')
    left, right = images[0], images[1]
    stereo = build_stereo(values, (left.shape[1], left.shape[0]),
                          (right.shape[1], right.shape[0]))
    pairs = []
    for k in range(0, len(images), 2):
        for image, name, model, side in ((images[k], names[k], stereo.left, 'left'),
                                         (images[k + 1], names[k + 1], stereo.right, 'right')):
            if image.shape[:2] != (model.height, model.width):
                raise ValueError(f'{name}: {image.shape[1]}x{image.shape[0]} px but '
                                 f'{side}.sensor.width_px/height_px say '
                                 f'{model.width}x{model.height}')
        pairs.append((grey(images[k]), grey(images[k + 1])))
    rig = {k: v for k, v in values.items() if k.startswith('rig.')}
    return check_pairs(stereo.left, stereo.right, rig, pairs, float(stereo.K_rect[1, 1]))


def json_safe(value: Any) -> Any:
    """
    Return a value with non-finite floats as None (JSON has no NaN or inf).

    :param value: a result dict (nested).
    :return: the cleaned copy.
    """
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def print_result(result: StereoCheckResult, as_json: bool, out: TextIO) -> None:
    """
    Print a check as one JSON object or a short table.

    :param result: the check.
    :param as_json: JSON.
    :param out: where to print.
    """
    if as_json:
        out.write(json.dumps(json_safe(result.as_dict()), indent=2) + '\n')
        return

    def px(value: float) -> str:
        return 'n/a' if not math.isfinite(value) else f'{value:.3f} px'

    lines = [f'verdict: {result.verdict}',
             f'matches: {result.matches} inliers of {result.matches_total} '
             f'({result.pairs} pairs)',
             f'vertical disparity rms with the description: '
             f'{px(result.vertical_disparity_rms_px)}, with the estimate: '
             f'{px(result.vertical_disparity_rms_px_after)}']
    if result.estimate:
        lines.append(f'{"parameter":24} {"estimate":>12} {"sigma":>10} {"tolerance":>10}')
        for name, est in result.estimate.items():
            seen = '' if est['sigma'] <= est['tolerance'] else '  (held: not seen)'
            lines.append(f'{name:24} {est["value"]:12.5f} {est["sigma"]:10.5f} '
                         f'{est["tolerance"]:10.5f}{seen}')
    out.write('\n'.join(lines) + '\n')
