#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Generate test/data/lateral_color_reference.json with optiland (lateral colour, issue #20).

Used only by test/test_lateral_color.py; optiland is not a dependency of the package nor of
``make test``. With the pin of ``requirements-reference.txt`` installed::

    python tools/make_lateral_color_reference.py          # about a minute

For each lens, optiland's own glass catalogue (its copy of refractiveindex.info, dispersive
``Material``s) gives the indices; the image plane is optiland's paraxial image plane at the
focus wavelength lambda_0 (``image_solve`` with lambda_0 as the primary wavelength); the chief
ray of each field angle is traced at each channel wavelength (R, G, B) to that one plane with
optiland's ``'iterative'`` aimer (tolerance 1e-11 mm at the stop), and its height recorded.
So every number here is optiland's: its materials, its paraxial solve, its aiming and its
trace. Conventions as tools/make_optiland_reference.py (mm, light along +z, heights as
magnitudes of the inverted image).

Lenses:

- ``cooke_triplet``: optiland.samples.objectives.CookeTriplet (Smith, "Modern Lens Design"),
  its own glasses (SK16 of HIKARI's catalogue and SCHOTT's F2, as optiland resolves the
  sample), object at infinity, lambda_0 = 550 nm; config/cooke_triplet.yaml's lens;
- ``case2_bk7``: the paper's Case 2 thick lens (r1 = 4, r2 = -4, t = 3 mm, stop 0.2 mm in front
  of H at lambda_0) in SCHOTT N-BK7, scene 1000 mm from H (at lambda_0 = 550 nm): the stop
  plane and the object plane stay where they are at lambda_0 for every channel.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import math
from pathlib import Path
import sys
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _reference_tool() -> Any:
    """Import tools/make_optiland_reference.py (its trace and closed forms)."""
    path = REPO / 'tools' / 'make_optiland_reference.py'
    spec = importlib.util.spec_from_file_location('make_optiland_reference', path)
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    return module


_TOOL = _reference_tool()
AIM_TOL_MM = _TOOL.AIM_TOL_MM
thick_lens_closed_form = _TOOL.thick_lens_closed_form
trace_chief = _TOOL.trace_chief
versions = _TOOL.versions

DEFAULT_OUTPUT = REPO / 'test' / 'data' / 'lateral_color_reference.json'
#: Channel wavelengths [R, G, B] and the focus wavelength, nm (the parameters' defaults).
CHANNELS_NM = (610.0, 550.0, 465.0)
FOCUS_NM = 550.0
#: Field angles per lens: uniform from 0 to this, deg.
SAMPLES = 49


def _cooke(focus_um: float):
    """Return optiland's sample Cooke triplet with lambda_0 primary, and its glass names."""
    from optiland.samples.objectives import CookeTriplet

    lens = CookeTriplet()
    lens.wavelengths.wavelengths.clear() if hasattr(lens.wavelengths, 'wavelengths') else None
    for um in sorted({focus_um, *(nm / 1000.0 for nm in CHANNELS_NM)}):
        lens.wavelengths.add(value=um, is_primary=(um == focus_um))
    glasses = []
    for s in list(lens.surfaces)[1:-1]:
        name = getattr(s.material_post, 'name', None)
        reference = getattr(s.material_post, 'reference', None)
        glasses.append(f'{reference.upper()}:{name}' if name else '')
    return lens, glasses


def _thick_bk7(n0: float, cf: dict[str, float], m_a: float, l_mm: float, field_mm: float):
    """Return optiland's Case 2 thick lens in N-BK7, stop m_a in front of H at lambda_0."""
    from optiland import optic
    from optiland.materials import Material

    bk7 = Material('N-BK7', 'schott')
    r1, r2, t = 4.0, -4.0, 3.0
    z_s = cf['front_principal_z_mm'] - m_a
    if not 0.0 < z_s < t:
        raise RuntimeError('the Case 2 stop is expected inside the glass')
    lens = optic.Optic()
    lens.surfaces.add(index=0, radius=np.inf, thickness=-(cf['front_principal_z_mm'] - l_mm))
    lens.surfaces.add(index=1, radius=r1, thickness=z_s, material=bk7)
    lens.surfaces.add(index=2, radius=np.inf, thickness=t - z_s, material=bk7, is_stop=True)
    lens.surfaces.add(index=3, radius=r2, thickness=cf['sensor_z_mm'] - t)
    lens.surfaces.add(index=4)
    lens.set_aperture(aperture_type='float_by_stop_size', value=1.0)
    for um in sorted({FOCUS_NM / 1000.0, *(nm / 1000.0 for nm in CHANNELS_NM)}):
        lens.wavelengths.add(value=um, is_primary=(um == FOCUS_NM / 1000.0))
    lens.fields.set_type(field_type='object_height')
    lens.fields.add(y=0.0)
    lens.fields.add(y=field_mm)
    lens.updater.update_paraxial()
    return lens


def _image_z(lens) -> float:
    """Return z of optiland's image surface (first vertex at z = 0)."""
    surfaces = list(lens.surfaces)
    return float(surfaces[-1].geometry.cs.z) - float(surfaces[1].geometry.cs.z)


def _channels(lens, hy: np.ndarray, pixel_mm: float) -> list[dict[str, Any]]:
    """Trace the chief rays of normalised fields ``hy`` at each channel wavelength."""
    zeros = np.zeros_like(hy)
    out = []
    for nm in CHANNELS_NM:
        rays = trace_chief(lens, zeros, hy, 'iterative', wavelength_um=nm / 1000.0)
        residual = float(np.max(np.hypot(rays['x_stop'], rays['y_stop'])))
        out.append({'wavelength_nm': nm,
                    'real_height_abs_mm': [float(v) for v in np.abs(rays['y_img'])],
                    'max_stop_residual_mm': residual})
    for ch in out:
        if ch['max_stop_residual_mm'] > 1e-3 * pixel_mm:
            raise RuntimeError(f"aiming residual {ch['max_stop_residual_mm']:.3g} mm")
    return out


def cooke_entry() -> dict[str, Any]:
    """Return the Cooke triplet's entry."""
    lens, glasses = _cooke(FOCUS_NM / 1000.0)
    lens.updater.image_solve()
    lens.updater.update_paraxial()
    field_max = float(lens.fields.max_field)
    theta_deg = np.linspace(0.0, 11.0, SAMPLES)
    hy = -theta_deg / field_max
    entry = {
        'description': 'optiland.samples.objectives.CookeTriplet with its own glasses; '
                       'object at infinity; image plane = image_solve at lambda_0',
        'params_file': 'config/cooke_triplet.yaml',
        'glass': glasses,
        'focus_wavelength_nm': FOCUS_NM,
        'sensor_z_mm': _image_z(lens),
        'field_angle_deg': [float(v) for v in theta_deg],
        'channels': _channels(lens, hy, 8e-3),
    }
    return entry


def case2_entry() -> dict[str, Any]:
    """Return the N-BK7 Case 2 thick lens's entry."""
    from optiland.materials import Material

    n0 = float(np.asarray(Material('N-BK7', 'schott').n(FOCUS_NM / 1000.0)).reshape(-1)[0])
    l_mm = 1000.0
    cf = thick_lens_closed_form(n0, 4.0, -4.0, 3.0, l_mm)
    theta_deg = np.linspace(0.0, 24.0, SAMPLES)
    field_mm = l_mm * math.tan(math.radians(theta_deg[-1]))
    lens = _thick_bk7(n0, cf, 0.2, l_mm, field_mm)
    closed_z = cf['sensor_z_mm']
    lens.updater.image_solve()
    solved_z = _image_z(lens)
    hy = l_mm * np.tan(np.radians(theta_deg)) / field_mm
    return {
        'description': "the paper's Case 2 thick lens in SCHOTT N-BK7, stop 0.2 mm in front of "
                       'H at lambda_0 (a flat stop surface in the glass), scene 1000 mm from H',
        'params_file': 'config/case2.yaml',
        'glass': 'SCHOTT:N-BK7',
        'index_at_focus': n0,
        'focus_wavelength_nm': FOCUS_NM,
        'sensor_z_mm': solved_z,
        'sensor_z_closed_form_mm': closed_z,
        'field_angle_deg': [float(v) for v in theta_deg],
        'channels': _channels(lens, hy, 4.0625e-3),
    }


def main(argv: list[str] | None = None) -> int:
    """Write the reference JSON."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('-o', '--output', type=Path, default=DEFAULT_OUTPUT)
    args = parser.parse_args(argv)
    doc = {
        'provenance': {'generated_by': 'tools/make_lateral_color_reference.py',
                       'date': datetime.date.today().isoformat(), 'versions': versions(),
                       'aim_tol_mm': AIM_TOL_MM},
        'channels_nm': list(CHANNELS_NM),
        'lenses': {'cooke_triplet': cooke_entry(), 'case2_bk7': case2_entry()},
    }
    args.output.write_text(json.dumps(doc, indent=1) + '\n')
    print(f'wrote {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
