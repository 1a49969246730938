# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A prescription whose air gaps move with the zoom and focus joints (issue 19), as a lens source.

:class:`MovingSource` is a :class:`~mechdeconv_ros.lenses.lens_source.PrescriptionSource` traced at
one lens state (``{'zoom': p, 'focus': q}``, joint positions; default the first row of each table):
its surfaces are ``lens.surfaces.*`` with the moving gaps of
:func:`mechdeconv_ros.lenses.lens_table.values_at` (linear between table rows, clamped outside).
Its ``values`` are those of that still lens, so every rule names ``lens.surfaces.*`` as for any
prescription; the tables themselves (shape, positions, gap indices) are checked first, naming
``lens.zoom.*`` / ``lens.focus.*``, and :meth:`MovingSource.check_physical` applies the
physical rules (:func:`mechdeconv_ros.lenses.refusals.check_first_order` and the surface rules) to
every reachable state, every row and mid-row and their combinations, naming the row of a
refusal (``lens.zoom.thickness_mm: at lens.zoom row 3 (position 0.1875) the lens cannot exist:
...``). :func:`mechdeconv_ros.lenses.sources.source_for` picks it when a ``lens.m.joint`` is
set.
"""

from __future__ import annotations

from typing import Any, Mapping

from mechdeconv_ros.lenses import lens_table
from mechdeconv_ros.lenses import refusals
from mechdeconv_ros.lenses.lens_source import ModelError, PrescriptionSource, with_overrides


def _still_rules(values: Mapping[str, Any]) -> list[str]:
    """Apply every rule that needs no trace to a still lens; return its warnings."""
    source = PrescriptionSource(values)
    _, distance, sensor_z, _ = refusals.check_first_order(values, source)
    return source.check_physical(distance, sensor_z)


class MovingSource(PrescriptionSource):
    """A surface prescription with moving gaps, at one lens state (module doc)."""

    mode = 'prescription'

    def __init__(self, values: Mapping[str, Any],
                 state: Mapping[str, float] | None = None) -> None:
        """
        Make the lens at a state.

        :param values: checked parameter values with at least one ``lens.m.joint``.
        :param state: mechanism -> joint position (missing: the table's first row).
        :raises ModelError: naming the table parameter at fault, or the lens's.
        """
        try:
            self.moving = lens_table.mechanisms(values)
        except lens_table.TableError as err:
            raise ModelError(err.parameter, err.reason) from None
        self.table_values = values
        self.state = {m.name: float((state or {}).get(m.name, m.positions[0]))
                      for m in self.moving}
        super().__init__(lens_table.values_at(values, self.state, self.moving))

    def check_physical(self, distance_mm: float, sensor_z_mm: float) -> list[str]:
        """Apply the surface rules here, then every rule at every reachable state."""
        warnings = super().check_physical(distance_mm, sensor_z_mm)
        try:
            lens_table.check_reachable(self.table_values, _still_rules, self.moving)
        except lens_table.TableError as err:
            raise ModelError(err.parameter, err.reason) from None
        return warnings

    def perturbed(self, scalars: Mapping[str, float]) -> MovingSource:
        """Return the lens at the same state with ``scalars`` overriding its values."""
        return type(self)(with_overrides(self.table_values, scalars), self.state)
