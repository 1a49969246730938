# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Regenerate the parameters tables from the schema (mechdeconv_ros.schema.params.SCHEMA).

README.md holds the main parameters (:data:`MAIN`: what a new user sets first), one row each
with the first clause of its description (a group of related ones in one row), between the
lines ``<!-- params:start -->`` and ``<!-- params:end -->`` (the rest of the README is left
alone); docs/parameters.md holds every parameter with its whole description. Usage::

    python tools/gen_readme_params.py           # rewrite both in place
    python tools/gen_readme_params.py --check   # exit 1 if either is out of date

test/test_readme.py asserts that both equal what this generates.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import re
import sys
from typing import Sequence

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from mechdeconv_ros.schema.params import (  # noqa: E402 - after the sys.path fix
    ASPHERE_POWERS, ParamSpec, SCHEMA)

START = '<!-- params:start -->'
END = '<!-- params:end -->'
#: The even asphere terms (docs/parameters.md lists each).
ASPHERE_FOLDED = tuple(f'lens.surfaces.asphere_a{p}' for p in ASPHERE_POWERS)
#: Groups that share one README row, by name prefix: (row label, description). The README has a
#: size limit; docs/parameters.md lists each member with its whole description.
FOLDED_GROUPS = {
    'lens.surfaces.': ('lens.surfaces.*',
                       'Prescription mode: radius, thickness, index or glass, semi-diameter, '
                       'conic, asphere terms of each surface (stop: lens.stop_surface).'),
    'port.': ('port.*', 'A flat or dome window in front of the lens.'),
    'sensor.pixel_size_': ('sensor.pixel_size_*', 'Pixel pitch along the rows (x) and the '
                                                  'columns (y), um.'),
    'sensor.axis_offset_': ('sensor.axis_offset_*', 'Where the lens axis meets the sensor, from '
                                                    'its centre (x, y), mm.'),
    'lens.tolerance.': ('lens.tolerance.*',
                        '1-sigma manufacturing tolerances of r1, r2, t, n and d_a.'),
    'lens.datasheet.': ('lens.datasheet.*',
                        'Datasheet mode: image height by field angle, tabled.'),
    'lens.zoom.': ('lens.zoom.*',
                   'Moving zoom group: its lens_state joint, positions and the gaps it moves.'),
    'lens.focus.': ('lens.focus.*', 'The same for a moving focus group.'),
    'image_rect.compressed.': ('image_rect.compressed.*',
                               'image_rect/compressed: format (jpeg, png), jpeg_quality, '
                               'png_level; only while subscribed.'),
}
#: The README's rows, in order: schema names, or a group's label (a key's label above). Every
#: other parameter is in docs/parameters.md.
MAIN = (
    'lens.focal_length_mm', 'lens.r1_mm', 'lens.r2_mm', 'lens.thickness_mm',
    'lens.refractive_index', 'lens.aperture_diameter_mm', 'lens.stop_offset_mm',
    'lens.surfaces.*', 'lens.datasheet.*', 'lens.zoom.*', 'sensor.pixel_size_*',
    'sensor.width_px', 'sensor.height_px', 'sensor.axis_offset_*', 'sensor.tilt_x_deg',
    'sensor.tilt_y_deg', 'scene.distance_mm', 'scene.medium', 'port.*', 'output.projection',
    'output.alpha', 'output.vignetting_correction', 'check.rate_hz')
#: The generated page with the whole descriptions.
PARAMETERS_PAGE = REPO / 'docs' / 'parameters.md'


def _number(value: float) -> str:
    """Format a bound or default compactly (``1e+04`` -> ``1e4``, ``4.0`` -> ``4.0``)."""
    text = f'{value:g}'
    if 'e' in text:
        mantissa, exponent = text.split('e')
        text = f'{mantissa}e{int(exponent)}'
    return text


def format_default(spec: ParamSpec) -> str:
    """
    Return the default as it would be written in a params file.

    :param spec: the parameter.
    :return: e.g. ``4.0``, ``0``, ``true``, ``linear``, ``[]``.
    """
    value = spec.default
    if spec.type == 'bool':
        return 'true' if value else 'false'
    if spec.type == 'double':
        text = _number(float(value))
        return text if any(c in text for c in '.e') else text + '.0'
    if spec.type == 'double_array':
        return '[' + ', '.join(_number(float(v)) for v in value) + ']'
    if spec.type == 'string_array':
        return '[' + ', '.join(repr(str(v)) for v in value) + ']'
    if spec.type == 'integer_array':
        return '[' + ', '.join(str(int(v)) for v in value) + ']'
    return str(value) or "''"


def format_range(spec: ParamSpec) -> str:
    """
    Return the allowed values: the inclusive range, the choices, or a dash.

    :param spec: the parameter.
    :return: e.g. ``0 to 1``, ``each 0 to 1e4``, ``nearest, linear``, ``-``.
    """
    if spec.choices:
        return ', '.join(spec.choices)
    if spec.minimum is None and spec.maximum is None:
        return '-'
    low = '-inf' if spec.minimum is None else _number(spec.minimum)
    high = 'inf' if spec.maximum is None else _number(spec.maximum)
    prefix = 'each ' if spec.type in ('double_array', 'integer_array') else ''
    return f'{prefix}{low} to {high}'


def _cell(text: str) -> str:
    return text.replace('|', '\\|').replace('\n', ' ')


def short_description(spec: ParamSpec) -> str:
    """
    Return the first clause of a description (up to its first '.', ';' or ':').

    Parenthesised asides are left out (the README's size limit; docs/parameters.md has them).

    :param spec: the parameter's spec.
    :return: the clause, with ``Read-only.`` for read-only parameters.
    """
    text = spec.description
    depth, cut = 0, len(text)
    for i, char in enumerate(text):
        depth += {'(': 1, ')': -1}.get(char, 0)
        # A clause ends at '. ', '; ' or ': ' outside parentheses ('eq. 8' does not end one).
        # A short lead-in ('Prescription mode:') keeps its clause.
        if depth == 0 and char in '.;:' and text[i + 1:i + 2] in (' ', '') and i > 20 and \
                not text[:i].endswith(('eq', 'e.g', 'i.e')):
            cut = i
            break
    text = re.sub(r' \([^()]*\)', '', text[:cut]) + '.'
    return text + (' Read-only.' if spec.read_only else '')


def params_table(full: bool = False) -> str:
    """
    Return a Markdown table of the schema parameters.

    :param full: every parameter in schema order with its whole description
        (docs/parameters.md), instead of the README's :data:`MAIN` rows with the first clause.
    :return: the table, without a trailing newline.
    :raises KeyError: naming a :data:`MAIN` entry that is neither a parameter nor a group.
    """
    if full:
        rows = ['| name | type | default | range | unit | description |',
                '| --- | --- | --- | --- | --- | --- |']
        for spec in SCHEMA:
            unit = {'': '-', '1': '1'}.get(spec.unit, spec.unit)
            cells: tuple[str, ...] = (
                f'`{spec.name}`', spec.type.replace('_', ' '), f'`{format_default(spec)}`',
                format_range(spec), unit,
                spec.description + (' Read-only.' if spec.read_only else ''))
            rows.append('| ' + ' | '.join(_cell(c) for c in cells) + ' |')
        return '\n'.join(rows)
    # The README's: the type shows in the default (4.0, 0, [], 'raw', true).
    rows = ['| name | default | range | description |', '| --- | --- | --- | --- |']
    specs = {spec.name: spec for spec in SCHEMA}
    labels = dict(FOLDED_GROUPS.values())
    for name in MAIN:
        if name in labels:
            rows.append(f'| `{name}` | - | - | {labels[name]} |')
            continue
        if name not in specs:
            raise KeyError(f'{name}: in MAIN of tools/gen_readme_params.py but not a schema '
                           'parameter or group: update MAIN')
        spec = specs[name]
        unit = {'': '-', '1': '1'}.get(spec.unit, spec.unit)
        span = format_range(spec)
        if unit not in ('-', '1') and span != '-':
            span += f' {unit}'
        cells = (f'`{spec.name}`', f'`{format_default(spec)}`', span, short_description(spec))
        rows.append('| ' + ' | '.join(_cell(c) for c in cells) + ' |')
    return '\n'.join(rows)


def _group(name: str) -> str | None:
    """Return the folded group (a key of :data:`FOLDED_GROUPS`) of a name, or None."""
    return next((prefix for prefix in FOLDED_GROUPS if name.startswith(prefix)), None)


def _members(group: str) -> list[str]:
    """Return the schema names of a folded group, in schema order."""
    return [spec.name for spec in SCHEMA if spec.name.startswith(group)]


def readme_row_names() -> list[str]:
    """
    Return the name of each row of the README's table, in order.

    :return: :data:`MAIN`: schema names and group labels.
    """
    return list(MAIN)


def group_members(label: str) -> list[str]:
    """
    Return the schema names a README row stands for.

    :param label: a row name (a schema name or a group's label).
    :return: the names (one for a plain parameter).
    """
    prefix = next((p for p, (name, _) in FOLDED_GROUPS.items() if name == label), None)
    return [label] if prefix is None else _members(prefix)


def parameters_page() -> str:
    """
    Return docs/parameters.md: every parameter with its whole description.

    :return: the page's text.
    """
    return ('# Parameters of correct_node\n\n'
            '<!-- Generated from mechdeconv_ros/schema/params.py by '
            'python tools/gen_readme_params.py: do not edit. -->\n'
            'Every parameter with its whole description, as `ros2 param describe` shows it '
            "(the README lists the main ones). Defaults are the paper's Case 2.\n\n"
            + params_table(full=True) + '\n')


def update(text: str) -> str:
    """
    Replace the table between the markers of a README.

    :param text: the README.
    :return: the README with the current table.
    :raises ValueError: when the markers are missing or out of order.
    """
    start, end = text.find(START), text.find(END)
    if start < 0 or end < start:
        raise ValueError(f'README needs the lines {START} and {END}, in that order')
    return text[:start] + START + '\n' + params_table() + '\n' + text[end:]


def table_in(text: str) -> str:
    """
    Return what a README holds between the markers, stripped.

    :param text: the README.
    :return: the table text.
    :raises ValueError: when the markers are missing or out of order.
    """
    start, end = text.find(START), text.find(END)
    if start < 0 or end < start:
        raise ValueError(f'README needs the lines {START} and {END}, in that order')
    return text[start + len(START):end].strip()


def main(argv: Sequence[str] | None = None) -> int:
    """
    Rewrite or check the README's parameters table.

    :param argv: arguments (default ``sys.argv[1:]``).
    :return: 0, or 1 when ``--check`` finds the table out of date.
    """
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--readme', type=Path, default=REPO / 'README.md')
    parser.add_argument('--page', type=Path, default=PARAMETERS_PAGE)
    parser.add_argument('--check', action='store_true',
                        help='do not write; exit 1 if the table is out of date')
    args = parser.parse_args(argv)
    text = args.readme.read_text(encoding='utf-8')
    new = update(text)
    page = args.page.read_text(encoding='utf-8') if args.page.exists() else ''
    pairs = ((args.readme, text, new), (args.page, page, parameters_page()))
    outdated = [path for path, old, want in pairs if old != want]
    if args.check:
        for path in outdated:
            print(f'{path}: parameters table is out of date; run '
                  'python tools/gen_readme_params.py', file=sys.stderr)
        return 1 if outdated else 0
    for path in outdated:
        path.write_text(new if path == args.readme else parameters_page(), encoding='utf-8')
        print(f'updated the parameters table of {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
