# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Real ``.zmx`` files edited as a user would, imported (issue 29, item 2).

Each test starts from a file of test/data/zmx (rayoptics' test files, unchanged there), makes
the edit an OpticStudio user or a text editor would (a surface type changed back to STANDARD,
the lens units switched to cm, a stop's semi-diameter left automatic, a model glass of
constant index, an aperture added), and checks the import against what does not depend on
this code: the same lens in mm, optiland's trace of the unedited file
(test/data/zmx_reference.json, through test_zmx_reference.compare), Zemax's own automatic
semi-diameter of the stop, and rayoptics' reading of ``___BLANK`` with vd 0 as a constant
index (rayoptics 0.9.8, zemax/zmxread.py: "Zemax treats Vd=0 as constant index").
"""

from __future__ import annotations

from pathlib import Path
import re

from mechdeconv_ros.lenses.lens_import import import_zmx
from mechdeconv_ros.lenses.zmx import decode, LensImportError, read
import pytest
from test_zmx_reference import compare, LENSES as REFERENCE_LENSES, optiland_indices

ROOT = Path(__file__).resolve().parents[1]
ZMX = ROOT / 'test' / 'data' / 'zmx'
GAUSS = 'US00583336-2-scaled'
EDMUND = 'edmund_55278'


def text_of(name: str) -> str:
    return decode((ZMX / f'{name}.zmx').read_bytes(), name)


def write(tmp_path: Path, name: str, text: str, utf16: bool = False) -> Path:
    path = tmp_path / f'{name}.zmx'
    path.write_bytes(text.encode('utf-16') if utf16 else text.encode('utf-8'))
    return path


def surface_block(text: str, number: int) -> tuple[int, int]:
    """Return the character span of ``SURF number``'s block."""
    start = re.search(rf'^SURF {number}\s*$', text, re.M).start()
    following = re.search(r'^SURF \d+\s*$', text[start + 5:], re.M)
    return start, start + 5 + following.start() if following else len(text)


def edit_surface(text: str, number: int, change) -> str:
    start, end = surface_block(text, number)
    return text[:start] + change(text[start:end]) + text[end:]


def add_line(text: str, number: int, line: str) -> str:
    return edit_surface(text, number, lambda block: block.replace('\n', f'\n  {line}\n', 1))


def test_stale_parm_on_a_standard_surface_is_not_an_asphere(tmp_path) -> None:
    # An even asphere turned back into STANDARD in OpticStudio keeps its PARM lines.
    text = add_line(text_of(GAUSS), 2, 'PARM 2 1.0E-4')
    text = add_line(text, 2, 'PARM 3 -2.0E-6')
    imported = import_zmx(write(tmp_path, GAUSS, text), resolve=optiland_indices(
        REFERENCE_LENSES[GAUSS]))
    assert not any(k.startswith('lens.surfaces.asphere_a') for k in imported.values)
    assert any('PARM 2, 3' in w and 'ignored' in w for w in imported.warnings)
    compare(GAUSS, imported.values)         # optiland's trace of the unedited file


def to_centimetres(text: str) -> str:
    """Switch a file's lens units to cm, every length and curvature converted."""
    def scaled(match, factor):
        key, number = match.group(1), match.group(2)
        if number.upper() == 'INFINITY':
            return match.group(0)
        return f'{key}{float(number) * factor!r}'
    text = re.sub(r'^UNIT MM', 'UNIT CM', text, flags=re.M)
    text = re.sub(r'^(ENPD )(\S+)', lambda m: scaled(m, 0.1), text, flags=re.M)
    text = re.sub(r'^(\s+CURV )(\S+)', lambda m: scaled(m, 10.0), text, flags=re.M)
    text = re.sub(r'^(\s+DISZ )(\S+)', lambda m: scaled(m, 0.1), text, flags=re.M)
    text = re.sub(r'^(\s+DIAM )(\S+)', lambda m: scaled(m, 0.1), text, flags=re.M)
    text = re.sub(r'^(\s+FLAP 0 )(\S+)', lambda m: scaled(m, 0.1), text, flags=re.M)
    return text


def test_a_centimetre_file_with_the_stop_set_by_enpd_is_the_same_lens(tmp_path) -> None:
    # The stop (surface 1) without its DIAM: ENPD 22 (mm) sets it, 2.2 in a cm file.
    base = edit_surface(text_of(EDMUND), 1, lambda b: re.sub(r'\n\s+DIAM [^\n]*', '', b))
    mm = import_zmx(write(tmp_path, 'mm', base, utf16=True)).values
    cm = import_zmx(write(tmp_path, 'cm', to_centimetres(base), utf16=True)).values
    assert mm['lens.aperture_diameter_mm'] == pytest.approx(22.0)     # stop = first surface
    assert cm.keys() == mm.keys()
    for key, value in mm.items():
        text = isinstance(value, str) or (isinstance(value, list) and value and
                                          isinstance(value[0], str))
        assert cm[key] == (value if text else pytest.approx(value, rel=1e-12)), key
    compare(EDMUND, import_zmx(write(tmp_path, 'cm2', to_centimetres(base), utf16=True),
                               resolve=optiland_indices(REFERENCE_LENSES[EDMUND])).values)


def test_an_automatic_semi_diameter_is_not_an_aperture() -> None:
    # US 583,336's stop (file surface 7) and surface 1 have automatic DIAMs (solve 0), the
    # others fixed (1) or picked up (2). The stop is set by the file's FNUM 4.5 (EPD =
    # EFL / 4.5) imaged on it, and must come out as Zemax's own automatic stop semi-diameter,
    # 4.215 mm (paraxial here, real rays in Zemax: within 1 %).
    lens = read(ZMX / f'{GAUSS}.zmx')
    assert [s.semi_diameter_auto for s in lens.surfaces[1:-1]] == [
        True] + [False] * 5 + [True] + [False] * 5
    imported = import_zmx(ZMX / f'{GAUSS}.zmx')
    semi = imported.values['lens.surfaces.semi_diameter_mm']
    assert semi[0] == 0.0 and semi[6] == 0.0
    assert semi[1:6] == [6.3, 6.3, 5.94, 5.94, 4.5]
    zemax_stop_semi_mm = 4.215000499256
    aperture = imported.values['lens.aperture_diameter_mm']
    assert aperture == pytest.approx(2 * zemax_stop_semi_mm, rel=0.01)
    assert not any('aperture' in w for w in imported.warnings)


def test_a_blank_glass_with_vd_0_is_a_constant_index(tmp_path) -> None:
    text = edit_surface(text_of(GAUSS), 2, lambda b: re.sub(
        r'\n\s+GLAS [^\n]*', '\n  GLAS ___BLANK 1 0 1.6 0 0 0 0 0 0 0', b))
    path = write(tmp_path, GAUSS, text)
    for wavelength in (486.1327, 587.5618, 656.2725):
        values = import_zmx(path, wavelength).values
        assert values['lens.surfaces.refractive_index'][1] == 1.6
        assert values['lens.surfaces.glass'][1] == ''


@pytest.mark.parametrize('line, needle', [
    ('CLAP 1.0 6.3 0', 'annular aperture (CLAP rmin 1)'),
    ('SQAP 3 2 0', 'a rectangular aperture (SQAP)'),
    ('ELAP 3 2 0', 'an elliptical aperture (ELAP)'),
    ('OBSC 0 1.5 0', 'a circular obscuration (OBSC)'),
], ids=['annulus', 'square', 'ellipse', 'obscuration'])
def test_apertures_the_model_cannot_honour_are_refused_by_name(tmp_path, line, needle) -> None:
    path = write(tmp_path, GAUSS, add_line(text_of(GAUSS), 3, line))
    with pytest.raises(LensImportError) as err:
        import_zmx(path)
    assert 'surface 3' in str(err.value) and needle in str(err.value)


def test_image_height_fields_are_in_lens_units(tmp_path) -> None:
    # US 8,427,765 gives its field as real image heights (FTYP 3): 8 and 13.6 mm.
    text = text_of('US08427765-1')
    assert read(ZMX / 'US08427765-1.zmx').max_field == pytest.approx(13.6)
    cm = write(tmp_path, 'cm', to_centimetres(text).replace(
        'YFLN 0 8.0 1.36E+1', 'YFLN 0 0.8 1.36'))
    lens = read(cm)
    assert lens.field_type == 3 and lens.max_field == pytest.approx(13.6)
    comments = ' '.join(import_zmx(cm).comments)
    assert 'design field: real image height up to 13.6 mm' in comments
