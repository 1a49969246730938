# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``mechdeconv stereo``: rectify a raw pair and write the pair's camera_info files.

    mechdeconv stereo --params STEREO.yaml [-p NAME=VALUE ...] LEFT.png RIGHT.png -o DIR

``STEREO.yaml`` is a ROS 2 params file for stereo_node (``/**/stereo_node:
ros__parameters:``, ``stereo_node`` or ``/**``, :mod:`mechdeconv_ros.schema.stereo_params`).
Writes ``DIR/left_rect.png``, ``DIR/right_rect.png`` (the exact rectification,
:mod:`mechdeconv_ros.imaging.stereo_remap`) and ``DIR/left_camera_info.yaml``,
``DIR/right_camera_info.yaml`` (camera_calibration_parsers YAML as ``mechdeconv camera-info``
writes, with the rectifying R and the pair's P:
``P[0, 3] = -f B`` of the right camera, B in metres). Every refusal is a ``ValueError`` whose
message names the parameter or file; the command line prints it as one line and exits 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Sequence

import cv2
from mechdeconv_ros.imaging.stereo_remap import StereoRectifier
from mechdeconv_ros.model.camera_yaml import info_yaml
from mechdeconv_ros.model.stereo import build_stereo, stereo_camera_infos
from mechdeconv_ros.schema.stereo_params import (
    check_stereo_values, load_stereo_params_file, STEREO_SPECS)
import numpy as np
import yaml

#: The colour (0 R, 1 G, 2 B) of each channel of an image cv2.imread returns (BGR, BGRA).
_BGR_COLOURS = {3: (2, 1, 0), 4: (2, 1, 0, 1)}
#: What the command writes into DIR.
OUTPUTS = ('left_rect.png', 'right_rect.png', 'left_camera_info.yaml',
           'right_camera_info.yaml')


def add_stereo_parser(sub: Any) -> argparse.ArgumentParser:
    """
    Add the ``stereo`` sub-command's parser.

    :param sub: the ``mechdeconv`` command's sub-parsers (``add_subparsers()``).
    :return: the new parser (the caller sets its ``func``).
    """
    stereo = sub.add_parser(
        'stereo', help='rectify a raw stereo pair and write its camera_info files',
        description='Rectify a raw stereo pair exactly (both lenses and the rig from a '
                    'stereo_node params file) and write DIR/left_rect.png, right_rect.png, '
                    'left_camera_info.yaml and right_camera_info.yaml (with R and P).')
    stereo.add_argument('--params', metavar='STEREO.yaml', required=True,
                        help='ROS 2 params file of stereo_node (e.g. config/stereo.yaml)')
    stereo.add_argument('-p', '--param', action='append', metavar='NAME=VALUE',
                        help='override one pair parameter, e.g. -p rig.rotation_x_deg=0.1')
    stereo.add_argument('left', help='left raw image')
    stereo.add_argument('right', help='right raw image')
    stereo.add_argument('-o', '--output', required=True, metavar='DIR',
                        help='folder to write into (made if missing)')
    return stereo


def pair_values(params: str | None, overrides: Sequence[str] = ()) -> dict[str, Any]:
    """
    Read a pair's params file and apply ``-p NAME=VALUE`` overrides.

    :param params: the stereo_node params file (None: every default).
    :param overrides: ``NAME=VALUE`` strings, VALUE in YAML.
    :return: the checked pair values.
    :raises ValueError: naming the option, file or parameter at fault.
    """
    try:
        values = load_stereo_params_file(params) if params else check_stereo_values({})
    except OSError as err:
        raise ValueError(f'--params: cannot read {params}: {err.strerror}') from None
    except ValueError as err:
        raise ValueError(f'--params {params}: {err}') from None
    for item in overrides:
        name, sep, text = item.partition('=')
        if not sep or name not in STEREO_SPECS:
            raise ValueError(f'-p {item}: expected NAME=VALUE with a known pair parameter name '
                             '(left.*, right.*, rig.*, output.*, ...)')
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            raise ValueError(f'-p {item}: the value is not YAML') from None
        values.update(check_stereo_values({name: value}, partial=True))
    return check_stereo_values(values)


def _write(path: Path, image: np.ndarray) -> None:
    try:
        written = cv2.imwrite(str(path), image)
    except cv2.error:
        written = False
    if not written:
        raise ValueError(f'-o {path.parent}: cannot write {path.name} there')


def run_stereo(values: dict[str, Any], left: np.ndarray, right: np.ndarray,
               out_dir: Path) -> list[Path]:
    """
    Rectify one raw pair and write the four files into ``out_dir`` (made if missing).

    :param values: checked pair values.
    :param left: the left raw image (as cv2.imread gives it: BGR colour or mono).
    :param right: the right raw image.
    :param out_dir: the output folder.
    :return: the written paths, in :data:`OUTPUTS` order.
    :raises ValueError: naming the parameter (a refused pair) or the folder (not writable).
    """
    stereo = build_stereo(values, (left.shape[1], left.shape[0]),
                          (right.shape[1], right.shape[0]))
    for side, image, model in (('LEFT', left, stereo.left), ('RIGHT', right, stereo.right)):
        if image.shape[:2] != (model.height, model.width):
            raise ValueError(f'{side}: the image is {image.shape[1]}x{image.shape[0]} px but '
                             f'{side.lower()}.sensor.width_px/height_px say '
                             f'{model.width}x{model.height}')
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ValueError(f'-o {out_dir}: cannot make the output folder there: '
                         f'{err.strerror}') from None
    channels = left.shape[2] if left.ndim == 3 else 1
    left_rect, right_rect = StereoRectifier(stereo).rectify(
        left, right, colours=_BGR_COLOURS.get(channels))
    paths = [out_dir / name for name in OUTPUTS]
    _write(paths[0], left_rect)
    _write(paths[1], right_rect)
    infos = stereo_camera_infos(stereo)
    for path, side in zip(paths[2:], ('left', 'right')):
        try:
            path.write_text(info_yaml(infos[side], side), encoding='utf-8')
        except OSError as err:
            raise ValueError(f'-o {out_dir}: cannot write {path.name} there: '
                             f'{err.strerror}') from None
    return paths
