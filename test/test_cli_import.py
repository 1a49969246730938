# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``mechdeconv import``: a .zmx file or a datasheet CSV table to a params file, in-process.

The written file loads with ``--params`` as it is (``info`` runs on it), names its source and
says the sensor is missing; a refusal exits 2 with one line on stderr and writes nothing.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from mechdeconv_ros.lenses.datasheet import make_table
from mechdeconv_ros.lenses.datasheet_csv import read_table, table_values
from mechdeconv_ros.lenses.zmx import LensImportError
from mechdeconv_ros.schema.params import load_params_file
from mechdeconv_ros.tools.cli import main
from numpy.testing import assert_allclose
import pytest

ROOT = Path(__file__).resolve().parents[1]
ZMX = ROOT / 'test' / 'data' / 'zmx'

TABLE = """field angle (deg), real image height (mm)
0, 0
10, 0.7040
20, 1.4010
30, 2.0770
40, 2.7180
"""


def run(capsys, *argv):
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.mark.parametrize('sep', [',', ';', '\t', ' '],
                         ids=['comma', 'semicolon', 'tab', 'space'])
def test_csv_separators_and_header(tmp_path, sep):
    path = tmp_path / 't.csv'
    path.write_text(TABLE.replace(', ', sep).replace(',', sep))
    angles, heights, ri = read_table(path)
    assert angles == [0.0, 10.0, 20.0, 30.0, 40.0]
    assert heights[1:3] == [0.704, 1.401] and ri == []


def test_csv_third_column_and_values(tmp_path):
    path = tmp_path / 't.csv'
    path.write_text('# vendor table\n0;0;1\n10;0.704;0.97\n20;1.401;0.9\n')
    result = table_values(path, 4.0)
    assert result.values['lens.focal_length_mm'] == 4.0
    assert result.values['lens.datasheet.relative_illumination'] == [1.0, 0.97, 0.9]
    assert result.values['lens.datasheet.image_height_mm'] == [0.0, 0.704, 1.401]


@pytest.mark.parametrize('text,expected', [
    ('0,0\n10,0.7\n9,0.8\n', 'line 3: field angle 9 deg does not increase'),
    ('0,0\n10,0.7\n20,0.6\n', 'line 3: image height 0.6 mm does not increase'),
    ('0,0\n10,0.7\nabc,1\n', 'line 3'),
    ('0,0,1,2\n10,1,1,2\n20,2,1,2\n', '4 columns'),
    ('0,0\n10,0.7\n20,1.4,0.9\n', 'line 3: 3 columns'),
    ('0,0\n10,0.7\n', '2 rows'),
    ('0,0\n-10,0.7\n20,1.4\n', 'outside 0 to 180'),
    ('', '0 rows'),
    ('0,0.1\n10,0.7\n20,1.4\n', 'image_height_mm: is 0.1 mm at 0 deg'),
], ids=['angle-not-monotonic', 'height-not-monotonic', 'text-row', 'four-columns',
        'ragged', 'too-short', 'negative-angle', 'empty', 'not-zero-on-axis'])
def test_csv_refusals_name_the_line(tmp_path, text, expected):
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    with pytest.raises(LensImportError, match='bad.csv'):
        table_values(path, 4.0)
    with pytest.raises(LensImportError) as err:
        table_values(path, 4.0)
    assert expected in str(err.value)


def test_csv_cli_refusal_writes_nothing(tmp_path, capsys):
    path = tmp_path / 'bad.csv'
    path.write_text('0,0\n10,0.7\n20,0.6\n')
    out = tmp_path / 'lens.yaml'
    status, _, err = run(capsys, 'import', path, '--focal-length-mm', 4, '-o', out)
    assert status == 2 and 'bad.csv: line 3' in err and 'Traceback' not in err
    assert not out.exists()
    status, _, err = run(capsys, 'import', tmp_path / 'bad.csv', '-o', out)
    assert status == 2 and '--focal-length-mm' in err
    status, _, err = run(capsys, 'import', ZMX / 'edmund_55278.zmx', '--focal-length-mm', 4,
                         '-o', out)
    assert status == 2 and not out.exists()


def test_csv_cli_writes_datasheet_params_that_load(tmp_path, capsys):
    path = tmp_path / 'm12.csv'
    path.write_text(TABLE)
    out = tmp_path / 'lens.yaml'
    status, _, err = run(capsys, 'import', path, '--focal-length-mm', 4.0, '-o', out)
    assert status == 0, err
    values = load_params_file(out)
    assert values['lens.datasheet.field_angle_deg'] == [0.0, 10.0, 20.0, 30.0, 40.0]
    assert values['lens.focal_length_mm'] == 4.0
    status, text, err = run(capsys, 'info', '--params', out, '--width', 640, '--height', 480,
                            '--json')
    assert status == 0, err


def test_zmx_import_writes_a_params_file_that_info_loads(tmp_path, capsys):
    out = tmp_path / 'lens.yaml'
    status, _, err = run(capsys, 'import', ZMX / 'edmund_55278.zmx', '-o', out)
    assert status == 0, err
    assert 'BK7' in err and 'SCHOTT:N-BK7' in err and 'obsolete' in err
    assert 'wrote' in err and 'Traceback' not in err
    text = out.read_text()
    assert 'edmund_55278.zmx ("55278 Mounted Achromat Pair")' in text
    assert 'add sensor.pixel_size_x_um' in text
    values = load_params_file(out)
    assert values['lens.stop_surface'] == 0 and len(values['lens.surfaces.radius_mm']) == 6
    assert values['lens.wavelength_nm'] == pytest.approx(587.6)
    assert values['lens.image_distance_mm'] == pytest.approx(43.707716717029655)
    status, report, err = run(capsys, 'info', '--params', out, '--width', 1920, '--height',
                              1200, '-p', 'sensor.pixel_size_x_um=5.86', '-p',
                              'sensor.pixel_size_y_um=5.86', '--json')
    assert status == 0, err
    # optiland's BK7 and SF5 data differ from the catalogs' in the 5th decimal of the index.
    assert_allclose(json.loads(report)['focal_length_mm'], 52.24355673278863, rtol=3e-5)


def test_zmx_import_at_another_wavelength(tmp_path, capsys):
    """--wavelength-nm: every index at 850 nm, lower than at the d-line (normal dispersion)."""
    d_line, near_ir = tmp_path / 'd.yaml', tmp_path / 'ir.yaml'
    assert run(capsys, 'import', ZMX / 'edmund_55278.zmx', '-o', d_line)[0] == 0
    assert run(capsys, 'import', ZMX / 'edmund_55278.zmx', '-o', near_ir,
               '--wavelength-nm', 850)[0] == 0
    n_d = load_params_file(d_line)['lens.surfaces.refractive_index']
    n_ir = load_params_file(near_ir)['lens.surfaces.refractive_index']
    for a, b in zip(n_d, n_ir):
        assert (a == b == 1.0) or 0.0 < a - b < 0.03


def test_wavelength_outside_the_range_is_refused(tmp_path, capsys):
    out = tmp_path / 'lens.yaml'
    status, _, err = run(capsys, 'import', ZMX / 'edmund_55278.zmx', '-o', out,
                         '--wavelength-nm', 100)
    assert status == 2 and 'wavelength 100 nm (given) is outside 350 to 2500 nm' in err
    status, _, err = run(capsys, 'import', ZMX / 'US05831776-1.zmx', '-o', out)
    assert status == 2 and "248 nm (the file's primary wavelength)" in err
    assert not out.exists()


@pytest.mark.parametrize('angles, heights', [
    # Rectilinear, f = 4 mm, starting off axis: h = f tan(theta) from 5 deg.
    ([5, 10, 20, 30], [4.0 * math.tan(math.radians(a)) for a in (5, 10, 20, 30)]),
    # Rectilinear from the axis with a coarse first step (h / theta is 7.7 % above f).
    ([0, 25, 40], [4.0 * math.tan(math.radians(a)) for a in (0, 25, 40)]),
    # Off axis, and twice the focal length given: both must warn.
    ([5, 10, 20], [8.0 * math.tan(math.radians(a)) for a in (5, 10, 20)]),
], ids=['rectilinear-off-axis', 'rectilinear-coarse', 'wrong-f-off-axis'])
def test_csv_import_and_model_give_one_focal_length_verdict(tmp_path, angles, heights) -> None:
    # Issue 29: the CSV import checked h/theta of a table starting at 0 only, the model
    # min(h/theta, h/tan theta) from any start: they disagreed on rectilinear tables.
    path = tmp_path / 'table.csv'
    path.write_text('\n'.join(f'{a}, {h!r}' for a, h in zip(angles, heights)) + '\n')
    imported = table_values(path, 4.0)
    model_warnings = make_table(imported.values).warnings
    assert imported.warnings == list(model_warnings)
    doubled = heights[-1] > 2 * 4.0 * math.tan(math.radians(angles[-1])) - 1e-9
    assert bool(imported.warnings) == doubled
