#!/usr/bin/env python3
# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Generate test/data/optiland_reference.json and optiland_wide_reference.json with optiland.

Used only by the tests (test/test_reference_optiland.py) and later by the accuracy
benchmark. optiland is not a dependency of the package nor of ``make test``; install the pin
of ``requirements-reference.txt`` (``pip install -r requirements-reference.txt``) and run::

    python tools/make_optiland_reference.py            # writes both files (about 5 min)
    python tools/make_optiland_reference.py --only wide   # optiland_wide_reference.json only
    python tools/make_optiland_reference.py -o out.json --wide-output wide.json

Conventions (docs/design.md section 1): mm; optical axis z, light travels +z, first lens vertex at
z = 0; radius > 0 when the centre of curvature is on the image side, 0 = flat; thickness =
axial distance to the next surface; index = index after the surface. One wavelength
(0.55 um) and constant-index ``IdealMaterial`` glasses, so no dispersion enters.

Thick lenses (the paper's Case 1 and Case 2 and the m_a / t variants of Case 2):

- f = n r1 r2 / ((n-1)(n r2 - n r1 + t(n-1))) (paper eq. 8);
  front principal plane z_H = -f(n-1)t/(n r2), rear z_H' = t - f(n-1)t/(n r1);
- aperture stop: the plane z_s = z_H - m_a. Inside the glass it is modelled in optiland by
  splitting the glass with a flat dummy surface (same index on both sides) that is the stop;
- object plane at z = z_H - l (l = 1000 mm from H); sensor at the paraxial image plane,
  v = f l / (l - f) behind H' (placed by the closed form, then confirmed by optiland's
  ``image_solve``; the difference is recorded).

Cooke triplet: ``optiland.samples.objectives.CookeTriplet`` with each glass replaced by an
``IdealMaterial`` of its own index at 0.55 um, stop at its own stop surface, object at
infinity, sensor at the paraxial back focal plane.

Chief rays: optiland's default ray aiming is paraxial, which misses the centre of a stop that
sits inside the glass by ~9 um at the Case 2 corner (half a pixel at the image). Every chief
ray here is aimed with optiland's ``'iterative'`` aimer (Newton on real traces, tolerance
``AIM_TOL_MM`` at the stop) and the crossing of the stop is re-measured from the traced
surface intersections and recorded (``stop_height_mm``, ``max_stop_residual_mm``). The
distortion curve is also traced with the ``'robust'`` aimer and with paraxial aiming; their
differences from the iterative result are recorded under ``aiming``.

Wide-angle, fisheye and aspheric designs (``optiland_wide_reference.json``, read by
test/test_reference_wide.py), scene at infinity, one wavelength (the primary) and each
glass an ``IdealMaterial`` of its index there:

- ``wide_angle_160``: optiland.samples.objectives.ProjectionLens160FOV (Laikin, Lens Design,
  4th ed., p. 112; 80 deg half field), scaled x2; ``fisheye_170``: WideAngle170FOV (p. 114;
  85 deg half field), scaled x5. These are config/wide_angle.yaml and config/fisheye.yaml;
- ``aspheric_singlet``: optiland.samples.simple.AsphericSinglet with its stop moved 10 mm in
  front (on the asphere's vertex the chief ray would never see the asphere) and its r^2
  coefficient dropped (our sag starts at a4); ``asphere_al50100``: a conic plano-convex
  asphere (the conic and a4..a8 of Thorlabs AL50100) behind a stop.

Sag z = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2)) + a4 r^4 + ... + a16 r^16 (optiland's
``even_asphere`` with coefficients [0, a4, ..., a16]). The flat stop surface is kept as a
surface (``prescription.stop_surface``, ``lens.stop_surface``). Chief rays are aimed with
optiland's ``'robust'`` aimer (the ``'iterative'`` one is a cross-check where it converges)
and parametrised by their object-space field angle, 97 samples from 0 to the largest angle
optiland traces (searched up to 15 deg past the design field; past 90 deg for the fisheye),
or to just before the real height folds back. Clear semi-diameters are the largest heights
of real chief and meridional marginal rays over the design field, rounded up to 1 um.

Signs: the object point lies at +y (finite: height Y > 0; infinity: the chief ray arrives
travelling towards -y, i.e. optiland's angle field -Hy), ``tan_field`` = its tangent seen from
the front principal point, > 0, and ``rho_ideal_mm`` = v tan_field > 0. ``real_height_mm`` is
the chief ray's height on the sensor plane signed as optiland gives it (a real image is
inverted: negative); ``real_height_abs_mm`` is its magnitude.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
from pathlib import Path
import platform
import re
import sys
import time
from typing import Any
import warnings

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUTPUT = REPO / 'test' / 'data' / 'optiland_reference.json'

WAVELENGTH_UM = 0.55
#: Chief-ray aiming tolerance at the stop, mm (optiland 'iterative' aimer).
AIM_TOL_MM = 1.0e-11
AIM_MAX_ITER = 50
#: Samples of the distortion curve, tan_field from 0 to its maximum.
CURVE_SAMPLES = 129
#: The curve reaches this multiple of the sensor half-diagonal in ideal image height.
CURVE_REACH = 1.25
#: Box grid for the radii mean error experiment: columns x rows, fraction of the sensor.
GRID_NX = 20
GRID_NY = 18
GRID_COVERAGE = 0.95

SENSOR_CASE2 = {'width_px': 640, 'height_px': 480, 'pixel_x_um': 4.0625, 'pixel_y_um': 4.4375}
SENSOR_CASE1 = {'width_px': 1600, 'height_px': 1200, 'pixel_x_um': 4.4, 'pixel_y_um': 4.4}

#: The thick lenses: (key, description, n, r1, r2, t, m_a, aperture diameter, l, sensor).
THICK_LENSES = (
    ('case2', 'Case 2 (paper default, 0.4 Mpx CMOS)', 1.5168, 4.0, -4.0, 3.0, 0.2, 1.0,
     1000.0, SENSOR_CASE2),
    ('case2_ma0.0', 'Case 2 with m_a = 0.0 mm', 1.5168, 4.0, -4.0, 3.0, 0.0, 1.0, 1000.0,
     SENSOR_CASE2),
    ('case2_ma0.5', 'Case 2 with m_a = 0.5 mm', 1.5168, 4.0, -4.0, 3.0, 0.5, 1.0, 1000.0,
     SENSOR_CASE2),
    ('case2_ma1.0', 'Case 2 with m_a = 1.0 mm', 1.5168, 4.0, -4.0, 3.0, 1.0, 1.0, 1000.0,
     SENSOR_CASE2),
    ('case2_t4', 'Case 2 with t = 4 mm', 1.5168, 4.0, -4.0, 4.0, 0.2, 1.0, 1000.0,
     SENSOR_CASE2),
    ('case2_t5', 'Case 2 with t = 5 mm', 1.5168, 4.0, -4.0, 5.0, 0.2, 1.0, 1000.0,
     SENSOR_CASE2),
    ('case1', 'Case 1 (paper, 2 Mpx CCD)', 1.5168, 6.0, -6.0, 4.0, 0.3, 1.5, 1000.0,
     SENSOR_CASE1),
)

#: The Cooke triplet is compared at 5 um pixels (it has no sensor of its own).
COOKE_PIXEL_UM = 5.0


_T0 = time.monotonic()


def log(msg: str) -> None:
    """Print a progress line to stderr, with the elapsed time."""
    print(f'[{time.monotonic() - _T0:6.1f} s] {msg}', file=sys.stderr, flush=True)


def thick_lens_closed_form(n: float, r1: float, r2: float, t: float,
                           l_mm: float) -> dict[str, float]:
    """
    Paraxial data of a thick lens in air from the paper's closed forms (eq. 7-8).

    :param n: refractive index of the glass
    :param r1: front radius, mm
    :param r2: rear radius, mm
    :param t: centre thickness, mm
    :param l_mm: object distance from the front principal plane, mm
    :return: f, z_H, z_H', v = f l / (l - f) and the sensor z, all mm
    """
    f = n * r1 * r2 / ((n - 1.0) * (n * r2 - n * r1 + t * (n - 1.0)))
    z_h = -f * (n - 1.0) * t / (n * r2)
    z_hp = t - f * (n - 1.0) * t / (n * r1)
    v = f * l_mm / (l_mm - f)
    return {'efl_mm': f, 'front_principal_z_mm': z_h, 'rear_principal_z_mm': z_hp,
            'image_distance_mm': v, 'sensor_z_mm': z_hp + v}


def _optic_from_rows(rows: list[dict[str, Any]], object_thickness: float, image_gap: float,
                     aperture_diameter: float | None, epd: float | None):
    """
    Build an optiland ``Optic`` from rows of (radius, thickness, index, is_stop).

    :param rows: the lens surfaces in order; radius 0 = flat; index after the surface
    :param object_thickness: object plane to first surface, mm (``inf`` for infinity)
    :param image_gap: last surface to the image plane, mm
    :param aperture_diameter: stop diameter for ``float_by_stop_size`` (or None)
    :param epd: entrance pupil diameter (used when ``aperture_diameter`` is None)
    :return: the optic
    """
    from optiland import optic
    from optiland.materials import IdealMaterial

    lens = optic.Optic()
    lens.surfaces.add(index=0, radius=np.inf, thickness=object_thickness)
    for i, row in enumerate(rows, start=1):
        radius = row['radius_mm'] if row['radius_mm'] != 0.0 else np.inf
        thickness = row['thickness_mm'] if i < len(rows) else image_gap
        lens.surfaces.add(index=i, radius=radius, thickness=thickness,
                          material=IdealMaterial(row['refractive_index']),
                          is_stop=bool(row.get('is_stop', False)))
    lens.surfaces.add(index=len(rows) + 1)
    if aperture_diameter is not None:
        lens.set_aperture(aperture_type='float_by_stop_size', value=aperture_diameter)
    else:
        lens.set_aperture(aperture_type='EPD', value=epd)
    lens.wavelengths.add(value=WAVELENGTH_UM, is_primary=True)
    return lens


def thick_lens_rows(n: float, r1: float, r2: float, t: float,
                    z_s: float) -> list[dict[str, Any]]:
    """
    Optiland surfaces of a thick lens with the stop plane z_s as an extra flat surface.

    Inside the glass the dummy splits it (index n on both sides); before or after the lens it
    is a flat surface in air.

    :return: rows with radius_mm, thickness_mm (to the next row), refractive_index, is_stop
    """
    glass = {'radius_mm': r1, 'thickness_mm': t, 'refractive_index': n, 'is_stop': False}
    rear = {'radius_mm': r2, 'thickness_mm': 0.0, 'refractive_index': 1.0, 'is_stop': False}
    if 0.0 < z_s < t:
        return [dict(glass, thickness_mm=z_s),
                {'radius_mm': 0.0, 'thickness_mm': t - z_s, 'refractive_index': n,
                 'is_stop': True},
                rear]
    if z_s <= 0.0:
        return [{'radius_mm': 0.0, 'thickness_mm': -z_s, 'refractive_index': 1.0,
                 'is_stop': True}, glass, rear]
    return [glass, dict(rear, thickness_mm=z_s - t),
            {'radius_mm': 0.0, 'thickness_mm': 0.0, 'refractive_index': 1.0, 'is_stop': True}]


def build_thick_lens(n: float, r1: float, r2: float, t: float, m_a: float,
                     aperture_diameter: float, l_mm: float, field_max_mm: float):
    """
    Build one thick lens in optiland, object at l from H, sensor at the paraxial image.

    :return: (optic, rows, first_vertex_z, closed-form dict); optiland z positions are shifted
        so that ``first_vertex_z`` is where our z = 0 (the first glass vertex) lies
    """
    cf = thick_lens_closed_form(n, r1, r2, t, l_mm)
    z_s = cf['front_principal_z_mm'] - m_a
    rows = thick_lens_rows(n, r1, r2, t, z_s)
    first_z = min(0.0, z_s)                      # our z of optiland's surface 1
    object_thickness = first_z - (cf['front_principal_z_mm'] - l_mm)
    last_z = max(t, z_s)
    lens = _optic_from_rows(rows, object_thickness, cf['sensor_z_mm'] - last_z,
                            aperture_diameter, None)
    lens.fields.set_type(field_type='object_height')
    lens.fields.add(y=0.0)
    lens.fields.add(y=field_max_mm)
    # optiland 0.6.3: the iterative aimer reads the stop's semi_aperture, which only
    # update_paraxial sets (TypeError on None otherwise). No surface gets a clipping aperture.
    lens.updater.update_paraxial()
    return lens, rows, first_z, cf


def build_cooke():
    """
    Build optiland's sample Cooke triplet with fixed-index glasses at ``WAVELENGTH_UM``.

    :return: (optic, rows, glass indices by name)
    """
    from optiland.samples.objectives import CookeTriplet

    sample = CookeTriplet()
    rows = []
    glasses: dict[str, float] = {}
    for s in list(sample.surfaces)[1:-1]:
        index = float(np.asarray(s.material_post.n(WAVELENGTH_UM)).reshape(-1)[0])
        name = getattr(s.material_post, 'name', None)
        if name is not None:
            glasses[f'{name} ({s.material_post.reference})'] = index
        radius = float(s.geometry.radius)
        rows.append({'radius_mm': 0.0 if math.isinf(radius) else radius,
                     'thickness_mm': float(s.thickness), 'refractive_index': index,
                     'is_stop': bool(s.is_stop)})
    lens = _optic_from_rows(rows, np.inf, rows[-1]['thickness_mm'], None,
                            float(sample.aperture.value))
    lens.fields.set_type(field_type='angle')
    for y in sample.fields.y_fields:
        lens.fields.add(y=float(y))
    lens.updater.update_paraxial()
    return lens, rows, glasses


def set_aiming(lens, mode: str) -> None:
    """Select optiland's chief-ray aiming (``'paraxial'``, ``'iterative'`` or ``'robust'``)."""
    lens.ray_tracer.set_aiming(mode, max_iter=AIM_MAX_ITER, tol=AIM_TOL_MM)


def trace_chief(lens, hx: np.ndarray, hy: np.ndarray, mode: str = 'iterative',
                wavelength_um: float = WAVELENGTH_UM) -> dict:
    """
    Trace chief rays (pupil 0, 0) at normalised fields and read every surface crossing.

    :return: dict of numpy arrays: object x/y/z and direction at launch, image x/y, stop x/y
        and the heights at every surface
    """
    set_aiming(lens, mode)
    hx = np.asarray(hx, dtype=float)
    hy = np.asarray(hy, dtype=float)
    zeros = np.zeros_like(hy)
    rays = lens.trace_generic(hx, hy, zeros, zeros, wavelength_um)
    surfaces = list(lens.surfaces)

    def at(i: int, name: str) -> np.ndarray:
        return np.array(getattr(surfaces[i], name), dtype=float).reshape(-1)

    stop = lens.surfaces.stop_index
    out = {
        'x_img': np.array(rays.x, dtype=float), 'y_img': np.array(rays.y, dtype=float),
        'x_stop': at(stop, 'x'), 'y_stop': at(stop, 'y'),
        'x0': at(0, 'x'), 'y0': at(0, 'y'), 'M0': at(0, 'M'), 'N0': at(0, 'N'),
        'r_surf': np.array([np.hypot(at(i, 'x'), at(i, 'y')) for i in range(len(surfaces))]),
    }
    return out


def paraxial_data(lens, first_z: float) -> dict[str, float]:
    """
    Paraxial data as optiland computes it, in our z (first glass vertex at 0).

    optiland's P1 is measured from its surface 1 and P2 from the image surface.
    """
    p = lens.paraxial
    z = [float(s.geometry.cs.z) for s in lens.surfaces]
    to_ours = first_z - z[1]
    image_z = z[-1] + to_ours
    rear = float(p.P2()) + image_z
    front = float(p.P1()) + first_z
    finite = not lens.object_surface.is_infinite
    return {
        'efl_mm': float(p.f2()),
        'front_principal_z_mm': front,
        'rear_principal_z_mm': rear,
        'image_distance_mm': image_z - rear,
        'sensor_z_mm': image_z,
        'magnification': float(p.magnification()) if finite else 0.0,
        'rear_focal_z_mm': float(p.F2()) + image_z,
        'front_focal_z_mm': float(p.F1()) + first_z,
    }


def image_solve_check(lens) -> float:
    """Return how far (mm) optiland's ``image_solve`` moves the image plane (then undo it)."""
    z_before = float(lens.surfaces[-1].geometry.cs.z)
    gap_before = float(lens.surfaces[-2].thickness)
    lens.updater.image_solve()
    moved = float(lens.surfaces[-1].geometry.cs.z) - z_before
    lens.updater.set_thickness(gap_before, len(lens.surfaces) - 2)
    return moved


def our_prescription(rows: list[dict[str, Any]], stop_z: float,
                     semi: list[float] | None = None) -> dict[str, Any]:
    """
    Prescription in our form: the dummy stop surface dropped, its gap given to its neighbour.

    The last thickness is 0: the sensor is placed separately (``paraxial.sensor_z_mm``).
    """
    surfaces: list[dict[str, Any]] = []
    stop_surface = None
    for i, r in enumerate(rows):
        before = 1.0 if i == 0 else rows[i - 1]['refractive_index']
        dummy = r['radius_mm'] == 0.0 and before == r['refractive_index']
        if dummy:
            if surfaces:
                surfaces[-1]['thickness_mm'] += r['thickness_mm']
            continue
        if r['is_stop']:
            stop_surface = len(surfaces)
        surfaces.append({'radius_mm': r['radius_mm'], 'thickness_mm': r['thickness_mm'],
                         'refractive_index': r['refractive_index'],
                         'semi_diameter_mm': 0.0 if semi is None else semi[i]})
    surfaces[-1]['thickness_mm'] = 0.0
    return {'surfaces': surfaces, 'stop_z_mm': stop_z, 'stop_surface': stop_surface,
            'object_index': 1.0}


def sensor_info(sensor: dict[str, Any]) -> dict[str, Any]:
    """Sensor size and half-diagonal (corner radius, from the image centre), mm."""
    w = sensor['width_px'] * sensor['pixel_x_um'] * 1e-3
    h = sensor['height_px'] * sensor['pixel_y_um'] * 1e-3
    return dict(sensor, width_mm=w, height_mm=h, corner_radius_mm=0.5 * math.hypot(w, h),
                tolerance_pixel_um=min(sensor['pixel_x_um'], sensor['pixel_y_um']))


def lst(a: np.ndarray) -> list[float]:
    """Return a numpy array as a list of Python floats (round-trip exact in JSON)."""
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]


def curve_and_aiming(lens, tan_max: float, finite: bool, l_mm: float, v: float,
                     field_max: float, pixel_um: float) -> tuple[dict, dict]:
    """
    Trace the distortion curve (iterative aiming), cross-check with robust and paraxial.

    :return: (curve dict, aiming dict)
    """
    tan = np.linspace(0.0, tan_max, CURVE_SAMPLES)
    if finite:
        hy = tan * l_mm / field_max
    else:
        # optiland's angle field +Hy launches rays travelling towards +y, i.e. from an object
        # point below the axis: trace -Hy so that the object lies at +y as in the finite case
        hy = -np.degrees(np.arctan(tan)) / field_max
    hy[-1] = np.clip(hy[-1], -1.0, 1.0)
    zeros = np.zeros_like(hy)
    it = trace_chief(lens, zeros, hy, 'iterative')
    # the field actually launched: object height / l, or the launch direction
    tan_launched = it['y0'] / l_mm if finite else -it['M0'] / it['N0']
    rb = trace_chief(lens, zeros, hy, 'robust')
    px = trace_chief(lens, zeros, hy, 'paraxial')
    pix_mm = pixel_um * 1e-3
    curve = {
        'samples': CURVE_SAMPLES,
        'tan_field': lst(tan_launched),
        'rho_ideal_mm': lst(v * tan_launched),
        'real_height_mm': lst(it['y_img']),
        'real_height_abs_mm': lst(np.abs(it['y_img'])),
        'stop_height_mm': lst(it['y_stop']),
        'max_chief_height_at_optiland_surface_mm': lst(it['r_surf'][1:-1].max(axis=1)),
    }
    aiming = {
        'mode': 'iterative',
        'tol_mm': AIM_TOL_MM,
        'max_iter': AIM_MAX_ITER,
        'max_stop_residual_mm': float(np.max(np.hypot(it['x_stop'], it['y_stop']))),
        'robust_max_stop_residual_mm': float(np.max(np.hypot(rb['x_stop'], rb['y_stop']))),
        'robust_minus_iterative_max_abs_px':
            float(np.max(np.abs(rb['y_img'] - it['y_img'])) / pix_mm),
        'paraxial_aiming_max_stop_residual_mm':
            float(np.max(np.hypot(px['x_stop'], px['y_stop']))),
        'paraxial_aiming_max_image_error_px':
            float(np.max(np.abs(px['y_img'] - it['y_img'])) / pix_mm),
        'pixel_um': pixel_um,
    }
    if not np.allclose(tan_launched, tan, rtol=1e-12, atol=1e-15):
        raise RuntimeError('optiland launched other fields than requested')
    return curve, aiming


def grid(lens, l_mm: float, v: float, sens: dict[str, Any], field_max: float) -> dict:
    """
    Real sensor positions of a box grid of object points (radii mean error experiment).

    Ideal (pinhole) positions x_i = v X / l, y_i = v Y / l cover ``GRID_COVERAGE`` of the sensor
    width and height; each object point (X, Y) is traced as a real two-dimensional field.
    """
    xs = np.linspace(-1.0, 1.0, GRID_NX) * 0.5 * GRID_COVERAGE * sens['width_mm']
    ys = np.linspace(-1.0, 1.0, GRID_NY) * 0.5 * GRID_COVERAGE * sens['height_mm']
    xi, yi = np.meshgrid(xs, ys)              # rows: y, columns: x
    xi, yi = xi.ravel(), yi.ravel()
    obj_x, obj_y = xi * l_mm / v, yi * l_mm / v
    r = trace_chief(lens, obj_x / field_max, obj_y / field_max, 'iterative')
    if not (np.allclose(r['x0'], obj_x, rtol=1e-12, atol=1e-12)
            and np.allclose(r['y0'], obj_y, rtol=1e-12, atol=1e-12)):
        raise RuntimeError('optiland launched other object points than requested')
    # rotational symmetry: the same radii traced as meridional fields, turned to each azimuth
    radius = np.hypot(obj_x, obj_y)
    m = trace_chief(lens, np.zeros_like(radius), radius / field_max, 'iterative')
    sym = max(np.max(np.abs(m['y_img'] * obj_x / radius - r['x_img'])),
              np.max(np.abs(m['y_img'] * obj_y / radius - r['y_img'])))
    return {
        'nx': GRID_NX, 'ny': GRID_NY, 'coverage': GRID_COVERAGE,
        'order': 'row-major: y (rows, ny) outer, x (columns, nx) inner',
        'object_x_mm': lst(obj_x), 'object_y_mm': lst(obj_y),
        'ideal_x_mm': lst(xi), 'ideal_y_mm': lst(yi),
        'real_x_mm': lst(r['x_img']), 'real_y_mm': lst(r['y_img']),
        'max_stop_residual_mm': float(np.max(np.hypot(r['x_stop'], r['y_stop']))),
        'skew_vs_meridional_max_abs_mm': float(sym),
    }


def thick_lens_entry(spec: tuple) -> tuple[dict, dict]:
    """Return the reference entry and the grid of one thick lens."""
    key, desc, n, r1, r2, t, m_a, ap, l_mm, sensor = spec
    sens = sensor_info(sensor)
    cf = thick_lens_closed_form(n, r1, r2, t, l_mm)
    tan_max = CURVE_REACH * sens['corner_radius_mm'] / cf['image_distance_mm']
    field_max = tan_max * l_mm
    lens, rows, first_z, cf = build_thick_lens(n, r1, r2, t, m_a, ap, l_mm, field_max)
    moved = image_solve_check(lens)
    par = paraxial_data(lens, first_z)
    z_s = cf['front_principal_z_mm'] - m_a
    curve, aiming = curve_and_aiming(lens, tan_max, True, l_mm, par['image_distance_mm'],
                                     field_max, sens['tolerance_pixel_um'])
    if curve['real_height_abs_mm'][-1] <= sens['corner_radius_mm']:
        raise RuntimeError(f'{key}: the curve does not reach the sensor corner')
    g = grid(lens, l_mm, par['image_distance_mm'], sens, field_max)
    closed_form_rel = max(abs(par[k] - v) / max(abs(v), 1.0) for k, v in cf.items())
    if closed_form_rel > 1e-12:
        raise RuntimeError(f'{key}: optiland paraxial data and the closed forms differ by '
                           f'{closed_form_rel:.2e}')
    entry = {
        'description': desc,
        'kind': 'thick_lens',
        'thick_lens': {'refractive_index': n, 'r1_mm': r1, 'r2_mm': r2, 'thickness_mm': t,
                       'stop_offset_mm': m_a, 'aperture_diameter_mm': ap},
        'object_distance_mm': l_mm,
        'object_distance_from': 'front principal plane H',
        'object_z_mm': cf['front_principal_z_mm'] - l_mm,
        'wavelength_um': WAVELENGTH_UM,
        'sensor': sens,
        'prescription': our_prescription(thick_lens_rows(n, r1, r2, t, -1.0)[1:], z_s),
        'optiland_surfaces': optiland_surface_table(lens, first_z, rows),
        'paraxial': par,
        'closed_form': cf,
        'closed_form_max_rel_difference': closed_form_rel,
        'optiland_image_solve_shift_mm': moved,
        'curve': curve,
        'aiming': aiming,
    }
    return entry, g


def optiland_surface_table(lens, first_z: float, rows: list[dict[str, Any]],
                           wavelength_um: float = WAVELENGTH_UM) -> list[dict]:
    """Return the optiland model as built: object, lens rows (dummy stop included), image."""
    z = [float(s.geometry.cs.z) for s in lens.surfaces]
    shift = first_z - z[1]
    table = []
    for i, s in enumerate(lens.surfaces):
        radius = float(s.geometry.radius)
        table.append({
            'index': i,
            'radius_mm': 0.0 if math.isinf(radius) else radius,
            'thickness_mm': float(s.thickness) if math.isfinite(float(s.thickness)) else None,
            'z_mm': z[i] + shift if math.isfinite(z[i]) else None,
            'refractive_index_after': float(np.asarray(
                s.material_post.n(wavelength_um)).reshape(-1)[0]),
            'is_stop': bool(s.is_stop),
            'role': 'object' if i == 0 else 'image' if i == len(z) - 1 else 'lens',
        })
    return table


def cooke_entry() -> dict:
    """Return the reference entry of the fixed-index Cooke triplet (object at infinity)."""
    lens, rows, glasses = build_cooke()
    moved = image_solve_check(lens)
    lens.updater.image_solve()                   # sensor at the paraxial back focal plane
    par = paraxial_data(lens, 0.0)
    lens.updater.update_paraxial()
    semi = [float(s.semi_aperture) for s in list(lens.surfaces)[1:-1]]
    z = [float(s.geometry.cs.z) for s in lens.surfaces]
    stop_index = lens.surfaces.stop_index
    field_max = float(lens.fields.max_field)
    tan_max = math.tan(math.radians(field_max))
    curve, aiming = curve_and_aiming(lens, tan_max, False, math.inf, par['efl_mm'],
                                     field_max, COOKE_PIXEL_UM)
    presc = our_prescription(rows, z[stop_index], semi)
    heights = curve['max_chief_height_at_optiland_surface_mm']
    if any(h > s for h, s in zip(heights, semi)):
        raise RuntimeError('cooke: a chief ray exceeds a paraxial semi-aperture')
    return {
        'description': 'optiland.samples.objectives.CookeTriplet, glasses fixed at their index '
                       f'at {WAVELENGTH_UM} um; semi-diameters from optiland update_paraxial '
                       '(EPD 10 mm, field 20 deg)',
        'kind': 'prescription',
        'glass_indices_at_wavelength': glasses,
        'object_distance_mm': None,
        'object_at_infinity': True,
        'field_max_deg': field_max,
        'entrance_pupil_diameter_mm': float(lens.paraxial.EPD()),
        'wavelength_um': WAVELENGTH_UM,
        'sensor': {'tolerance_pixel_um': COOKE_PIXEL_UM},
        'prescription': presc,
        'optiland_surfaces': optiland_surface_table(lens, 0.0, rows),
        'paraxial': par,
        'optiland_image_solve_shift_mm': moved,
        'image_distance_note': 'sample back focal gap 42.20778 mm replaced by image_solve',
        'curve': curve,
        'aiming': aiming,
    }


# --- wide-angle and aspheric designs (issue 11) -------------------------------------------

DEFAULT_WIDE_OUTPUT = REPO / 'test' / 'data' / 'optiland_wide_reference.json'
#: The even-asphere orders of our prescription (lens.surfaces.asphere_a4 .. asphere_a16).
ASPHERE_ORDERS = (4, 6, 8, 10, 12, 14, 16)
#: Samples of each whole-field curve, uniform in field angle from 0 to optiland's reach.
WIDE_CURVE_SAMPLES = 97
#: optiland's reach is searched up to the design half-field plus this, deg.
REACH_MARGIN_DEG = 15.0
#: Resolution of the reach search, deg.
REACH_RESOLUTION_DEG = 0.02
#: Field angles whose clear semi-diameters are measured (fractions of the design field).
CLEAR_APERTURE_FIELDS = (0.0, 0.25, 0.5, 0.7, 0.85, 1.0)


def _row(radius: float, thickness: float, index: float, is_stop: bool = False,
         conic: float = 0.0, asphere: tuple[float, ...] = ()) -> dict[str, Any]:
    """Return one lens row: radius 0 = flat, index after the surface, a4..a16 coefficients."""
    coefficients = list(asphere) + [0.0] * (len(ASPHERE_ORDERS) - len(asphere))
    return {'radius_mm': float(radius), 'thickness_mm': float(thickness),
            'refractive_index': float(index), 'is_stop': bool(is_stop),
            'conic': float(conic), 'asphere': [float(a) for a in coefficients]}


def sample_rows(sample, scale: float, wavelength_um: float) -> tuple[list[dict], dict]:
    """
    Read an optiland sample's lens surfaces as rows, scaled by ``scale``.

    Every glass becomes its index at ``wavelength_um``; an even-asphere coefficient C_i of
    r^(2i) scales as scale^(1 - 2i). optiland's r^2 term has no counterpart in our
    prescription (a4 is the lowest order): a sample that uses it is refused.

    :return: (rows, glass indices by name)
    """
    rows = []
    glasses: dict[str, float] = {}
    for s in list(sample.surfaces)[1:-1]:
        index = float(np.asarray(s.material_post.n(wavelength_um)).reshape(-1)[0])
        name = getattr(s.material_post, 'name', None)
        if name is not None:
            glasses[str(name)] = index
        radius = float(s.geometry.radius)
        coefficients = [float(c) for c in getattr(s.geometry, 'coefficients', [])]
        if coefficients and coefficients[0] != 0.0:
            raise RuntimeError('an r^2 asphere term has no counterpart in our prescription')
        asphere = [c * scale ** (1 - 2 * (i + 1)) for i, c in enumerate(coefficients)][1:]
        # scaled lengths rounded to 1e-10 mm: 1.2087 x 5 is 6.0435, not 6.043500000000001
        rows.append(_row(0.0 if math.isinf(radius) else round(radius * scale, 10),
                         round(float(s.thickness) * scale, 10), index, bool(s.is_stop),
                         float(getattr(s.geometry, 'k', 0.0)), tuple(asphere)))
    return rows, glasses


def build_wide_optic(rows: list[dict[str, Any]], wavelength_um: float, aperture: tuple,
                     field_max_deg: float):
    """
    Build an optiland ``Optic``, object at infinity, angle fields up to ``field_max_deg``.

    Surfaces with a conic or an a4..a16 term are optiland ``even_asphere`` surfaces
    (coefficients [0, a4, ..., a16]: optiland's list starts at r^2); every medium is an
    ``IdealMaterial`` of the row's index.
    """
    from optiland import optic
    from optiland.materials import IdealMaterial

    lens = optic.Optic()
    lens.surfaces.add(index=0, radius=np.inf, thickness=np.inf)
    for i, row in enumerate(rows, start=1):
        kwargs: dict[str, Any] = {
            'index': i, 'radius': row['radius_mm'] if row['radius_mm'] != 0.0 else np.inf,
            'thickness': row['thickness_mm'],
            'material': IdealMaterial(row['refractive_index']), 'is_stop': row['is_stop']}
        if row['conic'] != 0.0 or any(row['asphere']):
            kwargs.update(surface_type='even_asphere', conic=row['conic'],
                          coefficients=[0.0] + list(row['asphere']))
        lens.surfaces.add(**kwargs)
    lens.surfaces.add(index=len(rows) + 1)
    lens.set_aperture(aperture_type=aperture[0], value=aperture[1])
    lens.fields.set_type(field_type='angle')
    lens.fields.add(y=0.0)
    lens.fields.add(y=field_max_deg)
    lens.wavelengths.add(value=wavelength_um, is_primary=True)
    lens.updater.update_paraxial()
    return lens


def _laikin(name: str, scale: float) -> Any:
    def rows(wavelength_um: float):
        from optiland.samples import objectives
        sample = getattr(objectives, name)()
        out, glasses = sample_rows(sample, scale, wavelength_um)
        aperture = (sample.aperture.ap_type, float(sample.aperture.value))
        return out, glasses, aperture, float(sample.fields.max_field)
    return rows


def _aspheric_singlet(wavelength_um: float):
    """Return optiland's AsphericSinglet, stop moved 10 mm in front, r^2 term dropped."""
    from optiland.samples.simple import AsphericSinglet

    sample = AsphericSinglet()
    front = sample.surfaces[1]
    n = float(np.asarray(front.material_post.n(wavelength_um)).reshape(-1)[0])
    c = [float(v) for v in front.geometry.coefficients]
    rows = [_row(0.0, 10.0, 1.0, is_stop=True),
            _row(float(front.geometry.radius), float(front.thickness), n,
                 conic=float(front.geometry.k), asphere=tuple(c[1:])),
            _row(0.0, float(sample.surfaces[2].thickness), 1.0)]
    return rows, {front.material_post.name: n}, ('EPD', 8.0), 25.0


def _al50100(wavelength_um: float):
    """Return a plano-convex asphere (conic and a4..a8 of Thorlabs AL50100) behind a stop."""
    from optiland.materials import Material

    n = float(np.asarray(Material('N-BK7').n(wavelength_um)).reshape(-1)[0])
    rows = [_row(0.0, 20.0, 1.0, is_stop=True),
            _row(50.3583, 10.2, n, conic=-0.789119,
                 asphere=(2.10405e-7, 1.76468e-11, 1.02641e-15)),
            _row(0.0, 90.0, 1.0)]
    return rows, {'N-BK7': n}, ('EPD', 10.0), 20.0


#: The designs (issue 11): key, description, rows builder, wavelength, sensor (pitch: the
#: 0.01 px tolerance), config file that ships the same lens (or None).
WIDE_DESIGNS = (
    ('wide_angle_160',
     'optiland.samples.objectives.ProjectionLens160FOV (Laikin, Lens Design, 4th ed., p. 112: '
     'f/2, 160 deg), scaled x2 to f = 1.89 mm',
     _laikin('ProjectionLens160FOV', 2.0), 0.5876,
     {'width_px': 1920, 'height_px': 1200, 'pixel_x_um': 2.0, 'pixel_y_um': 2.0},
     'config/wide_angle.yaml'),
    ('fisheye_170',
     'optiland.samples.objectives.WideAngle170FOV (Laikin, Lens Design, 4th ed., p. 114: '
     'f/1.8, 170 deg), scaled x5 to f = 1.03 mm',
     _laikin('WideAngle170FOV', 5.0), 0.5876,
     {'width_px': 1280, 'height_px': 960, 'pixel_x_um': 2.0, 'pixel_y_um': 2.0},
     'config/fisheye.yaml'),
    ('aspheric_singlet',
     'optiland.samples.simple.AsphericSinglet (R 20 mm even asphere in N-SF11) with the stop '
     'moved 10 mm in front so that chief rays cross the asphere off axis; its r^2 coefficient '
     'is dropped (our prescription starts at a4), its r^4 and r^6 ones kept',
     _aspheric_singlet, 0.587,
     {'width_px': 1920, 'height_px': 1080, 'pixel_x_um': 5.0, 'pixel_y_um': 5.0}, None),
    ('asphere_al50100',
     'plano-convex N-BK7 asphere with the conic and a4..a8 of Thorlabs AL50100 (R 50.3583 mm, '
     'k -0.789119, 10.2 mm thick), stop 20 mm in front',
     _al50100, 0.5876,
     {'width_px': 1920, 'height_px': 1080, 'pixel_x_um': 5.0, 'pixel_y_um': 5.0}, None),
)


def _chief_ok(lens, angle_deg: float, field_max: float, wavelength_um: float) -> bool:
    """Return whether optiland's robust aimer puts a chief ray at this angle on the image."""
    try:
        r = trace_chief(lens, np.zeros(1), np.array([-angle_deg / field_max]), 'robust',
                        wavelength_um)
    except Exception:                            # optiland refuses or fails to aim
        return False
    return bool(np.isfinite(r['y_img'][0]) and abs(r['y_stop'][0]) < 1e-9)


def optiland_reach(lens, design_deg: float, cap_deg: float, wavelength_um: float) -> float:
    """
    Return the largest field angle (deg, <= ``cap_deg``) optiland traces a chief ray at.

    Bisection between the design field (which must trace) and the cap, to
    ``REACH_RESOLUTION_DEG``; 90 deg itself is avoided (optiland refuses tan(90 deg)).
    """
    field_max = float(lens.fields.max_field)
    if not _chief_ok(lens, design_deg, field_max, wavelength_um):
        raise RuntimeError(f'optiland does not trace the design field {design_deg} deg')
    if _chief_ok(lens, cap_deg, field_max, wavelength_um):
        return cap_deg
    lo, hi = design_deg, cap_deg
    while hi - lo > REACH_RESOLUTION_DEG:
        mid = 0.5 * (lo + hi)
        if abs(mid - 90.0) < 1e-3:
            mid = 90.0 + 2e-3
        if _chief_ok(lens, mid, field_max, wavelength_um):
            lo = mid
        else:
            hi = mid
    return lo


def clear_semi_diameters(lens, design_deg: float, wavelength_um: float) -> list[float]:
    """
    Return each lens surface's clear semi-diameter, mm, rounded up to 1 um.

    The largest height of the chief ray and the two meridional marginal rays (robust aiming)
    over ``CLEAR_APERTURE_FIELDS`` of the design field: the lens as built passes the whole
    design field unvignetted on axis of the pupil and clips beyond it.
    """
    field_max = float(lens.fields.max_field)
    surfaces = list(lens.surfaces)
    high = np.zeros(len(surfaces) - 2)
    for frac in CLEAR_APERTURE_FIELDS:
        hy = np.full(3, -frac * design_deg / field_max)
        set_aiming(lens, 'robust')
        lens.trace_generic(np.zeros(3), hy, np.zeros(3), np.array([-1.0, 0.0, 1.0]),
                           wavelength_um)
        for i, s in enumerate(surfaces[1:-1]):
            h = np.hypot(np.asarray(s.x, dtype=float), np.asarray(s.y, dtype=float))
            if not np.all(np.isfinite(h)):
                raise RuntimeError(f'a pupil ray is lost at {frac * design_deg} deg')
            high[i] = max(high[i], float(np.max(h)))
    return [math.ceil(h * 1000.0) / 1000.0 for h in high]


def _curve_angles(end_deg: float) -> np.ndarray:
    """Return ``WIDE_CURVE_SAMPLES`` field angles from 0 to ``end_deg`` (90 itself avoided)."""
    angles = np.linspace(0.0, end_deg, WIDE_CURVE_SAMPLES)
    angles[np.abs(angles - 90.0) < 1e-3] = 90.0 - 2e-3
    return angles


def wide_curve(lens, angles: np.ndarray, wavelength_um: float, pixel_um: float) -> tuple:
    """
    Trace the whole-field curve by field angle (robust aiming), cross-check iterative aiming.

    :return: (curve dict, aiming dict)
    """
    field_max = float(lens.fields.max_field)
    hy = -angles / field_max                     # object at +y, as for the other lenses
    zeros = np.zeros_like(hy)
    rb = trace_chief(lens, zeros, hy, 'robust', wavelength_um)
    launched = np.degrees(np.arctan2(-rb['M0'], rb['N0']))
    if not np.allclose(launched, angles, rtol=0, atol=1e-9):
        raise RuntimeError('optiland launched other fields than requested')
    pix_mm = pixel_um * 1e-3
    height = rb['y_img']
    if not np.all(np.isfinite(height)):
        raise RuntimeError('optiland lost a chief ray inside its reach')
    with np.errstate(divide='ignore', invalid='ignore'):
        tan = np.where(np.abs(launched) < 89.0, np.tan(np.radians(launched)), np.nan)
    curve = {
        'samples': int(angles.size),
        'field_angle_deg': lst(launched),
        'tan_field': [None if not math.isfinite(t) else float(t) for t in tan],
        'real_height_mm': lst(height),
        'real_height_abs_mm': lst(np.abs(height)),
        'stop_height_mm': lst(rb['y_stop']),
        'max_chief_height_at_optiland_surface_mm': lst(rb['r_surf'][1:-1].max(axis=1)),
        'monotonic': bool(np.all(np.diff(np.abs(height)) > 0.0)),
    }
    aiming: dict[str, Any] = {
        'mode': 'robust', 'tol_mm': AIM_TOL_MM, 'max_iter': AIM_MAX_ITER,
        'max_stop_residual_mm': float(np.max(np.hypot(rb['x_stop'], rb['y_stop']))),
        'pixel_um': pixel_um,
    }
    try:
        it = trace_chief(lens, zeros, hy, 'iterative', wavelength_um)
        good = np.isfinite(it['y_img']) & (np.hypot(it['x_stop'], it['y_stop']) < 1e-9)
        aiming['iterative_converged_fields'] = int(np.sum(good))
        aiming['iterative_minus_robust_max_abs_px'] = (
            float(np.max(np.abs(it['y_img'][good] - height[good]))) / pix_mm
            if np.any(good) else None)
    except Exception as err:                     # the paraxial seed fails far off axis
        aiming['iterative_converged_fields'] = 0
        aiming['iterative_error'] = f'{type(err).__name__}: {err}'[:300]
    return curve, aiming


def our_surfaces(rows: list[dict[str, Any]], semi: list[float]) -> dict[str, Any]:
    """
    Return the prescription in our form, the flat stop surface kept (``lens.stop_surface``).

    The last thickness is 0: the sensor is placed separately (``paraxial.sensor_z_mm``).
    """
    surfaces = []
    for row, s in zip(rows, semi):
        surfaces.append({'radius_mm': row['radius_mm'], 'thickness_mm': row['thickness_mm'],
                         'refractive_index': row['refractive_index'], 'semi_diameter_mm': s,
                         'conic': row['conic'], 'asphere': list(row['asphere'])})
    surfaces[-1]['thickness_mm'] = 0.0
    stop = next(i for i, row in enumerate(rows) if row['is_stop'])
    stop_z = float(sum(row['thickness_mm'] for row in rows[:stop]))
    return {'surfaces': surfaces, 'stop_surface': stop, 'stop_z_mm': stop_z,
            'object_index': 1.0, 'asphere_orders': list(ASPHERE_ORDERS)}


def prescription_params(presc: dict[str, Any]) -> dict[str, Any]:
    """Return the ``lens.surfaces.*`` and ``lens.stop_surface`` values of a prescription."""
    surfaces = presc['surfaces']
    params: dict[str, Any] = {
        f'lens.surfaces.{name}': [s[name] for s in surfaces]
        for name in ('radius_mm', 'thickness_mm', 'refractive_index', 'semi_diameter_mm',
                     'conic')}
    for j, order in enumerate(ASPHERE_ORDERS):
        params[f'lens.surfaces.asphere_a{order}'] = [s['asphere'][j] for s in surfaces]
    params['lens.stop_surface'] = presc['stop_surface']
    return params


def wide_entry(spec: tuple) -> dict[str, Any]:
    """Return the reference entry of one wide-angle or aspheric design (object at infinity)."""
    key, desc, builder, wavelength_um, sensor, config = spec
    rows, glasses, aperture, design_deg = builder(wavelength_um)
    cap = design_deg + REACH_MARGIN_DEG
    lens = build_wide_optic(rows, wavelength_um, aperture, cap)
    moved = image_solve_check(lens)
    lens.updater.image_solve()                   # sensor at the paraxial back focal plane
    par = paraxial_data(lens, 0.0)
    lens.updater.update_paraxial()
    sens = sensor_info(sensor)
    t0 = time.monotonic()
    reach = optiland_reach(lens, design_deg, cap, wavelength_um)
    log(f'{key}: optiland reaches {reach:.2f} deg (design {design_deg} deg, searched to '
        f'{cap} deg) in {time.monotonic() - t0:.1f} s')
    curve, aiming = wide_curve(lens, _curve_angles(reach), wavelength_um,
                               sens['tolerance_pixel_um'])
    fold = None
    if not curve['monotonic']:
        # the real height folds back (a field point imaged twice): the valid field ends
        # before the fold, so the curve does too (its last sample before the maximum)
        height = np.abs(curve['real_height_mm'])
        first_drop = int(np.argmax(np.diff(height) <= 0.0))
        fold = curve['field_angle_deg'][first_drop]
        end = curve['field_angle_deg'][first_drop - 1]
        log(f'{key}: the real height folds near {fold:.2f} deg: the curve ends at {end:.2f} deg')
        curve, aiming = wide_curve(lens, _curve_angles(end), wavelength_um,
                                   sens['tolerance_pixel_um'])
        if not curve['monotonic']:
            raise RuntimeError(f'{key}: the curve still folds')
    semi = clear_semi_diameters(lens, design_deg, wavelength_um)
    heights = curve['max_chief_height_at_optiland_surface_mm']
    presc = our_surfaces(rows, semi)
    z = [float(s.geometry.cs.z) for s in lens.surfaces]
    if abs(z[lens.surfaces.stop_index] - z[1] - presc['stop_z_mm']) > 1e-12:
        raise RuntimeError(f'{key}: stop position mismatch')
    design_height = trace_chief(lens, np.zeros(1), np.array([-design_deg / cap]), 'robust',
                                wavelength_um)['y_img'][0]
    circle = abs(float(design_height))
    return {
        'description': desc,
        'kind': 'prescription',
        'config': config,
        'glass_indices_at_wavelength': glasses,
        'object_distance_mm': None,
        'object_at_infinity': True,
        'design_field_deg': design_deg,
        'optiland_reach_deg': reach,
        'reach_searched_to_deg': cap,
        'fold_near_deg': fold,
        'curve_end_deg': curve['field_angle_deg'][-1],
        'aperture': {'type': aperture[0], 'value': aperture[1]},
        'entrance_pupil_diameter_mm': float(lens.paraxial.EPD()),
        'wavelength_um': wavelength_um,
        'sensor': sens,
        'image_circle_radius_mm': circle,
        'image_circle_note': '|real height| at the design field; the clear semi-diameters '
                             'pass every chief and meridional marginal ray up to it',
        'sensor_corner_beyond_image_circle': sens['corner_radius_mm'] > circle,
        'prescription': presc,
        'params': prescription_params(presc),
        'chief_ray_within_semi_diameter_over_curve': [
            bool(h <= s) for h, s in zip(heights, semi)],
        'optiland_surfaces': optiland_surface_table(lens, 0.0, rows, wavelength_um),
        'paraxial': par,
        'optiland_image_solve_shift_mm': moved,
        'curve': curve,
        'aiming': aiming,
    }


def wide_document(cmd: str) -> dict[str, Any]:
    """Trace every design of ``WIDE_DESIGNS`` and return the reference document."""
    lenses: dict[str, Any] = {}
    for spec in WIDE_DESIGNS:
        t0 = time.monotonic()
        lenses[spec[0]] = entry = wide_entry(spec)
        log(f'{spec[0]:16s} done in {time.monotonic() - t0:5.1f} s: reach '
            f'{entry["optiland_reach_deg"]:.2f} deg, stop residual '
            f'{entry["aiming"]["max_stop_residual_mm"]:.1e} mm, iterative aiming converged at '
            f'{entry["aiming"]["iterative_converged_fields"]}/{entry["curve"]["samples"]}')
    return {
        'provenance': provenance(cmd),
        'conventions': {
            'units': 'mm unless the name says otherwise',
            'axis': 'z along the optical axis, light travels +z, first lens vertex at z = 0',
            'radius': '> 0 when the centre of curvature is on the image side; 0 = flat',
            'thickness': 'axial distance to the next surface; the last is 0 (the sensor is at '
                         'paraxial.sensor_z_mm, the paraxial back focal plane)',
            'refractive_index': "index after the surface at the entry's wavelength_um "
                                '(constant, no dispersion)',
            'sag': 'z(r) = c r^2 / (1 + sqrt(1 - (1 + conic) c^2 r^2)) + sum a_k r^k, '
                   'k = asphere_orders (4 .. 16), c = 1 / radius',
            'stop': 'prescription.stop_surface: the 0-based index of the flat stop surface '
                    '(kept as a surface of index 1 on both sides), stop_z_mm its vertex',
            'params': 'the same lens as lens.surfaces.* / lens.stop_surface parameter values',
            'field_angle_deg': "the chief ray's object-space angle to the axis; the object "
                               'point lies at +y (the ray travels towards -y); may exceed 90',
            'tan_field': 'tan(field_angle_deg) below 89 deg, null beyond',
            'real_height_mm': 'chief-ray height on the sensor plane, signed as optiland gives '
                              'it (negative: inverted image)',
            'aiming': "optiland 'robust' ray aiming (tolerance tol_mm at the stop); optiland's "
                      "'iterative' aimer is a cross-check where it converges",
            'semi_diameter_mm': 'clear semi-diameters measured with real chief and marginal '
                                'rays over the design field (rounded up to 1 um)',
        },
        'lenses': lenses,
    }


def dumps(doc: dict[str, Any]) -> str:
    """Serialise to JSON with every list of numbers on one line (exact float repr, no NaN)."""
    text = json.dumps(doc, indent=1, allow_nan=False)
    number = r'-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?'
    flat = re.compile(r'\[\s*(' + number + r'(?:,\s*' + number + r')*)\s*\]')
    return flat.sub(lambda m: '[' + re.sub(r',\s*', ', ', m.group(1)) + ']', text) + '\n'


def versions() -> dict[str, str]:
    """Versions of the packages that computed the reference."""
    from importlib import metadata

    out = {'python': platform.python_version(), 'platform': platform.platform()}
    for name in ('optiland', 'numpy', 'numba', 'scipy'):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


def provenance(cmd: str) -> dict[str, Any]:
    """Return what made a reference document: generator, command, date, versions, runtime."""
    return {
        'generator': 'tools/make_optiland_reference.py',
        'command': cmd,
        'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime(
            '%Y-%m-%dT%H:%M:%SZ'),
        'versions': versions(),
        'runtime_s': round(time.monotonic() - _T0, 1),
    }


def base_document() -> tuple[dict[str, Any], dict[str, Any]]:
    """Trace the thick lenses and the Cooke triplet; return (lenses, grids)."""
    lenses: dict[str, Any] = {}
    grids: dict[str, Any] = {}
    for spec in THICK_LENSES:
        t0 = time.monotonic()
        lenses[spec[0]], grids[spec[0]] = thick_lens_entry(spec)
        a = lenses[spec[0]]['aiming']
        log(f'{spec[0]:12s} done in {time.monotonic() - t0:5.1f} s: '
            f'stop residual {a["max_stop_residual_mm"]:.1e} mm, grid '
            f'{grids[spec[0]]["max_stop_residual_mm"]:.1e} mm; paraxial aiming would be off by '
            f'{a["paraxial_aiming_max_image_error_px"]:.3f} px')
    t0 = time.monotonic()
    lenses['cooke_triplet'] = cooke_entry()
    a = lenses['cooke_triplet']['aiming']
    log(f'cooke_triplet done in {time.monotonic() - t0:5.1f} s: stop residual '
        f'{a["max_stop_residual_mm"]:.1e} mm; paraxial aiming would be off by '
        f'{a["paraxial_aiming_max_image_error_px"]:.3f} px')
    return lenses, grids


def main(argv: list[str] | None = None) -> int:
    """Generate the reference JSON files."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('-o', '--output', type=Path, default=DEFAULT_OUTPUT,
                        help='output JSON of the thick lenses and the Cooke triplet '
                             '(default: %(default)s)')
    parser.add_argument('--wide-output', type=Path, default=DEFAULT_WIDE_OUTPUT,
                        help='output JSON of the wide-angle and aspheric designs '
                             '(default: %(default)s)')
    parser.add_argument('--only', choices=('base', 'wide'),
                        help='regenerate one of the two files only (default: both)')
    args = parser.parse_args(argv)
    warnings.filterwarnings('ignore', module='numba')
    warnings.filterwarnings('ignore', message='.*numba.*')
    try:
        from numba.core.errors import NumbaWarning
        warnings.simplefilter('ignore', NumbaWarning)
    except ImportError:
        pass
    log('importing optiland')
    import optiland  # noqa: F401
    cmd = ' '.join([Path(sys.executable).name,
                    os.path.relpath(Path(__file__).resolve(), REPO)] + sys.argv[1:])
    if args.only in (None, 'base'):
        lenses, grids = base_document()
        doc = {
            'provenance': provenance(cmd),
            'conventions': {
                'units': 'mm unless the name says otherwise',
                'axis': 'z along the optical axis, light travels +z, first lens vertex at z = 0',
                'radius': '> 0 when the centre of curvature is on the image side; 0 = flat',
                'thickness': 'axial distance to the next surface; the last is 0 (the sensor is at '
                             'paraxial.sensor_z_mm)',
                'refractive_index': 'index after the surface (constant, no dispersion)',
                'stop': 'prescription.stop_z_mm is the stop plane the chief ray crosses at '
                        'height 0; stop_surface the 0-based surface index when the stop is a '
                        'lens surface',
                'tan_field': 'Y / l for a finite object (Y object height, l from H); '
                             'tan(theta) at infinity',
                'rho_ideal_mm': "paraxial image distance v (from H') times tan_field",
                'real_height_mm': 'chief-ray height on the sensor plane, signed as optiland gives '
                                  'it (negative: inverted image)',
                'grids': 'object points (object_x_mm, object_y_mm) on the object plane, tan = '
                         'object / l; ideal_* = v * tan (same sign as the object point); real_* '
                         'the chief ray on the sensor plane as optiland gives it (inverted)',
                'aiming': 'optiland iterative ray aiming; stop residuals re-measured from the '
                          'traced surface intersections',
            },
            'wavelength_um': WAVELENGTH_UM,
            'lenses': lenses,
            'grids': grids,
        }
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(dumps(doc))
        log(f'wrote {args.output} ({args.output.stat().st_size / 1024:.0f} KiB)')
    if args.only in (None, 'wide'):
        doc = wide_document(cmd)
        doc['provenance']['runtime_s'] = round(time.monotonic() - _T0, 1)
        args.wide_output.parent.mkdir(parents=True, exist_ok=True)
        args.wide_output.write_text(dumps(doc))
        log(f'wrote {args.wide_output} ({args.wide_output.stat().st_size / 1024:.0f} KiB)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
