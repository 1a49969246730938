# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A lens known only by its datasheet: real image height against field angle (a TABLE lens).

Lens datasheets (M12 board lenses, machine-vision lenses) give the effective focal length f
and a table of real image heights h_i at field angles theta_i (object space, scene at
infinity), often with the relative illumination RI_i. ``lens.datasheet.field_angle_deg``,
``lens.datasheet.image_height_mm`` and ``lens.focal_length_mm`` hold them; this module checks
the table and interpolates it.

Interpolation (exact at the table's points, smooth between them): the image height is odd in
theta, h(theta) = f theta + a3 theta^3 + a5 theta^5 + ..., so the focal ratio
q = h / theta = f + a3 s + a5 s^2 + ... is a smooth function of s = theta^2 with q(0) = f.
h(theta) = theta q(theta^2), q the not-a-knot cubic spline through (0, f) and
(theta_i^2, h_i / theta_i). It has rho(0) = 0 and slope f at the axis by construction, and
reproduces a traced 160-deg wide-angle lens sampled every 5 deg within 0.006 px of 2 um to
90 deg (docs/design.md section 2.13), where a PCHIP on h(theta) is off by 0.12 px at 80 deg
and 1.4 px at 90 deg. A spline can overshoot between points: when the interpolated h is not
strictly increasing on a dense grid, the table falls back to the monotone PCHIP
(Fritsch-Carlson) on h(theta) with slope f at the axis, and says so in the model's warnings.
Beyond the last point nothing is extrapolated: the valid field ends there.

Relative illumination (optional ``lens.datasheet.relative_illumination``, same length, > 0,
<= 1.5): linear in the field angle between the points, 1 on the axis when the table starts
past it; beyond the table's last point nothing is known (0: the field ends there anyway).

The lens source (:class:`TableSource`, docs/design.md section 6.1): f from the table, both
principal planes at z = 0, the paraxial image plane by the Gaussian v = f l / (l - f). The
table is for a scene at infinity; for a finite scene the heights are scaled by v / f (the
lens refocused by moving it; the change of distortion with the scene distance is not known
and ignored). What needs surfaces does not apply and says so: tolerances (sigmas NaN), the
surface rules, ``lens.stop_offset_mm`` (the f-number takes ``lens.aperture_diameter_mm`` as
the entrance pupil). Parameters that would be silently ignored and matter are refused (a
prescription as well as a table, ``lens.glass``/``lens.surfaces.glass``,
``lens.image_distance_mm``); the thick-lens parameters that are ignored are named in a
warning when they differ from their defaults.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Mapping, Sequence

from mechdeconv_ros.lenses.lens_errors import TableError
from mechdeconv_ros.lenses.lens_source import (
    FirstOrder, FloatArray, Illumination, LensSource, ModelError, NotApplicable)
from mechdeconv_ros.schema.params import SPECS
import numpy as np

FIELD = 'lens.datasheet.field_angle_deg'
HEIGHT = 'lens.datasheet.image_height_mm'
ILLUMINATION = 'lens.datasheet.relative_illumination'
FOCAL = 'lens.focal_length_mm'
#: Largest field angle a table may hold (a fisheye at infinity sees behind its vertex).
MAX_FIELD_DEG = 179.0
#: Points per table interval on which the interpolant's monotonicity is checked.
CHECK_PER_INTERVAL = 64
#: A table whose first point implies a focal length this far (relative) from
#: ``lens.focal_length_mm`` is accepted with a warning.
FOCAL_MISMATCH = 0.05


def is_table_mode(values: Mapping[str, Any]) -> bool:
    """
    Return True when the values describe a datasheet lens (a non-empty angle table).

    :param values: checked parameter values.
    :return: whether ``lens.datasheet.field_angle_deg`` is non-empty.
    """
    raw = values.get(FIELD)
    return raw is not None and len(raw) > 0


@dataclass(frozen=True)
class DatasheetTable:
    """
    A checked datasheet table and its interpolant.

    ``theta_rad`` and ``height_mm`` include the axis point (0, 0) first; ``spline_s`` and
    ``spline_q`` / ``spline_slope`` are the cubic Hermite form of q(s) (s = theta^2), or the
    PCHIP of h(theta) when ``monotone_fallback`` is set.
    """

    focal_length_mm: float
    theta_rad: FloatArray
    height_mm: FloatArray
    illumination: FloatArray | None
    knots: FloatArray
    values: FloatArray
    slopes: FloatArray
    monotone_fallback: bool
    warnings: tuple[str, ...]

    @property
    def max_field_rad(self) -> float:
        """Return the last tabulated field angle."""
        return float(self.theta_rad[-1])

    def height(self, theta_rad: FloatArray) -> FloatArray:
        """
        Return the real image height at field angles; NaN beyond the table.

        :param theta_rad: field angles (rad), any shape, >= 0.
        :return: heights, mm.
        """
        theta = np.asarray(theta_rad, dtype=np.float64)
        clipped = np.clip(theta, 0.0, self.max_field_rad)
        if self.monotone_fallback:
            out = _hermite(self.knots, self.values, self.slopes, clipped)
        else:
            out = clipped * _hermite(self.knots, self.values, self.slopes, clipped * clipped)
        return np.where((theta >= 0.0) & (theta <= self.max_field_rad * (1 + 1e-12)), out,
                        np.nan)

    def relative_illumination(self, theta_rad: FloatArray) -> FloatArray | None:
        """
        Return the tabulated relative illumination at field angles (None without a table).

        :param theta_rad: field angles (rad).
        :return: RI, linear between the points, held beyond the last.
        """
        if self.illumination is None:
            return None
        return np.interp(np.asarray(theta_rad, dtype=np.float64), self.theta_rad,
                         self.illumination)


def _hermite(x: FloatArray, y: FloatArray, d: FloatArray, query: FloatArray) -> FloatArray:
    """Evaluate the cubic Hermite interpolant of (x, y, slopes d) at ``query`` (in range)."""
    k = np.clip(np.searchsorted(x, query, side='right') - 1, 0, x.size - 2)
    h = x[k + 1] - x[k]
    t = (query - x[k]) / h
    t2 = t * t
    t3 = t2 * t
    return ((2.0 * t3 - 3.0 * t2 + 1.0) * y[k] + (t3 - 2.0 * t2 + t) * h * d[k]
            + (3.0 * t2 - 2.0 * t3) * y[k + 1] + (t3 - t2) * h * d[k + 1])


def spline_slopes(x: FloatArray, y: FloatArray) -> FloatArray:
    """
    Return the knot slopes of the not-a-knot cubic spline through (x, y).

    Two points give the line, three the parabola (the not-a-knot spline's limits).

    :param x: strictly increasing abscissae (at least 2).
    :param y: values.
    :return: dy/dx at every knot.
    """
    n = x.size
    h = np.diff(x)
    delta = np.diff(y) / h
    if n == 2:
        return np.full(2, delta[0])
    if n == 3:
        # The parabola through the three points.
        c = (delta[1] - delta[0]) / (x[2] - x[0])
        return np.array([delta[0] - c * h[0], delta[0] + c * h[0], delta[1] + c * h[1]])
    a = np.zeros((n, n))
    b = np.zeros(n)
    for i in range(1, n - 1):
        a[i, i - 1], a[i, i], a[i, i + 1] = h[i], 2.0 * (h[i - 1] + h[i]), h[i - 1]
        b[i] = 3.0 * (h[i] * delta[i - 1] + h[i - 1] * delta[i])
    # Not-a-knot: the third derivative is continuous at the second and last-but-one knots.
    a[0, 0], a[0, 1] = h[1], h[0] + h[1]
    b[0] = ((h[0] + 2.0 * (h[0] + h[1])) * h[1] * delta[0] + h[0] ** 2 * delta[1]) / (h[0] + h[1])
    a[-1, -2], a[-1, -1] = h[-1] + h[-2], h[-2]
    b[-1] = (h[-1] ** 2 * delta[-2] + (2.0 * (h[-2] + h[-1]) + h[-1]) * h[-2] * delta[-1]) \
        / (h[-2] + h[-1])
    return np.linalg.solve(a, b)


def pchip_slopes(x: FloatArray, y: FloatArray, first_slope: float) -> FloatArray:
    """
    Return Fritsch-Carlson (PCHIP) knot slopes, the first one given.

    Interior slopes are the weighted harmonic means of the neighbouring secants (0 at a local
    extremum); the last is the one-sided three-point estimate limited as in SciPy's
    ``PchipInterpolator``; ``first_slope`` is clamped to three times the first secant so the
    interpolant stays monotone.

    :param x: strictly increasing abscissae (at least 2).
    :param y: values.
    :param first_slope: slope at x[0].
    :return: slopes.
    """
    h = np.diff(x)
    delta = np.diff(y) / h
    d = np.zeros(x.size)
    for i in range(1, x.size - 1):
        if delta[i - 1] * delta[i] > 0.0:
            w1, w2 = 2.0 * h[i] + h[i - 1], h[i] + 2.0 * h[i - 1]
            d[i] = (w1 + w2) / (w1 / delta[i - 1] + w2 / delta[i])
    d[0] = min(max(first_slope, 0.0), 3.0 * delta[0])
    if x.size == 2:
        d[-1] = delta[-1]
    else:
        end = ((2.0 * h[-1] + h[-2]) * delta[-1] - h[-1] * delta[-2]) / (h[-1] + h[-2])
        if np.sign(end) != np.sign(delta[-1]):
            end = 0.0
        elif np.sign(delta[-1]) != np.sign(delta[-2]) and abs(end) > abs(3.0 * delta[-1]):
            end = 3.0 * delta[-1]
        d[-1] = end
    return d


def _array(values: Mapping[str, Any], name: str) -> FloatArray:
    raw = values.get(name)
    out = np.asarray([float(v) for v in (() if raw is None else raw)], dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(out))
    if bad.size:
        raise TableError(name, f'value {bad[0]} is {out[bad[0]]}: every value must be finite')
    return out


def make_table(values: Mapping[str, Any]) -> DatasheetTable:
    """
    Check a datasheet table and build its interpolant.

    :param values: checked parameter values (``lens.datasheet.*``, ``lens.focal_length_mm``).
    :return: the table.
    :raises TableError: naming the parameter when the arrays differ in length, are not
        strictly increasing, hold non-finite values, when the heights do not increase with
        the angle, when the focal length is missing, or the illumination is out of range.
    """
    theta_deg = _array(values, FIELD)
    height = _array(values, HEIGHT)
    ri = _array(values, ILLUMINATION)
    f = float(values.get(FOCAL, 0.0))
    if theta_deg.size == 0:
        raise TableError(FIELD, 'is empty: a datasheet lens needs its field angles')
    if height.size != theta_deg.size:
        raise TableError(HEIGHT, f'has {height.size} values but {FIELD} has '
                                 f'{theta_deg.size}: give one image height per field angle')
    if ri.size not in (0, theta_deg.size):
        raise TableError(ILLUMINATION, f'has {ri.size} values but {FIELD} has '
                                       f'{theta_deg.size}: give one per field angle, or none')
    if not f > 0.0 or not math.isfinite(f):
        raise TableError(FOCAL, 'is 0: a datasheet lens needs its effective focal length '
                                '(the slope of the image height at the axis)')
    if theta_deg[0] < 0.0:
        raise TableError(FIELD, f'starts at {theta_deg[0]:g} deg: field angles are measured '
                                'from the axis, >= 0')
    steps = np.flatnonzero(np.diff(theta_deg) <= 0.0)
    if steps.size:
        i = int(steps[0])
        raise TableError(FIELD, f'is not strictly increasing: value {i + 1} '
                                f'({theta_deg[i + 1]:g} deg) follows {theta_deg[i]:g} deg')
    if theta_deg[-1] > MAX_FIELD_DEG:
        raise TableError(FIELD, f'ends at {theta_deg[-1]:g} deg, beyond {MAX_FIELD_DEG:g} deg')
    if theta_deg[0] == 0.0 and height[0] != 0.0:
        raise TableError(HEIGHT, f'is {height[0]:g} mm at 0 deg: the axis images at height 0')
    if theta_deg[0] > 0.0 and height[0] <= 0.0:
        raise TableError(HEIGHT, f'is {height[0]:g} mm at {theta_deg[0]:g} deg: heights off '
                                 'the axis must be > 0')
    steps = np.flatnonzero(np.diff(height) <= 0.0)
    if steps.size:
        i = int(steps[0])
        raise TableError(HEIGHT, f'does not increase with the field angle: '
                                 f'{height[i + 1]:g} mm at {theta_deg[i + 1]:g} deg after '
                                 f'{height[i]:g} mm at {theta_deg[i]:g} deg')
    if ri.size and (np.any(ri <= 0.0) or np.any(ri > 1.5)):
        i = int(np.flatnonzero((ri <= 0.0) | (ri > 1.5))[0])
        raise TableError(ILLUMINATION, f'value {i} is {ri[i]:g}: relative illumination is '
                                       'a ratio to the axis, in (0, 1.5]')
    if theta_deg[0] > 0.0:
        theta_deg = np.concatenate([[0.0], theta_deg])
        height = np.concatenate([[0.0], height])
        if ri.size:
            ri = np.concatenate([[1.0], ri])
    theta = np.radians(theta_deg)
    warnings: list[str] = []
    first_f = height[1] / math.tan(theta[1]) if theta[1] < 0.5 * math.pi else math.nan
    first_q = height[1] / theta[1]
    if min(abs(first_f - f), abs(first_q - f)) > FOCAL_MISMATCH * f:
        warnings.append(
            f'{HEIGHT}: the first point ({height[1]:g} mm at {theta_deg[1]:g} deg) implies a '
            f'focal length of {first_q:.4g} mm (h / theta; {first_f:.4g} mm as h / tan theta), '
            f'{FOCAL} is {f:g} mm: check the table and the focal length')
    knots = theta * theta
    q = np.concatenate([[f], height[1:] / theta[1:]])
    slopes = spline_slopes(knots, q)
    table = DatasheetTable(f, theta, height, ri if ri.size else None, knots, q, slopes, False,
                           ())
    dense = _dense_theta(theta)
    if not np.all(np.diff(table.height(dense)) > 0.0):
        warnings.append(f'{HEIGHT}: the smooth interpolation of the table overshoots between '
                        'its points (it would fold); the table is interpolated by the monotone '
                        'PCHIP instead (less smooth)')
        table = DatasheetTable(f, theta, height, table.illumination, theta, height,
                               pchip_slopes(theta, height, f), True, ())
    return DatasheetTable(**{**table.__dict__, 'warnings': tuple(warnings)})


def _dense_theta(theta: FloatArray) -> FloatArray:
    steps = np.linspace(0.0, 1.0, CHECK_PER_INTERVAL, endpoint=False)
    dense = (theta[:-1, None] + np.diff(theta)[:, None] * steps[None, :]).ravel()
    return np.concatenate([dense, theta[-1:]])


def table_params(field_deg: Sequence[float], height_mm: Sequence[float], focal_mm: float,
                 relative_illumination: Sequence[float] | None = None) -> dict[str, Any]:
    """
    Return the parameters of a datasheet lens (for ``mechdeconv import`` and config files).

    The table is checked as the model will check it; the prescription arrays are emptied so
    the table is the lens.

    :param field_deg: field angles, deg, strictly increasing from the axis.
    :param height_mm: real image heights, mm, one per angle.
    :param focal_mm: effective focal length, mm.
    :param relative_illumination: optional relative illumination, one per angle.
    :return: ``{'lens.datasheet.field_angle_deg': [...], ..., 'lens.focal_length_mm': f}``.
    :raises TableError: naming the parameter at fault.
    """
    out: dict[str, Any] = {
        FIELD: [float(v) for v in field_deg],
        HEIGHT: [float(v) for v in height_mm],
        ILLUMINATION: [float(v) for v in relative_illumination or ()],
        FOCAL: float(focal_mm),
        'lens.surfaces.radius_mm': [],
    }
    make_table(out)
    return out


#: Thick-lens parameters a datasheet lens ignores (a warning names those not at their default).
IGNORED = ('lens.r1_mm', 'lens.r2_mm', 'lens.thickness_mm', 'lens.refractive_index',
           'lens.wavelength_nm')
#: What needs surfaces and does not apply to a table: always noted in the model's warnings.
NOT_APPLICABLE = ('datasheet lens: lens.tolerance.* and lens.stop_offset_mm do not apply (no '
                  'surfaces: the tolerance sigmas are n/a; the f-number takes '
                  'lens.aperture_diameter_mm as the entrance pupil)')
#: Heights of the relative illumination curve of a table (from the axis to the sensor edge).
RI_SAMPLES = 257


class TableSource(LensSource):
    """A lens given by its datasheet: focal length and real image height by field angle."""

    mode = 'datasheet'
    lens_parameter = HEIGHT
    stop_parameter = FIELD

    def __init__(self, values: Mapping[str, Any]) -> None:
        """
        Check the table and the parameters that cannot apply to it.

        :param values: checked parameter values with a non-empty ``lens.datasheet.*`` table.
        :raises ModelError: naming the parameter at fault.
        """
        self.values = values
        try:
            self.table = make_table(values)
        except TableError as err:
            raise ModelError(err.parameter, err.reason) from None
        if len(values.get('lens.surfaces.radius_mm', ())) > 0:
            raise ModelError('lens.surfaces.radius_mm',
                             'a prescription and a datasheet table (lens.datasheet.*) both '
                             'describe the lens: empty one of them')
        refused = {
            'lens.image_distance_mm': float(values.get('lens.image_distance_mm', 0.0)) != 0.0,
            'lens.glass': bool(str(values.get('lens.glass', '')).strip()),
            'lens.surfaces.glass': len(values.get('lens.surfaces.glass', ())) > 0,
        }
        for name, set_ in refused.items():
            if set_:
                raise ModelError(name, 'does not apply to a datasheet lens (its table fixes '
                                       'the image heights, with the sensor in focus): set it '
                                       'back to its default')
        ignored = [name for name in IGNORED if values.get(name, SPECS[name].default)
                   != SPECS[name].default]
        self.notes = [NOT_APPLICABLE, *self.table.warnings]
        if ignored:
            self.notes.append(f'{", ".join(ignored)}: not used by a datasheet lens (the table '
                              'is the lens)')

    def first_order(self) -> FirstOrder:
        """Return the datasheet's focal length; the principal planes at z = 0."""
        return FirstOrder(self.table.focal_length_mm, 0.0, 0.0)

    def real_heights(self, field_angle_rad: FloatArray, distance_mm: float,
                     guide: Any = None) -> tuple[FloatArray, None]:
        """Interpolate the table (scaled by v / f for a finite scene); NaN beyond it."""
        _, v = self.image_plane(distance_mm)
        return self.table.height(field_angle_rad) * (v / self.table.focal_length_mm), None

    def check_physical(self, distance_mm: float, sensor_z_mm: float) -> list[str]:
        """Return the table's notes (interpolation, focal length, ignored parameters)."""
        return list(self.notes)

    def relative_illumination(self, model: Any, *, with_fraction: bool = True,
                              known: Illumination | None = None) -> Illumination:
        """
        Return the datasheet's relative illumination over the sensor radius.

        :param model: the model of this lens.
        :param with_fraction: ignored (a datasheet gives no stop-only beam).
        :param known: ignored.
        :return: RI at real heights from the axis to the raw image's edge (0 beyond the
            table).
        :raises NotApplicable: when the datasheet gives none.
        """
        if self.table.illumination is None:
            raise NotApplicable('the datasheet gives no relative illumination '
                                f'({ILLUMINATION} is empty)')
        px, py = model.pixel_mm
        corner = math.hypot((model.width - 1) / 2.0 * px, (model.height - 1) / 2.0 * py)
        edge = math.hypot(model.width / 2.0 * px, model.height / 2.0 * py)
        heights = np.linspace(0.0, 1.02 * edge, RI_SAMPLES)
        field = model.field_curve or model.curve
        theta = field.angle_from_real(heights)
        ri = np.where(np.isfinite(theta),
                      self.table.relative_illumination(np.nan_to_num(theta)), 0.0)
        corner_ri = float(np.interp(corner, heights, ri))
        return Illumination(heights, ri, None, corner, corner_ri)
