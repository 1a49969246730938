# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Read a lens datasheet's distortion table (CSV) into datasheet-mode parameters.

The table: one row per field angle, columns field angle theta in degrees (from the axis),
real image height in mm, and optionally the relative illumination (0 to 1, 1 on the axis).
Columns are separated by commas, semicolons, tabs or spaces; one header line (any
non-numeric first row) and ``#`` comments are allowed. Theta and the height must both
increase strictly from row to row (the map from angle to height is one-to-one, docs/design.md
section 2.5); theta in [0, 180) deg, heights >= 0.

Parameters: ``lens.datasheet.field_angle_deg``, ``lens.datasheet.image_height_mm``,
``lens.datasheet.relative_illumination`` (with a third column), ``lens.focal_length_mm``
(the effective focal length, given by the user: a table of heights does not fix it) and
``scene.distance_mm`` 0 (infinity, where datasheet tables are given).
"""

from __future__ import annotations

import math
from pathlib import Path
import re

from mechdeconv_ros.lenses.params_file import Imported
from mechdeconv_ros.lenses.zmx import decode, LensImportError

_SEPARATORS = re.compile(r'[,;\s]+')


def _row(text: str) -> list[str]:
    return [t for t in _SEPARATORS.split(text.strip()) if t]


def read_table(path: str | Path) -> tuple[list[float], list[float], list[float]]:
    """
    Read the table.

    :param path: the CSV file.
    :return: field angles (deg), image heights (mm) and relative illumination ([] when the
        table has two columns).
    :raises LensImportError: naming the file and line, for anything but such a table.
    """
    name = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise LensImportError(f'{name}: cannot read it: {err.strerror}') from None
    rows: list[tuple[int, list[float]]] = []
    width = 0
    for line, raw in enumerate(decode(data, name).splitlines(), start=1):
        text = raw.split('#', 1)[0]
        tokens = _row(text)
        if not tokens:
            continue
        try:
            numbers = [float(t) for t in tokens]
        except ValueError:
            if not rows and width == 0:
                width = -1                         # the one header line
                continue
            raise LensImportError(f'{name}: line {line}: {raw.strip()!r} is not a row of '
                                  'numbers (field angle deg, image height mm[, relative '
                                  'illumination])') from None
        if width <= 0:
            width = len(numbers)
            if width not in (2, 3):
                raise LensImportError(f'{name}: line {line}: {width} columns; expected 2 '
                                      '(field angle deg, image height mm) or 3 (+ relative '
                                      'illumination)')
        if len(numbers) != width:
            raise LensImportError(f'{name}: line {line}: {len(numbers)} columns, the table '
                                  f'has {width}')
        if not all(math.isfinite(v) for v in numbers):
            raise LensImportError(f'{name}: line {line}: values must be finite')
        rows.append((line, numbers))
    if len(rows) < 3:
        raise LensImportError(f'{name}: {len(rows)} rows of numbers: a distortion table needs '
                              'at least 3 (field angle deg, image height mm)')
    _check(name, rows)
    angles = [r[1][0] for r in rows]
    heights = [r[1][1] for r in rows]
    ri = [r[1][2] for r in rows] if width == 3 else []
    return angles, heights, ri


def _check(name: str, rows: list[tuple[int, list[float]]]) -> None:
    for (line, values), previous in zip(rows, [None] + rows[:-1]):
        theta, height = values[0], values[1]
        if not 0.0 <= theta < 180.0:
            raise LensImportError(f'{name}: line {line}: field angle {theta:g} deg is outside '
                                  '0 to 180 deg')
        if height < 0.0:
            raise LensImportError(f'{name}: line {line}: image height {height:g} mm < 0: give '
                                  'heights as magnitudes from the axis')
        if len(values) == 3 and not 0.0 < values[2] <= 1.5:
            raise LensImportError(f'{name}: line {line}: relative illumination {values[2]:g} '
                                  'is not in (0, 1.5]')
        if previous is None:
            continue
        before = previous[1]
        if theta <= before[0]:
            raise LensImportError(f'{name}: line {line}: field angle {theta:g} deg does not '
                                  f'increase (line {previous[0]}: {before[0]:g} deg): the '
                                  'table must be monotonic')
        if height <= before[1]:
            raise LensImportError(f'{name}: line {line}: image height {height:g} mm does not '
                                  f'increase (line {previous[0]}: {before[1]:g} mm): the '
                                  'table is not monotonic (a fold, or columns swapped?)')


def table_values(path: str | Path, focal_length_mm: float) -> Imported:
    """
    Read a datasheet table and return its datasheet-mode parameters.

    :param path: the CSV file.
    :param focal_length_mm: the lens's effective focal length.
    :return: values, comments and warnings for
    :func:`mechdeconv_ros.lenses.params_file.params_text`.
    :raises LensImportError: as :func:`read_table`, or for a focal length <= 0.
    """
    if not (math.isfinite(focal_length_mm) and focal_length_mm > 0.0):
        raise LensImportError(f'--focal-length-mm {focal_length_mm:g}: must be a positive '
                              'focal length in mm')
    from mechdeconv_ros.lenses.datasheet import table_params

    angles, heights, ri = read_table(path)
    try:
        # The model's own check of a table (heights 0 at 0 deg, the angle range, ...).
        values: dict = table_params(angles, heights, focal_length_mm, ri or None)
    except ValueError as err:
        raise LensImportError(f'{path}: {err}') from None
    values.pop('lens.surfaces.radius_mm', None)
    if not ri:
        values.pop('lens.datasheet.relative_illumination', None)
    # A datasheet's distortion table is for an object at infinity.
    values['scene.distance_mm'] = 0.0
    comments = [f'Imported by `mechdeconv import` from {Path(path).name}: a datasheet '
                f'distortion table ({len(angles)} rows, to {angles[-1]:g} deg, '
                f'{heights[-1]:g} mm), f = {focal_length_mm:g} mm.',
                'The sensor is not in the table: add sensor.pixel_size_x_um, pixel_size_y_um, '
                'width_px and height_px.']
    warnings = []
    slope = heights[1] / math.radians(angles[1]) if angles[0] == 0.0 else 0.0
    if angles[0] == 0.0 and slope > 0 and abs(slope / focal_length_mm - 1.0) > 0.05:
        warnings.append("the table's first step gives" f' f ~ {slope:.4g} mm, '
                        f'{100.0 * (slope / focal_length_mm - 1.0):+.1f} % from '
                        f'--focal-length-mm {focal_length_mm:g}')
    return Imported(values=values, comments=comments, warnings=warnings)
