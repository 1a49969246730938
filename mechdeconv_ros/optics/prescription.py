# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Prescriptions of rotationally symmetric lenses: surfaces, paraxial data, exact ray transfer.

Pure numpy, no ROS. The lower half of the tracer: a :class:`Prescription` of
:class:`Surface` s, its paraxial (ABCD) data and image plane, and the exact trace of given
rays surface by surface (:func:`trace_surfaces`). Finding the chief ray of a field point
(ray aiming) and tracing the whole field is :mod:`mechdeconv_ros.optics.raytrace`; the surface
geometry (sag, intersection) is :mod:`mechdeconv_ros.optics.surfaces`.

Conventions
-----------
Lengths in mm. Optical axis z, light travels +z, the first surface vertex is at z = 0 and
surface ``i + 1`` lies ``surfaces[i].thickness_mm`` behind surface ``i``. A radius is > 0
when the centre of curvature lies on the image side (+z); 0 means a flat surface. The
curvature is c = 1/r (0 for flat). ``refractive_index`` of a surface is the index of the
medium *after* it; the medium before the first surface has ``Prescription.object_index``.
Heights y are signed in the meridional (y, z) plane. Surfaces are numbered from 0 in error
messages, as the ``lens.stop_surface`` parameter is.

Exact trace (2-D, meridional plane)
-----------------------------------
A ray is a point (y, z) and a unit direction (k_y, k_z), k_z > 0. In coordinates local to a
vertex (z' = z - z_v) a surface is c (y^2 + z'^2) - 2 z' = 0. The ray meets it after the path

    s = C / (B + sqrt(B^2 - c C)),   B = k_z - c (y k_y + z' k_z),   C = c (y^2 + z'^2) - 2 z'

(the cancellation-free root on the vertex side; c = 0 gives the plane s = -z'/k_z). The
unit surface normal there is N = (-c y, 1 - c z'). Conic and aspheric surfaces are met by
Newton's method from the conic's root (:func:`surfaces.intersect`, the sphere above is its
closed-form special case). Refraction from index n to n' (vector
Snell law, mu = n/n'):

    sin_i = k x N,  cos_i = k . N,  cos_t = sqrt(1 - mu^2 sin_i^2),
    k' = mu k + (cos_t - mu cos_i) N,

which keeps n sin(i) = n' sin(t) (the tangential component) exactly. A ray fails (NaN) when
it misses a sphere (B^2 < c C), would hit its far hemisphere (1 - c z' <= 0), travels
backwards to reach a later surface (s < 0: outside the lens edge), lands outside a non-zero
semi-diameter, or is totally internally reflected (mu^2 sin_i^2 > 1).

Paraxial data
-------------
ABCD matrices on (y, n u): a transfer of length d in index n is [[1, d/n], [0, 1]], a
refraction is [[1, 0], [-phi, 1]] with the surface power phi = (n' - n) c. For the system
from the first to the last vertex, [[A, B], [C, D]], the power is Phi = -C and

    efl = 1 / Phi            (the focal length when object and image space are air)
    z_F  = -D n_0 / Phi,     z_H  = z_F + n_0 / Phi = n_0 (1 - D) / Phi
    z_F' = z_last + A n' / Phi,   z_H' = z_F' - n' / Phi

with n_0 the object-space and n' the image-space index.

Object and image
----------------
The object distance l is measured from the front principal plane H to the object, so the
object plane is z = z_H - l (l = inf allowed). The image distance v from H' follows the
Gaussian equation n'/v = Phi - n_0/l, in air 1/v = 1/f - 1/l (v = f for l = inf); a real
image needs v > 0, i.e. l > f.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import NamedTuple

from mechdeconv_ros.optics import surfaces
import numpy as np

#: |1/f| below this (1/mm) is treated as an afocal system.
AFOCAL_POWER_PER_MM = 1e-9
#: A ray that must travel backwards by more than this to reach a surface fails.
BACKWARD_TOLERANCE_MM = 1e-9

_ERRSTATE = {'invalid': 'ignore', 'divide': 'ignore', 'over': 'ignore'}


def finite_number(what: str, value: object) -> float:
    """Return ``value`` as a finite float, or raise ValueError naming ``what``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f'{what} must be a number, got {value!r}') from None
    if not math.isfinite(number):
        raise ValueError(f'{what} must be finite, got {number}')
    return number


@dataclass(frozen=True)
class Surface:
    """
    One refracting surface: spherical, flat, conic or even asphere.

    ``radius_mm`` is signed (> 0: centre of curvature on the image side, 0 = flat),
    ``thickness_mm`` the axial distance to the next surface (ignored for the last one),
    ``refractive_index`` the index after the surface (1.0 = air), ``semi_diameter_mm``
    the clear semi-aperture (0 = unlimited), ``conic`` the conic constant k and ``asphere``
    the coefficients a4, a6, ..., a16 (up to seven, mm^(1-2j)); see :mod:`surfaces` for the
    sag. The defaults (k = 0, no asphere) are the sphere. Values are checked by
    :class:`Prescription`.
    """

    radius_mm: float
    thickness_mm: float
    refractive_index: float
    semi_diameter_mm: float = 0.0
    conic: float = 0.0
    asphere: tuple[float, ...] = ()

    @property
    def curvature_per_mm(self) -> float:
        """Return the curvature c = 1/r in 1/mm (0 for a flat surface)."""
        return 0.0 if self.radius_mm == 0 else 1.0 / self.radius_mm


def _check_shape(i: int, surface: Surface, semi: float) -> None:
    """Check the conic and asphere coefficients of surface ``i`` (semi-diameter ``semi``)."""
    conic = finite_number(f'surface {i}: conic', surface.conic)
    try:
        terms = tuple(surface.asphere)
    except TypeError:
        raise ValueError(f'surface {i}: asphere must be a sequence of a4..a16') from None
    if len(terms) > surfaces.ASPHERE_TERMS:
        raise ValueError(f'surface {i}: {len(terms)} asphere coefficients, at most '
                         f'{surfaces.ASPHERE_TERMS} (a4..a16)')
    for j, a in enumerate(terms):
        finite_number(f'surface {i}: asphere a{2 * j + 4}', a)
    limit = surfaces.domain_limit_mm(surface)
    if conic != 0.0 and semi > 0 and semi > limit:
        raise ValueError(f'surface {i}: conic {conic:g} leaves the sag undefined beyond '
                         f'r = {limit:.4g} mm, inside the semi-diameter {semi:g} mm')


@dataclass(frozen=True)
class Prescription:
    """
    A rotationally symmetric lens: surfaces in order and the aperture-stop plane.

    ``stop_z_mm`` is the axial position of the stop plane (z = 0 at the first vertex); it may
    lie before the first surface, inside the glass or after the last surface. The stop only
    defines the chief ray; ``stop_semi_diameter_mm`` (0 = not given) is informational and
    never clips a chief ray, which crosses the stop at its centre. ``object_index`` is the
    index of object space.

    :raises ValueError: naming the problem, e.g. ``surface 1: refractive index 0.9 < 1``.
    """

    surfaces: tuple[Surface, ...]
    stop_z_mm: float
    object_index: float = 1.0
    stop_semi_diameter_mm: float = 0.0

    def __post_init__(self) -> None:
        """Check every number and store the surfaces as a tuple."""
        try:
            surfaces = tuple(self.surfaces)
        except TypeError:
            raise ValueError('surfaces must be a sequence of Surface') from None
        object.__setattr__(self, 'surfaces', surfaces)
        if not surfaces:
            raise ValueError('a prescription needs at least one surface')
        last = len(surfaces) - 1
        for i, surface in enumerate(surfaces):
            if not isinstance(surface, Surface):
                raise ValueError(f'surface {i}: expected a Surface, got {surface!r}')
            finite_number(f'surface {i}: radius', surface.radius_mm)
            thickness = finite_number(f'surface {i}: thickness', surface.thickness_mm)
            if i < last and thickness < 0:
                raise ValueError(f'surface {i}: thickness {thickness:g} mm < 0')
            index = finite_number(f'surface {i}: refractive index', surface.refractive_index)
            if index < 1:
                raise ValueError(f'surface {i}: refractive index {index:g} < 1')
            semi = finite_number(f'surface {i}: semi-diameter', surface.semi_diameter_mm)
            if semi < 0:
                raise ValueError(f'surface {i}: semi-diameter {semi:g} mm < 0')
            _check_shape(i, surface, semi)
        finite_number('stop position', self.stop_z_mm)
        index = finite_number('object-space refractive index', self.object_index)
        if index < 1:
            raise ValueError(f'object-space refractive index {index:g} < 1')
        semi = finite_number('stop semi-diameter', self.stop_semi_diameter_mm)
        if semi < 0:
            raise ValueError(f'stop semi-diameter {semi:g} mm < 0')

    @property
    def image_index(self) -> float:
        """Return the refractive index of image space (after the last surface)."""
        return float(self.surfaces[-1].refractive_index)

    def index_before(self, i: int) -> float:
        """Return the refractive index of the medium in front of surface ``i``."""
        return float(self.object_index if i == 0 else self.surfaces[i - 1].refractive_index)


@dataclass(frozen=True)
class Paraxial:
    """
    First-order (Gaussian) data of a prescription, positions on the z axis in mm.

    ``efl_mm`` is 1/Phi, the focal length when object and image space are air (in general
    the front focal length is n_0/Phi and the rear one n'/Phi).
    """

    efl_mm: float
    front_principal_z_mm: float
    rear_principal_z_mm: float
    front_focal_z_mm: float
    rear_focal_z_mm: float
    last_vertex_z_mm: float
    power_per_mm: float = 0.0
    object_index: float = 1.0
    image_index: float = 1.0


class Rays(NamedTuple):
    """
    A bundle of meridional rays: points (y, z) in mm and unit directions (dy, dz).

    Failed rays hold NaN.
    """

    y: np.ndarray
    z: np.ndarray
    dy: np.ndarray
    dz: np.ndarray


def vertex_z(prescription: Prescription) -> np.ndarray:
    """
    Return the z position of each surface vertex.

    :param prescription: the lens.
    :return: array of shape (number of surfaces,), mm; the first is 0.
    """
    thicknesses = [s.thickness_mm for s in prescription.surfaces[:-1]]
    return np.concatenate(([0.0], np.cumsum(thicknesses, dtype=float)))


def surfaces_before(prescription: Prescription, z_mm: float) -> int:
    """
    Return how many surfaces have their vertex at or before the plane z.

    :param prescription: the lens.
    :param z_mm: the plane.
    :return: the count.
    """
    return int(np.searchsorted(vertex_z(prescription), z_mm, side='right'))


def paraxial_matrix(prescription: Prescription, count: int, z_start: float,
                    z_end: float) -> tuple[float, float, float, float]:
    """
    Return the (y, n u) matrix from plane z_start to plane z_end.

    z_start lies in object space, z_end in the medium after the first ``count`` surfaces,
    which are all refracted in between.

    :param prescription: the lens.
    :param count: how many surfaces (from the first) refract between the planes.
    :param z_start: the start plane, in object space.
    :param z_end: the end plane.
    :return: ``(A, B, C, D)``.
    """
    a, b, c, d = 1.0, 0.0, 0.0, 1.0
    z = z_start
    index = prescription.object_index
    for i, z_vertex in enumerate(vertex_z(prescription)[:count]):
        reduced = (z_vertex - z) / index
        a, b = a + reduced * c, b + reduced * d
        surface = prescription.surfaces[i]
        power = (surface.refractive_index - index) * surface.curvature_per_mm
        c, d = c - power * a, d - power * b
        z = float(z_vertex)
        index = surface.refractive_index
    reduced = (z_end - z) / index
    return a + reduced * c, b + reduced * d, c, d


def paraxial(prescription: Prescription) -> Paraxial:
    """
    Return the first-order (Gaussian) data of a prescription.

    :param prescription: the lens.
    :return: focal length, principal and focal planes (module docstring for the formulas).
    :raises ValueError: when the system is afocal (|1/f| < 1e-9 /mm).
    """
    z_last = float(vertex_z(prescription)[-1])
    # Absurd curvatures can overflow to inf * 0 = NaN; that reads as "afocal" below.
    with np.errstate(all='ignore'):
        a, _, c, d = paraxial_matrix(prescription, len(prescription.surfaces), 0.0, z_last)
    a, c, d = float(a), float(c), float(d)
    power = -c
    if not abs(power) >= AFOCAL_POWER_PER_MM:
        raise ValueError(f'the lens is afocal (power {power:.3g} /mm ~ 0): it has no focal '
                         'length')
    n_object = float(prescription.object_index)
    n_image = prescription.image_index
    front_focal = -d * n_object / power
    rear_focal = z_last + a * n_image / power
    return Paraxial(efl_mm=1.0 / power,
                    front_principal_z_mm=front_focal + n_object / power,
                    rear_principal_z_mm=rear_focal - n_image / power,
                    front_focal_z_mm=front_focal,
                    rear_focal_z_mm=rear_focal,
                    last_vertex_z_mm=z_last,
                    power_per_mm=power,
                    object_index=n_object,
                    image_index=n_image)


def check_distance(object_distance_mm: float) -> float:
    """
    Return a scene distance as a float, or raise ValueError when it is none.

    :param object_distance_mm: l from H, > 0 (``math.inf`` allowed).
    :return: l.
    :raises ValueError: for a non-number, NaN or l <= 0.
    """
    try:
        distance = float(object_distance_mm)
    except (TypeError, ValueError):
        raise ValueError(f'scene distance must be a number, got {object_distance_mm!r}') \
            from None
    if math.isnan(distance) or distance <= 0:
        raise ValueError(f'scene distance {distance:g} mm must be > 0 (inf for infinity)')
    return distance


def image_plane(prescription: Prescription, object_distance_mm: float) -> tuple[float, float]:
    """
    Return the paraxial image plane of the object plane at distance l from H.

    :param prescription: the lens.
    :param object_distance_mm: l > 0 from the front principal plane to the object (the
        object plane is at z = z_H - l); ``math.inf`` for infinity.
    :return: (sensor_z_mm, image_distance_mm), the image plane z and v measured from H'
        (Gaussian n'/v = 1/f - n_0/l in reduced form; in air 1/v = 1/f - 1/l).
    :raises ValueError: when the lens forms no real image (l <= f, or a diverging lens).
    """
    distance = check_distance(object_distance_mm)
    par = paraxial(prescription)
    focal = par.object_index * par.efl_mm
    if par.power_per_mm < 0:
        raise ValueError(f'the lens is diverging (focal length {par.efl_mm:.4g} mm): it '
                         'forms no real image')
    if distance <= focal:
        raise ValueError(f'scene distance {distance:g} mm is inside the focal length '
                         f'{focal:.4g} mm: the lens forms no real image')
    image_distance = par.image_index / (par.power_per_mm - par.object_index / distance)
    if not (math.isfinite(image_distance) and image_distance > 0):
        raise ValueError(f'scene distance {distance:g} mm is too close to the focal length '
                         f'{focal:.4g} mm: the image is at infinity')
    return par.rear_principal_z_mm + image_distance, image_distance


def _nan_where(bad: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    return tuple(np.where(bad, np.nan, a) for a in arrays)


def trace_surfaces(prescription: Prescription, rays: Rays, first: int = 0,
                   stop: int | None = None) -> Rays:
    """
    Trace rays exactly through surfaces ``first`` to ``stop - 1`` of a prescription.

    The rays must be in the medium in front of surface ``first``. Surface ``first`` may be
    reached by propagating backwards along the ray (a line in a homogeneous medium); any
    later surface only forwards (beyond 1e-9 mm), otherwise the ray left the lens body.

    :param prescription: the lens.
    :param rays: starting points and unit directions (dz > 0).
    :param first: index of the first surface to trace.
    :param stop: one past the last surface to trace (None: all).
    :return: the rays at the last surface, after its refraction (NaN for failed rays).
    """
    count = len(prescription.surfaces) if stop is None else stop
    y, z, dy, dz = (np.asarray(a, dtype=float) for a in rays)
    z_vertices = vertex_z(prescription)
    with np.errstate(**_ERRSTATE):
        for i in range(first, count):
            surface = prescription.surfaces[i]
            z_local = z - z_vertices[i]
            s, _, normal_y, normal_z, bad = surfaces.intersect(
                surface, 0.0, y, z_local, 0.0, dy, dz)
            y = y + s * dy
            z_local = z_local + s * dz
            if i > first:
                bad |= s < -BACKWARD_TOLERANCE_MM
            if surface.semi_diameter_mm > 0:
                bad |= ~(np.abs(y) <= surface.semi_diameter_mm)
            _, dy, dz = surfaces.refract(0.0, dy, dz, 0.0, normal_y, normal_z,
                                         prescription.index_before(i), surface.refractive_index)
            bad |= ~(dz > 0)
            y, z, dy, dz = _nan_where(bad, y, z_local + z_vertices[i], dy, dz)
    return Rays(y, z, dy, dz)


def transfer_to_plane(rays: Rays, z_mm: float) -> Rays:
    """
    Move rays along their straight lines to the plane z = z_mm.

    :param rays: rays in a homogeneous medium.
    :param z_mm: the plane.
    :return: the rays at the plane (NaN where dz <= 0 or already NaN).
    """
    with np.errstate(**_ERRSTATE):
        dz = np.where(rays.dz > 0, rays.dz, np.nan)
        y = rays.y + (z_mm - rays.z) * (rays.dy / dz)
        return Rays(y, np.where(np.isnan(y), np.nan, float(z_mm)), rays.dy, dz)
