# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The one place that decides which lens source the ``lens.*`` parameters describe.

Pure Python, no ROS. :func:`source_for` is the dispatch of docs/design.md section 6.1, in this
order (the first that applies):

1. a datasheet table (``lens.datasheet.field_angle_deg`` not empty):
   :class:`~mechdeconv_ros.lenses.datasheet.TableSource`;
2. a prescription whose gaps move with a joint (a ``lens.m.joint`` set, m in
   :data:`~mechdeconv_ros.schema.params.MECHANISMS`):
   :class:`~mechdeconv_ros.lenses.moving_source.MovingSource` at the given lens state;
3. a surface prescription (``lens.surfaces.radius_mm`` given):
   :class:`~mechdeconv_ros.lenses.lens_source.PrescriptionSource`;
4. else the paper's thick lens: :class:`~mechdeconv_ros.lenses.lens_source.ThickLensSource`.

:func:`~mechdeconv_ros.model.model.build_model` calls it when it is given no source, and so do
the command line and the demo for a moving lens at a lens state. A new kind of lens adds one
line here.
"""

from __future__ import annotations

from typing import Any, Mapping

from mechdeconv_ros.lenses.datasheet import is_table_mode, TableSource
from mechdeconv_ros.lenses.lens_errors import is_prescription_mode
from mechdeconv_ros.lenses.lens_source import LensSource, PrescriptionSource, ThickLensSource
from mechdeconv_ros.lenses.moving_source import MovingSource
from mechdeconv_ros.schema.params import MECHANISMS


def is_moving(values: Mapping[str, Any]) -> bool:
    """
    Return True when a joint moves gaps of the lens (a ``lens.m.joint`` is set).

    :param values: checked parameter values.
    :return: whether any mechanism has a joint.
    """
    return any(values.get(f'lens.{m}.joint') for m in MECHANISMS)


def source_for(values: Mapping[str, Any],
               state: Mapping[str, float] | None = None) -> LensSource:
    """
    Return the lens source of checked parameter values (module doc: the order).

    :param values: checked parameter values.
    :param state: mechanism -> joint position, for a moving lens (missing: the first row of
        its table); ignored by the other sources.
    :return: the source.
    :raises ModelError: naming the parameter when the values describe no lens.
    """
    if is_table_mode(values):
        return TableSource(values)
    if is_moving(values):
        return MovingSource(values, state)
    if is_prescription_mode(values):
        return PrescriptionSource(values)
    return ThickLensSource(values)
