#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Generate test/data/zmx_reference.json: optiland's own reading and trace of real ``.zmx`` files.

Used only by test/test_zmx_reference.py. optiland (0.6.3, ``requirements-reference.txt``) is
not a dependency of the package; run::

    python tools/make_zmx_reference.py            # about a minute

For each file of :data:`FILES` (vendor and patent files that rayoptics ships for its own
tests: test/data/zmx/README.md) optiland loads the file itself
(``optiland.fileio.load_zemax_file``: its own parser, its own glass data), and this tool
records, at the file's primary wavelength:

- the effective focal length (``paraxial.f2``);
- the index optiland gives each medium (surface i's ``material_post``) and what kind of
  material it resolved (catalog ``Material``, ``AbbeMaterial`` from nd/vd, ideal);
- the real chief-ray height on the file's own image surface at field angles from 0 to the
  chosen maximum (the file's largest angle field, or one chosen here when the file has only
  the axis), aimed by optiland's ``'robust'`` aimer so that it crosses the stop centre.

Signs: optiland's angle field -Hy makes the chief ray arrive travelling towards -y, so the
recorded ``real_height_mm`` is the magnitude of the image height (our convention: a real
image is inverted, docs/design.md section 1). ``tolerance_pixel_um`` is the pixel pitch of a
sensor whose image circle the traced field covers; the test demands 0.01 of it.
"""

from __future__ import annotations

import datetime
from importlib import metadata
import json
from pathlib import Path
import platform
import re
import sys
import warnings

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / 'test' / 'data'
OUTPUT = DATA / 'zmx_reference.json'

#: (key, file under test/data/zmx, largest field angle in deg, pixel pitch in um, note).
FILES = (
    ('edmund_55278', 'edmund_55278.zmx', 8.0, 3.45,
     'Edmund Optics 55278 mounted achromat pair (SF5 / BK7, obsolete Schott names), '
     'UTF-16, no field off the axis in the file: 8 deg chosen'),
    ('thorlabs_ACL3026U', 'thorlabs_ACL3026U.zmx', 10.0, 3.45,
     'Thorlabs ACL3026U aspheric condenser (EVENASPH, B270), UTF-16: 10 deg chosen'),
    ('thorlabs_354710-C', 'thorlabs_354710-C.zmx', 4.0, 1.4,
     'Thorlabs 354710-C molded asphere (D-ZK3M model glass, 1550 nm), UTF-16: 4 deg chosen, '
     'inside the semi-diameters the file computed for the axis'),
    ('US00583336-2-scaled', 'US00583336-2-scaled.zmx', 24.0, 5.0,
     "US 583,336 example 2 double Gauss (patent), 24 deg: the file's largest field"),
    ('US08427765-1', 'US08427765-1.zmx', 24.0, 5.0,
     'US 8,427,765 example 1 (patent, EVENASPH), fields by real image height up to '
     '13.6 mm: 24 deg chosen, inside that image height'),
)
#: Field samples from the axis to the largest angle.
SAMPLES = 41


def versions() -> dict[str, str]:
    """Return the versions of the packages that computed the reference."""
    out = {'python': platform.python_version()}
    for name in ('optiland', 'numpy'):
        out[name] = metadata.version(name)
    return out


def _scalar(value) -> float:
    return float(np.ravel(np.asarray(value, dtype=float))[0])


def entry(key: str, name: str, field_deg: float, pixel_um: float, note: str) -> dict:
    """Load one file with optiland and trace it (see the module docstring)."""
    from optiland.fileio import load_zemax_file

    optic = load_zemax_file(str(DATA / 'zmx' / name))
    wavelength = float(optic.primary_wavelength)
    optic.fields.set_type(field_type='angle')
    optic.fields.fields.clear()
    optic.fields.add(y=0.0)
    optic.fields.add(y=field_deg)
    optic.ray_tracer.set_aiming('robust', max_iter=50, tol=1e-11)
    angles = np.linspace(0.0, field_deg, SAMPLES)
    rays = optic.trace_generic(np.zeros(SAMPLES), -angles / field_deg, np.zeros(SAMPLES),
                               np.zeros(SAMPLES), wavelength)
    heights = np.abs(np.asarray(rays.y, dtype=float))
    stop = optic.surfaces.stop_index
    stop_y = np.asarray(optic.surfaces[stop].y, dtype=float).ravel()
    media = []
    for surface in optic.surfaces:
        material = surface.material_post
        media.append({'kind': type(material).__name__,
                      'name': str(getattr(material, 'name', '') or ''),
                      'index': _scalar(material.n(wavelength))})
    z = [float(s.geometry.cs.z) for s in optic.surfaces]
    return {
        'file': f'test/data/zmx/{name}',
        'note': note,
        'wavelength_um': wavelength,
        'efl_mm': float(optic.paraxial.f2()),
        'field_deg': angles.tolist(),
        'real_height_mm': heights.tolist(),
        'max_stop_residual_mm': float(np.max(np.abs(stop_y))),
        'media': media,
        'vertex_z_mm': z[1:],
        'tolerance_pixel_um': pixel_um,
    }


def dumps(doc: dict) -> str:
    """Serialise with every list of numbers on one line (exact float repr, no NaN)."""
    text = json.dumps(doc, indent=1, allow_nan=False)
    number = r'-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?'
    flat = re.compile(r'\[\s*(' + number + r'(?:,\s*' + number + r')*)\s*\]')
    return flat.sub(lambda m: '[' + re.sub(r',\s*', ', ', m.group(1)) + ']', text) + '\n'


def main() -> int:
    """Write :data:`OUTPUT`."""
    warnings.simplefilter('ignore')
    lenses = {}
    for spec in FILES:
        print(f'tracing {spec[1]}', file=sys.stderr, flush=True)
        lenses[spec[0]] = entry(*spec)
    doc = {
        'provenance': {
            'generator': 'tools/make_zmx_reference.py',
            'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime(
                '%Y-%m-%dT%H:%M:%SZ'),
            'versions': versions(),
        },
        'lenses': lenses,
    }
    OUTPUT.write_text(dumps(doc))
    print(f'wrote {OUTPUT}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
