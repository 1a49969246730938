#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Generate test/data/glass_reference.json: glass indices computed by optiland's material model.

Used only by test/test_glass.py (which must pass without optiland). optiland is not a
dependency of the package; install the pin of ``requirements-reference.txt`` and run::

    python tools/make_glass_reference.py      # writes test/data/glass_reference.json

For each glass of ``GLASSES`` (catalog, name as optiland's database spells it) and each
wavelength of ``WAVELENGTHS_NM`` inside the formula's range: optiland's
``Material(name, catalog=...).n(lambda_um)`` and ``.abbe()`` (``MaterialFile`` of the glass's
own file when optiland's name search resolves to another glass: it maps SF11 to N-SF11);
for the model glasses, optiland's ``AbbeMaterial(nd, vd, model='buchdahl')`` at the same
wavelengths (a second, independent
model of an (nd, vd) glass, recorded for comparison in docs/design.md section 2.11).
"""

from __future__ import annotations

import argparse
from importlib import resources
from importlib.metadata import version
import json
from pathlib import Path
import sys
import warnings

REPO = Path(__file__).resolve().parent.parent
OUTPUT = REPO / 'test' / 'data' / 'glass_reference.json'
GLASSES = [('SCHOTT', 'N-BK7'), ('SCHOTT', 'N-SF11'), ('SCHOTT', 'N-LASF9'),
           ('SCHOTT', 'N-FK51A'), ('SCHOTT', 'F2'), ('SCHOTT', 'SF11'), ('SCHOTT', 'LF7'),
           ('OHARA', 'S-LAH66'), ('OHARA', 'S-BSL7'), ('OHARA', 'S-TIH53'),
           ('HOYA', 'TAFD25'), ('HOYA', 'E-FD1'), ('HOYA', 'BSC7'),
           ('CDGM', 'H-ZF52'), ('CDGM', 'H-K9L'), ('CDGM', 'H-LAK51A'),
           ('SUMITA', 'K-VC89'), ('HIKARI', 'J-BK7A')]
WAVELENGTHS_NM = [435.8343, 486.1327, 546.074, 587.5618, 656.2725, 850.0, 1000.0]


def _scalar(value: object) -> float:
    """Return optiland's one-element array (or scalar) as a float."""
    import numpy as np
    return float(np.asarray(value, dtype=float).ravel()[0])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('-o', '--output', type=Path, default=OUTPUT)
    args = parser.parse_args(argv)
    from optiland.materials import AbbeMaterial, Material
    from optiland.materials.material_file import MaterialFile
    sys.path.insert(0, str(REPO))
    from mechdeconv_ros.optics.glass import lookup
    glasses = []
    for catalog, name in GLASSES:
        ours = lookup(f'{catalog}:{name}')
        lo, hi = ours.wavelength_range_nm
        with warnings.catch_warnings():
            warnings.simplefilter('error')  # a fuzzy match would be another glass
            material = Material(name, catalog=catalog.lower())
            resolved = str(material.filename).split('database/')[-1]
            if Path(resolved).stem != name:
                # optiland's name search maps some old names to new glasses (SF11 -> N-SF11):
                # read the glass's own file instead.
                folder = resources.files('optiland.database') / 'data-nk' / 'glass'
                path = next(Path(str(folder)).glob(f'{catalog.lower()}/**/{name}.yml'))
                material = MaterialFile(str(path))
            waves = [w for w in WAVELENGTHS_NM if lo <= w <= hi]
            glasses.append({
                'catalog': catalog, 'name': name,
                'optiland_name_lookup': resolved,
                'optiland_file': str(material.filename).split('database/')[-1],
                'wavelength_nm': waves,
                'n': [_scalar(material.n(w / 1000.0)) for w in waves],
                'abbe': _scalar(material.abbe()),
            })
        model = AbbeMaterial(ours.nd, ours.vd, model='buchdahl')
        glasses[-1]['buchdahl_n'] = [_scalar(model.n(w / 1000.0)) for w in waves]
    result = {'generator': 'tools/make_glass_reference.py',
              'optiland': version('optiland'),
              'note': 'optiland Material(name, catalog).n(um) and .abbe(); buchdahl_n: '
                      "AbbeMaterial(nd, vd, model='buchdahl') of the catalog nd/vd",
              'glasses': glasses}
    args.output.write_text(json.dumps(result, indent=1) + '\n', encoding='utf-8')
    print(f'wrote {args.output}: {len(glasses)} glasses')
    return 0


if __name__ == '__main__':
    sys.exit(main())
