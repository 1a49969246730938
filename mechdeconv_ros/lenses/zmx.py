# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Read a Zemax OpticStudio sequential lens file (``.zmx``) into a plain description.

No ROS, no glass data: this module only reads the file and refuses what this package's model
(a rotationally symmetric, centred, refracting lens: docs/design.md section 2.2) cannot
trace. :mod:`mechdeconv_ros.lenses.lens_import` turns the result into parameters.

The file
--------
Text, ASCII / UTF-8 / Latin-1 or UTF-16 with a byte-order mark, CRLF or LF line ends. One
keyword per line; the lines of a surface follow its ``SURF n`` line, indented. Read here:

- ``UNIT MM|CM|IN|METER`` lens units (converted to mm: curvatures divide, lengths multiply);
- ``WAVM slot um weight`` (or an older ``WAVL um um ...``) and ``PWAV slot``: wavelengths in
  um and the primary one; ``FTYP type ...`` and ``YFLN``: the field type (0 angle in deg,
  1 object height, 2 paraxial and 3 real image height, those in lens units) and the y field
  values (the design field, named in the import's comments); ``ENPD`` (lens units) or
  ``FNUM`` (image-space F/#, EFL / ENPD): the system aperture, which sets the stop when the
  stop has no fixed semi-diameter;
  ``GCAT`` the glass catalogs in the file's order of search; ``MODE``; ``MNUM`` (number of
  configurations: the surface data hold the current one);
- per surface: ``TYPE`` (STANDARD when absent), ``CURV c`` (1/mm, radius = 1/c, 0 = flat),
  ``DISZ t`` (to the next surface; ``INFINITY`` for an object at infinity), ``GLAS name mode
  pickup nd vd ...`` (the medium after the surface; mode 1 is a model glass of nd/vd, mode 2
  a pick-up of surface ``pickup``; ``___BLANK`` with vd 0 is a constant index nd, as Zemax and
  rayoptics read it), ``CONI k``, ``PARM j a`` (on an EVENASPH surface only: term j is a
  r^(2j), j = 1 .. 8; a STANDARD surface keeps stale PARM values from an earlier type, which
  are not its sag and are ignored with a note), ``DIAM s solve`` (the semi-diameter: solve 0
  is Zemax's automatic one, the beam footprint it computed, not an aperture, so it is not
  imported; fixed (1) or picked up (2) it is the clear semi-diameter), ``CLAP rmin rmax`` (a
  circular aperture: the smaller of it and DIAM; an annulus, rmin > 0, is refused), ``STOP``,
  ``SCBD`` / ``SCAD`` (tilts and decenters before / after the surface) and ``COMM``. Apertures
  this model cannot honour are refused by name: ``SQAP`` / ``ELAP`` (rectangular, elliptical),
  ``OBSC`` / ``SQOB`` / ``ELOB`` (obscurations), ``SPID`` (spider), ``UDAP`` / ``UDOB``
  (user-defined).

Everything else (coatings, tolerances, multi-configuration operands, merit functions,
drawing and POP settings) is read past. The sag of a STANDARD / EVENASPH surface is
z = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2)) + sum_j a_j r^(2j): this package's sag
(docs/design.md section 2.2) when a_1 (r^2) is 0, which is checked.

Surfaces keep the file's numbers (object surface 0, the last one the image surface) in
:class:`ZmxSurface` and in every message, which names the file, the line and the surface.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path

from mechdeconv_ros.optics.pose import rot_x, rot_y, sensor_tilts_of_break

#: Surface types this package traces.
SUPPORTED_TYPES = ('STANDARD', 'EVENASPH')

#: The coordinate break: imported just before the image surface (the sensor's pose), dropped
#: when it moves nothing, refused anywhere else (:func:`fold_breaks`).
BREAK_TYPE = 'COORDBRK'
#: Largest sensor tilt a coordinate break may give (deg; ``sensor.tilt_*_deg``'s range).
MAX_BREAK_TILT_DEG = 10.0
#: Largest sensor decenter it may give (mm; ``sensor.axis_offset_*_mm``'s range).
MAX_BREAK_DECENTER_MM = 100.0

#: Surface types refused with a reason (what the model cannot trace), by type-name prefix.
_REFUSED_TYPES = (
    ('COORDBRK', 'a coordinate break (the lens is not centred on one axis)'),
    ('TOROIDAL', 'a toroidal surface (not rotationally symmetric)'),
    ('BICONIC', 'a biconic surface (not rotationally symmetric)'),
    ('CYLINDER', 'a cylinder lens (not rotationally symmetric)'),
    ('GRIN', 'a gradient-index medium'),
    ('GRADIENT', 'a gradient-index medium'),
    ('GRADIUM', 'a gradient-index medium'),
    ('DGRATING', 'a diffraction grating'),
    ('GRATING', 'a diffraction grating'),
    ('ELGRATIN', 'a diffraction grating'),
    ('VOLPHASE', 'a volume-phase hologram'),
    ('HOLOGRM', 'a hologram'),
    ('BINARY', 'a diffractive (binary optic) surface'),
    ('NONSEQCO', 'a non-sequential component'),
    ('BLACKBOX', 'an encrypted black box (its prescription is hidden)'),
    ('PARAXIAL', 'an ideal paraxial lens (no real ray trace exists)'),
    ('ODDASPHE', 'an odd asphere (odd powers of r)'),
    ('QTYPE', 'a Q-type (Forbes) asphere'),
    ('QED', 'a Q-type (Forbes) asphere'),
    ('XPOLYNOM', 'a freeform polynomial surface'),
    ('SZERNSAG', 'a Zernike freeform surface'),
    ('FZERNSAG', 'a Zernike freeform surface'),
    ('USERSURF', 'a user-defined (DLL) surface'),
    ('TILTSURF', 'a tilted surface'),
    ('FRESNEL', 'a Fresnel surface'),
)

#: Aperture keywords of a surface this model cannot honour, and what they are.
_REFUSED_APERTURES = {
    'SQAP': 'a rectangular aperture', 'ELAP': 'an elliptical aperture',
    'OBSC': 'a circular obscuration', 'SQOB': 'a rectangular obscuration',
    'ELOB': 'an elliptical obscuration', 'SPID': 'a spider obscuration',
    'UDAP': 'a user-defined aperture', 'UDOB': 'a user-defined obscuration',
}

#: Lens units and their length in mm.
_UNITS = {'MM': 1.0, 'CM': 10.0, 'IN': 25.4, 'METER': 1000.0, 'M': 1000.0}

#: Object-space glass names read as water (the index then comes from Quan & Fry 1995).
WATER_GLASSES = {'WATER': 'water', 'H2O': 'water', 'SEAWATER': 'seawater',
                 'SEA_WATER': 'seawater'}
#: A DISZ at or beyond this (mm) is an object at infinity (Zemax writes INFINITY or 1e10).
INFINITE_DISTANCE_MM = 1.0e9

#: Even asphere terms PARM 1..8 are a2 .. a16.
ASPHERE_TERMS = 8


class LensImportError(ValueError):
    """A lens file or table this package cannot import: the message names file, line, why."""


@dataclass
class ZmxSurface:
    """
    One surface of the file, in the file's units converted to mm.

    ``glass`` is the medium after the surface as the file names it ('' = air),
    ``glass_mode`` the GLAS line's mode (0 catalog, 1 model glass, 2 pick-up), ``nd`` and
    ``vd`` the GLAS line's index and Abbe number (0 when absent), ``asphere`` the terms
    a2 .. a16 (PARM 1 .. 8).
    """

    number: int
    line: int
    type: str = 'STANDARD'  # noqa: A003 - the file's TYPE keyword
    curvature: float = 0.0
    thickness: float | None = None
    glass: str = ''
    glass_mode: int = 0
    glass_line: int = 0
    pickup: int = -1
    nd: float = 0.0
    vd: float = 0.0
    conic: float = 0.0
    asphere: list[float] = field(default_factory=lambda: [0.0] * ASPHERE_TERMS)
    #: PARM j -> value as read (lens units); the asphere terms once the type is known.
    parm: dict[int, float] = field(default_factory=dict)
    semi_diameter: float = 0.0
    #: DIAM's solve is automatic (0): Zemax's computed footprint, not an aperture.
    semi_diameter_auto: bool = False
    aperture: float = 0.0
    stop: bool = False
    comment: str = ''
    type_line: int = 0
    #: A coordinate break's PARM j: (value as written, its line).
    break_params: dict[int, tuple[float, int]] = field(default_factory=dict)


@dataclass
class ZmxLens:
    """A sequential lens file as read: its surfaces (object first, image last) and settings."""

    path: str
    name: str = ''
    surfaces: list[ZmxSurface] = field(default_factory=list)
    wavelengths_um: dict[int, float] = field(default_factory=dict)
    primary_slot: int = 1
    field_type: int = 0
    field_y: list[float] = field(default_factory=list)
    field_count: int = -1
    entrance_pupil: float = 0.0
    entrance_pupil_mm: float = 0.0
    #: FNUM: the image-space F/# (at infinity: EFL / entrance pupil diameter); 0 when absent.
    f_number: float = 0.0
    catalogs: list[str] = field(default_factory=list)
    configurations: int = 1
    unit_mm: float = 1.0
    notes: list[str] = field(default_factory=list)
    #: ``''`` (air), ``'water'`` or ``'seawater'``: the object space's medium.
    object_medium: str = ''
    #: The sensor's pose from a coordinate break before the image surface (parameter values).
    sensor_pose: dict[str, float] = field(default_factory=dict)

    @property
    def primary_wavelength_um(self) -> float:
        """Return the primary wavelength in um (the PWAV slot, else the first one)."""
        if self.primary_slot in self.wavelengths_um:
            return self.wavelengths_um[self.primary_slot]
        if self.wavelengths_um:
            return self.wavelengths_um[min(self.wavelengths_um)]
        return 0.55

    @property
    def stop_number(self) -> int:
        """Return the file's number of the stop surface."""
        for surface in self.surfaces:
            if surface.stop:
                return surface.number
        return 1

    @property
    def object_distance_mm(self) -> float:
        """Return the object surface's DISZ (``math.inf`` for an object at infinity)."""
        thickness = self.surfaces[0].thickness
        if thickness is None or abs(thickness) >= INFINITE_DISTANCE_MM:
            return math.inf
        return float(thickness)

    @property
    def max_field(self) -> float:
        """Return the largest y field value (deg, or mm for FTYP 1-3), 0 when none."""
        values = self.field_y[:self.field_count] if self.field_count >= 0 else self.field_y
        scale = self.unit_mm if self.field_type in (1, 2, 3) else 1.0
        return max((abs(v) for v in values), default=0.0) * scale

    @property
    def field_text(self) -> str:
        """Return the design field in words ('' when the file has none)."""
        if self.max_field == 0.0:
            return ''
        what = {0: 'field angle', 1: 'object height', 2: 'paraxial image height',
                3: 'real image height'}.get(self.field_type)
        if what is None:
            return ''
        unit = 'deg' if self.field_type == 0 else 'mm'
        return f'design field: {what} up to {self.max_field:.6g} {unit}'


def decode(data: bytes, path: str) -> str:
    """
    Decode a lens file's bytes: UTF-16 (BOM, or NULs every other byte), UTF-8 or Latin-1.

    :param data: the file's bytes.
    :param path: the file name, for messages.
    :return: the text.
    :raises LensImportError: for binary data (an encrypted or compiled file).
    """
    text: str | None = None
    if data[:2] in (b'\xff\xfe', b'\xfe\xff'):
        try:
            text = data.decode('utf-16')
        except UnicodeDecodeError:
            raise LensImportError(f'{path}: a UTF-16 byte-order mark, but the text does not '
                                  'decode as UTF-16 (truncated or corrupt file)') from None
    elif len(data) >= 4 and data[1::2][:64].count(0) > 24 and data[0::2][:64].count(0) == 0:
        try:
            text = data.decode('utf-16-le')
        except UnicodeDecodeError:
            text = None
    if text is None:
        if data[:3] == b'\xef\xbb\xbf':
            data = data[3:]
        try:
            text = data.decode('utf-8')
        except UnicodeDecodeError:
            text = data.decode('latin-1')
    if '\x00' in text:
        raise LensImportError(f'{path}: binary data, not a lens text file (an encrypted or '
                              'compiled file, e.g. a black box .zbb or a .zos archive, cannot '
                              'be imported: export the lens from OpticStudio as .zmx)')
    return text


def _number(path: str, line: int, keyword: str, token: str) -> float:
    """Return ``token`` as a finite float (INFINITY allowed), or refuse naming the line."""
    text = token.replace(',', '.') if token.count(',') == 1 and '.' not in token else token
    if text.upper() in ('INFINITY', 'INF', '+INFINITY'):
        return math.inf
    try:
        value = float(text)
    except ValueError:
        raise LensImportError(f'{path}: line {line}: {keyword}: {token!r} is not a number '
                              '(a corrupt or truncated file?)') from None
    if math.isnan(value):
        raise LensImportError(f'{path}: line {line}: {keyword}: not a number ({token!r})')
    return value


def _finite(path: str, line: int, keyword: str, token: str) -> float:
    value = _number(path, line, keyword, token)
    if not math.isfinite(value):
        raise LensImportError(f'{path}: line {line}: {keyword}: {token} must be finite')
    return value


def _field(tokens: list[str], index: int) -> str | None:
    return tokens[index] if len(tokens) > index else None


def _refuse_type(path: str, line: int, number: int, type_name: str) -> None:
    upper = type_name.upper()
    if upper in SUPPORTED_TYPES or upper == BREAK_TYPE:
        return      # a coordinate break is judged once the file is read (fold_breaks)
    for prefix, why in _REFUSED_TYPES:
        if upper.startswith(prefix):
            raise LensImportError(f'{path}: line {line}: surface {number} is {why} (TYPE '
                                  f'{type_name}): this model traces only centred, rotationally '
                                  'symmetric refracting surfaces (STANDARD, EVENASPH)')
    raise LensImportError(f'{path}: line {line}: surface {number}: surface type {type_name} '
                          'cannot be traced by this model (it traces STANDARD and EVENASPH '
                          'surfaces only)')


def _read_surface_line(lens: ZmxLens, surface: ZmxSurface, keyword: str, tokens: list[str],
                       line: int) -> None:
    """Apply one indented line to ``surface`` (or refuse it)."""
    path, number, unit = lens.path, surface.number, lens.unit_mm
    where = f'{path}: line {line}: surface {number}'
    value = _field(tokens, 1)
    if keyword == 'TYPE':
        surface.type = value or 'STANDARD'
        surface.type_line = line
        _refuse_type(path, line, number, surface.type)
    elif keyword == 'PARM' and len(tokens) >= 3 and surface.type.upper() == BREAK_TYPE:
        surface.break_params[int(_finite(path, line, keyword, tokens[1]))] = (
            _finite(path, line, keyword, tokens[2]), line)
    elif keyword == 'CURV' and value is not None:
        surface.curvature = _finite(path, line, keyword, value) / unit
    elif keyword == 'DISZ' and value is not None:
        thickness = _number(path, line, keyword, value)
        surface.thickness = thickness if math.isinf(thickness) else thickness * unit
    elif keyword == 'CONI' and value is not None:
        surface.conic = _finite(path, line, keyword, value)
    elif keyword == 'PARM' and len(tokens) >= 3:
        # What PARM j means depends on the type: read now, applied by _apply_parms.
        term = int(_finite(path, line, keyword, tokens[1]))
        surface.parm[term] = _finite(path, line, keyword, tokens[2])
    elif keyword == 'DIAM' and value is not None:
        surface.semi_diameter = abs(_finite(path, line, keyword, value)) * unit
        solve = _field(tokens, 2)
        surface.semi_diameter_auto = solve is not None and solve == '0'
    elif keyword == 'CLAP' and len(tokens) >= 3:
        inner = _finite(path, line, keyword, tokens[1])
        if inner != 0.0:
            raise LensImportError(f'{where} has an annular aperture (CLAP rmin {inner:g}): '
                                  'this model has no central obscuration')
        surface.aperture = abs(_finite(path, line, keyword, tokens[2])) * unit
    elif keyword in _REFUSED_APERTURES:
        raise LensImportError(f'{where} has {_REFUSED_APERTURES[keyword]} ({keyword}): this '
                              'model has circular apertures only (DIAM, CLAP)')
    elif keyword == 'STOP':
        surface.stop = True
    elif keyword == 'COMM':
        surface.comment = ' '.join(tokens[1:])
    elif keyword == 'GLAS' and value is not None:
        _read_glass(lens, surface, tokens, line)
    elif keyword in ('SCBD', 'SCAD'):
        moves = [_number(path, line, keyword, t) for t in tokens[3:8]]
        if any(m != 0.0 for m in moves if math.isfinite(m)):
            before = 'before' if keyword == 'SCBD' else 'after'
            raise LensImportError(f'{where} is tilted or decentered ({keyword}: a coordinate '
                                  f'change {before} the surface): this model traces centred '
                                  'lenses only')
    elif keyword in ('TILT', 'DECX', 'DECY', 'TILX', 'TILY') and value is not None:
        if _number(path, line, keyword, value) != 0.0:
            raise LensImportError(f'{where} is tilted or decentered ({keyword}): this model '
                                  'traces centred lenses only')
    elif keyword in ('GRIN', 'GRAD', 'GRDN'):
        raise LensImportError(f'{where} has a gradient-index medium ({keyword}): this model '
                              'traces homogeneous glasses only')


def _read_glass(lens: ZmxLens, surface: ZmxSurface, tokens: list[str], line: int) -> None:
    path, name = lens.path, tokens[1]
    if name.upper() == 'MIRROR':
        raise LensImportError(f'{path}: line {line}: surface {surface.number} is a mirror '
                              '(GLAS MIRROR): this model traces refracting lenses only')
    surface.glass, surface.glass_line = name, line
    mode = _field(tokens, 2)
    pickup = _field(tokens, 3)
    surface.glass_mode = int(_finite(path, line, 'GLAS', mode)) if mode is not None else 0
    surface.pickup = int(_finite(path, line, 'GLAS', pickup)) if pickup is not None else -1
    nd, vd = _field(tokens, 4), _field(tokens, 5)
    surface.nd = _finite(path, line, 'GLAS', nd) if nd is not None else 0.0
    surface.vd = _finite(path, line, 'GLAS', vd) if vd is not None else 0.0


def _read_header_line(lens: ZmxLens, keyword: str, tokens: list[str], line: int) -> None:
    """Apply one top-level line to ``lens`` (or refuse the file)."""
    path = lens.path
    value = _field(tokens, 1)
    if keyword == 'MODE' and value is not None and value.upper() != 'SEQ':
        raise LensImportError(f'{path}: line {line}: MODE {value}: a non-sequential file; '
                              'only sequential lens files (MODE SEQ) can be imported')
    if value is None:
        return
    if keyword == 'NAME':
        lens.name = ' '.join(tokens[1:])
    elif keyword == 'UNIT':
        unit = value.upper()
        if unit not in _UNITS:
            raise LensImportError(f'{path}: line {line}: UNIT {value}: unknown lens unit '
                                  f'(known: {", ".join(_UNITS)})')
        if lens.surfaces:
            raise LensImportError(f'{path}: line {line}: UNIT after the surface data')
        lens.unit_mm = _UNITS[unit]
    elif keyword == 'WAVM' and len(tokens) >= 3:
        slot = int(_finite(path, line, keyword, tokens[1]))
        lens.wavelengths_um[slot] = _finite(path, line, keyword, tokens[2])
    elif keyword == 'WAVL':
        for slot, token in enumerate(tokens[1:], start=1):
            lens.wavelengths_um[slot] = _finite(path, line, keyword, token)
    elif keyword == 'PWAV':
        lens.primary_slot = int(_finite(path, line, keyword, value))
    elif keyword == 'FTYP':
        lens.field_type = int(_finite(path, line, keyword, value))
        count = _field(tokens, 3)
        if count is not None:
            lens.field_count = int(_finite(path, line, keyword, count))
    elif keyword == 'YFLN':
        lens.field_y = [_finite(path, line, keyword, t) for t in tokens[1:]]
    elif keyword == 'ENPD':
        # In lens units (converted once UNIT is known, in _check_whole).
        lens.entrance_pupil = _finite(path, line, keyword, value)
    elif keyword == 'FNUM':
        lens.f_number = _finite(path, line, keyword, value)
    elif keyword == 'GCAT':
        lens.catalogs = [t.upper() for t in tokens[1:]]
    elif keyword == 'MNUM':
        lens.configurations = int(_finite(path, line, keyword, value))
    elif keyword in ('BBOX', 'ENCR', 'ENCRYPT'):
        raise LensImportError(f'{path}: line {line}: an encrypted or black-box lens ({keyword}):'
                              ' its prescription is hidden and cannot be imported')


def parse(text: str, path: str = '<zmx>') -> ZmxLens:
    """
    Parse the text of a sequential ``.zmx`` file.

    :param text: the decoded file.
    :param path: the file name used in messages.
    :return: the lens as the file describes it (object surface first, image surface last).
    :raises LensImportError: naming the file, the line and the surface, for anything this
        package cannot import (see the module docstring).
    """
    lens = ZmxLens(path=path)
    try:
        return _parse(lens, text)
    except LensImportError as err:
        # A coordinate break inside the lens comes first in the file: name it, not a
        # refusal of a surface behind it (a mirror of a folded system, say).
        _refuse_inner_break(lens, sum(1 for raw in text.splitlines()
                                      if raw.split()[:1] == ['SURF']))
        raise err


def _refuse_inner_break(lens: ZmxLens, count: int) -> None:
    """Refuse the first moving coordinate break read that is not just before the image."""
    for surface in lens.surfaces:
        moving = any(surface.break_params.get(j, (0.0, 0))[0] for j in range(1, 6))
        if surface.type.upper() == BREAK_TYPE and moving and 0 < surface.number < count - 2:
            raise _inner_break(lens, surface) from None


def _inner_break(lens: ZmxLens, surface: ZmxSurface) -> LensImportError:
    """Return the refusal of a coordinate break inside the lens (an element's decenter)."""
    return LensImportError(f'{lens.path}: line {surface.type_line}: surface {surface.number} '
                           f'is a coordinate break ({BREAK_TYPE}) inside the lens: it '
                           'decenters or tilts the elements after it, and this model traces '
                           'centred lenses only (a break just before the image surface is '
                           'imported: it places the sensor)')


def _parse(lens: ZmxLens, text: str) -> ZmxLens:
    """Read the lines of :func:`parse` into ``lens``."""
    path = lens.path
    current: ZmxSurface | None = None
    seen_keyword = False
    for line, raw in enumerate(text.splitlines(), start=1):
        tokens = raw.split()
        if not tokens:
            continue
        keyword = tokens[0].upper()
        if keyword.isalpha() and len(keyword) <= 8:
            seen_keyword = True
        if keyword == 'SURF':
            number = int(_finite(path, line, keyword, tokens[1])) if len(tokens) > 1 else -1
            if number != len(lens.surfaces):
                raise LensImportError(f'{path}: line {line}: SURF {tokens[1:2]}: expected '
                                      f'surface {len(lens.surfaces)} (surfaces out of order: '
                                      'a corrupt or truncated file?)')
            current = ZmxSurface(number=number, line=line)
            lens.surfaces.append(current)
        elif current is not None and raw[:1] in (' ', '\t'):
            _read_surface_line(lens, current, keyword, tokens, line)
        else:
            current = None
            _read_header_line(lens, keyword, tokens, line)
    if len(lens.surfaces) >= 3:
        fold_breaks(lens)
    _check_whole(lens, seen_keyword)
    return lens


def _apply_parms(lens: ZmxLens, surface: ZmxSurface) -> None:
    """Make PARM values asphere terms on an EVENASPH surface; note stale ones elsewhere."""
    where = f'{lens.path}: line {surface.line}: surface {surface.number}'
    if surface.type.upper() != 'EVENASPH':
        stale = sorted(j for j, a in surface.parm.items() if a != 0.0)
        if stale:
            lens.notes.append(f'surface {surface.number} ({surface.type}) carries PARM '
                              f'{", ".join(map(str, stale))} (left from another surface type: '
                              'not terms of its sag): ignored')
        return
    for term, coefficient in surface.parm.items():
        if 1 <= term <= ASPHERE_TERMS:
            # a_j r^(2j) in lens units: mm^(1 - 2j) after scaling.
            surface.asphere[term - 1] = coefficient * lens.unit_mm ** (1 - 2 * term)
        elif coefficient != 0.0:
            raise LensImportError(f'{where}: PARM {term} = {coefficient:g}: an even asphere '
                                  f'has terms 1 to {ASPHERE_TERMS}')


def _check_whole(lens: ZmxLens, seen_keyword: bool) -> None:
    """Refuse a file that is not a complete, sequential refracting lens."""
    path = lens.path
    lens.entrance_pupil_mm = lens.entrance_pupil * lens.unit_mm
    for surface in lens.surfaces:
        _apply_parms(lens, surface)
    if not lens.surfaces:
        what = 'no surfaces (SURF lines)' if seen_keyword else 'no Zemax keywords'
        raise LensImportError(f'{path}: not a Zemax lens file: {what}')
    if len(lens.surfaces) < 3:
        raise LensImportError(f'{path}: {len(lens.surfaces)} surfaces: a lens file has an '
                              'object surface, at least one lens surface and an image surface '
                              '(a truncated file?)')
    for surface in lens.surfaces:
        if surface.thickness is None:
            raise LensImportError(f'{path}: line {surface.line}: surface {surface.number} has '
                                  'no thickness (DISZ): a truncated file?')
    object_glass = (lens.surfaces[0].glass or '').upper()
    if object_glass in WATER_GLASSES:
        lens.object_medium = WATER_GLASSES[object_glass]
    elif object_glass and object_glass != 'AIR':
        raise LensImportError(f'{path}: line {lens.surfaces[0].glass_line}: the object space is'
                              f' glass {lens.surfaces[0].glass}: this model has its object in '
                              'air or in water (a water glass it can name: '
                              f'{", ".join(sorted(WATER_GLASSES))}; docs/underwater.md)')
    for surface in lens.surfaces[1:-1]:
        if math.isinf(surface.thickness or 0.0):
            raise LensImportError(f'{path}: line {surface.line}: surface {surface.number}: '
                                  'an infinite thickness inside the lens (afocal or corrupt)')
        if (surface.thickness or 0.0) < 0.0:
            raise LensImportError(f'{path}: line {surface.line}: surface {surface.number}: '
                                  f'thickness {surface.thickness:g} mm < 0 (the next surface '
                                  'lies in front of it): this model needs surfaces in order '
                                  'along the axis')
        if surface.type.upper() == 'EVENASPH' and surface.asphere[0] != 0.0:
            raise LensImportError(f'{path}: line {surface.line}: surface {surface.number}: '
                                  f'even asphere r^2 term PARM 1 = {surface.asphere[0]:g}: this '
                                  "model's sag has terms a4 to a16 only")
    last = lens.surfaces[-2]
    if last.glass and last.glass.upper() != 'AIR':
        raise LensImportError(f'{path}: line {last.glass_line}: the image space (after surface '
                              f'{last.number}) is glass {last.glass}: this model needs the '
                              'sensor in air (or the file is truncated)')
    stops = [s.number for s in lens.surfaces if s.stop]
    if stops and not 0 < stops[0] < len(lens.surfaces) - 1:
        raise LensImportError(f'{path}: the stop is surface {stops[0]}, the object or image '
                              'surface: it must be a lens surface')
    image = lens.surfaces[-1]
    if image.curvature != 0.0:
        lens.notes.append(f'the image surface (surface {image.number}) is curved (radius '
                          f'{1.0 / image.curvature:.6g} mm): the sensor of this model is flat, at '
                          'its vertex')
    if lens.surfaces[0].curvature != 0.0:
        lens.notes.append('the object surface is curved: the scene of this model is a plane')
    if lens.configurations > 1:
        lens.notes.append(f'{lens.configurations} configurations: imported the one stored in '
                          'the surface data (the configuration current when the file was saved)')
    if not stops:
        lens.notes.append('no STOP surface: surface 1 taken as the stop')


def fold_breaks(lens: ZmxLens) -> None:
    """
    Import the coordinate breaks the model can trace; refuse the others naming the line.

    A break that moves nothing (a dummy) is dropped, its thickness added to the surface before
    it. A break just before the image surface, behind a surface into air, places the sensor
    (docs/design.md section 2.16): Zemax's ``PARM 1, 2`` decenter x, y (lens units), ``PARM 3,
    4`` tilt about x, then about the new y (deg, right-handed), ``PARM 6`` the order (0:
    decenter then tilt, 1: tilt then decenter); its frame ``F = R_x(a) R_y(b)`` (the
    right-handed rotations of :mod:`mechdeconv_ros.optics.pose`). The sensor
    plane is the image surface's (the break's origin moved by its own thickness along the new
    z); the lens axis meets it at ``z_A`` (the new distance from the last lens surface, so
    ``lens.image_distance_mm``), the sensor centre lies at ``(V - A) . F e_x`` along x and
    ``(V - A) . F e_y`` along y from it, and with the file's +y up in the image (the raw image
    is the inverted image read upright) ``sensor.axis_offset_x_mm = (V - A) . F e_x``,
    ``axis_offset_y_mm = -(V - A) . F e_y``, ``tilt_x_deg = -a``, ``tilt_y_deg = -b``
    (:func:`~mechdeconv_ros.optics.pose.sensor_tilts_of_break`; docs/design.md section 1.1). A
    break elsewhere (an element's decenter or tilt), in glass, with a rotation about the axis
    (``PARM 5``) or a tilt or decenter beyond the parameters' ranges is refused.

    :param lens: the lens as read; changed in place.
    :raises LensImportError: naming the file, line and surface.
    """
    i = len(lens.surfaces) - 1
    while i >= 0:
        surface = lens.surfaces[i]
        if surface.type.upper() == BREAK_TYPE:
            _fold_break(lens, i)
        i -= 1


def _fold_break(lens: ZmxLens, i: int) -> None:
    """Drop, import or refuse the coordinate break ``lens.surfaces[i]``."""
    surface = lens.surfaces[i]
    where = f'{lens.path}: line {surface.type_line}: surface {surface.number}'
    value = {j: surface.break_params.get(j, (0.0, surface.type_line))[0] for j in range(1, 7)}
    line = {j: surface.break_params.get(j, (0.0, surface.type_line))[1] for j in range(1, 7)}
    if i in (0, len(lens.surfaces) - 1):
        raise LensImportError(f'{where}: the object or image surface is a coordinate break '
                              f'({BREAK_TYPE}): a lens file starts at the scene and ends at '
                              'the sensor')
    before = lens.surfaces[i - 1]
    if not any(value[j] for j in range(1, 6)):
        before.thickness = (before.thickness or 0.0) + (surface.thickness or 0.0)
        del lens.surfaces[i]
        return
    if i != len(lens.surfaces) - 2:
        raise _inner_break(lens, surface)
    if before.glass and before.glass.upper() != 'AIR':
        raise LensImportError(f'{where} is a coordinate break ({BREAK_TYPE}) in glass '
                              f'{before.glass}: the sensor of this model sits in air')
    if value[5]:
        raise LensImportError(f'{lens.path}: line {line[5]}: surface {surface.number}: the '
                              f'coordinate break turns the sensor {value[5]:g} deg about the '
                              'axis (PARM 5): not a parameter of this model')
    for j in (3, 4):
        if abs(value[j]) > MAX_BREAK_TILT_DEG:
            raise LensImportError(f'{lens.path}: line {line[j]}: surface {surface.number}: '
                                  f'the coordinate break tilts the sensor {value[j]:g} deg '
                                  f'(PARM {j}): more than the {MAX_BREAK_TILT_DEG:g} deg of '
                                  'an assembly error (sensor.tilt_*_deg)')
    _place_sensor(lens, i, value, line)


def _place_sensor(lens: ZmxLens, i: int, value: dict[int, float],
                  line: dict[int, int]) -> None:
    """Turn the break before the image into the sensor's pose (see :func:`fold_breaks`)."""
    surface, before = lens.surfaces[i], lens.surfaces[i - 1]
    # F = R_x(a) R_y(b) (right-handed, docs/design.md section 1.1): its columns are the new
    # x, y, z axes in the lens frame.
    frame = rot_x(math.radians(value[3])) @ rot_y(math.radians(value[4]))
    ex, ey, ez = (tuple(float(x) for x in frame[:, k]) for k in range(3))
    dx, dy = value[1] * lens.unit_mm, value[2] * lens.unit_mm
    z_break = before.thickness or 0.0
    if value[6]:
        origin = [dx * ex[k] + dy * ey[k] for k in range(3)]
        origin[2] += z_break
    else:
        origin = [dx, dy, z_break]
    t = surface.thickness or 0.0
    vertex = [origin[k] + t * ez[k] for k in range(3)]
    # Where the axis meets the plane: n . (A - V) = 0 with A = (0, 0, z_A).
    z_axis = vertex[2] + (ez[0] * vertex[0] + ez[1] * vertex[1]) / ez[2]
    rel = (vertex[0], vertex[1], vertex[2] - z_axis)
    offsets = (sum(rel[k] * ex[k] for k in range(3)), -sum(rel[k] * ey[k] for k in range(3)))
    for j, offset, name in ((1, offsets[0], 'x'), (2, offsets[1], 'y')):
        if abs(offset) > MAX_BREAK_DECENTER_MM:
            raise LensImportError(f'{lens.path}: line {line[j]}: surface {surface.number}: '
                                  f'the coordinate break puts the sensor centre {offset:g} mm '
                                  f'off the axis along {name}: beyond sensor.axis_offset_'
                                  f'{name}_mm')
    before.thickness = z_axis
    tilt_x, tilt_y = sensor_tilts_of_break(value[3], value[4])
    lens.sensor_pose = {'sensor.axis_offset_x_mm': offsets[0],
                        'sensor.axis_offset_y_mm': offsets[1],
                        'sensor.tilt_x_deg': tilt_x, 'sensor.tilt_y_deg': tilt_y}
    lens.notes.append(
        f'surface {surface.number} (line {surface.type_line}): the coordinate break before the '
        f'image surface places the sensor: axis offset {offsets[0]:.6g}, {offsets[1]:.6g} mm, '
        f'tilt {tilt_x:g}, {tilt_y:g} deg (sensor.axis_offset_*, sensor.tilt_*: the tilts '
        f'{value[3]:g}, {value[4]:g} deg of the break with their signs changed); the axis '
        f'meets it {z_axis:.6g} mm behind the last lens surface')
    del lens.surfaces[i]


def read(path: str | Path) -> ZmxLens:
    """
    Read and parse a ``.zmx`` file.

    :param path: the file.
    :return: see :func:`parse`.
    :raises LensImportError: when the file cannot be read or imported.
    """
    name = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise LensImportError(f'{name}: cannot read it: {err.strerror}') from None
    if not data.strip():
        raise LensImportError(f'{name}: empty file, not a lens file')
    return parse(decode(data, name), name)
