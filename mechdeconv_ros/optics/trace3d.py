# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Exact 3-D (skew) ray tracing through a rotationally symmetric lens, with every aperture.

Pure numpy, no ROS. The meridional trace of :mod:`mechdeconv_ros.optics.raytrace` finds chief rays;
the irradiance of a sensor point needs whole beams, skew rays included, and every aperture
that clips them: the aperture stop, each surface's clear semi-diameter and the lens edges.

Conventions as in :mod:`mechdeconv_ros.optics.raytrace`: mm, optical axis z, light travels +z,
first vertex at z = 0, radius > 0 when the centre of curvature lies on the image side. A ray is a
point (x, y, z) and a unit direction (k_x, k_y, k_z) with k_z > 0.

Surfaces
--------
Spheres, conics and even aspheres: the exact intersection and the vector Snell law of
:mod:`mechdeconv_ros.optics.surfaces` (``intersect`` / ``refract``), in vertex-local coordinates.

Apertures
---------
A ray fails when it misses a surface or meets its far hemisphere (outside the sag's domain),
must travel backwards by more than 1e-9 mm to reach a later surface (it left the lens body
through its edge, e.g. where the two faces of a biconvex lens meet), lands outside a non-zero
semi-diameter, is totally internally reflected, or crosses the aperture stop outside its
clear radius. The stop is either a plane z = z_s (thick-lens mode: an iris anywhere, also
inside the glass) or one surface of the prescription (clipped where the ray meets it).

Backward tracing
----------------
:func:`reversed_system` mirrors a lens about a plane z = z_0 (z' = z_0 - z): the surfaces in
reverse order, each radius negated (a sag z(r) becomes -z(r)), the index after a mirrored
surface is the index before the original one. A ray traced backwards from a sensor point at
z_0 is then an ordinary forward ray of the mirrored system starting at z' = 0.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

from mechdeconv_ros.optics.prescription import Prescription, Surface, vertex_z
from mechdeconv_ros.optics.surfaces import intersect, refract
import numpy as np

#: A ray that must travel backwards by more than this to reach a later surface fails.
BACKWARD_TOLERANCE_MM = 1e-9

#: The margin of a ray that fails other than at an aperture rim (:func:`trace_margin`).
FAILED = -2.0

_ERRSTATE = {'invalid': 'ignore', 'divide': 'ignore', 'over': 'ignore'}


class Element(NamedTuple):
    """
    One step of a system: a refracting surface or the stop plane.

    ``surface`` is None for a stop plane (no refraction). ``clear_radius_mm`` clips (0 = no
    limit); for the stop surface it is the smaller of its semi-diameter and the stop radius.
    """

    z_mm: float
    surface: Surface | None
    n_before: float
    n_after: float
    clear_radius_mm: float
    is_stop: bool


@dataclass(frozen=True)
class System:
    """
    An ordered list of elements, traced forwards (+z).

    ``free_exit``: a ray leaving the last surface may travel in any direction (k_z <= 0
    too): the backward trace into a scene at infinity, which a fisheye sees past 90 deg.
    Otherwise every ray must keep k_z > 0 (it must reach the next plane: the sensor, or an
    object plane at a finite distance).
    """

    elements: tuple[Element, ...]
    free_exit: bool = False

    def without_semi_diameters(self) -> System:
        """Return the system whose only clipping aperture is the stop (edges still clip)."""
        return System(tuple(e._replace(clear_radius_mm=e.clear_radius_mm if e.is_stop else 0.0)
                            for e in self.elements), self.free_exit)


def lens_system(prescription: Prescription, stop_radius_mm: float,
                stop_surface: int | None = None) -> System:
    """
    Describe a lens with its apertures, in its own frame.

    :param prescription: the lens.
    :param stop_radius_mm: the clear radius of the aperture stop (0 = no stop clipping).
    :param stop_surface: the surface that carries the stop (prescription mode), or None for a
        stop plane at ``prescription.stop_z_mm`` (thick-lens mode).
    :return: the system.
    """
    z_v = vertex_z(prescription)
    elements: list[Element] = []
    for i, surface in enumerate(prescription.surfaces):
        radius = float(surface.semi_diameter_mm)
        is_stop = stop_surface == i
        if is_stop and stop_radius_mm > 0:
            radius = min(radius, stop_radius_mm) if radius > 0 else stop_radius_mm
        elements.append(Element(float(z_v[i]), surface, prescription.index_before(i),
                                float(surface.refractive_index), radius, is_stop))
    if stop_surface is None:
        z_s = float(prescription.stop_z_mm)
        count = int(np.searchsorted(z_v, z_s, side='right'))
        index = prescription.index_before(count)
        elements.insert(count, Element(z_s, None, index, index, float(stop_radius_mm), True))
    return System(tuple(elements))


def _mirror(surface: Surface) -> Surface:
    """Return the surface seen from behind: every sag coefficient negated."""
    return dataclasses.replace(surface, radius_mm=-float(surface.radius_mm),
                               asphere=tuple(-float(a) for a in surface.asphere))


def reversed_system(system: System, z0_mm: float, free_exit: bool = False) -> System:
    """
    Mirror a system about the plane z = z0 (module docstring), for backward tracing.

    :param system: the lens.
    :param z0_mm: the mirror plane, usually the sensor plane (then z' = 0 is the sensor).
    :param free_exit: rays may leave the (mirrored) last surface in any direction (a scene
        at infinity behind it).
    :return: the mirrored system, elements in reverse order.
    """
    out = []
    for e in reversed(system.elements):
        surface = None if e.surface is None else _mirror(e.surface)
        out.append(Element(float(z0_mm) - e.z_mm, surface, e.n_after, e.n_before,
                           e.clear_radius_mm, e.is_stop))
    return System(tuple(out), free_exit)


def trace_pass(system: System, x: np.ndarray, y: np.ndarray, z: np.ndarray,
               kx: np.ndarray, ky: np.ndarray, kz: np.ndarray
               ) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """
    Trace rays through every element and tell which pass.

    :param system: the elements in the order the rays meet them.
    :param x: starting points, mm, in front of the first element (any shape, broadcast).
    :param y: see ``x``.
    :param z: see ``x``.
    :param kx: unit directions, ``kz > 0``.
    :param ky: see ``kx``.
    :param kz: see ``kx``.
    :return: ``(passed, (x, y, z, kx, ky, kz))``: a boolean mask and the rays after the last
        element (meaningless where not passed).
    """
    margin, rays = _trace(system, x, y, z, kx, ky, kz)
    return margin >= 0.0, rays


def trace_margin(system: System, x: np.ndarray, y: np.ndarray, z: np.ndarray,
                 kx: np.ndarray, ky: np.ndarray, kz: np.ndarray) -> np.ndarray:
    """
    Trace rays and return how far inside the clear apertures they pass.

    The margin is min over the clipping apertures of (R - r) / R, r the ray's radius where it
    meets an aperture of clear radius R (1 without any), clamped at -1, and :data:`FAILED`
    (-2) for a ray that fails in any other way (miss, lens edge, TIR) while inside every
    aperture so far (a ray clipped before it fails keeps its negative margin). A ray passes
    when its margin is >= 0; across an aperture rim the margin is continuous, which lets a
    root finder locate the rim in a few steps.

    :param system: the elements in the order the rays meet them.
    :return: the margins (the broadcast shape of the inputs).
    """
    return _trace(system, x, y, z, kx, ky, kz)[0]


def trace_passes(system: System, x: np.ndarray, y: np.ndarray, z: np.ndarray,
                 kx: np.ndarray, ky: np.ndarray, kz: np.ndarray) -> np.ndarray:
    """
    Return which rays pass, exactly ``trace_margin(...) >= 0``, dropping failed rays early.

    A ray's margin never rises and a failure is never undone, so a ray that is outside an
    aperture or failed after some element fails at the end: only the others go on to the next
    element. Much faster than :func:`trace_margin` where most rays fail at the first elements
    (the fine scans of :func:`mechdeconv_ros.optics.illumination.beam_area` beyond a fisheye's
    image circle), where the margins themselves are not needed.

    :param system: the elements in the order the rays meet them.
    :return: the pass mask (the broadcast shape of the inputs).
    """
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (x, y, z, kx, ky, kz)))
    shape = arrays[0].shape
    rays = tuple(a.ravel() for a in arrays)
    alive = np.arange(rays[0].size)
    bad = ~(rays[5] > 0)
    margin = np.ones(alive.size)
    first = True
    last = max((i for i, e in enumerate(system.elements) if e.surface is not None), default=-1)
    with np.errstate(**_ERRSTATE):
        for i, element in enumerate(system.elements):
            rays = _advance(system, i, first and element.surface is not None, last, rays,
                            margin, bad)
            first = first and element.surface is None
            keep = ~bad & (margin >= 0.0)
            if not keep.all():
                alive, margin, bad = alive[keep], margin[keep], bad[keep]
                rays = tuple(a[keep] for a in rays)
    passed = np.zeros(arrays[0].size, dtype=bool)
    passed[alive] = True
    return passed.reshape(shape)


def _trace(system: System, x: np.ndarray, y: np.ndarray, z: np.ndarray,
           kx: np.ndarray, ky: np.ndarray, kz: np.ndarray
           ) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """Return the margins (:func:`trace_margin`) and the rays after the last element."""
    x, y, z, kx, ky, kz = np.broadcast_arrays(*(np.asarray(a, dtype=float)
                                                for a in (x, y, z, kx, ky, kz)))
    bad = ~(kz > 0)
    margin = np.ones(bad.shape)
    first = True
    last = max((i for i, e in enumerate(system.elements) if e.surface is not None), default=-1)
    with np.errstate(**_ERRSTATE):
        # The element step of _advance, inline: calling it here measured 8-20 % slower on the
        # aiming's many small traces (a change to one must be made to both).
        for i, e in enumerate(system.elements):
            z_local = z - e.z_mm
            if e.surface is None:
                # A stop plane: where the ray's line crosses it, without moving the ray (an
                # iris close to a curved face may be crossed before or after it).
                s = -z_local / kz
                bad |= ~np.isfinite(s)
                if e.clear_radius_mm > 0:
                    r = np.hypot(x + s * kx, y + s * ky)
                    np.fmin(margin, 1.0 - r / e.clear_radius_mm, out=margin)
                continue
            s, nx, ny, nz, failed = intersect(e.surface, x, y, z_local, kx, ky, kz)
            bad |= failed
            if not first:
                bad |= s < -BACKWARD_TOLERANCE_MM
            first = False
            x = x + s * kx
            y = y + s * ky
            z = z + s * kz
            if e.clear_radius_mm > 0:
                np.fmin(margin, 1.0 - np.hypot(x, y) / e.clear_radius_mm, out=margin)
            if e.n_before != e.n_after:
                kx, ky, kz = refract(kx, ky, kz, nx, ny, nz, e.n_before, e.n_after)
                bad |= ~np.isfinite(kz) if (system.free_exit and i == last) else ~(kz > 0)
    np.maximum(margin, -1.0, out=margin)
    # A ray that an aperture had clipped before it failed otherwise keeps that (continuous)
    # margin; only a ray whose hard failure is the limit gets FAILED.
    margin[np.isnan(margin) | (bad & (margin >= 0.0))] = FAILED
    return margin, (x, y, z, kx, ky, kz)


def _advance(system: System, i: int, first: bool, last: int, rays: tuple[np.ndarray, ...],
             margin: np.ndarray, bad: np.ndarray) -> tuple[np.ndarray, ...]:
    """
    Move the rays through element ``i``; update ``margin`` and ``bad`` in place.

    The caller holds ``np.errstate(**_ERRSTATE)``. ``first``: the first surface met (a ray
    starts in front of it, so it may not be behind the ray); ``last``: the index of the last
    element with a surface.

    :return: the rays after the element.
    """
    e = system.elements[i]
    x, y, z, kx, ky, kz = rays
    z_local = z - e.z_mm
    if e.surface is None:
        # A stop plane: where the ray's line crosses it, without moving the ray (an
        # iris close to a curved face may be crossed before or after it).
        s = -z_local / kz
        bad |= ~np.isfinite(s)
        if e.clear_radius_mm > 0:
            r = np.hypot(x + s * kx, y + s * ky)
            np.fmin(margin, 1.0 - r / e.clear_radius_mm, out=margin)
        return rays
    s, nx, ny, nz, failed = intersect(e.surface, x, y, z_local, kx, ky, kz)
    bad |= failed
    if not first:
        bad |= s < -BACKWARD_TOLERANCE_MM
    x = x + s * kx
    y = y + s * ky
    z = z + s * kz
    if e.clear_radius_mm > 0:
        np.fmin(margin, 1.0 - np.hypot(x, y) / e.clear_radius_mm, out=margin)
    if e.n_before != e.n_after:
        kx, ky, kz = refract(kx, ky, kz, nx, ny, nz, e.n_before, e.n_after)
        bad |= ~np.isfinite(kz) if (system.free_exit and i == last) else ~(kz > 0)
    return x, y, z, kx, ky, kz


def direction_from_cosines(kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
    """Return k_z = sqrt(1 - k_x^2 - k_y^2) (NaN outside the unit disk)."""
    with np.errstate(**_ERRSTATE):
        return np.sqrt(1.0 - kx * kx - ky * ky)
