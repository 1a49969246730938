# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Turn a Zemax ``.zmx`` lens into this package's parameters: the conversion of ``mechdeconv import``.

``mechdeconv import`` runs this (no ROS). Two sources:

- a Zemax ``.zmx`` file (:mod:`mechdeconv_ros.lenses.zmx` reads it) becomes a prescription
  (``lens.surfaces.*``, docs/design.md section 2.2) at one wavelength: this module;
- a datasheet table (:mod:`mechdeconv_ros.lenses.datasheet_csv`) becomes datasheet mode
  (``lens.datasheet.*`` and ``lens.focal_length_mm``).

Both give an :class:`~mechdeconv_ros.lenses.params_file.Imported`, which
:mod:`mechdeconv_ros.lenses.params_file` writes as a ROS 2 params file.

From a ``.zmx`` file, as designed:

- the surfaces between the object surface and the image surface, in order, each with
  radius = 1/CURV (0 flat), thickness DISZ, clear semi-diameter (DIAM, or a smaller CLAP),
  conic and even asphere terms a4..a16 (PARM 2..8); a dummy surface (flat, the same medium
  on both sides) is kept: it changes no ray and keeps the file's surface numbers (ours are
  the file's minus 1);
- ``lens.stop_surface`` the STOP surface, ``lens.aperture_diameter_mm`` twice its clear
  semi-diameter (else the paraxial image of ENPD on it);
- every medium's index at the wavelength (the file's primary one unless given): a catalog
  glass by :func:`mechdeconv_ros.optics.glass.refractive_index`, searched in the file's GCAT
  catalogs first; a model glass (GLAS mode 1) or a glass no catalog holds, by its nd / vd
  (``MODEL:nd:vd``, with a warning); a withdrawn glass the file gives no nd / vd for, by its
  catalog successor of the same name (``BK7`` -> ``SCHOTT:N-BK7``, ``X_MOLD`` -> ``X``, with
  a warning); none of these: refused;
- ``scene.distance_mm``: the object surface's DISZ d (from the first vertex) measured from
  the front principal plane H instead, l = d + z_H (z_H from the first vertex, section 2.2),
  0 for an object at infinity (DISZ INFINITY or >= 1e9 mm);
- ``lens.image_distance_mm``: the image surface's distance from the last lens surface (the
  design's focus, not always the paraxial image).

Refusals raise :class:`LensImportError` naming the file, line or surface and why.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Callable

from mechdeconv_ros.lenses.params_file import Imported
from mechdeconv_ros.lenses.zmx import LensImportError, read, ZmxLens, ZmxSurface
from mechdeconv_ros.optics.prescription import Paraxial, paraxial, Prescription, Surface
from mechdeconv_ros.schema.params import ASPHERE_POWERS, check_values, SPECS

#: The GLAS line's nd / vd when a catalog glass carries no data of its own (Zemax writes
#: 1.5 / 40 as a placeholder): not a usable model glass.
PLACEHOLDER_ND_VD = (1.5, 40.0)


@dataclass(frozen=True)
class Medium:
    """A resolved medium: the ``lens.surfaces.glass`` entry, its index and any warning."""

    glass: str
    index: float
    warning: str = ''


Resolver = Callable[[ZmxLens, ZmxSurface, float], Medium]


def _given_nd_vd(surface: ZmxSurface) -> bool:
    if surface.glass_mode == 1:
        return surface.nd > 1.0 and surface.vd > 0.0
    return (surface.nd > 1.0 and surface.vd > 0.0 and
            (surface.nd, surface.vd) != PLACEHOLDER_ND_VD)


def resolve_medium(lens: ZmxLens, surface: ZmxSurface, wavelength_nm: float) -> Medium:
    """
    Return the medium after ``surface`` at ``wavelength_nm`` (see :func:`_resolve`).

    :param lens: the file (its GCAT catalogs give the search order).
    :param surface: the surface whose GLAS line names the medium ('' = air).
    :param wavelength_nm: the wavelength.
    :return: the medium.
    :raises LensImportError: for a glass no catalog holds and the file gives no nd / vd, or
        a wavelength outside the range of the glass's dispersion formula.
    """
    from mechdeconv_ros.optics.glass import GlassError

    try:
        return _resolve(lens, surface, wavelength_nm)
    except GlassError as err:
        raise LensImportError(f'{lens.path}: line {surface.glass_line}: surface '
                              f'{surface.number}: {err}') from None


def _resolve(lens: ZmxLens, surface: ZmxSurface, wavelength_nm: float) -> Medium:
    """
    Return the medium after ``surface`` at ``wavelength_nm``.

    :param lens: the file (its GCAT catalogs give the search order).
    :param surface: the surface whose GLAS line names the medium ('' = air).
    :param wavelength_nm: the wavelength.
    :return: the medium.
    :raises LensImportError: for a glass no catalog holds and the file gives no nd / vd.
    """
    from mechdeconv_ros.optics import glass as catalog

    name = surface.glass
    where = f'{lens.path}: line {surface.glass_line}: surface {surface.number}'
    if not name or name.upper() == 'AIR':
        return Medium('', 1.0)
    model = f'MODEL:{surface.nd:.6g}:{surface.vd:.6g}'
    if surface.glass_mode == 1 or name.upper().startswith('___BLANK'):
        if not _given_nd_vd(surface):
            raise LensImportError(f'{where}: a model glass without nd and vd')
        return Medium(model, catalog.model_glass_index(surface.nd, surface.vd, wavelength_nm),
                      f'surface {surface.number}: model glass nd {surface.nd:.6g}, vd '
                      f'{surface.vd:.4g}: index extended off the d-line by the model glass '
                      'dispersion (docs/design.md)')
    found = _catalog_glass(catalog, lens.catalogs, name)
    if found is not None:
        qualified = f'{found.catalog}:{found.name}'
        index = catalog.refractive_index(qualified, wavelength_nm)
        warning = ''
        if found.obsolete:
            warning = (f'surface {surface.number}: glass {name} is obsolete (withdrawn from '
                       f'the current catalog); index from the {found.catalog} catalog' "'s "
                       'obsolete-glass data')
        return Medium(qualified, index, warning)
    if _given_nd_vd(surface):
        return Medium(model, catalog.model_glass_index(surface.nd, surface.vd, wavelength_nm),
                      f'surface {surface.number}: glass {name} is in none of the catalogs; '
                      f'used the nd {surface.nd:.6g} and vd {surface.vd:.4g} of its GLAS line '
                      f'as a model glass ({model})')
    successor = _successor(catalog, lens.catalogs, name)
    if successor is not None:
        qualified = f'{successor.catalog}:{successor.name}'
        why = ('a molded variant: the index after moulding differs by about 1e-3'
               if name.upper().endswith('_MOLD') else
               'withdrawn (obsolete): successors differ in the 4th to 5th decimal of the index')
        return Medium(qualified, catalog.refractive_index(qualified, wavelength_nm),
                      f'surface {surface.number}: glass {name} is in none of the catalogs '
                      f'and its GLAS line gives no nd / vd; used {qualified} (nd '
                      f'{successor.nd:.6g}, vd {successor.vd:.4g}), the catalog glass it '
                      f'stands for: {name} is {why}')
    raise LensImportError(f'{where}: glass {name} is in none of the catalogs (searched '
                          f'{", ".join(lens.catalogs + ["all"])}) and its GLAS line gives no '
                          'nd / vd: replace it by a catalog glass or a model glass in the file')


def _catalog_glass(catalog: Any, catalogs: list[str], name: str) -> Any:
    """Return the glass ``name`` from the file's catalogs first, then any; None if none."""
    for candidate in [f'{c}:{name}' for c in catalogs] + [name]:
        try:
            return catalog.lookup(candidate)
        except ValueError:                       # GlassError: unknown, ambiguous
            continue
    return None


def _successor(catalog: Any, catalogs: list[str], name: str) -> Any:
    """
    Return the successor of a withdrawn glass, or None.

    Zemax names a molded variant ``NAME_MOLD`` (the index after moulding differs by about
    1e-3 from the catalog's): the catalog glass ``NAME``. Schott replaced its lead and arsenic
    glasses by ``N-`` (and ``P-``) glasses of the same nd / vd to about 1e-4: BK7 is N-BK7.
    """
    upper = name.upper()
    candidates = []
    if upper.endswith('_MOLD'):
        candidates.append(name[:-len('_MOLD')])
    if not upper.startswith(('N-', 'P-')):
        candidates += [f'N-{name}', f'P-{name}']
    for candidate in candidates:
        found = _catalog_glass(catalog, catalogs, candidate)
        if found is not None:
            return found
    return None


def _semi_diameter(surface: ZmxSurface) -> float:
    if surface.aperture > 0.0 and (surface.semi_diameter == 0.0 or
                                   surface.aperture < surface.semi_diameter):
        return surface.aperture
    return surface.semi_diameter


def _pickup_glass(lens: ZmxLens, surface: ZmxSurface) -> ZmxSurface:
    """Return the surface whose glass ``surface`` picks up (GLAS mode 2), or itself."""
    seen = set()
    while surface.glass_mode == 2 and 0 <= surface.pickup < len(lens.surfaces):
        if surface.number in seen:
            raise LensImportError(f'{lens.path}: line {surface.glass_line}: surface '
                                  f'{surface.number}: glass pick-ups form a loop')
        seen.add(surface.number)
        source = lens.surfaces[surface.pickup]
        if not source.glass:
            break
        surface = source
    return surface


def zmx_values(lens: ZmxLens, wavelength_nm: float | None = None,
               resolve: Resolver = resolve_medium) -> Imported:
    """
    Convert a read ``.zmx`` lens to parameter values (see the module docstring).

    :param lens: from :func:`mechdeconv_ros.lenses.zmx.read`.
    :param wavelength_nm: the wavelength (default: the file's primary wavelength).
    :param resolve: the glass resolver (tests inject their own).
    :return: the values (only the parameters the file sets), comments and warnings.
    :raises LensImportError: as :func:`resolve_medium`, or when the lens is not one this
        package can trace (e.g. afocal).
    """
    wavelength = _wavelength(lens, wavelength_nm)
    out = Imported(values={})
    out.warnings += lens.notes
    surfaces = lens.surfaces[1:-1]
    media = _media(lens, surfaces, wavelength, resolve, out)
    built = _built(surfaces, media)
    para = _paraxial(lens, built)
    _surface_values(out.values, surfaces, built, media)
    _stop_values(lens, built, out)
    distance = lens.object_distance_mm
    out.values['scene.distance_mm'] = (0.0 if math.isinf(distance)
                                       else distance + para.front_principal_z_mm)
    _optional_values(surfaces, media, wavelength, out)
    out.comments[:0] = _comments(lens, wavelength, para.efl_mm, distance)
    _check(lens, out)
    return out


def _wavelength(lens: ZmxLens, wavelength_nm: float | None) -> float:
    """Return the wavelength to import at (nm): the given one, else the file's primary one."""
    wavelength = float(wavelength_nm) if wavelength_nm else lens.primary_wavelength_um * 1e3
    spec = SPECS.get('lens.wavelength_nm')
    low, high = (spec.minimum, spec.maximum) if spec is not None else (200.0, 20000.0)
    if not low <= wavelength <= high:
        given = 'given' if wavelength_nm else "the file's primary wavelength"
        raise LensImportError(f'{lens.path}: wavelength {wavelength:g} nm ({given}) is outside '
                              f'{low:g} to {high:g} nm (lens.wavelength_nm); choose one with '
                              '--wavelength-nm')
    return wavelength


def _media(lens: ZmxLens, surfaces: list[ZmxSurface], wavelength: float, resolve: Resolver,
           out: Imported) -> list[Medium]:
    """Return the medium after each surface (glass pick-ups followed); image space is air."""
    media = []
    for surface in surfaces:
        medium = resolve(lens, _pickup_glass(lens, surface), wavelength)
        media.append(medium)
        if medium.warning and medium.warning not in out.warnings:
            out.warnings.append(medium.warning)
    if media[-1].index != 1.0:
        raise LensImportError(f'{lens.path}: the image space (after surface '
                              f'{surfaces[-1].number}) is not air')
    return media


def _built(surfaces: list[ZmxSurface], media: list[Medium]) -> list[Surface]:
    """Return the prescription's surfaces (the last one's thickness 0: the image distance)."""
    return [Surface(radius_mm=0.0 if s.curvature == 0.0 else 1.0 / s.curvature,
                    thickness_mm=float(s.thickness or 0.0) if i < len(surfaces) - 1 else 0.0,
                    refractive_index=m.index,
                    semi_diameter_mm=_semi_diameter(s),
                    conic=s.conic,
                    asphere=tuple(s.asphere[1:]))
            for i, (s, m) in enumerate(zip(surfaces, media))]


def _paraxial(lens: ZmxLens, built: list[Surface]) -> Paraxial:
    """Return the paraxial data of the surfaces; refuse a lens that has none (afocal)."""
    try:
        return paraxial(Prescription(tuple(built), 0.0))
    except ValueError as err:
        raise LensImportError(f'{lens.path}: {err}') from None


def _surface_values(values: dict[str, Any], surfaces: list[ZmxSurface], built: list[Surface],
                    media: list[Medium]) -> None:
    """Set ``lens.surfaces.*`` (conic and asphere terms only where a surface has them)."""
    values['lens.surfaces.radius_mm'] = [s.radius_mm for s in built]
    values['lens.surfaces.thickness_mm'] = [float(s.thickness or 0.0) for s in surfaces]
    values['lens.surfaces.refractive_index'] = [m.index for m in media]
    values['lens.surfaces.semi_diameter_mm'] = [s.semi_diameter_mm for s in built]
    if any(s.conic for s in built):
        values['lens.surfaces.conic'] = [s.conic for s in built]
    for j, power in enumerate(ASPHERE_POWERS):
        terms = [s.asphere[j] for s in built]
        if any(terms):
            values[f'lens.surfaces.asphere_a{power}'] = terms


def _stop_values(lens: ZmxLens, built: list[Surface], out: Imported) -> None:
    """Set the stop and its diameter, narrowed to what the other semi-diameters pass."""
    values = out.values
    stop = lens.stop_number - 1
    values['lens.stop_surface'] = stop
    values['lens.aperture_diameter_mm'] = _aperture(lens, built, stop, out)
    largest = _largest_aperture(built, stop, lens.object_distance_mm)
    if values['lens.aperture_diameter_mm'] > largest:
        out.warnings.append(f'the stop (file surface {lens.stop_number}) is '
                            f'{values["lens.aperture_diameter_mm"]:.6g} mm wide, but the clear '
                            'semi-diameters of the other surfaces pass a paraxial axial beam '
                            f'through at most {largest:.6g} mm of it: '
                            'lens.aperture_diameter_mm set to that')
        values['lens.aperture_diameter_mm'] = largest


def _optional_values(surfaces: list[ZmxSurface], media: list[Medium], wavelength: float,
                     out: Imported) -> None:
    """Set the wavelength, glass names and image distance (a comment where not a parameter)."""
    optional = {'lens.wavelength_nm': wavelength,
                'lens.surfaces.glass': [m.glass for m in media],
                'lens.image_distance_mm': float(surfaces[-1].thickness or 0.0)}
    if optional['lens.image_distance_mm'] == 0.0:
        out.warnings.append('the image surface is on the last lens vertex: '
                            'lens.image_distance_mm 0 puts the sensor at the paraxial image')
    for name, value in optional.items():
        if name in SPECS:
            out.values[name] = value
        else:
            out.comments.append(f'{name}: {value} (not a parameter of this build)')


def _aperture(lens: ZmxLens, built: list[Surface], stop: int, out: Imported) -> float:
    """Return the stop's physical diameter: 2 x its semi-diameter, else ENPD imaged on it."""
    semi = built[stop].semi_diameter_mm
    if semi > 0.0:
        return 2.0 * semi
    if lens.entrance_pupil_mm > 0.0 and math.isinf(lens.object_distance_mm):
        # Paraxial marginal ray from infinity at the pupil's edge: (y, n u) = (D/2, 0).
        y, nu, index = lens.entrance_pupil_mm / 2.0, 0.0, 1.0
        for surface in built[:stop]:
            nu -= (surface.refractive_index - index) * surface.curvature_per_mm * y
            index = surface.refractive_index
            y += surface.thickness_mm * nu / index
        if abs(y) > 0.0:
            return 2.0 * abs(y)
    out.warnings.append('the stop has no semi-diameter and the file no usable entrance pupil: '
                        'lens.aperture_diameter_mm left at its default; set it')
    return float(SPECS['lens.aperture_diameter_mm'].default)


def _largest_aperture(built: list[Surface], stop: int, object_distance: float) -> float:
    """
    Return the widest stop diameter whose paraxial axial beam every clear semi-diameter passes.

    The paraxial marginal ray from the axial object point (height 1 at the first vertex for
    an object at infinity, else slope 1 from the object) has height y_i at vertex i; a stop of
    radius rho fills surface i to rho |y_i / y_stop|, which must stay within its
    semi-diameter s_i: rho <= s_i |y_stop / y_i|.

    :param built: the surfaces.
    :param stop: the stop's index.
    :param object_distance: the object's distance before the first vertex (``math.inf``).
    :return: the diameter in mm (``math.inf`` when no semi-diameter limits it).
    """
    y, nu, index = (1.0, 0.0, 1.0) if math.isinf(object_distance) else \
        (object_distance, 1.0, 1.0)
    heights = []
    for surface in built:
        heights.append(y)
        nu -= (surface.refractive_index - index) * surface.curvature_per_mm * y
        index = surface.refractive_index
        y += surface.thickness_mm * nu / index
    y_stop = abs(heights[stop])
    if y_stop == 0.0:
        return math.inf
    limits = [s.semi_diameter_mm * y_stop / abs(h) for i, (s, h) in enumerate(zip(built, heights))
              if i != stop and s.semi_diameter_mm > 0.0 and h != 0.0]
    # A hair inside the limit, so the model's own check (the same paraxial ray) passes.
    return 2.0 * min(limits) * (1.0 - 1e-9) if limits else math.inf


def _comments(lens: ZmxLens, wavelength: float, efl: float, distance: float) -> list[str]:
    where = 'infinity' if math.isinf(distance) else f'{distance:.6g} mm before the first vertex'
    title = f' ("{lens.name}")' if lens.name else ''
    return [
        f'Imported by `mechdeconv import` from {Path(lens.path).name}{title}, as designed: '
        f'{len(lens.surfaces) - 2} surfaces (file surfaces 1 to {len(lens.surfaces) - 2}; '
        f'ours are numbered from 0), stop = file surface {lens.stop_number}, object at '
        f'{where}, wavelength {wavelength:.6g} nm, effective focal length {efl:.9g} mm.',
        'The sensor is not in the file: add sensor.pixel_size_x_um, pixel_size_y_um, '
        'width_px and height_px (or leave width/height 0 for the node to take them from the '
        'images).',
    ]


def _check(lens: ZmxLens, out: Imported) -> None:
    """Refuse values that the parameter schema or the model would refuse on loading."""
    from mechdeconv_ros.lenses.lens_errors import ModelError
    from mechdeconv_ros.lenses.lens_params import make_prescription

    try:
        values = check_values(out.values)
        make_prescription(values)
    except ModelError as err:
        raise LensImportError(f'{lens.path}: the imported lens is refused by the model: '
                              f'{err}') from None
    except ValueError as err:
        raise LensImportError(f'{lens.path}: the imported lens does not fit the parameter '
                              f'ranges: {err}') from None


def import_zmx(path: str | Path, wavelength_nm: float | None = None,
               resolve: Resolver = resolve_medium) -> Imported:
    """
    Read a ``.zmx`` file and convert it (:func:`zmx.read`, :func:`zmx_values`).

    :param path: the file.
    :param wavelength_nm: the wavelength (default: the file's primary one).
    :param resolve: the glass resolver.
    :return: the imported values.
    :raises LensImportError: naming the file, line or surface, for anything not imported.
    """
    return zmx_values(read(path), wavelength_nm, resolve)
