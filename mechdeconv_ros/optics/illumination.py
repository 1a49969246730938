# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Relative illumination: the sensor irradiance of a uniform Lambertian scene, traced.

Pure numpy, no ROS. Geometric optics, no coating or absorption losses.

Model
-----
Radiance is conserved along a ray (L / n^2, and the sensor is in air), so a sensor point
receives E = L * Omega_p with the projected solid angle

    Omega_p(h) = integral over the passing image-side directions of cos(theta') dOmega'
               = area of the passing set in the (k_x, k_y) direction-cosine plane,

because dk_x dk_y = cos(theta') dOmega'. A direction passes when its ray, traced BACKWARDS
from the sensor point (0, h) on the sensor plane through the lens, clears every aperture (the
stop, each semi-diameter, the lens edges) without total internal reflection: every such ray
ends on the uniform scene. This is the irradiance on the flat sensor, not the flux of the cone
that leaves an object point: with field curvature the corner bundle does not converge on the
sensor. The relative illumination is

    RI(h) = Omega_p(h) / Omega_p(0),        h the REAL radial distance on the sensor (mm).

``pupil_pass_fraction(h) = Omega_p(h) / Omega_stop(h)``, where Omega_stop counts the
directions that pass the stop alone (semi-diameters ignored, lens edges and TIR kept): the
share of the beam through the stop that the other apertures let through, the mechanical
vignetting, which a smaller stop reduces. RI = pupil_pass_fraction x (the natural fall-off,
cos^4-like, of the stop-limited beam).

Integration
-----------
The passing set is symmetric in k_x. For each height a scan of k_y along k_x = 0 and a
bisection of its two ends give [k_lo, k_hi] (for a convex set the extreme k_y lie on
k_x = 0); with c = (k_lo + k_hi)/2, r = (k_hi - k_lo)/2 the rows k_y = c - r cos(t) at the
midpoints of N equal steps of t in [0, pi] carry the half-width b(t) of the set (bisection in
k_x from 0), and

    Omega_p = integral 2 b dk_y = integral_0^pi 2 b(t) r sin(t) dt ~ (pi / N) sum 2 b r sin t,

exact for an ellipse (b = r' sin t) and free of the square-root end behaviour of b(k_y).

Closed forms (tests): an unclipped Lambertian disk of radius a at distance d, seen from a
point at lateral offset h on a parallel plane, gives (Moon 1936; Sparrow & Cess, Radiation
Heat Transfer, disk-to-parallel-element view factor)

    Omega_p = (pi / 2) (1 - (d^2 + h^2 - a^2) / sqrt((d^2 + h^2 + a^2)^2 - 4 a^2 h^2)),

pi a^2 / (a^2 + d^2) = pi sin^2(theta_max) on the axis, and for a << d the cos^4 law
Omega_p ~ pi a^2 d^2 / (d^2 + h^2)^2 = pi (a / d)^2 cos^4(theta).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Mapping

from mechdeconv_ros.optics.prescription import image_plane, paraxial, Prescription
from mechdeconv_ros.optics.trace3d import (
    direction_from_cosines, FAILED, lens_system, reversed_system, System, trace_margin, trace_pass,
    trace_passes)
from mechdeconv_ros.schema.params import scene_distance
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: Heights of the traced RI curve, uniform from the axis to just past the raw image corner
#: (linear interpolation between them: at the kink where a rim starts to clip it errs by
#: about 0.1 percentage point on the lenses of the tests).
RI_SAMPLES = 48
#: A drop of RI by more than CLIFF between two heights gets CLIFF_SAMPLES heights inside;
#: so do the two intervals around a height where the curve bends by more than BEND (second
#: difference of RI): the onset of a rim's cut-off, where an f/1.8 beam starts to be clipped
#: and a straight line over one step of 1/48 of the field errs by up to a percentage point.
CLIFF = 0.1
BEND = 0.01
CLIFF_SAMPLES = 15
#: Samples of the meridional (k_x = 0) scan of each height over k_y in (-1, 1).
SCAN_SAMPLES = 128
#: Rows of the k_y integration, the most root-finding steps of an edge and the change of its
#: estimate (direction cosine) below which it stops.
ROWS = 16
ROOT_STEPS = 40
EDGE_TOLERANCE = 1e-6
#: A margin this small is the rim itself.
ROOT_MARGIN = 1e-13
#: Multiples of the meridional half-width probed to bracket each row's half-width.
PROBE_FACTORS = (0.8, 1.0, 1.25, 1.6, 2.5, 4.0, 8.0)


@dataclass(frozen=True)
class Illumination:
    """
    The traced relative illumination over the real sensor radius.

    ``height_mm`` increases from 0 (uniform, denser where RI falls off a cliff); ``ri`` is 1
    on the axis; ``pupil_pass_fraction`` is
    None when it was not asked for. ``corner_height_mm`` is the real radius of the raw image's
    corner pixel centre, ``corner_ri`` the RI there.
    """

    height_mm: FloatArray
    ri: FloatArray
    pupil_pass_fraction: FloatArray | None
    corner_height_mm: float
    corner_ri: float

    def at(self, height_mm: FloatArray) -> FloatArray:
        """
        Interpolate RI at real sensor radii (linear; the last value beyond the curve).

        :param height_mm: real radii, mm, any shape.
        :return: RI, same shape.
        """
        return np.interp(np.asarray(height_mm, dtype=np.float64), self.height_mm, self.ri)

    @property
    def lit_height_mm(self) -> float:
        """Return the largest traced height that any ray reaches (RI > 0)."""
        lit = np.flatnonzero(self.ri > 0.0)
        return float(self.height_mm[lit[-1]]) if lit.size else 0.0

    def report(self) -> dict[str, Any]:
        """Return the JSON-ready ``relative_illumination`` entry of ``mechdeconv info``."""
        out: dict[str, Any] = {
            'image_height_mm': [round(float(h), 9) for h in self.height_mm],
            'ri': [round(float(v), 6) for v in self.ri],
            'corner_ri': round(float(self.corner_ri), 6),
            'corner_height_mm': round(float(self.corner_height_mm), 9),
            'lit_height_mm': round(float(self.lit_height_mm), 9),
        }
        if self.pupil_pass_fraction is not None:
            out['pupil_pass_fraction'] = [round(float(v), 6) for v in self.pupil_pass_fraction]
            out['corner_pupil_pass_fraction'] = round(float(np.interp(
                self.corner_height_mm, self.height_mm, self.pupil_pass_fraction)), 6)
        return out


def stop_of(values: Mapping[str, Any]) -> tuple[float, int | None]:
    """
    Return the aperture stop of a parameter set: (clear radius in mm, stop surface or None).

    The stop's clear diameter is ``lens.aperture_diameter_mm``; in prescription mode it sits
    on surface ``lens.stop_surface`` (whose semi-diameter clips in addition), in thick-lens
    mode it is a plane at the prescription's ``stop_z_mm``.

    :param values: checked parameter values.
    :return: the stop radius and the surface carrying it.
    """
    radius = 0.5 * float(values['lens.aperture_diameter_mm'])
    if len(values['lens.surfaces.radius_mm']) > 0:
        return radius, int(values['lens.stop_surface'])
    return radius, None


def backward_system(prescription: Prescription, stop_radius_mm: float,
                    stop_surface: int | None, sensor_z_mm: float,
                    scene_at_infinity: bool = False) -> System:
    """
    Return the lens mirrored about the sensor plane: backward rays start at z' = 0.

    :param prescription: the lens.
    :param stop_radius_mm: clear radius of the stop.
    :param stop_surface: surface carrying the stop, None for a stop plane.
    :param sensor_z_mm: the sensor plane.
    :param scene_at_infinity: a ray leaving the front surface in any direction reaches the
        scene (past 90 deg for a fisheye); at a finite distance it must head for the object
        plane.
    :return: the mirrored system (:func:`mechdeconv_ros.optics.trace3d.reversed_system`).
    """
    system = lens_system(prescription, stop_radius_mm, stop_surface)
    return reversed_system(system, sensor_z_mm, scene_at_infinity)


def _margin(system: System, height: FloatArray, kx: FloatArray, ky: FloatArray) -> np.ndarray:
    """Return the aperture margins of backward rays from (0, height, 0), cosines (kx, ky)."""
    kz = direction_from_cosines(kx, ky)
    return trace_margin(system, 0.0, height, 0.0, kx, ky, kz)


def _edge(system: System, height: FloatArray, fixed: FloatArray, a: FloatArray,
          fa: FloatArray, b: FloatArray, fb: FloatArray, along_x: bool,
          steps: int) -> FloatArray:
    """
    Locate the rim between a passing cosine ``a`` and a failing one ``b`` (along k_x or k_y).

    The Illinois variant of regula falsi on the continuous aperture margin converges in a
    few steps where an aperture rim clips; while the failing end is a hard failure (TIR, a
    missed surface, a lens edge: no margin to interpolate) the step is a bisection. An entry
    stops when its estimate moves by less than EDGE_TOLERANCE; ``steps`` bounds the calls.
    """
    def margin(index: np.ndarray, c: FloatArray) -> np.ndarray:
        if along_x:
            return _margin(system, height[index], c, fixed[index])
        return _margin(system, height[index], fixed[index], c)

    a, fa, b, fb = (np.array(v, dtype=np.float64) for v in (a, fa, b, fb))
    wa, wb = fa.copy(), fb.copy()
    side = np.zeros(a.shape, dtype=np.int8)
    estimate = np.full(a.shape, np.nan)
    active = np.arange(a.size)
    for _ in range(steps):
        if active.size == 0:
            break
        ai, bi, wai, wbi = a[active], b[active], wa[active], wb[active]
        with np.errstate(invalid='ignore', divide='ignore'):
            c = (ai * wbi - bi * wai) / (wbi - wai)
        secant = ((c - ai) * (c - bi) < 0.0) & (fb[active] > FAILED)
        c = np.where(secant, c, 0.5 * (ai + bi))
        fc = margin(active, c)
        keep = fc >= 0.0
        sa = side[active]
        a[active] = np.where(keep, c, ai)
        fa[active] = np.where(keep, fc, fa[active])
        wa[active] = np.where(keep, fc, np.where(sa < 0, 0.5 * wai, wai))
        b[active] = np.where(keep, bi, c)
        fb[active] = np.where(keep, fb[active], fc)
        wb[active] = np.where(keep, np.where(sa > 0, 0.5 * wbi, wbi), fc)
        side[active] = np.where(keep, 1, -1)
        # Converged: the estimate moved by less than the tolerance (the first step never
        # stops), the margin vanishes, or the bracket is narrower than the tolerance.
        done = ((np.abs(c - estimate[active]) <= EDGE_TOLERANCE)
                | (np.minimum(np.abs(fc), fa[active]) <= ROOT_MARGIN)
                | (np.abs(b[active] - a[active]) <= EDGE_TOLERANCE))
        estimate[active] = c
        active = active[~done]
    # The edge by linear interpolation of the true margins in the final bracket.
    with np.errstate(invalid='ignore', divide='ignore'):
        c = (a * fb - b * fa) / (fb - fa)
    c = np.clip(c, np.minimum(a, b), np.maximum(a, b))     # rounding may step out
    return np.where(np.isfinite(c) & (fb > FAILED), c, 0.5 * (a + b))


def beam_area(system: System, heights_mm: FloatArray, *, scan: int = SCAN_SAMPLES,
              rows: int = ROWS, steps: int = ROOT_STEPS) -> FloatArray:
    """
    Return the projected solid angle of the passing directions at each sensor height.

    :param system: the backward system (:func:`backward_system`), sensor at z' = 0.
    :param heights_mm: sensor points (0, h), any shape.
    :param scan: samples of the meridional scan.
    :param rows: rows of the k_y integration.
    :param steps: root-finding steps per edge.
    :return: Omega_p in steradians (projected), same shape; 0 where no ray passes.
    """
    heights = np.asarray(heights_mm, dtype=np.float64)
    h = heights.ravel()
    area = np.zeros(h.size)
    ky = -1.0 + (np.arange(scan) + 0.5) * (2.0 / scan)
    # Which directions pass (trace_passes drops each ray as it fails: the scans beyond a
    # fisheye's image circle fail early); the margins, which the rim search needs, only at the
    # first and last passing sample of each height and their failing neighbours (below).
    kx = np.zeros(1)
    through = trace_passes(system, 0.0, h[:, None], 0.0, kx, ky[None, :],
                           direction_from_cosines(kx, ky[None, :]))
    missed = np.flatnonzero(~through.any(axis=1))
    if missed.size and scan < 32 * SCAN_SAMPLES:
        # A beam narrower than the scan step (a tiny stop, or the last sliver of a vignetted
        # field): look again, 16 times finer, at those heights only.
        area[missed] = beam_area(system, h[missed], scan=16 * scan, rows=rows, steps=steps)
    live = np.flatnonzero(through.any(axis=1))
    if live.size == 0:
        return area.reshape(heights.shape)
    through = through[live]
    hl = h[live]
    n = hl.size
    lo = np.argmax(through, axis=1)
    hi = scan - 1 - np.argmax(through[:, ::-1], axis=1)
    below, above = np.maximum(lo - 1, 0), np.minimum(hi + 1, scan - 1)
    scanned = _margin(system, hl[:, None], kx, ky[np.stack((lo, hi, below, above), axis=1)])
    good = np.concatenate((ky[lo], ky[hi]))
    f_good = np.concatenate((scanned[:, 0], scanned[:, 1]))
    bad = np.concatenate((np.where(lo > 0, ky[below], -1.0), np.where(hi < scan - 1,
                                                                      ky[above], 1.0)))
    f_bad = np.concatenate((np.where(lo > 0, scanned[:, 2], FAILED),
                            np.where(hi < scan - 1, scanned[:, 3], FAILED)))
    edges = _edge(system, np.concatenate((hl, hl)), np.zeros(2 * n), good, f_good, bad, f_bad,
                  False, steps)
    k_lo, k_hi = edges[:n], edges[n:]
    centre = 0.5 * (k_lo + k_hi)[:, None]
    radius = 0.5 * (k_hi - k_lo)[:, None]
    t = (np.arange(rows) + 0.5) * (math.pi / rows)
    row_ky = centre - radius * np.cos(t)[None, :]
    row_h = np.broadcast_to(hl[:, None], row_ky.shape)
    kmax = np.sqrt(np.maximum(0.0, 1.0 - row_ky * row_ky)) * (1.0 - 1e-12)
    # A first bracket from the meridional half-width (exact for a circle; an off-axis beam is
    # wider sagittally), then the rim.
    guess = radius * np.sin(t)[None, :]
    factors = np.array((0.0,) + PROBE_FACTORS)[:, None, None]
    probe = np.minimum(factors * guess[None], kmax[None])
    f_probe = _margin(system, row_h[None], probe, row_ky[None])
    centre_ok = f_probe[0] >= 0.0
    # Largest passing probe and the next one (or k_max): a bracket of the rim.
    count = np.sum(np.cumprod(f_probe >= 0.0, axis=0), axis=0)
    count = np.maximum(count, 1)
    padded = np.concatenate((probe, kmax[None]))
    f_padded = np.concatenate((f_probe, np.full((1,) + kmax.shape, FAILED)))
    pick = [np.take_along_axis(v, (count + d - 1)[None], axis=0)[0]
            for v in (padded, f_padded) for d in (0, 1)]
    # Rows whose centre (k_x = 0) fails carry no beam (a convex set's rows all pass there).
    rows_ok = np.flatnonzero(centre_ok.ravel())
    half = np.zeros(row_ky.size)
    half[rows_ok] = _edge(system, row_h.ravel()[rows_ok], row_ky.ravel()[rows_ok],
                          *(v.ravel()[rows_ok] for v in (pick[0], pick[2], pick[1], pick[3])),
                          True, steps)
    half = half.reshape(row_ky.shape)
    area[live] = (math.pi / rows) * np.sum(2.0 * half * radius * np.sin(t)[None, :], axis=1)
    return area.reshape(heights.shape)


def relative_illumination(model: Any, *, samples: int = RI_SAMPLES,
                          with_fraction: bool = True,
                          known: Illumination | None = None) -> Illumination:
    """
    Trace the relative illumination of a :class:`~mechdeconv_ros.model.model.LensModel`.

    :param model: the lens model (its values, prescription, sensor and pixel pitch).
    :param samples: heights from the axis to 1.02 x the raw image's half-diagonal.
    :param with_fraction: also trace the stop-only beam for ``pupil_pass_fraction``.
    :param known: the curve of this model traced without the fraction (the gain map's): only
        the stop-only beam is traced then, at its heights.
    :return: the curve.
    :raises ValueError: when not even the axial beam passes the lens.
    """
    values = model.values
    radius, surface = stop_of(values)
    distance = scene_distance(values)
    # The sensor's plane (lens.image_distance_mm may move it off the paraxial image plane).
    sensor_z, _ = model.source.image_plane(distance)
    system = backward_system(model.prescription, radius, surface, sensor_z,
                             math.isinf(distance))
    px, py = model.pixel_mm
    corner = math.hypot((model.width - 1) / 2.0 * px, (model.height - 1) / 2.0 * py)
    edge = model.half_diagonal_mm
    if known is not None and with_fraction:
        heights = known.height_mm
        area = known.ri * beam_area(system, np.zeros(1))[0]
        stop_only = beam_area(system.without_semi_diameters(), heights)
        with np.errstate(invalid='ignore', divide='ignore'):
            fraction = np.where(stop_only > 0, np.minimum(1.0, area / stop_only), 0.0)
        return Illumination(heights, known.ri, fraction, known.corner_height_mm,
                            known.corner_ri)
    heights = np.linspace(0.0, 1.02 * edge, samples)
    area = beam_area(system, heights)
    if not area[0] > 0:
        raise ValueError('no ray from the scene reaches the centre of the sensor: the stop '
                         'or a semi-diameter blocks the axial beam')
    # A cliff (a whole beam clipped within one step, e.g. at a fisheye's design field, where
    # the front rim cuts every ray at once) or a bend (where a rim starts to clip): trace 15
    # heights inside each such interval, so that linear interpolation holds there too.
    ri = area / area[0]
    bend = np.flatnonzero(np.abs(ri[:-2] - 2.0 * ri[1:-1] + ri[2:]) > BEND)
    cliffs = np.union1d(np.flatnonzero(ri[:-1] - ri[1:] > CLIFF),
                        np.union1d(bend, bend + 1))
    if cliffs.size:
        inner = (np.arange(1, CLIFF_SAMPLES + 1) / (CLIFF_SAMPLES + 1))[None, :]
        extra = (heights[cliffs, None] + inner * (heights[cliffs + 1] - heights[cliffs])[:, None]
                 ).ravel()
        heights = np.concatenate((heights, extra))
        area = np.concatenate((area, beam_area(system, extra)))
        order = np.argsort(heights)
        heights, area = heights[order], area[order]
    ri = area / area[0]
    fraction = None
    if with_fraction:
        stop_only = beam_area(system.without_semi_diameters(), heights)
        with np.errstate(invalid='ignore', divide='ignore'):
            fraction = np.where(stop_only > 0, np.minimum(1.0, area / stop_only), 0.0)
    return Illumination(heights, ri, fraction, corner, float(np.interp(corner, heights, ri)))


# ---------------------------------------------------------------------------------------------
# Independent reference: forward flux count
# ---------------------------------------------------------------------------------------------

def _r2_sequence(count: int, dims: int, rng: np.random.Generator) -> FloatArray:
    """Return ``count`` points of Roberts' R_d low-discrepancy sequence, randomly shifted."""
    phi = 2.0
    for _ in range(64):
        phi = (1.0 + phi) ** (1.0 / (dims + 1))
    alpha = (1.0 / phi) ** np.arange(1, dims + 1)
    n = np.arange(1, count + 1, dtype=np.float64)[:, None]
    return np.mod(rng.random(dims)[None, :] + n * alpha[None, :], 1.0)


def _disk(u: FloatArray, v: FloatArray, radius: float) -> tuple[FloatArray, FloatArray]:
    r = radius * np.sqrt(u)
    return r * np.cos(2.0 * math.pi * v), r * np.sin(2.0 * math.pi * v)


def forward_flux(prescription: Prescription, stop_radius_mm: float, stop_surface: int | None,
                 object_distance_mm: float, sensor_radius_mm: float, *, bins: int = 8,
                 rays: int = 2_000_000, entrance_radius_mm: float, field_cosine: float,
                 chunk: int = 250_000, seed: int = 0) -> tuple[FloatArray, FloatArray]:
    """
    Count the flux a uniform Lambertian scene sends onto the sensor, ray by ray (reference).

    Rays are spread uniformly (a randomly shifted R_4 sequence) over the scene and over a disk
    of radius ``entrance_radius_mm`` on the first-vertex plane z = 0: for a scene at infinity
    uniform in the object-space direction cosines (|k| <= ``field_cosine``; every ray then
    carries the same etendue), for a scene at distance l each ray from a point of the object
    plane to a point of the entrance disk carries d^2 / D^4 (cos^2 / D^2 between parallel
    planes, D the ray's length, d the planes' distance). They are traced forwards through
    every aperture and binned where they cross the sensor plane, in ``bins`` annuli of equal
    area up to ``sensor_radius_mm``. The disks must contain every ray that reaches the sensor
    within that radius (choose them generously).

    :param prescription: the lens.
    :param stop_radius_mm: clear radius of the stop.
    :param stop_surface: surface carrying the stop, None for the stop plane.
    :param object_distance_mm: l from the front principal plane (``math.inf`` allowed).
    :param sensor_radius_mm: outer radius of the last annulus.
    :param bins: number of annuli.
    :param rays: number of rays.
    :param entrance_radius_mm: radius of the entrance disk on z = 0.
    :param field_cosine: for l = inf the largest direction cosine, else the object-plane disk
        radius divided by l.
    :param chunk: rays per batch.
    :param seed: shift of the sequence.
    :return: ``(edges_mm, irradiance)``: the annuli's radii (bins + 1) and the flux per unit
        area in each for unit radiance (projected sr: E / L).
    """
    rng = np.random.default_rng(seed)
    system = lens_system(prescription, stop_radius_mm, stop_surface)
    sensor_z, _ = image_plane(prescription, object_distance_mm)
    flux = np.zeros(bins)
    infinite = math.isinf(object_distance_mm)
    if not infinite:
        object_z = paraxial(prescription).front_principal_z_mm - object_distance_mm
        object_radius = field_cosine * object_distance_mm
    points = _r2_sequence(rays, 4, rng)
    for start in range(0, rays, chunk):
        u = points[start:start + chunk]
        x, y = _disk(u[:, 0], u[:, 1], entrance_radius_mm)
        if infinite:
            kx, ky = _disk(u[:, 2], u[:, 3], field_cosine)
            kz = np.sqrt(1.0 - kx * kx - ky * ky)
            weight = np.ones_like(x)
        else:
            ox, oy = _disk(u[:, 2], u[:, 3], object_radius)
            dx, dy, dz = x - ox, y - oy, -object_z
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            kx, ky, kz = dx / length, dy / length, dz / length
            weight = dz * dz / length ** 4
        ok, (ex, ey, ez, ekx, eky, ekz) = trace_pass(system, x, y, 0.0, kx, ky, kz)
        s = (sensor_z - ez[ok]) / ekz[ok]
        r2 = (ex[ok] + s * ekx[ok]) ** 2 + (ey[ok] + s * eky[ok]) ** 2
        index = np.floor(bins * r2 / sensor_radius_mm ** 2).astype(np.int64)
        keep = index < bins
        flux += np.bincount(index[keep], weights=weight[ok][keep], minlength=bins)
    edges = sensor_radius_mm * np.sqrt(np.arange(bins + 1) / bins)
    # Monte Carlo measure of one ray: the entrance disk times the scene disk (in direction
    # cosines or on the object plane), over the number of rays.
    scene = field_cosine if infinite else object_radius
    measure = math.pi * entrance_radius_mm ** 2 * math.pi * scene ** 2 / rays
    area = math.pi * sensor_radius_mm ** 2 / bins
    return edges, flux * measure / area


def annulus_means(illumination_height_mm: FloatArray, ri: FloatArray,
                  edges_mm: FloatArray, points: int = 64) -> FloatArray:
    """
    Average a traced RI curve over annuli (area-weighted), to compare with binned flux.

    :param illumination_height_mm: the curve's heights.
    :param ri: the curve's values.
    :param edges_mm: annulus radii.
    :param points: quadrature points per annulus (midpoint rule in r^2).
    :return: the mean RI of each annulus.
    """
    out = []
    for a, b in zip(edges_mm[:-1], edges_mm[1:]):
        r2 = a * a + (np.arange(points) + 0.5) / points * (b * b - a * a)
        out.append(float(np.mean(np.interp(np.sqrt(r2), illumination_height_mm, ri))))
    return np.array(out)


# ---------------------------------------------------------------------------------------------
# Export
# ---------------------------------------------------------------------------------------------

def raw_attenuation(model: Any, illumination: Illumination | None = None) -> FloatArray:
    """
    Return the relative illumination at every raw pixel (DSO / TUM monoVO ``vignette.png``).

    :param model: the lens model.
    :param illumination: its curve (default: traced).
    :return: ``(height, width)`` float64, RI at each pixel centre's real radius (pixel pitch
        per axis, radius from the principal point ``K``).
    """
    curve = illumination or model.illumination(with_fraction=False)
    x = (np.arange(model.width) - model.K[0, 2]) * model.pixel_mm[0]
    y = (np.arange(model.height) - model.K[1, 2]) * model.pixel_mm[1]
    return curve.at(np.hypot(x[None, :], y[:, None]))


@dataclass(frozen=True)
class LensfunFit:
    """
    A lensfun ``pa`` vignetting entry: Cd = Cs (1 + k1 r^2 + k2 r^4 + k3 r^6).

    r is normalised to the half-diagonal of the image (r = 1 at the corner), as lensfun
    defines it for vignetting; ``max_error_pts`` is the largest |fit - RI| over r in
    [0, ``fit_radius``], in percentage points. ``fit_radius`` is 1 unless the light ends
    inside the image (RI < 1 / ``output.max_vignetting_gain``, or a cliff where a rim cuts
    the beam, e.g. at a fisheye's image circle), where the polynomial stops being fitted.
    """

    k1: float
    k2: float
    k3: float
    max_error_pts: float
    focal_mm: float
    f_number: float
    distance_m: float
    fit_radius: float = 1.0

    def xml(self) -> str:
        """Return the ``<vignetting model="pa" .../>`` element."""
        return (f'<vignetting model="pa" focal="{self.focal_mm:.4g}" '
                f'aperture="{self.f_number:.3g}" distance="{self.distance_m:.4g}" '
                f'k1="{self.k1:.6g}" k2="{self.k2:.6g}" k3="{self.k3:.6g}"/>')

    def comment(self) -> str:
        """Return the XML comment with the fit's largest error (max fit error N pts)."""
        text = f'max fit error {self.max_error_pts:.3g} pts'
        if self.fit_radius < 1.0:
            text += (f' (fitted to r <= {self.fit_radius:.3f}, where the light ends: '
                     'the image circle or a rim)')
        return f'<!-- {text} -->'


#: lensfun's distance for a scene at infinity (metres): its database uses 1000 for "far".
LENSFUN_INFINITY_M = 1000.0


#: Where the light ends inside the image, the lensfun fit stops where RI starts to fall
#: faster than this per unit of r (r normalised to the half-diagonal): the onset of the
#: rim's cut-off. Natural fall-off and the gradual clipping of a lens that fills its image
#: fall at most about 1 per unit r (0.6 on case1, 3.6 on the strongly clipped retrofocus
#: test lens, whose light reaches the corner and which is fitted to r = 1); a rim that ends
#: the image circle cuts the whole beam within a few percent of the half-diagonal (50 to
#: 170 per unit r on fisheye.yaml and wide_angle.yaml).
CUT_OFF_SLOPE = 2.0


def _fit_end_mm(curve: Illumination, max_gain: float, half_diagonal_mm: float) -> float:
    """
    Return the real radius up to which the lensfun polynomial is fitted (mm).

    Before RI falls below 1 / ``max_gain`` (the corrected field ends there); and, where the
    light ends inside the image (a fisheye's image circle, a rim cutting every ray), before
    the final cut-off starts: walking inwards from the last lit height, the cut-off goes on
    while RI falls faster than :data:`CUT_OFF_SLOPE` per unit r. A sixth-order polynomial in
    r follows the light up to that onset, not the cliff. The rule reads the slope, not the
    drop between two samples, so it does not depend on the curve's sampling.
    """
    heights, ri = curve.height_mm, curve.ri
    end = float(heights[-1])
    dark = np.flatnonzero(ri < 1.0 / max_gain)
    if dark.size:
        end = float(heights[max(dark[0] - 1, 0)])
    lit = np.flatnonzero(ri > 0.0)
    if lit.size and heights[lit[-1]] < curve.corner_height_mm:
        slope = (ri[:-1] - ri[1:]) / np.diff(heights) * half_diagonal_mm
        i = int(lit[-1])
        while i > 0 and slope[i - 1] > CUT_OFF_SLOPE:
            i -= 1
        end = min(end, float(heights[i]))
    return end


def lensfun_fit(model: Any, illumination: Illumination | None = None,
                samples: int = 201) -> LensfunFit:
    """
    Fit lensfun's ``pa`` vignetting polynomial to the traced RI (linear least squares).

    :param model: the lens model (focal length, f-number, scene distance, sensor).
    :param illumination: its curve (default: traced).
    :param samples: radii, uniform in r from 0 to the fit radius (:class:`LensfunFit`).
    :return: the fit.
    """
    curve = illumination or model.illumination(with_fraction=False)
    half_diagonal = model.half_diagonal_mm
    reach = min(1.0, _fit_end_mm(curve, float(model.values['output.max_vignetting_gain']),
                                 half_diagonal) / half_diagonal)
    r = np.linspace(0.0, reach, samples)
    ri = curve.at(r * half_diagonal)
    r2 = r * r
    basis = np.stack([r2, r2 * r2, r2 * r2 * r2], axis=1)
    k, *_ = np.linalg.lstsq(basis, ri - 1.0, rcond=None)
    error = float(np.max(np.abs(1.0 + basis @ k - ri))) * 100.0
    distance = scene_distance(model.values)
    summary = model.summary
    return LensfunFit(float(k[0]), float(k[1]), float(k[2]), error,
                      float(model.focal_length_mm), float(summary['f_number']),
                      LENSFUN_INFINITY_M if math.isinf(distance) else distance / 1000.0, reach)


def stop_flux(prescription: Prescription, stop_radius_mm: float, stop_surface: int | None,
              object_distance_mm: float, sensor_radius_mm: float, *, bins: int = 8,
              rays: int = 2_000_000, stop_cosine: float | None = None,
              chunk: int = 250_000, seed: int = 0) -> tuple[FloatArray, FloatArray]:
    """
    Count the flux through the stop onto the sensor, ray by ray (reference for wide fields).

    Rays are spread uniformly (a randomly shifted R_4 sequence) over the stop's vertex plane
    (the stop's clear disk; 1.25 x it on a curved stop surface, which the vertex plane meets
    elsewhere) and over the direction cosines of the medium there (|k| <= ``stop_cosine``):
    every ray carries the same etendue n^2 dA dk_x dk_y, conserved to the sensor. The count's
    noise is that of the rays that land in an annulus: a disk of directions much wider than
    the beam wastes most rays (an f/1.8 fisheye's directions at its stop stay within
    |k| < 0.22; sampled to 0.95, one ray in 40 lands and an annulus of 8 holds about 8000 of
    1.5 M, 1 % noise), so by default a pilot of 2^17 rays over |k| <= 0.999 finds the
    largest |k| that lands inside ``sensor_radius_mm`` and the count samples 1.2 x that.
    Each ray is traced forwards from the stop to the sensor plane and backwards through the
    lens in front of the stop into the scene; it counts when it clears every aperture both
    ways. Binned as :func:`forward_flux`, whose sampling over the scene wastes
    most rays on a wide-angle lens whose entrance pupil wanders across the front element.

    :param prescription: the lens.
    :param stop_radius_mm: clear radius of the stop.
    :param stop_surface: surface carrying the stop, None for the stop plane.
    :param object_distance_mm: l (only the sensor position depends on it).
    :param sensor_radius_mm: outer radius of the last annulus.
    :param bins: number of annuli of equal area.
    :param rays: number of rays.
    :param stop_cosine: the largest direction cosine at the stop (choose it generously);
        None: from a pilot count.
    :param chunk: rays per batch.
    :param seed: shift of the sequence.
    :return: ``(edges_mm, irradiance)`` as :func:`forward_flux` (E / L, projected sr).
    """
    rng = np.random.default_rng(seed)
    system = lens_system(prescription, stop_radius_mm, stop_surface)
    sensor_z, _ = image_plane(prescription, object_distance_mm)
    j = next(i for i, e in enumerate(system.elements) if e.is_stop)
    stop = system.elements[j]
    front = reversed_system(System(system.elements[:j]), stop.z_mm,
                            math.isinf(object_distance_mm))
    rear = System(system.elements[j if stop.surface is not None else j + 1:])
    n = stop.n_before
    flat = stop.surface is None or (float(stop.surface.radius_mm) == 0.0
                                    and not any(getattr(stop.surface, 'asphere', ()) or ()))
    clear = stop.clear_radius_mm if stop.clear_radius_mm > 0 else stop_radius_mm
    sample_radius = clear if flat else 1.25 * clear

    def landed(u: FloatArray, cosine: float) -> tuple[FloatArray, FloatArray]:
        """Return the sensor radius^2 and |k| at the stop of the rays that land."""
        x, y = _disk(u[:, 0], u[:, 1], sample_radius)
        kx, ky = _disk(u[:, 2], u[:, 3], cosine)
        kz = np.sqrt(1.0 - kx * kx - ky * ky)
        ok = x * x + y * y <= stop_radius_mm ** 2 if stop.surface is None else True
        back, _ = trace_pass(front, x, y, 0.0, -kx, -ky, kz)
        ahead, (ex, ey, ez, ekx, eky, ekz) = trace_pass(rear, x, y, stop.z_mm, kx, ky, kz)
        ok = ok & back & ahead
        s = (sensor_z - ez[ok]) / ekz[ok]
        return ((ex[ok] + s * ekx[ok]) ** 2 + (ey[ok] + s * eky[ok]) ** 2,
                np.hypot(kx, ky)[ok])

    if stop_cosine is None:
        r2, k = landed(_r2_sequence(1 << 17, 4, rng), 0.999)
        k = k[r2 < sensor_radius_mm ** 2]
        stop_cosine = min(0.999, 1.2 * float(k.max())) if k.size else 0.999
    flux = np.zeros(bins)
    points = _r2_sequence(rays, 4, rng)
    for start in range(0, rays, chunk):
        r2, _ = landed(points[start:start + chunk], stop_cosine)
        index = np.floor(bins * r2 / sensor_radius_mm ** 2).astype(np.int64)
        flux += np.bincount(index[index < bins], minlength=bins)
    edges = sensor_radius_mm * np.sqrt(np.arange(bins + 1) / bins)
    measure = n * n * math.pi * sample_radius ** 2 * math.pi * stop_cosine ** 2 / rays
    area = math.pi * sensor_radius_mm ** 2 / bins
    return edges, flux * measure / area
