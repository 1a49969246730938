# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Write config/zoom.yaml: a published 2.5x f/2.8 zoom and its zoom cam table.

Source: Nikon, Japanese patent application S53-131852 (1978), "80-200 mm f/2.8", a
mechanically compensated zoom, as tabulated in W. J. Smith, "Modern Lens Design", 2nd ed.
(McGraw-Hill, 2005), p. 527-528, figure 20.3 (numbers transcribed from the lens file of the
open-source lentil renderer, github.com/zpelgrims/lentil, polynomial-optics/lenses/
nikon-zoom.fx, which cites that page): 22 surfaces, three air gaps that move (after surfaces
4, 9 and 12; given at the short, middle and long ends), the iris (surface 17) in the fixed
rear group. The three gaps add up to 55.34 mm in every row (the front and rear groups do not
move), which this script checks. As tabulated the lens has f = 57.2 to 143.0 mm (the 2.5x
ratio of the title; the table is scaled by 0.715), so the sensor is scaled likewise (24 x
13.5 mm: 960 x 540 pixels of 25 um, or 1920 x 1080 of 12.5 um; a 27 deg diagonal at the
short end, the design's 30).

The patent gives three positions; a zoom motor passes through every position in between,
where the compensator keeps the image plane fixed. The cam is rebuilt from the design: the
variator gap d1 (after surface 4) moves linearly with the joint position p in [0, 1]
(p = 0 short, p = 1 long), and at each p the compensator gap d3 (after surface 12) is
solved, by bisection on the paraxial trace, so that the image of a scene at infinity stays
where it is at p = 0; d2 = 55.338 - d1 - d3. The solved cam meets the long row to 0.03 mm
(1.555 / 5.105 against 1.536 / 5.133 mm); the middle row as transcribed (25.27, 19.23,
10.84) is not on it: it puts the image 5 mm behind the other two rows, and at d1 = 25.27 the
only compensator gap that keeps the image plane is 3.17 mm, so it is left out.

Run ``.venv/bin/python tools/make_zoom_config.py`` (writes config/zoom.yaml).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from mechdeconv_ros.model.model import make_prescription
from mechdeconv_ros.optics.raytrace import image_plane
from mechdeconv_ros.schema.params import check_values

# radius, thickness (short focal length), index (d), semi-diameter; 0 = flat (the iris).
PATENT = (
    (148.570, 5.000, 1.564, 32.2),
    (-479.279, 0.357, 1.0, 32.2),
    (192.855, 6.286, 1.589, 31.0),
    (-134.999, 2.214, 1.805, 31.0),
    (-874.852, 1.860, 1.0, 30.5),       # d1: variator gap
    (-285.712, 3.893, 1.755, 19.0),
    (-44.764, 1.036, 1.517, 19.0),
    (59.357, 5.357, 1.0, 19.0),
    (-45.071, 1.250, 1.589, 16.0),
    (166.174, 36.928, 1.0, 16.0),       # d2
    (164.284, 5.000, 1.658, 15.0),
    (-33.928, 1.036, 1.795, 15.0),
    (-85.047, 16.550, 1.0, 15.0),       # d3: compensator gap
    (30.464, 5.357, 1.670, 16.7),
    (162.202, 3.071, 1.0, 16.3),
    (-374.997, 1.786, 1.805, 15.2),
    (259.105, 17.857, 1.0, 14.5),
    (0.0, 18.000, 1.0, 9.4),            # iris
    (-17.214, 1.714, 1.713, 10.5),
    (-30.230, 0.286, 1.0, 11.5),
    (62.857, 3.071, 1.773, 12.6),
    (-466.815, 40.080, 1.0, 12.6),      # image distance: the model computes it
)
#: The moving gaps and the patent's rows (short, middle, long focal length).
GAPS = (4, 9, 12)
PATENT_ROWS = ((1.860, 36.928, 16.550), (25.270, 19.230, 10.840), (48.678, 1.536, 5.133))
STOP_SURFACE = 17
#: Stop diameter, mm: f/2.8 at 80 mm (28.6 mm entrance pupil) with this rear group.
STOP_DIAMETER_MM = 14.0
ROWS = 17
OUT = Path(__file__).resolve().parents[1] / 'config' / 'zoom.yaml'


def values_with(gaps: tuple[float, float, float]) -> dict:
    """Return the checked parameter values of the lens with the three moving gaps."""
    thickness = [s[1] for s in PATENT]
    for i, gap in zip(GAPS, gaps):
        thickness[i] = gap
    return check_values({
        'lens.surfaces.radius_mm': [s[0] for s in PATENT],
        'lens.surfaces.thickness_mm': thickness,
        'lens.surfaces.refractive_index': [s[2] for s in PATENT],
        'lens.surfaces.semi_diameter_mm': [s[3] for s in PATENT],
        'lens.stop_surface': STOP_SURFACE, 'lens.aperture_diameter_mm': STOP_DIAMETER_MM,
        'scene.distance_mm': 0.0})


def image_z(gaps: tuple[float, float, float]) -> tuple[float, float]:
    """Return the paraxial image plane z (scene at infinity) and the focal length."""
    prescription = make_prescription(values_with(gaps))
    sensor_z, v = image_plane(prescription, math.inf)
    return sensor_z, v


def solve_row(d1: float, total: float, target_z: float, near_d3: float) -> tuple[float, ...]:
    """Solve the compensator gap d3 that keeps the image at ``target_z`` (bisection)."""
    def error(d3: float) -> float:
        return image_z((d1, total - d1 - d3, d3))[0] - target_z

    lo, hi = max(0.05, near_d3 - 6.0), min(near_d3 + 6.0, total - d1 - 0.05)
    # Walk to a bracket on the branch next to the previous row's solution.
    grid = [lo + (hi - lo) * k / 240 for k in range(241)]
    signs = [error(d) for d in grid]
    brackets = [(grid[k], grid[k + 1]) for k in range(240) if signs[k] * signs[k + 1] <= 0.0]
    if not brackets:
        raise RuntimeError(f'no compensator position keeps the image plane at d1 = {d1}')
    a, b = min(brackets, key=lambda ab: abs(0.5 * (ab[0] + ab[1]) - near_d3))
    for _ in range(60):
        m = 0.5 * (a + b)
        if error(a) * error(m) <= 0.0:
            b = m
        else:
            a = m
    d3 = 0.5 * (a + b)
    return (d1, total - d1 - d3, d3)


def main() -> None:
    """Solve the cam, check it against the patent, write the params file."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, default=OUT)
    args = parser.parse_args()
    totals = [sum(row) for row in PATENT_ROWS]
    assert max(totals) - min(totals) < 0.01, totals
    total = sum(PATENT_ROWS[0])
    target_z, _ = image_z(PATENT_ROWS[0])
    rows = []
    d3 = PATENT_ROWS[0][2]
    for k in range(ROWS):
        p = k / (ROWS - 1)
        d1 = PATENT_ROWS[0][0] + p * (PATENT_ROWS[2][0] - PATENT_ROWS[0][0])
        row = PATENT_ROWS[0] if k == 0 else solve_row(d1, total, target_z, d3)
        d3 = row[2]
        rows.append(row)
        print(f'p = {p:.4f}: gaps {row[0]:8.3f} {row[1]:8.3f} {row[2]:8.3f} mm, '
              f'f = {image_z(row)[1]:.2f} mm')
    for patent, p in zip(PATENT_ROWS, (0.0, 0.5, 1.0)):
        got = rows[round(p * (ROWS - 1))]
        print(f'patent row at p = {p}: {patent}, solved {tuple(round(g, 3) for g in got)}')
    text = f"""# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
#
# A 2.5x f/2.8 zoom lens with its zoom driven from sensor_msgs/JointState (issue 19).
# Design: Nikon, Japanese patent application S53-131852 (1978, "80-200 mm f/2.8"), as tabulated
# in W. J. Smith, "Modern Lens Design", 2nd ed., p. 527-528, fig. 20.3 (22 surfaces, d-line
# indices; the iris is surface 17, flat). As tabulated: f = 57.2 to 143.0 mm. Three air gaps
# move (after surfaces 4, 9 and 12). The joint "zoom" runs from 0.0 (short) to 1.0 (long): the
# variator gap moves linearly with it and the compensator gap is solved at {ROWS} positions so
# that the image plane stays fixed (tools/make_zoom_config.py, which checks it against the
# patent's rows). Sensor: 24 x 13.5 mm, 960 x 540 pixels of 25 um; scene at infinity.
# No focus table: the source gives none (lens.focus.joint stays '').
/**:
  ros__parameters:
    lens:
      aperture_diameter_mm: {STOP_DIAMETER_MM}
      stop_surface: {STOP_SURFACE}
      surfaces:
        radius_mm: {[s[0] for s in PATENT]}
        thickness_mm: {[s[1] for s in PATENT]}
        refractive_index: {[s[2] for s in PATENT]}
        semi_diameter_mm: {[s[3] for s in PATENT]}
      zoom:
        joint: zoom
        positions: {[round(k / (ROWS - 1), 6) for k in range(ROWS)]}
        surfaces: {list(GAPS)}
        thickness_mm: [{', '.join(f'{g:.4f}' for row in rows for g in row)}]
    sensor:
      pixel_size_x_um: 25.0
      pixel_size_y_um: 25.0
      width_px: 960
      height_px: 540
    scene:
      distance_mm: 0.0
"""
    args.out.write_text(text, encoding='utf-8')
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
