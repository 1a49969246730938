# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Regenerate the parameters table of README.md from the schema (mechdeconv_ros.params.SCHEMA).

The table sits between the lines ``<!-- params:start -->`` and ``<!-- params:end -->``; the
rest of the README is left alone. Usage::

    python tools/gen_readme_params.py           # rewrite README.md in place
    python tools/gen_readme_params.py --check   # exit 1 if README.md is out of date

test/test_readme.py asserts that the README table equals :func:`params_table`.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
from typing import Sequence

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from mechdeconv_ros.params import ParamSpec, SCHEMA  # noqa: E402 - after the sys.path fix

START = '<!-- params:start -->'
END = '<!-- params:end -->'


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
    return str(value)


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
    prefix = 'each ' if spec.type == 'double_array' else ''
    return f'{prefix}{low} to {high}'


def _cell(text: str) -> str:
    return text.replace('|', '\\|').replace('\n', ' ')


def params_table() -> str:
    """
    Return the Markdown table of every schema parameter, in schema order.

    :return: the table, one row per parameter, without a trailing newline.
    """
    rows = ['| name | type | default | range | unit | description |',
            '| --- | --- | --- | --- | --- | --- |']
    for spec in SCHEMA:
        unit = {'': '-', '1': '1'}.get(spec.unit, spec.unit)
        description = spec.description + (' Read-only.' if spec.read_only else '')
        cells = (f'`{spec.name}`', spec.type.replace('_', ' '), f'`{format_default(spec)}`',
                 format_range(spec), unit, description)
        rows.append('| ' + ' | '.join(_cell(c) for c in cells) + ' |')
    return '\n'.join(rows)


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
    parser.add_argument('--check', action='store_true',
                        help='do not write; exit 1 if the table is out of date')
    args = parser.parse_args(argv)
    text = args.readme.read_text(encoding='utf-8')
    new = update(text)
    if args.check:
        if new != text:
            print(f'{args.readme}: parameters table is out of date; run '
                  'python tools/gen_readme_params.py', file=sys.stderr)
            return 1
        return 0
    if new != text:
        args.readme.write_text(new, encoding='utf-8')
        print(f'updated the parameters table of {args.readme}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
