# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Patent prescriptions of production lenses, each paired with its lensfun entries.

Data only (used by :mod:`benchmarks.real_lenses`). Every row is (radius, thickness after, nd,
vd) in mm at the patent's scale unless ``scale`` says otherwise; nd = 1 is air; the
aperture stop is a flat surface (radius 0) and ``stop`` its 0-based index; the last
thickness (the back focus) is ignored (the sensor sits at the paraxial image plane of a
scene at infinity). Aspheres: {surface index: (conic k, a4, a6, a8, a10, a12)}, sag
z = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2)) + sum a_i r^i. Glass is given as nd / vd
(d line, ``MODEL:nd:vd``). No semi-diameters: the distortion is the chief ray's, which a
clear aperture that lets it pass does not change.

Sources and their licences (the numbers below are copied from them, rounded to the
patents' printed precision where a source stores float32 values):

* singer-yang/DeepLens, ``datasets/lenses/camera/*.json``: Canon EF 35/2, EF 50/1.8 II,
  EF 85/1.8 USM, EF 100/2.8 Macro, RF 16/2.8 STM. Its licence is unresolved here: one
  stored version of its LICENSE is MIT (Copyright (c) 2022 Xinge Yang), another is
  CC BY-NC 4.0. The numbers are the patents' published tables (cited per lens); no params
  file is shipped from this source until the licence question is settled
  (:data:`SHIPPABLE_SOURCES`).
* zpelgrims/lentil, ``polynomial-optics/database/lenses.json`` entry 6 and
  ``polynomial-optics/lenses/fisheye-ii.fx`` (MIT License, Copyright (c) Zeno Pelgrims):
  Takumar 50/1.4 (US 3,451,745, at f = 100: halved here) and the AF DX Fisheye-Nikkor
  10.5 mm (US 7,161,746 B2 via Pierre Toscani's transcription).
* mjhoptics/ray-optics, the Nikkor Z 14-30 model of its tests (BSD 3-Clause License,
  Copyright (c) Michael J. Hayford): JP 2019-008031 Example 1 at the wide end. The middle
  and tele air gaps are the patent's Table 1 (its variable distances D1, D2, D3, D4, Bf);
  that they are right is checked by the trace: they give the table's focal lengths.

The permission notices of those licences ask that the notice be kept with copies of
substantial portions; the prescriptions are short tables of numbers from patents (facts),
copied with attribution and the notices above.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from mechdeconv_ros.schema.params import ASPHERE_POWERS, check_values, defaults

Row = tuple[float, float, float, float]
Asphere = tuple[float, float, float, float, float, float]

DEEPLENS = 'singer-yang/DeepLens datasets/lenses/camera'
LENTIL = 'zpelgrims/lentil polynomial-optics'
RAYOPTICS = 'mjhoptics/ray-optics tests'
#: Each source's licence as far as it could be checked.
LICENCES = {
    DEEPLENS: 'unresolved (stored LICENSE versions: MIT, Copyright (c) 2022 Xinge Yang; '
              'and CC BY-NC 4.0)',
    LENTIL: 'MIT (Copyright (c) Zeno Pelgrims; the LICENSE file was not in the stored copy)',
    RAYOPTICS: 'BSD-3-Clause (Copyright (c) 2017-2021, Michael J. Hayford)'}
#: Sources whose prescriptions may be shipped as params files (config/lenses).
SHIPPABLE_SOURCES = (LENTIL, RAYOPTICS)


@dataclass(frozen=True)
class RealLens:
    """One production lens: its patent prescription and the lensfun entry it is checked with."""

    key: str
    name: str
    category: str
    patent: str
    source: str
    rows: tuple[Row, ...]
    stop: int
    stop_semi_mm: float  # the transcription's stop semi-diameter (reference only)
    lensfun_model: str
    lensfun_focal: float
    nominal_focal: float
    aspheres: dict[int, Asphere] = field(default_factory=dict)
    scale: float = 1.0
    gaps: dict[int, float] = field(default_factory=dict)
    lensfun_crop: float = 1.0
    f_number: float = 0.0
    corrections: tuple[str, ...] = ()
    notes: str = ''


EF35 = (
    (28.25, 1.50, 1.58913, 61.2), (15.79, 15.28, 1.0, 0.0),
    (37.84, 10.54, 1.80610, 40.9), (-19.77, 1.53, 1.64769, 33.8), (-142.05, 3.09, 1.0, 0.0),
    (0.0, 3.54, 1.0, 0.0),
    (-27.54, 1.94, 1.67270, 32.1), (45.81, 2.00, 1.0, 0.0),
    (-46.16, 1.10, 1.78472, 25.7), (276.83, 3.58, 1.77250, 49.6), (-24.15, 0.10, 1.0, 0.0),
    (134.67, 3.20, 1.77250, 49.6), (-46.19, 37.83, 1.0, 0.0))

EF50 = (
    (34.30, 4.50, 1.6280, 57.0), (247.65, 2.40, 1.0, 0.0),
    (21.51, 4.35, 1.70154, 41.2), (40.31, 0.92, 1.0, 0.0),
    (78.44, 1.40, 1.6727, 25.6), (15.32, 6.75, 1.0, 0.0),
    (0.0, 4.95, 1.0, 0.0),
    (-15.83, 1.10, 1.6990, 30.1), (135.97, 5.70, 1.7995, 42.2), (-21.24, 0.15, 1.0, 0.0),
    (162.15, 3.00, 1.7200, 55.2), (-49.97, 37.563, 1.0, 0.0))

EF85 = (
    (185.36, 4.40, 1.65160, 58.5), (-427.66, 0.20, 1.0, 0.0),
    (63.58, 4.60, 1.77250, 49.6), (156.32, 0.15, 1.0, 0.0),
    (33.99, 8.20, 1.71300, 53.8), (241.98, 0.16, 1.0, 0.0),
    (278.09, 3.20, 1.71736, 29.5), (26.41, 8.82, 1.0, 0.0),
    (0.0, 3.59, 1.0, 0.0),
    (-101.48, 2.40, 1.80518, 25.4), (-52.90, 1.50, 1.51633, 64.2), (36.36, 16.30, 1.0, 0.0),
    (-9058.59, 2.00, 1.80518, 25.4), (41.85, 12.40, 1.80610, 41.0), (-410.77, 0.20, 1.0, 0.0),
    (73.06, 5.40, 1.77250, 49.6), (-122.05, 38.91, 1.0, 0.0))

EF100 = (
    (82.83, 4.20, 1.60311, 60.7), (557.60, 3.60, 1.0, 0.0),
    (62.43, 4.20, 1.78590, 44.2), (159.85, 0.15, 1.0, 0.0),
    (38.67, 6.41, 1.78590, 44.2), (59.07, 2.86, 1.0, 0.0),
    (128.46, 1.80, 1.80518, 25.4), (28.92, 5.45, 1.0, 0.0),
    (0.0, 5.08, 1.0, 0.0),
    (-26.31, 1.80, 1.69895, 30.1), (-173.98, 4.50, 1.80610, 40.9), (-36.74, 0.15, 1.0, 0.0),
    (230.07, 4.00, 1.78590, 44.2), (-62.64, 2.50, 1.0, 0.0),
    (425.29, 3.70, 1.80518, 25.4), (-66.08, 1.83, 1.0, 0.0),
    (-60.97, 1.50, 1.76200, 40.1), (37.30, 14.09, 1.0, 0.0),
    (44.78, 5.50, 1.51633, 64.1), (363.26, 42.42, 1.0, 0.0))

RF16 = (
    (27.125, 1.10, 1.60311, 60.6), (9.735, 3.67, 1.0, 0.0),
    (30.493, 1.00, 1.48749, 70.2), (10.589, 3.21, 1.0, 0.0),
    (40.191, 1.71, 1.83481, 42.7), (-392.36, 5.43, 1.0, 0.0),
    (0.0, 1.80, 1.0, 0.0),
    (38.857, 6.25, 1.83481, 42.7), (-8.128, 0.90, 1.90366, 31.3), (-16.045, 4.69, 1.0, 0.0),
    (-16.526, 0.92, 1.68893, 31.1), (19.781, 5.80, 1.59282, 68.6), (-26.412, 0.91, 1.0, 0.0),
    (-50.009, 2.10, 1.53110, 55.9), (-32.615, 6.74, 1.0, 0.0),
    (-109.118, 4.42, 1.62299, 58.2), (-31.615, 12.54, 1.0, 0.0))
RF16_ASPHERES = {
    13: (0.0, 5.22756e-05, -1.92650e-06, 3.51677e-08, -3.71946e-10, 1.36387e-12),
    14: (0.0, 1.10438e-04, -1.14287e-06, 2.01498e-08, -1.88642e-10, 6.28660e-13)}

#: Takumar 50/1.4 at the patent's f = 100 (``scale`` 0.5 halves it).
TAKUMAR = (
    (110.0, 10.0, 1.80416, 46.6), (588.748, 0.2, 1.0, 0.0),
    (51.6, 14.5, 1.79446, 45.4), (100.426, 3.5, 1.0, 0.0),
    (119.0, 3.0, 1.71736, 29.5), (32.792, 16.26, 1.0, 0.0),
    (0.0, 16.25, 1.0, 0.0),
    (-36.5, 2.0, 1.68893, 31.1), (131.5, 20.0, 1.77252, 49.6), (-56.806, 0.2, 1.0, 0.0),
    (-160.0, 8.5, 1.77252, 49.6), (-74.352, 0.2, 1.0, 0.0),
    (122.0, 9.5, 1.77252, 49.6), (2092.573, 63.31, 1.0, 0.0))

#: AF DX Fisheye-Nikkor 10.5 mm, US 7,161,746 B2; d13 (after the stop, row 12) as printed.
NIKKOR105_PRINTED_D13 = 8.776
#: The corrected d13 (see ``corrections``).
NIKKOR105_D13 = 6.4398
NIKKOR105 = (
    (85.00, 2.040, 1.62041, 60.29), (16.45, 8.320, 1.0, 0.0),
    (61.18, 1.700, 1.81600, 46.63), (20.15, 10.316, 1.0, 0.0),
    (-204.00, 3.430, 1.72000, 43.69), (-31.26, 0.250, 1.0, 0.0),
    (-27.00, 2.780, 1.77250, 49.61), (11.48, 4.930, 1.72825, 28.46), (-55.84, 5.865, 1.0, 0.0),
    (59.67, 2.570, 1.51742, 52.42), (-14.20, 1.410, 1.83481, 42.72), (-76.00, 3.660, 1.0, 0.0),
    (0.0, NIKKOR105_D13, 1.0, 0.0),
    (-1732.00, 1.490, 1.84666, 23.78), (29.90, 4.020, 1.49700, 81.61),
    (-21.55, 0.190, 1.0, 0.0),
    (44.74, 3.210, 1.65160, 58.54), (-44.74, 41.100, 1.0, 0.0))

#: Nikkor Z 14-30 f/4 S, JP 2019-008031 Example 1, wide end (f = 14.42).
Z1430 = (
    (190.7535, 3.0, 1.6937, 53.32), (18.8098, 9.5, 1.0, 0.0),
    (51.563, 2.9, 1.6937, 53.32), (22.702, 9.7, 1.0, 0.0),
    (-71.0651, 1.9, 1.49782, 82.57), (44.4835, 0.1, 1.0, 0.0),
    (32.608, 4.5, 1.90265, 35.73), (296.5863, 28.616, 1.0, 0.0),
    (63.0604, 2.0, 1.59349, 67.0), (499.8755, 0.1, 1.0, 0.0),
    (24.0057, 1.2, 1.883, 40.66), (13.347, 4.5, 1.56883, 56.0), (333.9818, 2.5, 1.0, 0.0),
    (0.0, 7.483, 1.0, 0.0),
    (36.3784, 1.1, 1.816, 46.59), (14.0097, 4.71, 1.51612, 64.08), (61.0448, 0.2, 1.0, 0.0),
    (27.9719, 3.15, 1.49782, 82.57), (-75.3921, 0.25, 1.0, 0.0),
    (91.9654, 3.05, 1.49782, 82.57), (-29.3923, 1.579, 1.0, 0.0),
    (72.093, 1.0, 1.795, 45.31), (20.9929, 5.766, 1.0, 0.0),
    (-538.2301, 4.8, 1.49782, 82.57), (-20.1257, 0.1, 1.0, 0.0),
    (-38.9341, 1.4, 1.76546, 46.75), (154.832, 21.36, 1.0, 0.0))
Z1430_ASPHERES = {
    1: (-1.0, -1.33157e-5, -3.07345e-8, 6.9126e-11, -3.76684e-14, 0.0),
    3: (-1.0, 3.67009e-5, 1.37031e-7, -5.20756e-10, 3.14884e-12, -5.6153e-15),
    16: (0.0, 1.75905e-5, -6.64635e-8, 2.26551e-10, -4.40763e-12, 0.0),
    25: (-1.0, -2.67902e-5, -3.34364e-8, -1.13765e-10, -1.88017e-13, 0.0)}
#: The zoom's variable gaps (0-based thickness indices: D1, D2, D3, D4, Bf), Table 1.
Z1430_GAPS = {
    'wide': {7: 28.616, 13: 7.483, 20: 1.579, 22: 5.766, 26: 21.36},
    'middle': {7: 12.942, 13: 6.371, 20: 2.261, 22: 6.196, 26: 26.809},
    'tele': {7: 2.214, 13: 3.521, 20: 2.007, 22: 9.3, 26: 36.297}}
#: The focal lengths Table 1 gives at the three positions.
Z1430_TABLE_FOCAL = {'wide': 14.42, 'middle': 20.0, 'tele': 29.101}

_Z_SOURCE = RAYOPTICS + "; middle/tele gaps: the patent's Table 1"


def _z(position: str, focal: float) -> RealLens:
    return RealLens(
        f'nikkor_z_14_30_{position}', f'Nikkor Z 14-30 f/4 S at {focal:g} mm ({position})',
        'zoom', 'JP 2019-008031 A, Example 1', _Z_SOURCE, Z1430, 13, 5.6335,
        'NIKKOR Z 14-30mm f/4 S', focal, focal, Z1430_ASPHERES,
        gaps=Z1430_GAPS[position], f_number=4.0,
        notes=f'Table 1 gives f = {Z1430_TABLE_FOCAL[position]:g} mm at this position.')


LENSES: tuple[RealLens, ...] = (
    RealLens('nikkor_10_5_fisheye', 'AF DX Fisheye-Nikkor 10.5 mm f/2.8G ED', 'fisheye',
             'US 7,161,746 B2', LENTIL + ', lenses/fisheye-ii.fx', NIKKOR105, 12, 9.0,
             'Nikon AF DX Fisheye-Nikkor 10.5mm f/2.8G ED', 10.5, 10.5, lensfun_crop=1.523,
             f_number=2.8,
             corrections=(
                 f'd13 (stop to surface 14) {NIKKOR105_PRINTED_D13} as printed; '
                 f'{NIKKOR105_D13} used (evidence: "Corrections and checks").',)),
    RealLens('canon_rf_16', 'Canon RF 16 mm F2.8 STM', 'wide-angle',
             'JP 2022-085382 A, Example 3', DEEPLENS, RF16, 6, 4.836,
             'Canon RF 16mm F2.8 STM', 16.0, 16.0, RF16_ASPHERES, f_number=2.8),
    RealLens('canon_ef_35_f2', 'Canon EF 35 mm f/2', 'wide-angle',
             'JP H04-015611 A (1992), Example 1', DEEPLENS, EF35, 5, 9.8795,
             'Canon EF 35mm f/2', 35.0, 35.0, f_number=2.0),
    _z('wide', 14.0),
    _z('middle', 20.0),
    _z('tele', 30.0),
    RealLens('canon_ef_50_f1_8_ii', 'Canon EF 50 mm f/1.8 II', 'normal',
             'JP S62-087922 A (1987), Example 1', DEEPLENS, EF50, 6, 9.645,
             'Canon EF 50mm f/1.8 MkII', 50.0, 50.0, f_number=1.8),
    RealLens('takumar_50_f1_4', 'Asahi (SMC) Takumar 50 mm f/1.4', 'normal',
             'US 3,451,745', LENTIL + ', database/lenses.json entry 6', TAKUMAR, 6, 13.2,
             'Super-Takumar 50mm f/1.4', 50.0, 50.0, scale=0.5, f_number=1.4),
    RealLens('canon_ef_85_f1_8', 'Canon EF 85 mm f/1.8 USM', 'short tele',
             'JP H05-157964 A (1993), Example 1', DEEPLENS, EF85, 8, 16.16,
             'Canon EF 85mm f/1.8 USM', 85.0, 85.0, f_number=1.8),
    RealLens('canon_ef_100_f2_8_macro', 'Canon EF 100 mm f/2.8 Macro (1990)', 'short tele',
             'JP H03-141313 A (1991), Example 1', DEEPLENS, EF100, 8, 11.7345,
             'Canon EF 100mm f/2.8 Macro', 100.0, 100.0, lensfun_crop=1.611,
             f_number=2.8),
)

#: lensfun entries that are the same optics under another name (their spread is noise).
SAME_OPTICS = {'Super-Takumar 50mm f/1.4': ('Pentax SMC Takumar 50mm f/1.4',)}


def lens_values(lens: RealLens) -> dict[str, Any]:
    """
    Return the parameter values (prescription mode) of a lens, scene at infinity.

    :param lens: the lens.
    :return: checked values; the sensor is left at its defaults (not ours to choose).
    """
    thickness = [t for _, t, _, _ in lens.rows]
    for index, gap in lens.gaps.items():
        thickness[index] = gap
    n = len(lens.rows)
    values = defaults()
    values.update({
        'lens.surfaces.radius_mm': [r * lens.scale for r, _, _, _ in lens.rows],
        'lens.surfaces.thickness_mm': [t * lens.scale for t in thickness],
        'lens.surfaces.refractive_index': [nd for _, _, nd, _ in lens.rows],
        'lens.surfaces.glass': ['' if nd == 1.0 else f'MODEL:{nd:.5f}:{vd:g}'
                                for _, _, nd, vd in lens.rows],
        'lens.stop_surface': lens.stop,
        'lens.aperture_diameter_mm': round(2.0 * stop_semi_diameter(lens), 4),
        'scene.distance_mm': 0.0, 'scene.focus_distance_mm': 0.0})
    if lens.aspheres:
        values['lens.surfaces.conic'] = [lens.aspheres.get(i, (0.0,))[0] for i in range(n)]
        for j, power in enumerate(ASPHERE_POWERS[:5]):
            values[f'lens.surfaces.asphere_a{power}'] = [
                lens.aspheres[i][j + 1] / lens.scale ** (power - 1) if i in lens.aspheres
                else 0.0 for i in range(n)]
    return check_values(values)


def stop_semi_diameter(lens: RealLens) -> float:
    """
    Return the stop's semi-diameter (mm) that gives the lens its nominal f-number.

    A paraxial marginal ray from infinity at height f / (2 N) is traced to the stop: the
    entrance pupil of diameter f / N images there. The transcriptions' stop sizes are not
    used (some are housing radii, not the iris).

    :param lens: the lens (``f_number`` > 0).
    :return: the semi-diameter, mm, at the lens's scale.
    """
    rows = [(r * lens.scale, lens.gaps.get(i, t) * lens.scale, nd)
            for i, (r, t, nd, _) in enumerate(lens.rows)]
    y, u, n = 1.0, 0.0, 1.0
    heights = []
    for r, t, n_after in rows:
        heights.append(y)
        c = 1.0 / r if r else 0.0
        u = (n * u - y * (n_after - n) * c) / n_after
        n = n_after
        y += u * t
    # The last u is -y0 / f (in air): f = -1 / u for y0 = 1.
    focal = -1.0 / u
    return heights[lens.stop] * focal / (2.0 * lens.f_number)
