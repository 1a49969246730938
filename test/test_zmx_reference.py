# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Imported real ``.zmx`` files against optiland's own reading and trace of the same files.

The files are vendor (Edmund, Thorlabs) and patent files that rayoptics ships for its tests
(test/data/zmx/README.md); ``test/data/zmx_reference.json`` holds what optiland 0.6.3 makes of
them (``tools/make_zmx_reference.py``: its own parser and glass data, chief rays aimed at the
stop centre, heights on the file's image surface). Asserted (issue 18, item 6):

- geometry: our import, with each medium at optiland's index, has optiland's vertex
  positions, its effective focal length within 1e-6 relative, and traces every chief ray
  within 0.01 px of optiland's (at a pixel pitch whose sensor the traced field covers) on the
  sensor at ``lens.image_distance_mm`` behind the last surface;
- glass: where optiland found the same catalog glass, our index at the file's wavelength
  agrees within 2e-5 (two catalog transcriptions), and the whole import (our glass) traces
  within 0.01 px with the focal length within 1e-6 wherever every index agrees to 1e-7.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from mechdeconv_ros.lenses.lens_import import import_zmx, Medium
from mechdeconv_ros.lenses.zmx import LensImportError
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.optics.raytrace import paraxial, Prescription, Surface, trace_field_angles
from mechdeconv_ros.optics.raytrace import vertex_z
from mechdeconv_ros.schema.params import check_values
import numpy as np
from numpy.testing import assert_allclose
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = json.loads((ROOT / 'test' / 'data' / 'zmx_reference.json').read_text())
LENSES = DATA['lenses']
#: Files our glass data cannot import as they stand (the geometry test above still runs).
REFUSED = {
    # Schott B 270 is in no bundled catalog and the file's GLAS line carries 1.5 / 40
    # placeholders, not its nd / vd.
    'thorlabs_ACL3026U': 'glass B270 is in none of the catalogs',
    # D-ZK3M (LightPath) is a model glass here, and 1550 nm is beyond the model's range.
    'thorlabs_354710-C': 'outside the valid range',
}
#: Lenses whose every index agrees with optiland's to 1e-7, so the whole import (our glass) is
#: traced against optiland. The others, and why: edmund_55278's SF5 differs by 1e-5 (two
#: transcriptions of Schott's catalog: the 2e-5 check above holds), US08427765-1's L-TIM28 is
#: not in optiland's database (it puts a 1.5 placeholder there). The test asserts this list, so
#: a lens that stops agreeing, or starts to, is seen.
WHOLE_IMPORT_TRACED = {'US00583336-2-scaled'}


def optiland_indices(ref: dict):
    """Return a resolver giving each medium optiland's index (file surface n -> media[n])."""
    def resolve(lens, surface, wavelength_nm):
        return Medium('', ref['media'][surface.number]['index'])
    return resolve


def prescription(values: dict) -> tuple[Prescription, float]:
    """Build our prescription from imported values; return it and the sensor's z."""
    count = len(values['lens.surfaces.radius_mm'])
    conic = values.get('lens.surfaces.conic', [0.0] * count)
    terms = [values.get(f'lens.surfaces.asphere_a{p}', [0.0] * count)
             for p in (4, 6, 8, 10, 12, 14, 16)]
    surfaces = tuple(Surface(r, t, n, s, k, tuple(a[i] for a in terms))
                     for i, (r, t, n, s, k) in enumerate(zip(
                         values['lens.surfaces.radius_mm'], values['lens.surfaces.thickness_mm'],
                         values['lens.surfaces.refractive_index'],
                         values['lens.surfaces.semi_diameter_mm'], conic)))
    probe = Prescription(surfaces, 0.0)
    z = vertex_z(probe)
    lens = Prescription(surfaces, float(z[values['lens.stop_surface']]))
    return lens, float(z[-1]) + values['lens.surfaces.thickness_mm'][-1]


def compare(key: str, values: dict) -> float:
    """Assert focal length and chief-ray heights against optiland; return the worst px."""
    ref = LENSES[key]
    lens, sensor_z = prescription(values)
    assert_allclose(paraxial(lens).efl_mm, ref['efl_mm'], rtol=1e-6)
    assert values['scene.distance_mm'] == 0.0           # every reference is at infinity
    theta = np.radians(ref['field_deg'])
    ours = -trace_field_angles(lens, math.inf, sensor_z, theta)
    assert np.all(np.isfinite(ours)), f'{key}: our trace loses rays optiland traces'
    pixel = ref['tolerance_pixel_um'] * 1e-3
    worst = float(np.max(np.abs(ours - np.array(ref['real_height_mm'])))) / pixel
    assert worst <= 0.01, f'{key}: {worst:.4f} px from optiland'
    return worst


def test_reference_provenance():
    """The reference says what made it; optiland aimed every chief ray at the stop centre."""
    assert DATA['provenance']['versions']['optiland'] == '0.6.3'
    assert len(LENSES) >= 3
    for key, ref in LENSES.items():
        assert (ROOT / ref['file']).is_file(), key
        assert ref['max_stop_residual_mm'] < 1e-9, key
        assert len(ref['field_deg']) == len(ref['real_height_mm']) >= 21


@pytest.mark.parametrize('key', sorted(LENSES), ids=sorted(LENSES))
def test_geometry_matches_optiland(key):
    """Surfaces, stop, image distance and asphere terms as optiland reads them."""
    ref = LENSES[key]
    imported = import_zmx(ROOT / ref['file'], resolve=optiland_indices(ref))
    values = imported.values
    lens, _ = prescription(values)
    assert_allclose(vertex_z(lens), np.array(ref['vertex_z_mm'][:-1]) - ref['vertex_z_mm'][0],
                    atol=1e-9)
    compare(key, values)
    # The model builds from the values as written, with the sensor at the file's image
    # surface: the raw focal length is the chief-ray scale there.
    pitch = ref['tolerance_pixel_um']
    model = build_model(check_values({**values, 'sensor.pixel_size_x_um': pitch,
                                      'sensor.pixel_size_y_um': pitch}), 640, 480)
    assert model.K[0, 0] > 0.0


def test_an_asphere_and_a_utf16_file_are_among_them():
    """At least one reference has aspheres, one is UTF-16, one is a stock (vendor) lens."""
    aspheric = utf16 = vendor = 0
    for key, ref in LENSES.items():
        values = import_zmx(ROOT / ref['file'], resolve=optiland_indices(ref)).values
        aspheric += any(k.startswith('lens.surfaces.asphere_a') for k in values)
        utf16 += (ROOT / ref['file']).read_bytes()[:2] == b'\xff\xfe'
        vendor += key.startswith(('edmund', 'thorlabs'))
    assert aspheric >= 2 and utf16 >= 2 and vendor >= 2


@pytest.mark.parametrize('key', sorted(LENSES), ids=sorted(LENSES))
def test_glass_indices_match_optiland(key):
    """Catalog glasses: our index agrees with optiland's; the whole import traces alike."""
    ref = LENSES[key]
    if key in REFUSED:
        with pytest.raises(LensImportError) as err:
            import_zmx(ROOT / ref['file'])
        assert REFUSED[key] in str(err.value)
        return
    imported = import_zmx(ROOT / ref['file'])
    ours = imported.values['lens.surfaces.refractive_index']
    theirs = [m['index'] for m in ref['media'][1:-1]]
    catalog = [m['kind'] == 'Material' for m in ref['media'][1:-1]]
    glass = imported.values.get('lens.surfaces.glass', [''] * len(ours))
    for i, (a, b, same) in enumerate(zip(ours, theirs, catalog)):
        if same and not glass[i].startswith('MODEL:'):
            assert abs(a - b) <= 2e-5, f'{key}: surface {i} ({glass[i]}): {a} vs {b}'
    agree = all(abs(a - b) <= 1e-7 for a, b in zip(ours, theirs))
    assert agree == (key in WHOLE_IMPORT_TRACED), f'{key}: indices agree to 1e-7: {agree}'
    if agree:
        compare(key, imported.values)
