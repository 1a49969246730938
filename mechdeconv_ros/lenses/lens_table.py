# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Moving lens groups: the zoom and focus tables, checked, and the gaps at a lens state.

A motorised zoom or focus moves groups of elements along the axis; in a prescription that is a
change of some AIR gaps (``lens.surfaces.thickness_mm[i]``, the axial distance from surface i
to surface i + 1, mm) while the glass stays as it is. For each mechanism m in
:data:`~mechdeconv_ros.schema.params.MECHANISMS` (``zoom``, ``focus``) the parameters

    ``lens.m.joint``         the sensor_msgs/JointState joint that carries its position
                             ('' = the mechanism does not move: its table is ignored);
    ``lens.m.positions``     p_0 < p_1 < ... < p_(n-1), n >= 2, in the joint's unit;
    ``lens.m.surfaces``      the gap indices i_0 .. i_(k-1) it moves;
    ``lens.m.thickness_mm``  n x k, row-major: row j holds those gaps at p_j

give, at a joint position p, each moving gap by linear interpolation between the two rows
around it,

    g(p) = g_j + (g_(j+1) - g_j) (p - p_j) / (p_(j+1) - p_j),     p_j <= p <= p_(j+1),

and outside the table the first or last row (clamped: :attr:`Mechanism.clamped` says so, the
node warns, throttled). A lens state is ``{'zoom': p_zoom, 'focus': p_focus}`` (names of the
mechanisms, not of the joints); a mechanism missing from it sits at its first row.

Refused, naming the parameter (:class:`TableError`, a ``ValueError`` whose text is
``<parameter>: <reason>``, as the model's refusals): a table whose length is not n x k, fewer
than 2 or not strictly increasing positions, a gap index out of range, on a glass thickness
(the medium after surface i is not air), the last entry (the image distance, which the model
computes) or moved by both mechanisms, and a moving joint without a prescription. Every
reachable lens (every row, and half-way between consecutive rows, of each mechanism, and their
combinations) must pass the model's physical rules: :func:`check_reachable` runs a given check
on each and names the row of a refusal. No ROS, no model import: the check is injected.
"""

from __future__ import annotations

from dataclasses import dataclass
import itertools
import math
from typing import Any, Callable, Iterator, Mapping

from mechdeconv_ros.lenses.lens_errors import TableError
from mechdeconv_ros.schema.params import MAX_TABLE_ROWS, MECHANISMS
import numpy as np

#: A lens state: mechanism name (``'zoom'``, ``'focus'``) -> joint position.
LensState = Mapping[str, float]


@dataclass(frozen=True)
class Mechanism:
    """One checked moving-group table (see the module doc)."""

    name: str
    joint: str
    positions: np.ndarray       # (n,) strictly increasing
    surfaces: tuple[int, ...]   # gap indices
    rows: np.ndarray            # (n, k) gaps, mm

    def gaps_at(self, position: float) -> np.ndarray:
        """
        Return the moving gaps at a joint position (linear between rows, clamped outside).

        :param position: the joint position.
        :return: ``(k,)`` gaps, mm.
        """
        p = self.positions
        x = min(max(float(position), float(p[0])), float(p[-1]))
        j = int(np.clip(np.searchsorted(p, x, side='right') - 1, 0, p.size - 2))
        t = (x - p[j]) / (p[j + 1] - p[j])
        return self.rows[j] + (self.rows[j + 1] - self.rows[j]) * t

    def clamped(self, position: float) -> bool:
        """Return True when ``position`` lies outside the table (the gaps are clamped)."""
        return not float(self.positions[0]) <= float(position) <= float(self.positions[-1])

    @property
    def step(self) -> float:
        """Return the smallest spacing of the table's positions (its resolution)."""
        return float(np.min(np.diff(self.positions)))

    def probe_positions(self) -> np.ndarray:
        """Return every row position and the mid-point of each pair of rows, increasing."""
        p = self.positions
        out = np.empty(2 * p.size - 1)
        out[0::2] = p
        out[1::2] = 0.5 * (p[:-1] + p[1:])
        return out


def _prefix(mechanism: str) -> str:
    return f'lens.{mechanism}'


def mechanisms(values: Mapping[str, Any]) -> tuple[Mechanism, ...]:
    """
    Return the moving mechanisms of a parameter set (those with a joint), checked.

    :param values: checked parameter values (every schema name).
    :return: the mechanisms in :data:`MECHANISMS` order; empty for a lens that does not move.
    :raises TableError: naming the parameter of a table that cannot be used.
    """
    out = []
    moved: dict[int, str] = {}
    for name in MECHANISMS:
        prefix = _prefix(name)
        joint = str(values.get(f'{prefix}.joint', ''))
        if not joint:
            continue
        radii = list(values.get('lens.surfaces.radius_mm', []))
        if not radii:
            raise TableError(f'{prefix}.joint',
                             f'{joint!r} moves lens groups, which needs a prescription '
                             '(lens.surfaces.*): the thick lens has no air gaps')
        thickness = list(values['lens.surfaces.thickness_mm'])
        index = list(values['lens.surfaces.refractive_index'])
        positions = np.asarray(values.get(f'{prefix}.positions', []), dtype=np.float64)
        surfaces = [int(i) for i in values.get(f'{prefix}.surfaces', [])]
        table = np.asarray(values.get(f'{prefix}.thickness_mm', []), dtype=np.float64)
        if positions.size < 2:
            raise TableError(f'{prefix}.positions',
                             f'has {positions.size} values: a moving {name} needs at least 2 '
                             'joint positions')
        if positions.size > MAX_TABLE_ROWS:
            raise TableError(f'{prefix}.positions',
                             f'has {positions.size} values, more than the {MAX_TABLE_ROWS} '
                             'rows a table may have')
        if not np.all(np.isfinite(positions)):
            raise TableError(f'{prefix}.positions', 'every position must be finite')
        steps = np.diff(positions)
        if np.any(steps <= 0.0):
            j = int(np.argmax(steps <= 0.0))
            raise TableError(f'{prefix}.positions',
                             f'must be strictly increasing: positions[{j + 1}] = '
                             f'{positions[j + 1]:g} does not follow positions[{j}] = '
                             f'{positions[j]:g}')
        if not surfaces:
            raise TableError(f'{prefix}.surfaces',
                             f'is empty: name the gaps (indices into lens.surfaces.thickness_mm) '
                             f'the {name} moves')
        for i in surfaces:
            if not 0 <= i < len(thickness):
                raise TableError(f'{prefix}.surfaces',
                                 f'{i} is not an index of lens.surfaces.thickness_mm (0 to '
                                 f'{len(thickness) - 1})')
            if i == len(thickness) - 1:
                raise TableError(f'{prefix}.surfaces',
                                 f'{i} is the last entry of lens.surfaces.thickness_mm, the '
                                 'image distance, which the model computes: it cannot move')
            if i < len(index) and float(index[i]) != 1.0:
                raise TableError(f'{prefix}.surfaces',
                                 f'{i} is a glass thickness (lens.surfaces.refractive_index[{i}]'
                                 f' = {float(index[i]):g}): only air gaps move')
            if i in moved:
                raise TableError(f'{prefix}.surfaces',
                                 f'gap {i} is moved by lens.{moved[i]}.surfaces already: a gap '
                                 'has one mechanism')
            moved[i] = name
        if len(set(surfaces)) != len(surfaces):
            raise TableError(f'{prefix}.surfaces', 'names a gap twice')
        expected = positions.size * len(surfaces)
        if table.size != expected:
            raise TableError(f'{prefix}.thickness_mm',
                             f'has {table.size} values but needs len(positions) x '
                             f'len(surfaces) = {positions.size} x {len(surfaces)} = {expected} '
                             '(row j: the gaps at positions[j])')
        if not np.all(np.isfinite(table)) or np.any(table < 0.0):
            bad = int(np.argmax(~np.isfinite(table) | (table < 0.0)))
            raise TableError(f'{prefix}.thickness_mm',
                             f'value {bad} (row {bad // len(surfaces)}) is {table[bad]:g}: gaps '
                             'must be finite and >= 0 mm')
        out.append(Mechanism(name, joint, positions, tuple(surfaces),
                             table.reshape(positions.size, len(surfaces))))
    return tuple(out)


def thicknesses_at(values: Mapping[str, Any], moving: tuple[Mechanism, ...],
                   state: LensState) -> list[float]:
    """
    Return ``lens.surfaces.thickness_mm`` with the moving gaps at a lens state.

    :param values: checked parameter values.
    :param moving: :func:`mechanisms` of those values.
    :param state: mechanism -> joint position (a missing mechanism sits at its first row).
    :return: the thicknesses, mm.
    """
    thickness = [float(t) for t in values['lens.surfaces.thickness_mm']]
    for mech in moving:
        position = state.get(mech.name, float(mech.positions[0]))
        for i, gap in zip(mech.surfaces, mech.gaps_at(position)):
            thickness[i] = float(gap)
    return thickness


def values_at(values: Mapping[str, Any], state: LensState,
              moving: tuple[Mechanism, ...] | None = None) -> dict[str, Any]:
    """
    Return the parameter values of the lens at a state: the gaps moved, the joints off.

    The result describes a lens that does not move (``lens.m.joint`` = ''), so it can be built
    and checked like any other set.

    :param values: checked parameter values.
    :param state: mechanism -> joint position.
    :param moving: :func:`mechanisms` of ``values`` (computed when None).
    :return: a new dict.
    :raises TableError: when the tables cannot be used.
    """
    moving = mechanisms(values) if moving is None else moving
    out = dict(values)
    if moving:
        out['lens.surfaces.thickness_mm'] = thicknesses_at(values, moving, state)
    for name in MECHANISMS:
        out[f'{_prefix(name)}.joint'] = ''
    return out


def reachable_states(moving: tuple[Mechanism, ...]) -> Iterator[tuple[dict[str, float],
                                                                      dict[str, int]]]:
    """
    Yield the lens states a set is checked at: every row and mid-row, all combinations.

    :param moving: the mechanisms.
    :return: ``(state, rows)`` pairs, ``rows`` the row index of each mechanism (a mid-point
        between rows j and j + 1 counts as row j + 0.5 and is reported as ``j``).
    """
    probes = [m.probe_positions() for m in moving]
    for combo in itertools.product(*(range(p.size) for p in probes)):
        state = {m.name: float(p[c]) for m, p, c in zip(moving, probes, combo)}
        yield state, {m.name: c for m, c in zip(moving, combo)}


def check_reachable(values: Mapping[str, Any], check: Callable[[Mapping[str, Any]], Any],
                    moving: tuple[Mechanism, ...] | None = None) -> int:
    """
    Run ``check`` on the lens at every reachable state; refuse naming the row at fault.

    :param values: checked parameter values.
    :param check: raises ``ValueError`` (a ModelError) for a lens that cannot exist, e.g. the
        model's physical rules.
    :param moving: :func:`mechanisms` of ``values`` (computed when None).
    :return: the number of states checked (0 for a lens that does not move).
    :raises TableError: naming ``lens.m.thickness_mm`` (the mechanism whose table was moved
        last, so the first at fault), its row and position, and the check's reason.
    """
    moving = mechanisms(values) if moving is None else moving
    if not moving:
        return 0
    count = 0
    for state, probes in reachable_states(moving):
        count += 1
        try:
            check(values_at(values, state, moving))
        except ValueError as err:
            where = []
            for mech in moving:
                probe = probes[mech.name]
                row = probe // 2
                if probe % 2:
                    where.append(f'lens.{mech.name} half-way between rows {row} and {row + 1} '
                                 f'(position {state[mech.name]:g})')
                else:
                    where.append(f'lens.{mech.name} row {row} (position {state[mech.name]:g})')
            blame = moving[-1].name if len(moving) == 1 or probes[moving[-1].name] else \
                moving[0].name
            raise TableError(f'lens.{blame}.thickness_mm',
                             f'at {" and ".join(where)} the lens cannot exist: {err}') from None
    return count


def parse_lens_state(text: str) -> dict[str, float]:
    """
    Parse a command-line lens state, ``zoom=X[,focus=Y]``.

    :param text: the option's value.
    :return: mechanism -> position.
    :raises ValueError: naming ``--lens-state`` for anything else.
    """
    state: dict[str, float] = {}
    for item in text.split(','):
        name, sep, number = item.partition('=')
        name = name.strip()
        if not sep or name not in MECHANISMS:
            raise ValueError(f'--lens-state: expected zoom=X[,focus=Y], got {text!r}')
        try:
            value = float(number)
        except ValueError:
            raise ValueError(f'--lens-state: {name} = {number.strip()!r} is not a number'
                             ) from None
        if not math.isfinite(value):
            raise ValueError(f'--lens-state: {name} must be finite, got {number.strip()!r}')
        if name in state:
            raise ValueError(f'--lens-state: {name} given twice')
        state[name] = value
    return state
