# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
An imported lens as a ROS 2 params file: its values, comments and warnings, written atomically.

``mechdeconv import`` converts a lens file (:mod:`mechdeconv_ros.lenses.lens_import` for a
``.zmx`` file, :mod:`mechdeconv_ros.lenses.datasheet_csv` for a datasheet table) into an
:class:`Imported`; this module writes it: the comments and warnings as ``#`` lines wrapped at
99 columns, then ``/**: ros__parameters:`` with the values in the schema's order
(:func:`params_text`). The file is written to a temporary file in the target folder and
renamed (:func:`write_atomically`), so a refusal never leaves a partial file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import os
from pathlib import Path
import tempfile
import textwrap
from typing import Any

from mechdeconv_ros.lenses.zmx import LensImportError
from mechdeconv_ros.schema.params import SPECS, to_params_yaml


@dataclass
class Imported:
    """Parameter values from a lens file, with the comments and warnings that go with them."""

    values: dict[str, Any]
    comments: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def params_text(imported: Imported) -> str:
    """
    Return the params file: the comments, then ``/**: ros__parameters:`` with the values.

    :param imported: from :func:`import_zmx` or the datasheet reader.
    :return: YAML text that :func:`mechdeconv_ros.schema.params.load_params_file` and rclpy load.
    """
    lines = []
    for line in imported.comments + [f'warning: {w}' for w in imported.warnings]:
        lines += textwrap.wrap(line, 97, initial_indent='# ', subsequent_indent='#   ')
    order = [spec.name for spec in SPECS.values() if spec.name in imported.values]
    order += [name for name in imported.values if name not in order]
    return '\n'.join(lines) + '\n' + to_params_yaml(imported.values, names=order)


def write_atomically(path: str | Path, text: str) -> None:
    """
    Write ``text`` to ``path`` through a temporary file in the same folder and a rename.

    :param path: the target.
    :param text: the content.
    :raises LensImportError: when the folder cannot be written.
    """
    target = Path(path)
    try:
        handle, temp = tempfile.mkstemp(prefix=f'.{target.name}.', suffix='.tmp',
                                        dir=str(target.parent.resolve()))
    except OSError as err:
        raise LensImportError(f'{path}: cannot write there: {err.strerror}') from None
    try:
        with os.fdopen(handle, 'w', encoding='utf-8') as stream:
            stream.write(text)
        os.replace(temp, target)
    except OSError as err:
        Path(temp).unlink(missing_ok=True)
        raise LensImportError(f'{path}: cannot write there: {err.strerror}') from None
