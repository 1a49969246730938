# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""Moving-group tables (issue 19): checks, refusals naming the parameter, interpolation."""

from __future__ import annotations

from pathlib import Path

from mechdeconv_ros.lenses import lens_table
from mechdeconv_ros.schema.params import check_values, load_params_file
import numpy as np
from numpy.testing import assert_allclose
import pytest

CONFIG = Path(__file__).resolve().parents[1] / 'config'


@pytest.fixture(scope='module')
def zoom_values():
    return load_params_file(CONFIG / 'zoom.yaml')


def _with(values, **changes):
    out = dict(values)
    out.update({k.replace('__', '.'): v for k, v in changes.items()})
    return check_values(out)


def test_zoom_config_has_a_checked_table(zoom_values):
    (zoom,) = lens_table.mechanisms(zoom_values)
    assert zoom.name == 'zoom' and zoom.joint == 'zoom'
    assert zoom.surfaces == (4, 9, 12)
    assert zoom.rows.shape == (17, 3)
    # The front and rear groups stay put: the moving gaps keep their sum (tools/ solves d2).
    assert_allclose(zoom.rows.sum(axis=1), 55.338, atol=1e-3)
    # Row 0 is the prescription's own gaps.
    thickness = zoom_values['lens.surfaces.thickness_mm']
    assert_allclose(zoom.rows[0], [thickness[i] for i in zoom.surfaces])


def test_gaps_interpolate_linearly_and_clamp(zoom_values):
    (zoom,) = lens_table.mechanisms(zoom_values)
    p = zoom.positions
    for j in (0, 5, 15):
        for t in (0.0, 0.25, 0.5, 1.0):
            x = p[j] + t * (p[j + 1] - p[j])
            assert_allclose(zoom.gaps_at(x), zoom.rows[j] + t * (zoom.rows[j + 1] - zoom.rows[j]),
                            atol=1e-12)
    assert_allclose(zoom.gaps_at(-3.0), zoom.rows[0])
    assert_allclose(zoom.gaps_at(7.0), zoom.rows[-1])
    assert zoom.clamped(-0.001) and zoom.clamped(1.001) and not zoom.clamped(1.0)


def test_values_at_moves_only_the_gaps(zoom_values):
    moved = lens_table.values_at(zoom_values, {'zoom': 0.5})
    before = zoom_values['lens.surfaces.thickness_mm']
    after = moved['lens.surfaces.thickness_mm']
    changed = [i for i, (a, b) in enumerate(zip(before, after)) if a != b]
    assert changed == [4, 9, 12]
    assert moved['lens.zoom.joint'] == '' and zoom_values['lens.zoom.joint'] == 'zoom'
    # A mechanism missing from the state sits at its first row.
    assert lens_table.values_at(zoom_values, {})['lens.surfaces.thickness_mm'] == before


def test_no_joint_means_no_mechanism():
    assert lens_table.mechanisms(check_values({})) == ()


@pytest.mark.parametrize('changes, parameter, words', [
    ({'lens.zoom.thickness_mm': [1.0] * 50}, 'lens.zoom.thickness_mm', '17 x 3 = 51'),
    ({'lens.zoom.positions': [0.0, 0.5, 0.5] + [1.0 + i for i in range(14)]},
     'lens.zoom.positions', 'strictly increasing'),
    ({'lens.zoom.positions': [0.0]}, 'lens.zoom.positions', 'at least 2'),
    ({'lens.zoom.surfaces': [4, 9, 30]}, 'lens.zoom.surfaces', 'not an index'),
    ({'lens.zoom.surfaces': [4, 9, 21]}, 'lens.zoom.surfaces', 'image distance'),
    ({'lens.zoom.surfaces': [4, 9, 13]}, 'lens.zoom.surfaces', 'glass thickness'),
    ({'lens.focus.joint': 'focus', 'lens.focus.positions': [0.0, 1.0],
      'lens.focus.surfaces': [4], 'lens.focus.thickness_mm': [1.0, 2.0]},
     'lens.focus.surfaces', 'moved by lens.zoom.surfaces'),
    ({'lens.zoom.surfaces': []}, 'lens.zoom.surfaces', 'is empty'),
], ids=['shape', 'not-increasing', 'one-position', 'out-of-range', 'last-entry', 'glass',
        'both-mechanisms', 'no-gaps'])
def test_refusals_name_the_parameter(zoom_values, changes, parameter, words):
    values = dict(zoom_values)
    values.update(changes)
    with pytest.raises(lens_table.TableError) as err:
        lens_table.mechanisms(check_values(values))
    assert err.value.parameter == parameter
    assert str(err.value).startswith(parameter + ':') and words in str(err.value)


def test_nan_and_negative_gaps_are_refused(zoom_values):
    values = dict(zoom_values)
    table = list(values['lens.zoom.thickness_mm'])
    table[7] = float('nan')
    values['lens.zoom.thickness_mm'] = table
    with pytest.raises(ValueError, match=r'lens\.zoom\.thickness_mm\[7\]: must be finite'):
        check_values(values)
    values = dict(zoom_values)
    # Past the schema (which refuses negatives), a raw mapping is checked again here.
    values['lens.zoom.thickness_mm'] = list(zoom_values['lens.zoom.thickness_mm'])
    values['lens.zoom.thickness_mm'][4] = -1.0
    with pytest.raises(lens_table.TableError, match='row 1'):
        lens_table.mechanisms(values)


def test_thick_lens_cannot_move():
    with pytest.raises(lens_table.TableError, match='lens.zoom.joint: .* prescription'):
        lens_table.mechanisms(check_values({'lens.zoom.joint': 'zoom'}))


def test_check_reachable_visits_rows_and_mid_rows_and_names_the_row(zoom_values):
    seen = []

    def check(values):
        seen.append(values['lens.surfaces.thickness_mm'][4])

    assert lens_table.check_reachable(zoom_values, check) == 33
    (zoom,) = lens_table.mechanisms(zoom_values)
    assert_allclose(sorted(seen), [zoom.gaps_at(p)[0] for p in zoom.probe_positions()])

    def refuse_long_end(values):
        if values['lens.surfaces.thickness_mm'][4] > 47.0:
            raise ValueError('lens.surfaces.thickness_mm: the image lies inside the glass')

    with pytest.raises(lens_table.TableError) as err:
        lens_table.check_reachable(zoom_values, refuse_long_end)
    assert err.value.parameter == 'lens.zoom.thickness_mm'
    assert 'half-way between rows 15 and 16 (position 0.96875)' in str(err.value)
    assert 'inside the glass' in str(err.value)


def test_two_mechanisms_check_their_product(zoom_values):
    values = check_values({**zoom_values, 'lens.focus.joint': 'focus_motor',
                           'lens.focus.positions': [0.0, 2.0, 4.0],
                           'lens.focus.surfaces': [16],
                           'lens.focus.thickness_mm': [17.857, 17.5, 17.0]})
    zoom, focus = lens_table.mechanisms(values)
    assert focus.joint == 'focus_motor'
    count = lens_table.check_reachable(values, lambda v: None)
    assert count == 33 * 5
    moved = lens_table.values_at(values, {'zoom': 1.0, 'focus': 3.0})
    assert_allclose(moved['lens.surfaces.thickness_mm'][16], 17.25)
    assert_allclose(moved['lens.surfaces.thickness_mm'][4], zoom.rows[-1][0])


@pytest.mark.parametrize('text, expected', [
    ('zoom=0.5', {'zoom': 0.5}), ('zoom=1,focus=-2.5', {'zoom': 1.0, 'focus': -2.5}),
    (' focus = 3 ', {'focus': 3.0})])
def test_parse_lens_state(text, expected):
    assert lens_table.parse_lens_state(text) == expected


@pytest.mark.parametrize('text', ['zoom', 'tilt=1', 'zoom=x', 'zoom=nan', 'zoom=1,zoom=2', ''])
def test_parse_lens_state_refusals(text):
    with pytest.raises(ValueError, match='--lens-state'):
        lens_table.parse_lens_state(text)


def test_probe_positions_are_rows_and_mid_rows(zoom_values):
    (zoom,) = lens_table.mechanisms(zoom_values)
    probes = zoom.probe_positions()
    assert probes.size == 33 and np.all(np.diff(probes) > 0)
    assert_allclose(probes[::2], zoom.positions)
    assert zoom.step == pytest.approx(0.0625)


def test_model_of_a_moving_lens_and_a_refused_row(zoom_values):
    # The seam: a moving lens is a lens source at a state, checked at every reachable state.
    from mechdeconv_ros.lenses.moving_source import MovingSource
    from mechdeconv_ros.model.model import build_model, ModelError

    model = build_model(zoom_values, 320, 180)
    assert isinstance(model.source, MovingSource) and model.source.state == {'zoom': 0.0}
    assert model.focal_length_mm == pytest.approx(57.206, abs=1e-3)
    long_end = build_model(zoom_values, 320, 180, source=MovingSource(zoom_values,
                                                                      {'zoom': 1.0}))
    assert long_end.focal_length_mm == pytest.approx(143.03, abs=1e-2)
    values = dict(zoom_values)
    table = list(values['lens.zoom.thickness_mm'])
    table[24:27] = [1.86, 500.0, 16.55]        # row 8: the variator 500 mm from the compensator
    values['lens.zoom.thickness_mm'] = table
    with pytest.raises(ModelError) as err:
        build_model(values, 320, 180)
    assert err.value.parameter == 'lens.zoom.thickness_mm'
    assert 'between rows 7 and 8' in str(err.value) and 'wider than the surfaces' in str(err.value)
    values['lens.zoom.surfaces'] = [4, 9, 30]
    with pytest.raises(ModelError, match=r'^lens\.zoom\.surfaces: 30 is not an index'):
        build_model(values, 320, 180)


def test_zoom_cam_keeps_the_image_plane_and_spans_the_patent_range(zoom_values):
    """tools/make_zoom_config.py solved the compensator: the image plane never moves."""
    import math

    from mechdeconv_ros.lenses.lens_source import PrescriptionSource

    (zoom,) = lens_table.mechanisms(zoom_values)
    planes, focals = [], []
    for p in zoom.positions:
        source = PrescriptionSource(lens_table.values_at(zoom_values, {'zoom': p}))
        planes.append(source.image_plane(math.inf)[0])
        focals.append(source.first_order().efl_mm)
    assert_allclose(planes, planes[0], atol=1e-3)     # the table has 0.1 um digits
    assert np.all(np.diff(focals) > 0)
    # The patent's 2.5x: f = 57.2 to 143.0 mm as tabulated; its long row to 0.03 mm.
    assert focals[-1] / focals[0] == pytest.approx(2.5, abs=0.01)
    assert_allclose(zoom.rows[-1], [48.678, 1.536, 5.133], atol=0.03)


def test_a_gap_named_glass_does_not_move_whatever_the_index_array_says(zoom_values):
    # Issue 29, the same read: lens.surfaces.glass sets the medium after a surface (the index
    # array is then not used), so a gap with a glass name is a glass thickness.
    values = dict(zoom_values)
    count = len(values['lens.surfaces.thickness_mm'])
    gap = values['lens.zoom.surfaces'][0]
    assert values['lens.surfaces.refractive_index'][gap] == 1.0
    glass = [''] * count
    glass[gap] = 'N-BK7'
    values['lens.surfaces.glass'] = glass
    with pytest.raises(lens_table.TableError) as err:
        lens_table.mechanisms(check_values(values))
    assert err.value.parameter == 'lens.zoom.surfaces'
    assert f'lens.surfaces.glass[{gap}] = N-BK7' in str(err.value)
    glass[gap] = 'AIR'
    assert lens_table.mechanisms(check_values(values))
