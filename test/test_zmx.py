# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The ``.zmx`` reader and importer: encodings, units, conventions, refusals and a fuzz.

Every refusal names the file, the line or surface and why, exits 2 from the CLI and writes
no file; a corrupted real file gives a result or a :class:`LensImportError`, never another
exception.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

from hypothesis import given, HealthCheck, settings
from hypothesis import strategies as st
from mechdeconv_ros.lenses.lens_import import import_zmx, Medium, zmx_values
from mechdeconv_ros.lenses.zmx import decode, LensImportError, parse
from mechdeconv_ros.optics.raytrace import paraxial
from mechdeconv_ros.optics.thick_lens import thick_lens
from mechdeconv_ros.tools.cli import main
from numpy.testing import assert_allclose
import pytest

ROOT = Path(__file__).resolve().parents[1]
FILES = ROOT / 'test' / 'data' / 'zmx'
HAVE_GLASS = importlib.util.find_spec('mechdeconv_ros.optics.glass') is not None

#: A biconvex singlet, f ~ 50 mm, object 1 m from the first vertex, in a real file's layout.
SINGLET = """VERS 190513 80 123457 L123457
MODE SEQ
NAME test singlet
NOTE 0 a comment line the importer does not need
UNIT MM X W X CM MR CPMM
ENPD 10
GCAT SCHOTT OHARA
FTYP 0 0 2 1 0 0 0
XFLN 0 0
YFLN 0 10
WAVM 1 0.58756 1
PWAV 1
COFN QF "COATING.DAT" "SCATTER_PROFILE.DAT" "ABG_DATA.DAT" "PROFILE.GRD"
SURF 0
  TYPE STANDARD
  CURV 0.0 0 0 0 0 ""
  DISZ 1000
SURF 1
  STOP
  TYPE STANDARD
  CURV 0.02 0 0 0 0 ""
  COAT THORB
  HIDE 0 0 0 0 0 0 0 0 0 0
  DISZ 5
  GLAS N-BK7 0 0 1.5168 64.17 0 0 0 0 0 0
  DIAM 10 1 0 0 1 ""
SURF 2
  TYPE EVENASPH
  CURV -0.02 0 0 0 0 ""
  PARM 1 0
  PARM 2 1e-6
  PARM 3 -2e-9
  CONI -0.5
  DISZ 47.5
  DIAM 10 1 0 0 1 ""
SURF 3
  TYPE STANDARD
  CURV 0.0
  DISZ 0
BLNK
TOL TOFF   0   0 0 0   0 0 0 0 0
MNUM 1 1
MOFF   0   1 "" 0 0 0 1 1 0 0.0 "" 0
"""


def fixed_index(lens, surface, wavelength_nm):
    """Resolve every glass to n = 1.5 (the tests of geometry need no catalog)."""
    return Medium('', 1.5 if surface.glass else 1.0)


def imported(text: str, name: str = 'lens.zmx'):
    return zmx_values(parse(text, name), resolve=fixed_index)


def test_singlet_surfaces_and_conventions():
    """CURV -> radius, DISZ, DIAM, CONI, PARM -> a4.., STOP, object distance from H."""
    values = imported(SINGLET).values
    assert_allclose(values['lens.surfaces.radius_mm'], [50.0, -50.0])
    assert values['lens.surfaces.thickness_mm'] == [5.0, 47.5]
    assert values['lens.surfaces.semi_diameter_mm'] == [10.0, 10.0]
    assert values['lens.surfaces.conic'] == [0.0, -0.5]
    assert values['lens.surfaces.asphere_a4'] == [0.0, 1e-6]
    assert values['lens.surfaces.asphere_a6'] == [0.0, -2e-9]
    assert 'lens.surfaces.asphere_a8' not in values
    assert values['lens.stop_surface'] == 0
    assert values['lens.aperture_diameter_mm'] == 20.0
    # The object surface is 1000 mm before the first vertex; the package measures from H.
    lens = thick_lens(1.5, 50.0, -50.0, 5.0, 0.0, 1.0)
    z_h = paraxial(lens).front_principal_z_mm
    assert z_h > 0.0
    assert_allclose(values['scene.distance_mm'], 1000.0 + z_h, rtol=1e-12)


def test_object_at_infinity_is_zero():
    text = SINGLET.replace('  DISZ 1000', '  DISZ INFINITY')
    assert imported(text).values['scene.distance_mm'] == 0.0
    text = SINGLET.replace('  DISZ 1000', '  DISZ 1.0E+10')
    assert imported(text).values['scene.distance_mm'] == 0.0


@pytest.mark.parametrize('encoding', ['ascii-lf', 'ascii-crlf', 'utf-16-bom', 'utf-8-bom',
                                      'utf-16-no-bom'])
def test_encodings_read_alike(tmp_path, encoding):
    """ASCII or UTF-16 with a BOM, CRLF or LF: the same lens."""
    text = SINGLET if encoding != 'ascii-crlf' else SINGLET.replace('\n', '\r\n')
    data = {'ascii-lf': text.encode('ascii'), 'ascii-crlf': text.encode('ascii'),
            'utf-16-bom': text.replace('\n', '\r\n').encode('utf-16'),
            'utf-8-bom': b'\xef\xbb\xbf' + text.encode('utf-8'),
            'utf-16-no-bom': text.encode('utf-16-le')}[encoding]
    path = tmp_path / 'lens.zmx'
    path.write_bytes(data)
    assert import_zmx(path, resolve=fixed_index).values == imported(SINGLET).values


def test_lens_units_are_converted():
    """UNIT CM: lengths x 10, curvatures / 10, a_j r^2j scaled by 10^(1 - 2j)."""
    text = (SINGLET.replace('UNIT MM', 'UNIT CM').replace('CURV 0.02 ', 'CURV 0.2 ')
            .replace('CURV -0.02 ', 'CURV -0.2 ').replace('DISZ 5\n', 'DISZ 0.5\n')
            .replace('DISZ 47.5', 'DISZ 4.75').replace('DISZ 1000', 'DISZ 100')
            .replace('DIAM 10 ', 'DIAM 1 ').replace('PARM 2 1e-6', 'PARM 2 1e-3')
            .replace('PARM 3 -2e-9', 'PARM 3 -2e-4'))
    a, b = imported(text).values, imported(SINGLET).values
    for key in b:
        if key == 'lens.surfaces.glass':
            assert a[key] == b[key]
        else:
            assert_allclose(a[key], b[key], rtol=1e-12, err_msg=key)


def test_pickup_glass_and_a_dummy_surface():
    """A pick-up (GLAS mode 2) takes the source's glass; a flat air dummy is kept."""
    seen = []

    def resolve(lens, surface, wavelength_nm):
        seen.append(surface.glass)
        return fixed_index(lens, surface, wavelength_nm)

    cemented = '  DISZ 2\n  GLAS ZZZ 2 1 1.6 40 0 0 0 0 0 0\nSURF 3\n  CURV -0.01\n  DISZ 40'
    doublet = SINGLET.replace('  DISZ 47.5', cemented).replace(
        'SURF 3\n  TYPE STANDARD\n  CURV 0.0\n  DISZ 0', 'SURF 4\n  CURV 0.0\n  DISZ 0')
    values = zmx_values(parse(doublet, 'd.zmx'), resolve=resolve).values
    assert values['lens.surfaces.refractive_index'] == [1.5, 1.5, 1.0]
    assert seen == ['N-BK7', 'N-BK7', '']
    dummy = SINGLET.replace('SURF 3\n', 'SURF 3\n  TYPE STANDARD\n  CURV 0\n  DISZ 2\n'
                                        'SURF 4\n').replace('  DISZ 47.5', '  DISZ 45.5')
    values = imported(dummy).values
    assert values['lens.surfaces.radius_mm'][2] == 0.0
    assert values['lens.surfaces.refractive_index'] == [1.5, 1.0, 1.0]
    assert values['lens.surfaces.thickness_mm'][1:] == [45.5, 2.0]
    loop = SINGLET.replace('GLAS N-BK7 0 0', 'GLAS N-BK7 2 1')
    with pytest.raises(LensImportError, match='line 25: surface 1: glass pick-ups form a loop'):
        imported(loop)


def test_the_written_file_names_its_source_and_the_missing_sensor():
    from mechdeconv_ros.lenses.params_file import params_text
    text = params_text(imported(SINGLET))
    assert 'lens.zmx ("test singlet")' in text and 'add sensor.pixel_size_x_um' in text
    assert text.count('/**:') == 1 and 'ros__parameters:' in text


REFUSALS = [
    ('nsc', lambda t: t.replace('MODE SEQ', 'MODE NSC'), ['line 2', 'non-sequential']),
    ('coordinate-break', lambda t: t.replace('  TYPE EVENASPH', '  TYPE COORDBRK'),
     ['line 28', 'surface 2', 'coordinate break', 'COORDBRK']),
    ('toroidal', lambda t: t.replace('  TYPE EVENASPH', '  TYPE TOROIDAL'),
     ['surface 2', 'toroidal']),
    ('grin', lambda t: t.replace('  TYPE EVENASPH', '  TYPE GRINSUR1'),
     ['surface 2', 'gradient-index', 'GRINSUR1']),
    ('grating', lambda t: t.replace('  TYPE EVENASPH', '  TYPE DGRATING'),
     ['surface 2', 'grating']),
    ('unknown-type', lambda t: t.replace('  TYPE EVENASPH', '  TYPE SUPERCONIC'),
     ['surface 2', 'SUPERCONIC']),
    ('black-box', lambda t: t.replace('  TYPE EVENASPH', '  TYPE BLACKBOX'),
     ['surface 2', 'black box']),
    ('mirror', lambda t: t.replace('GLAS N-BK7', 'GLAS MIRROR'),
     ['line 25', 'surface 1', 'mirror']),
    ('tilt', lambda t: t.replace('  DISZ 5\n', '  DISZ 5\n  SCBD 1 0 0 0 0 5 0 0\n'),
     ['surface 1', 'tilted or decentered']),
    ('decenter', lambda t: t.replace('  DISZ 5\n', '  DISZ 5\n  SCAD 1 0 0.5 0 0 0 0 0\n'),
     ['surface 1', 'tilted or decentered']),
    ('r2-term', lambda t: t.replace('PARM 1 0', 'PARM 1 1e-3'), ['surface 2', 'PARM 1']),
    ('negative-thickness', lambda t: t.replace('DISZ 5\n', 'DISZ -5\n'),
     ['surface 1', '< 0']),
    ('truncated', lambda t: t[:t.index('  DISZ 47.5')], ['surface 2', 'truncated']),
    ('truncated-header', lambda t: t[:t.index('SURF 1')], ['truncated']),
    ('not-a-lens', lambda t: 'hello world\nthis is a readme\n', ['not a Zemax lens file']),
    ('json', lambda t: '{"surfaces": [1, 2]}', ['not a Zemax lens file']),
    ('bad-number', lambda t: t.replace('CURV 0.02 ', 'CURV 0.0x2 '),
     ['line 21', 'CURV', 'not a number']),
    ('out-of-order', lambda t: t.replace('SURF 2', 'SURF 5'), ['SURF', 'out of order']),
    ('image-in-glass', lambda t: t.replace('  DISZ 47.5', '  DISZ 47.5\n  GLAS F2 0 0 1.62 36'),
     ['image space', 'F2']),
]


@pytest.mark.parametrize('case', REFUSALS, ids=[c[0] for c in REFUSALS])
def test_refusals_name_file_line_and_reason(case):
    _, change, expected = case
    with pytest.raises(LensImportError) as err:
        imported(change(SINGLET), 'bad.zmx')
    message = str(err.value)
    assert message.startswith('bad.zmx'), message
    for part in expected:
        assert part in message, (part, message)


def test_binary_data_is_refused():
    with pytest.raises(LensImportError, match='binary data'):
        decode(b'ZMX\x00\x01\x02\x03\xff' * 40, 'enc.zmx')


@pytest.mark.parametrize('name,expected', [
    ('thorlabs_ASL5040-UV.zmx', ['line 76', 'surface 1', 'Q-type', 'QED_TYPE']),
    ('edmund_37992.zmx', ['line 86', 'surface 2', 'coordinate break']),
    ('HoO-V2C18Ex46.zmx', ['surface 2', 'coordinate break']),
], ids=['q-type-asphere', 'off-axis-parabola', 'toroidal-mirror-system'])
def test_real_files_refused(name, expected):
    with pytest.raises(LensImportError) as err:
        import_zmx(FILES / name, resolve=fixed_index)
    for part in expected:
        assert part in str(err.value)


def test_cli_refusal_exits_2_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / 'lens.yaml'
    assert main(['import', str(FILES / 'edmund_37992.zmx'), '-o', str(out)]) == 2
    err = capsys.readouterr().err
    assert 'edmund_37992.zmx: line 86: surface 2' in err and 'Traceback' not in err
    assert not out.exists() and list(tmp_path.iterdir()) == []
    out.write_text('kept\n')
    bad = tmp_path / 'cut.zmx'
    bad.write_text(SINGLET[:SINGLET.index('  DISZ 47.5')])
    assert main(['import', str(bad), '-o', str(out)]) == 2
    assert out.read_text() == 'kept\n'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['cut.zmx', 'lens.yaml']


@pytest.mark.skipif(not HAVE_GLASS, reason='needs mechdeconv_ros.optics.glass (branch glass)')
def test_unknown_glass_without_nd_vd_is_refused_by_name():
    text = SINGLET.replace('GLAS N-BK7 0 0 1.5168 64.17 0 0 0 0 0 0',
                           'GLAS UNOBTAINIUM-7 0 0 1.5 40 0 0 0 0 0 0')
    with pytest.raises(LensImportError) as err:
        zmx_values(parse(text, 'g.zmx'))
    assert 'line 25' in str(err.value) and 'UNOBTAINIUM-7' in str(err.value)
    text = text.replace('1.5 40 0', '1.6 45 0')
    result = zmx_values(parse(text, 'g.zmx'))
    assert any('UNOBTAINIUM-7' in w and 'MODEL:1.6:45' in w for w in result.warnings)
    from mechdeconv_ros.optics.glass import model_glass_index
    assert result.values['lens.surfaces.refractive_index'][0] == \
        model_glass_index(1.6, 45.0, 587.56)
    plain = zmx_values(parse(SINGLET, 'g.zmx'))
    assert plain.warnings == []
    assert plain.values['lens.surfaces.refractive_index'][0] == pytest.approx(1.5168, abs=2e-5)
    withdrawn = zmx_values(parse(SINGLET.replace('GLAS N-BK7 0 0 1.5168 64.17', 'GLAS BK7'),
                                 'g.zmx'))
    assert 'glass BK7' in withdrawn.warnings[0] and 'SCHOTT:N-BK7' in withdrawn.warnings[0]
    assert withdrawn.values == plain.values


REAL = (FILES / 'US00583336-2-scaled.zmx').read_bytes()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cut=st.integers(0, len(REAL)),
       flips=st.lists(st.tuples(st.integers(0, len(REAL) - 1), st.integers(0, 255)),
                      max_size=6))
def test_fuzz_flips_and_truncations_refuse_cleanly(cut, flips):
    """Byte flips and truncations of a real file: a result or LensImportError, nothing else."""
    data = bytearray(REAL)
    for at, value in flips:
        data[at] = value
    data = bytes(data[:cut] if cut < len(REAL) // 2 or not flips else data)
    try:
        lens = parse(decode(data, 'fuzz.zmx'), 'fuzz.zmx')
        result = zmx_values(lens) if HAVE_GLASS else zmx_values(lens, resolve=fixed_index)
    except LensImportError as err:
        assert str(err).startswith('fuzz.zmx')
        return
    for value in result.values.values():
        numbers = [v for v in (value if isinstance(value, list) else [value])
                   if not isinstance(v, str)]
        assert all(map(math.isfinite, numbers))


def test_real_file_with_a_finite_object():
    """US 5,831,776: object 110.86 mm before the first vertex -> scene.distance_mm from H."""
    from mechdeconv_ros.model.model import make_prescription
    from mechdeconv_ros.schema.params import check_values

    # (The file's 248 nm is outside lens.wavelength_nm's range: the geometry needs none.)
    values = import_zmx(FILES / 'US05831776-1.zmx', 550.0, resolve=fixed_index).values
    assert len(values['lens.surfaces.radius_mm']) == 42 and values['lens.stop_surface'] == 19
    z_h = paraxial(make_prescription(check_values(values))).front_principal_z_mm
    assert_allclose(values['scene.distance_mm'], 110.8588354359 + z_h, rtol=1e-12)


def test_a_curved_image_surface_is_imported_flat_with_a_warning():
    flat = 'SURF 3\n  TYPE STANDARD\n  CURV 0.0'
    text = SINGLET.replace(flat, flat.replace('CURV 0.0', 'CURV -0.01'))
    result = imported(text)
    assert any('image surface (surface 3) is curved (radius -100 mm)' in w
               for w in result.warnings)
