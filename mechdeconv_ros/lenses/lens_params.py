# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Parameters to prescription: the ``lens.*`` values as a traceable lens, and their tolerances.

Pure Python and numpy, no ROS. Thick-lens mode (``lens.surfaces.radius_mm`` empty) builds the
paper's two-surface lens (eq. 7-8, :func:`mechdeconv_ros.optics.thick_lens.thick_lens`; a datasheet
focal length becomes the symmetric biconvex lens of
``optics.biconvex_for_focal_length``) with its stop ``lens.stop_offset_mm`` in front of H;
prescription mode builds the surfaces of ``lens.surfaces.*`` (conic and even asphere terms,
one per surface or none for all 0) with the stop on surface ``lens.stop_surface``.
Conventions: docs/design.md section 1.

Glass by name (docs/design.md section 2.11): ``lens.glass`` (thick lens) and
``lens.surfaces.glass`` (one name per surface) become refractive indices at
``lens.wavelength_nm`` (:func:`with_glass_indices`) before the lens is built; the resolved
values carry the indices and no names, so tolerances perturb the indices. A thick lens given by
``lens.focal_length_mm`` and a glass is designed at the d line (its radii from n_d) and traced
at the wavelength, so its focal length follows the glass's dispersion.

Tolerances: each lens quantity varied by its 1-sigma (``lens.tolerance.*``) is named as a
parameter, ``lens.r1_mm`` or an array element ``lens.surfaces.radius_mm[2]``; every surface of
a prescription gets the tolerance class of the thick-lens parameters.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from mechdeconv_ros.lenses.lens_errors import is_prescription_mode, ModelError
from mechdeconv_ros.optics import glass
from mechdeconv_ros.optics.prescription import Prescription, Surface, vertex_z
from mechdeconv_ros.optics.surfaces import domain_limit_mm
from mechdeconv_ros.optics.thick_lens import biconvex_for_focal_length, thick_lens
from mechdeconv_ros.schema.params import ASPHERE_POWERS


def make_prescription(values: Mapping[str, Any]) -> Prescription:
    """
    Build the lens from the ``lens.*`` values.

    :param values: checked parameter values.
    :return: the thick lens (two surfaces, stop at ``z_H - m_a``) or the prescription.
    :raises ModelError: when the description is not a lens that focuses.
    """
    values = with_glass_indices(values)
    if is_prescription_mode(values):
        return _surface_prescription(values)
    n = float(values['lens.refractive_index'])
    t = float(values['lens.thickness_mm'])
    if n <= 1.0:
        raise ModelError('lens.refractive_index',
                         f'n = {n:g} is not glass: a lens needs an index above 1 (air)')
    f_nominal = float(values['lens.focal_length_mm'])
    r1, r2 = float(values['lens.r1_mm']), float(values['lens.r2_mm'])
    if f_nominal > 0.0:
        try:
            radius = biconvex_for_focal_length(f_nominal, n, t)
        except ValueError as err:
            raise ModelError('lens.focal_length_mm', str(err)) from None
        r1, r2 = radius, -radius
    try:
        return thick_lens(n, r1, r2, t, float(values['lens.stop_offset_mm']),
                          float(values['lens.aperture_diameter_mm']))
    except ValueError as err:
        raise ModelError('lens.r1_mm', f'r1 = {r1:g} mm, r2 = {r2:g} mm, t = {t:g} mm: {err}'
                         ) from None


def _glass_index(name: str, wavelength_nm: float, parameter: str, where: str) -> float:
    """Return a named glass's index at the wavelength, or refuse naming the parameter."""
    try:
        found = glass.lookup(name)
    except glass.GlassError as err:
        raise ModelError(parameter, f'{where}{err}') from None
    try:
        return float(found.index(wavelength_nm))
    except glass.GlassError as err:
        raise ModelError('lens.wavelength_nm', f'{where}{err}') from None


def with_glass_indices(values: Mapping[str, Any]) -> Mapping[str, Any]:
    """
    Return the values with every named glass replaced by its index at ``lens.wavelength_nm``.

    Thick-lens mode: ``lens.glass`` sets ``lens.refractive_index`` (and, with
    ``lens.focal_length_mm``, the radii of the biconvex lens designed at the d line, which
    become ``lens.r1_mm``/``lens.r2_mm`` with the focal length then 0). Prescription mode:
    each non-empty ``lens.surfaces.glass`` name other than AIR sets that surface's
    ``lens.surfaces.refractive_index`` (which may be empty: '' and AIR are 1.0 then). The
    names are cleared, so resolving twice changes nothing. Values without names are returned
    as they are.

    :param values: checked parameter values.
    :return: the values (a new dict when a glass was resolved).
    :raises ModelError: naming ``lens.glass`` or ``lens.surfaces.glass`` (and the surface) for
        an unknown or ambiguous glass or a misplaced name, ``lens.wavelength_nm`` for a
        wavelength outside the glass's formula range.
    """
    thick = str(values.get('lens.glass', '') or '').strip()
    names = [str(n) for n in values.get('lens.surfaces.glass', []) or []]
    if not thick and not names:
        return values
    prescription_mode = is_prescription_mode(values)
    if thick and prescription_mode:
        raise ModelError('lens.glass', f"{thick!r} names the thick lens's glass, but "
                                       'lens.surfaces.* describe the lens: name the glass of '
                                       'each surface in lens.surfaces.glass')
    if names and not prescription_mode:
        raise ModelError('lens.surfaces.glass', 'names the glasses of a prescription, but '
                                                'lens.surfaces.radius_mm is empty (thick-lens '
                                                'mode): use lens.glass')
    wave = float(values['lens.wavelength_nm'])
    out = {k: (list(v) if isinstance(v, list) else v) for k, v in values.items()}
    if thick:
        out['lens.glass'] = ''
        out['lens.refractive_index'] = _glass_index(thick, wave, 'lens.glass', '')
        focal = float(values['lens.focal_length_mm'])
        if focal > 0.0:
            n_d = _glass_index(thick, glass.LINES_NM['d'], 'lens.glass', '')
            try:
                radius = biconvex_for_focal_length(focal, n_d, float(values['lens.thickness_mm']))
            except ValueError as err:
                raise ModelError('lens.focal_length_mm', f'{thick} (n_d = {n_d:.6g}): {err}'
                                 ) from None
            out['lens.r1_mm'], out['lens.r2_mm'] = radius, -radius
            out['lens.focal_length_mm'] = 0.0
        return out
    count = len(values['lens.surfaces.radius_mm'])
    given = [float(n) for n in values['lens.surfaces.refractive_index']]
    if len(names) != count:
        raise ModelError('lens.surfaces.glass', f'has {len(names)} names but '
                                                f'lens.surfaces.radius_mm has {count}: give one '
                                                "per surface ('' = its refractive_index), or "
                                                'none')
    if given and len(given) != count:
        return values   # _surface_prescription refuses the index array's length
    indices = []
    for i, name in enumerate(names):
        text = name.strip()
        if not text or text.upper() == 'AIR':
            indices.append(given[i] if given else 1.0)
        else:
            indices.append(_glass_index(text, wave, 'lens.surfaces.glass', f'surface {i}: '))
    out['lens.surfaces.refractive_index'] = indices
    out['lens.surfaces.glass'] = []
    return out


def _surface_prescription(values: Mapping[str, Any]) -> Prescription:
    radii = list(values['lens.surfaces.radius_mm'])
    count = len(radii)
    arrays = {}
    for name in ('thickness_mm', 'refractive_index', 'semi_diameter_mm'):
        key = f'lens.surfaces.{name}'
        array = list(values[key])
        if name == 'semi_diameter_mm' and not array:
            array = [0.0] * count
        if len(array) != count:
            raise ModelError(key, f'has {len(array)} values but lens.surfaces.radius_mm has '
                                  f'{count}: give one per surface')
        arrays[name] = array
    stop = int(values['lens.stop_surface'])
    if not 0 <= stop < count:
        raise ModelError('lens.stop_surface',
                         f'{stop} is not a surface index (the prescription has {count} '
                         f'surfaces: 0 to {count - 1})')
    if arrays['refractive_index'][-1] != 1.0:
        raise ModelError('lens.surfaces.refractive_index',
                         'the last surface must end in air (index 1.0): the sensor is in air')
    conics = _per_surface(values, 'lens.surfaces.conic', count)
    terms = [_per_surface(values, f'lens.surfaces.asphere_a{p}', count) for p in ASPHERE_POWERS]
    surfaces = tuple(
        Surface(float(r), float(t), float(n), float(s), conics[i],
                tuple(term[i] for term in terms))
        for i, (r, t, n, s) in enumerate(zip(radii, arrays['thickness_mm'],
                                             arrays['refractive_index'],
                                             arrays['semi_diameter_mm'])))
    for i, surface in enumerate(surfaces):
        limit = domain_limit_mm(surface)
        # (A sphere wider than its hemisphere is the semi-diameter's fault: checked below.)
        if surface.conic != 0.0 and 0.0 < surface.semi_diameter_mm and \
                limit < surface.semi_diameter_mm:
            raise ModelError('lens.surfaces.conic',
                             f'surface {i}: k = {surface.conic:g} with radius '
                             f'{surface.radius_mm:g} mm leaves the sag undefined beyond r = '
                             f'{limit:.4g} mm, inside its semi-diameter '
                             f'{surface.semi_diameter_mm:g} mm')
    try:
        probe = Prescription(surfaces, 0.0)
        return Prescription(surfaces, float(vertex_z(probe)[stop]))
    except ValueError as err:
        raise ModelError('lens.surfaces.radius_mm', str(err)) from None


def _per_surface(values: Mapping[str, Any], key: str, count: int) -> list[float]:
    """Return the array ``key`` with one value per surface (empty = all 0)."""
    array = [float(v) for v in values[key]]
    if not array:
        return [0.0] * count
    if len(array) != count:
        raise ModelError(key, f'has {len(array)} values but lens.surfaces.radius_mm has '
                              f'{count}: give one per surface, or none for all 0')
    for i, value in enumerate(array):
        if not math.isfinite(value):
            raise ModelError(key, f'value {i} is {value}: coefficients must be finite')
    return array


def tolerance_keys(values: Mapping[str, Any]) -> tuple[dict[str, float], dict[str, float]]:
    """Return the scalar lens quantities with their 1-sigma tolerances, for propagation."""
    tol = {'r': float(values['lens.tolerance.r1_mm']),
           't': float(values['lens.tolerance.thickness_mm']),
           'n': float(values['lens.tolerance.refractive_index'])}
    nominal: dict[str, float] = {}
    sigmas: dict[str, float] = {}
    if is_prescription_mode(values):
        # Every surface gets the tolerance class of the thick-lens parameters.
        for kind, key, sigma in (('radius_mm', 'r', tol['r']), ('thickness_mm', 't', tol['t']),
                                 ('refractive_index', 'n', tol['n'])):
            for i, value in enumerate(values[f'lens.surfaces.{kind}']):
                if kind == 'radius_mm' and value == 0.0:
                    continue
                if kind == 'refractive_index' and value == 1.0:
                    continue
                nominal[f'lens.surfaces.{kind}[{i}]'] = float(value)
                sigmas[f'lens.surfaces.{kind}[{i}]'] = sigma
    else:
        for name, sigma_name in (('lens.r1_mm', 'lens.tolerance.r1_mm'),
                                 ('lens.r2_mm', 'lens.tolerance.r2_mm'),
                                 ('lens.thickness_mm', 'lens.tolerance.thickness_mm'),
                                 ('lens.refractive_index', 'lens.tolerance.refractive_index')):
            if name in ('lens.r1_mm', 'lens.r2_mm') and (
                    float(values['lens.focal_length_mm']) > 0.0 or values[name] == 0.0):
                continue
            nominal[name] = float(values[name])
            sigmas[name] = float(values[sigma_name])
    return nominal, sigmas


def with_overrides(values: Mapping[str, Any], scalars: Mapping[str, float]) -> dict[str, Any]:
    """Return a copy of ``values`` with scalar (and ``name[i]`` array element) overrides."""
    out = {k: (list(v) if isinstance(v, list) else v) for k, v in values.items()}
    for key, value in scalars.items():
        if key.endswith(']'):
            name, index = key[:-1].split('[')
            out[name][int(index)] = value
        else:
            out[key] = value
    return out
