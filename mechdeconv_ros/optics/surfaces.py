# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Ray-surface geometry of rotationally symmetric surfaces: sphere, conic and even asphere.

Pure numpy, no ROS. :mod:`mechdeconv_ros.optics.raytrace` calls :func:`intersect` and
:func:`refract` for every surface of a prescription (its meridional trace passes x = k_x = 0).

Conventions
-----------
Lengths in mm, coordinates local to the surface vertex (z' = z - z_vertex), light travels +z.
A surface has the curvature c = 1/radius (0 = flat; radius > 0 when the centre of curvature
lies on the image side), the conic constant k (0 sphere, -1 paraboloid, < -1 hyperboloid,
-1 < k < 0 prolate and k > 0 oblate ellipsoid) and the even asphere coefficients
a4, a6, ..., a16 (mm^-3 ... mm^-15). Its sag at the radius r (r^2 = x^2 + y^2) is

    z(r) = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2)) + a4 r^4 + a6 r^6 + ... + a16 r^16,

defined where 1 - (1 + k) c^2 r^2 >= 0 (its domain). Written with u = r^2,
dz/du = c / (2 sqrt(1 - (1 + k) c^2 u)) + 2 a4 u + 3 a6 u^2 + ... + 8 a16 u^7, and the unit
normal, oriented into the medium after the surface (n_z > 0), is

    N = (-2 x dz/du, -2 y dz/du, 1) / sqrt(1 + 4 u (dz/du)^2).

Intersection
------------
The conic part is the quadric F = c (x^2 + y^2) + c (1 + k) z^2 - 2 z = 0. A ray p + s k meets
it where c A s^2 - 2 B s + C = 0 with

    A = k_x^2 + k_y^2 + (1 + k) k_z^2,  B = k_z - c (x k_x + y k_y + (1 + k) z k_z),
    C = c (x^2 + y^2 + (1 + k) z^2) - 2 z,

at s = C / (B + sqrt(B^2 - c A C)): the cancellation-free root on the vertex side of the
quadric (c = 0 gives the plane s = -z/k_z). A sphere (k = 0, no asphere terms) ends there and
its normal is (-c x, -c y, 1 - c z), of unit length on the surface; the branch holds when
1 - c z > 0. With asphere terms, Newton's method on g(s) = z(s) - sag(r^2(s)) starts from that
root (or from the vertex plane when the quadric is missed) and stops after the step that
brings the error below 1e-12 mm (quadratic convergence: a step under 1e-8 mm, see
NEWTON_FINAL_STEP_MM); a ray that does not converge in MAX_NEWTON_ITERATIONS fails, and a
ray whose point is off the sag by more than 1e-9 mm is flagged bad.

A ray fails (``bad``) when it misses the surface, lands outside the sag's domain or on the far
branch of the quadric, or does not converge. Semi-diameters, backward travel and total
internal reflection are the caller's (:mod:`raytrace`) and :func:`refract`'s to check.

Refraction from index n to n' (vector Snell law, mu = n/n', cos_i = k . N):

    sin^2 i = |k x N|^2,  cos_t = sqrt(1 - mu^2 sin^2 i),  k' = mu k + (cos_t - mu cos_i) N,

NaN where the ray is totally internally reflected (mu^2 sin^2 i > 1) or meets the surface
from behind (cos_i <= 0).
"""

from __future__ import annotations

import functools
from typing import Protocol, Union

import numpy as np

#: Newton on an asphere stops when |step| <= this (mm).
INTERSECT_TOLERANCE_MM = 1e-12
#: Newton converges quadratically: after a step of d the error is about K d^2, with K the
#: ratio of the sag's second to first derivative along the ray (below 1e4 /mm for any lens
#: surface), so a step of 1e-8 mm leaves an error below 1e-12 mm and is the last one taken.
NEWTON_FINAL_STEP_MM = 1e-8
#: Newton iterations before a ray that has not converged fails.
MAX_NEWTON_ITERATIONS = 30
#: Number of even asphere coefficients: a4, a6, ..., a16.
ASPHERE_TERMS = 7

_ERRSTATE = {'invalid': 'ignore', 'divide': 'ignore', 'over': 'ignore'}

ArrayLike = Union[np.ndarray, float]


class SurfaceShape(Protocol):
    """What :func:`sag` and :func:`intersect` read from a surface (raytrace.Surface)."""

    @property
    def curvature_per_mm(self) -> float:  # noqa: D102 - a protocol member
        ...

    @property
    def conic(self) -> float:  # noqa: D102 - a protocol member
        ...

    @property
    def asphere(self) -> tuple[float, ...]:  # noqa: D102 - a protocol member
        ...


def is_spherical(surface: SurfaceShape) -> bool:
    """Return True for a sphere or plane (k = 0 and every asphere coefficient 0)."""
    return surface.conic == 0.0 and not any(surface.asphere)


def _poly(surface: SurfaceShape) -> tuple[float, ...]:
    """Return a4..a16 without trailing zeros (so an all-zero asphere costs nothing)."""
    return _trimmed(tuple(surface.asphere))


@functools.lru_cache(maxsize=256)
def _trimmed(coefficients: tuple[float, ...]) -> tuple[float, ...]:
    out = [float(a) for a in coefficients]
    while out and out[-1] == 0.0:
        out.pop()
    return tuple(out)


def sag(surface: SurfaceShape, r2: ArrayLike) -> np.ndarray:
    """
    Return the sag z(r) of a surface.

    :param surface: the surface (curvature, conic, asphere).
    :param r2: r^2 = x^2 + y^2 in mm^2, any shape.
    :return: z in mm, vertex-local; NaN outside the sag's domain.
    """
    return _sag_and_slope(surface, np.asarray(r2, dtype=float))[0]


def sag_slope(surface: SurfaceShape, r2: ArrayLike) -> np.ndarray:
    """
    Return dz/d(r^2) of a surface's sag.

    :param surface: the surface.
    :param r2: r^2 in mm^2.
    :return: dz/du (1/mm); NaN outside the domain.
    """
    return _sag_and_slope(surface, np.asarray(r2, dtype=float))[1]


def _sag_and_slope(surface: SurfaceShape, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    with np.errstate(**_ERRSTATE):
        return _sag_and_slope_quiet(surface, u)


def sag_at_height(surface: SurfaceShape, height_mm: float) -> float:
    """
    Return the sag at a height, continued beyond the rim by a flat bevel (scalar).

    Beyond its rim (:func:`domain_limit_mm`) a surface is continued by a flat bevel, so the
    sag stays at its rim value there; at the rim itself the square root of the sag is clamped
    at 0 where :func:`sag` would round to NaN. What the refusals and the sensor plane need
    (edge thicknesses, the last surface's bulge).

    :param surface: the surface (curvature, conic, asphere).
    :param height_mm: the height a (its sign is ignored), mm.
    :return: z in mm, vertex-local.
    """
    a = min(abs(height_mm), domain_limit_mm(surface))
    with np.errstate(**_ERRSTATE):
        return float(_sag_and_slope_quiet(surface, np.asarray(a * a, dtype=float), rim=True)[0])


def _sag_and_slope_quiet(surface: SurfaceShape, u: np.ndarray,
                         rim: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the sag and dz/du; the caller holds ``np.errstate(**_ERRSTATE)``.

    ``rim``: clamp the square root's argument at 0 (a height at the rim, rounded past it).
    """
    c = surface.curvature_per_mm
    q = 1.0 + surface.conic
    # NaN outside the domain; an array even for 0-d input (np.divide writes into it).
    argument = 1.0 - (q * c * c) * u
    root = np.asarray(np.sqrt(np.maximum(argument, 0.0) if rim else argument))
    z = c * u / (1.0 + root)
    dz = np.divide(0.5 * c, root, out=root)
    poly = _poly(surface)
    if poly:
        # Horner in u: P = sum_j a_j u^j and Q = sum_j (j + 2) a_j u^j, so that the
        # asphere terms are P u^2 and their derivative Q u (in place: no temporaries).
        last = len(poly) - 1
        value = np.full(u.shape, poly[last])
        slope = np.full(u.shape, (last + 2) * poly[last])
        for j in range(last - 1, -1, -1):
            value *= u
            value += poly[j]
            slope *= u
            slope += (j + 2) * poly[j]
        value *= u
        value *= u
        z += value
        slope *= u
        dz += slope
    return z, dz


def domain_limit_mm(surface: SurfaceShape) -> float:
    """
    Return the largest radius at which the sag is defined (inf when it is everywhere).

    :param surface: the surface.
    :return: 1 / (|c| sqrt(1 + k)) for 1 + k > 0 and c != 0, else inf.
    """
    c = surface.curvature_per_mm
    q = 1.0 + surface.conic
    if c == 0.0 or q <= 0.0:
        return float('inf')
    return 1.0 / (abs(c) * np.sqrt(q))


def intersect(surface: SurfaceShape, x: ArrayLike, y: ArrayLike, z_local: ArrayLike,
              kx: ArrayLike, ky: ArrayLike, kz: ArrayLike
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """
    Intersect rays with a surface exactly.

    Pass ``x = kx = 0.0`` (scalars) for meridional rays: the trace then runs in 2-D.

    :param surface: the surface (curvature, conic, asphere).
    :param x: ray point x, mm (vertex-local).
    :param y: ray point y, mm.
    :param z_local: ray point z - z_vertex, mm.
    :param kx: unit direction x component.
    :param ky: unit direction y component.
    :param kz: unit direction z component.
    :return: ``(s, nx, ny, nz, bad)``: the signed path length from the point to the surface,
        the unit normal there (n_z > 0; n_x is the scalar 0.0 for meridional rays) and a bool
        array of failed rays (their values are NaN or meaningless).
    """
    if not is_spherical(surface) and np.broadcast(x, y, z_local, kx, ky, kz).shape == ():
        # One ray given as scalars: Newton updates arrays in place, so trace it as an array.
        out = intersect(surface, *(np.reshape(np.asarray(v, dtype=float), 1)
                                   for v in (x, y, z_local, kx, ky, kz)))
        return tuple(np.reshape(v, ()) for v in out)    # type: ignore[return-value]
    meridional = np.isscalar(x) and np.isscalar(kx) and x == 0.0 and kx == 0.0
    y = np.asarray(y, dtype=float)
    z = np.asarray(z_local, dtype=float)
    ky = np.asarray(ky, dtype=float)
    kz = np.asarray(kz, dtype=float)
    c = surface.curvature_per_mm
    q = 1.0 + surface.conic
    with np.errstate(**_ERRSTATE):
        if meridional:
            b = kz - c * (y * ky + q * z * kz) if q != 1.0 else kz - c * (y * ky + z * kz)
            cc = (c * (y * y + q * z * z) if q != 1.0 else c * (y * y + z * z)) - 2.0 * z
            a = ky * ky + q * kz * kz
        else:
            x = np.asarray(x, dtype=float)
            kx = np.asarray(kx, dtype=float)
            b = kz - c * (x * kx + y * ky + q * z * kz)
            cc = c * (x * x + y * y + q * z * z) - 2.0 * z
            a = kx * kx + ky * ky + q * kz * kz
        if q == 1.0:
            s = cc / (b + np.sqrt(b * b - c * cc))   # unit k: A = 1 (NaN on a miss)
        else:
            s = cc / (b + np.sqrt(b * b - c * a * cc))
        if is_spherical(surface):
            py = y + s * ky
            pz = z + s * kz
            ny = -c * py
            nz = 1.0 - c * pz
            nx = 0.0 if meridional else -c * (x + s * kx)
            bad = ~(nz > 0) | ~np.isfinite(s)
            return s, nx, ny, nz, bad
        # The quadric's vertex-side branch (its sag is the conic part), else start on the plane.
        branch = 1.0 - c * q * (z + s * kz)
        start = np.where(np.isfinite(s) & (branch > 0), s, -z / kz)
        s, u, height, slope = _newton(surface, x, y, z, kx, ky, kz, start, meridional)
        py = y + s * ky
        pz = z + s * kz
        px = 0.0 if meridional else x + s * kx
        # The normal where Newton made its last (< 1e-12 mm) step: the same to ~1e-12.
        norm = np.sqrt(1.0 + 4.0 * u * slope * slope)
        nx = 0.0 if meridional else -2.0 * px * slope / norm
        ny = -2.0 * py * slope / norm
        nz = 1.0 / norm
        bad = (~np.isfinite(s) | ~np.isfinite(nz)
               | ~(np.abs(pz - height) <= 1e3 * INTERSECT_TOLERANCE_MM * (1.0 + np.abs(pz))))
        return s, nx, ny, nz, bad


def _newton(surface: SurfaceShape, x: ArrayLike, y: np.ndarray, z: np.ndarray, kx: ArrayLike,
            ky: np.ndarray, kz: np.ndarray, s: np.ndarray, meridional: bool
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """
    Solve z + s k_z = sag(r^2(s)) by Newton from ``s``.

    :return: s (NaN where it does not converge), and r^2, the sag and dz/du where the last
        step was computed (within INTERSECT_TOLERANCE_MM of s).
    """
    s = np.array(s, dtype=float)
    u = height = slope = s
    converged = False
    for _ in range(MAX_NEWTON_ITERATIONS):
        py = y + s * ky
        if meridional:
            u = py * py
            du = py * ky
        else:
            px = x + s * kx
            u = px * px + py * py
            du = px * kx + py * ky
        du *= 2.0
        height, slope = _sag_and_slope_quiet(surface, u)     # inside intersect's errstate
        du *= slope
        np.subtract(kz, du, out=du)
        step = z + s * kz
        step -= height
        step /= du
        s -= step
        # Rays that converged stay at their root (their steps are ~0); NaN rays stay NaN.
        np.abs(step, out=step)
        # Any step above the tolerance (NaN compares False: as np.nanmax, without its copy).
        if not np.greater(step, NEWTON_FINAL_STEP_MM).any():
            converged = True
            break
    if not converged:
        # Out of iterations: keep the rays whose last step met the tolerance.
        s = np.where(step <= NEWTON_FINAL_STEP_MM, s, np.nan)
    return s, u, height, slope


def refract(kx: ArrayLike, ky: ArrayLike, kz: ArrayLike, nx: ArrayLike, ny: ArrayLike,
            nz: ArrayLike, n_before: float, n_after: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Refract unit directions at unit normals (vector Snell law, 3-D).

    :param kx: direction x components (0.0 for meridional rays).
    :param ky: direction y components.
    :param kz: direction z components.
    :param nx: normal x components (0.0 for meridional rays).
    :param ny: normal y components.
    :param nz: normal z components (> 0: into the medium after the surface).
    :param n_before: refractive index before the surface.
    :param n_after: refractive index after the surface.
    :return: refracted ``(kx, ky, kz)`` (kx the scalar 0.0 when ``kx`` and ``nx`` are the
        scalar 0.0); NaN where the ray is totally internally reflected or
        meets the surface from behind (k . N <= 0).
    """
    with np.errstate(**_ERRSTATE):
        mu = n_before / n_after
        if np.isscalar(kx) and np.isscalar(nx) and kx == 0.0 and nx == 0.0:
            # Meridional: the same operations as the 2-D trace, k x N = k_y n_z - k_z n_y.
            sin_i = ky * nz - kz * ny
            cos_i = ky * ny + kz * nz
            cos_t = np.sqrt(1.0 - mu * mu * sin_i * sin_i)
            cos_t = np.where(cos_i > 0, cos_t, np.nan)
            g = cos_t - mu * cos_i
            return 0.0, mu * ky + g * ny, mu * kz + g * nz
        cx = ky * nz - kz * ny
        cy = kz * nx - kx * nz
        cz = kx * ny - ky * nx
        cos_i = kx * nx + ky * ny + kz * nz
        cos_t = np.sqrt(1.0 - mu * mu * (cx * cx + cy * cy + cz * cz))   # NaN on TIR
        cos_t = np.where(cos_i > 0, cos_t, np.nan)
        g = cos_t - mu * cos_i
        return mu * kx + g * nx, mu * ky + g * ny, mu * kz + g * nz
