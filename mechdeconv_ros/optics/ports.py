# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Underwater ports: a flat or dome window in front of a lens, the scene in water.

Pure numpy, no ROS. Frames and signs as :mod:`mechdeconv_ros.optics.prescription`: mm, the
lens's first vertex at z = 0, light travelling +z, x and y the camera's optical frame (REP-103:
x right, y down; an image pixel further right / down sees a scene point at larger x / y).

Geometry (docs/underwater.md)
-----------------------------
Flat port: a plate of thickness t whose inner face meets the axis at z_i = -d (d =
``port.distance_mm``) and whose outer face is parallel to it, t further toward the scene. Its
plane is turned about the point (0, 0, -d) as every tilted plane (docs/design.md section 1.1,
:func:`mechdeconv_ros.optics.pose.tilt_rotation`): first by tilt_x about its row (x) line, then
by tilt_y about its own turned column line, so its normal toward the lens is
:func:`~mechdeconv_ros.optics.pose.port_normal`, ``n = (-sin b, -sin a cos b, cos a cos b)``:
a positive tilt_x brings the part of the port at y > 0 (seen at larger v) closer to the lens,
a positive tilt_y the part at x > 0 (larger u).

Dome port: two concentric spheres, inner radius R, outer R + t, centred at
C = (dx, dy, z_E + c) with z_E the lens's paraxial entrance pupil (in air) and c
``port.center_offset_mm`` (> 0 toward the scene: z_C = z_E - c). Its inner vertex lies at
z_C - R.

Untilted and undecentred, a port keeps the rotational symmetry: it is two more surfaces in
front of the lens (:func:`ported_prescription`), object space in the medium of index n_w, and
the meridional tracer finds its chief rays. Otherwise :func:`trace_scene_points` traces skew
rays in 3-D: the scene point P, in the medium, sends the ray P + s k (k unit) through the port
(vector Snell at each face, :func:`mechdeconv_ros.optics.surfaces.refract`) and the lens
(:mod:`mechdeconv_ros.optics.trace3d`); the chief ray is the one crossing the stop plane at
its centre, found by a 2-D Newton on the direction's (k_x / k_z, k_y / k_z) with a
finite-difference Jacobian, started from the symmetric port's chief ray (or the line toward
the stop centre) and converged to 1e-10 mm at the stop. A start that the port stops (a tilted
port reflects totally where the symmetric one did not) is continued: aimed through the port
with 0, 1/4, 1/2, 3/4 of its tilt and decentring first. The chief ray is clipped by the lens's
edges, not by its clear semi-diameters (it stands for the beam's centre). A scene point must
lie in the water (:func:`in_medium`): in front of the flat port's outer plane, outside the
dome's outer sphere; a ray is never traced backwards to the port.

A scene at infinity (:func:`trace_scene_directions`): a direction has an exact image through
any port. Its rays are parallel in the medium (unit k); the chief ray is the one through the
stop centre, found by the same Newton on the ray's offset (u_1, u_2) square to k from a point
on the axis, O + u_1 e_1 + u_2 e_2 (e_1, e_2 an orthonormal basis square to k), which holds
at any angle of k to the axis.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math

from mechdeconv_ros.optics.pose import port_normal
from mechdeconv_ros.optics.prescription import (
    paraxial_matrix, Prescription, Surface, surfaces_before)
from mechdeconv_ros.optics.surfaces import refract
from mechdeconv_ros.optics.trace3d import lens_system, System, trace_pass
import numpy as np

#: The 2-D Newton of the chief ray stops when the stop is met within this (mm).
STOP_TOLERANCE_MM = 1e-10
#: Newton iterations of the chief-ray aiming in 3-D.
MAX_ITERATIONS = 30

_ERRSTATE = {'invalid': 'ignore', 'divide': 'ignore', 'over': 'ignore'}


@dataclass(frozen=True)
class Port:
    """
    A port: ``kind`` ``flat`` or ``dome``, its thickness and index, and its placement.

    Flat: ``distance_mm`` (lens vertex to inner face), ``tilt_x_rad``/``tilt_y_rad``. Dome:
    ``radius_mm`` (inner), ``center_z_mm`` (lens frame) and ``decenter_x_mm``/``_y_mm``.
    """

    kind: str
    thickness_mm: float
    index: float
    distance_mm: float = 0.0
    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0
    radius_mm: float = 0.0
    center_z_mm: float = 0.0
    decenter_x_mm: float = 0.0
    decenter_y_mm: float = 0.0

    @property
    def symmetric(self) -> bool:
        """Return True when the port keeps the lens's rotational symmetry."""
        return (self.tilt_x_rad == 0.0 and self.tilt_y_rad == 0.0
                and self.decenter_x_mm == 0.0 and self.decenter_y_mm == 0.0)

    @property
    def inner_vertex_z_mm(self) -> float:
        """Return z where the axis meets the inner face (untilted, undecentred)."""
        if self.kind == 'flat':
            return -self.distance_mm
        return self.center_z_mm - self.radius_mm

    @property
    def shift_mm(self) -> float:
        """Return how far the lens's first vertex lies behind the port's outer vertex."""
        return self.thickness_mm - self.inner_vertex_z_mm

    def normal(self) -> np.ndarray:
        """Return the flat port's unit normal toward the lens (module docstring)."""
        return port_normal(self.tilt_x_rad, self.tilt_y_rad)


def entrance_pupil_z(lens: Prescription) -> float:
    """
    Return z of a lens's paraxial entrance pupil (the stop imaged into object space).

    :param lens: the lens (its object index is used).
    :return: z (mm, lens frame); the stop itself when it lies in front of the lens.
    """
    count = surfaces_before(lens, lens.stop_z_mm)
    if count == 0:
        return float(lens.stop_z_mm)
    a, b, _, _ = paraxial_matrix(lens, count, 0.0, lens.stop_z_mm)
    # The ray (y, n u) at z = 0 meets the stop centre when a y + b n u = 0: it crosses the axis
    # at z = -y / u = b n_0 / a.
    return float(b * lens.object_index / a) if a != 0.0 else math.inf


def ported_prescription(lens: Prescription, port: Port, medium_index: float) -> Prescription:
    """
    Return the port (untilted, centred) and the lens as one prescription, scene in the medium.

    :param lens: the lens in air.
    :param port: the port (its tilts and decentring are ignored here).
    :param medium_index: n of the scene's medium.
    :return: the prescription; its first vertex is the port's outer vertex, the lens's first
        vertex at ``port.shift_mm``.
    """
    gap = -port.inner_vertex_z_mm
    if port.kind == 'flat':
        outer = Surface(0.0, port.thickness_mm, port.index)
        inner = Surface(0.0, gap, 1.0)
    else:
        outer = Surface(port.radius_mm + port.thickness_mm, port.thickness_mm, port.index)
        inner = Surface(port.radius_mm, gap, 1.0)
    return replace(lens, surfaces=(outer, inner) + tuple(lens.surfaces),
                   stop_z_mm=lens.stop_z_mm + port.shift_mm, object_index=float(medium_index))


def _unit(kx: np.ndarray, ky: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the unit direction of slopes (kx / kz, ky / kz), kz > 0."""
    norm = np.sqrt(1.0 + kx * kx + ky * ky)
    return kx / norm, ky / norm, 1.0 / norm


def _through_port(port: Port, medium_index: float, p: tuple[np.ndarray, ...],
                  k: tuple[np.ndarray, ...], *, forward: bool = True
                  ) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """
    Refract rays from the medium through both faces of the port into air (NaN: failed).

    With ``forward`` the ray must travel forward (s >= 0) from its start to the outer face: a
    start behind the flat port's outer plane or inside the dome's outer sphere is in the
    housing, not in the water, and fails instead of being traced backwards. Without it the
    start is any point of the ray's line (a scene at infinity).
    """
    x, y, z = p
    kx, ky, kz = k
    indices = ((medium_index, port.index), (port.index, 1.0))
    with np.errstate(**_ERRSTATE):
        if port.kind == 'flat':
            n = port.normal()
            anchor = np.array([0.0, 0.0, -port.distance_mm])
            for face, (offset, (n0, n1)) in enumerate(zip((port.thickness_mm, 0.0), indices)):
                q = anchor - offset * n
                s = ((q[0] - x) * n[0] + (q[1] - y) * n[1] + (q[2] - z) * n[2]) / (
                    kx * n[0] + ky * n[1] + kz * n[2])
                if face == 0 and forward:
                    s = np.where(s >= 0.0, s, np.nan)
                x, y, z = x + s * kx, y + s * ky, z + s * kz
                kx, ky, kz = refract(kx, ky, kz, n[0], n[1], n[2], n0, n1)
            return (x, y, z), (kx, ky, kz)
        c = (port.decenter_x_mm, port.decenter_y_mm, port.center_z_mm)
        for face, (radius, (n0, n1)) in enumerate(
                zip((port.radius_mm + port.thickness_mm, port.radius_mm), indices)):
            dx, dy, dz = x - c[0], y - c[1], z - c[2]
            b = dx * kx + dy * ky + dz * kz
            cc = dx * dx + dy * dy + dz * dz - radius * radius
            # The near intersection of the line (where it enters the sphere).
            s = -b - np.sqrt(b * b - cc)
            if face == 0 and forward:
                s = np.where(s >= 0.0, s, np.nan)
            x, y, z = x + s * kx, y + s * ky, z + s * kz
            nx, ny, nz = (c[0] - x) / radius, (c[1] - y) / radius, (c[2] - z) / radius
            kx, ky, kz = refract(kx, ky, kz, nx, ny, nz, n0, n1)
        return (x, y, z), (kx, ky, kz)


def in_medium(port: Port, points: np.ndarray) -> np.ndarray:
    """
    Return where scene points lie in the water, in front of the port's outer face.

    Flat: on the scene's side of the (tilted) outer plane. Dome: outside the outer sphere and
    in front of its centre's plane square to the axis (the dome's cap faces the scene).

    :param port: the port.
    :param points: ``(N, 3)`` points, lens frame.
    :return: ``(N,)`` booleans.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if port.kind == 'flat':
        n = port.normal()
        outer = np.array([0.0, 0.0, -port.distance_mm]) - port.thickness_mm * n
        return (pts - outer) @ n < 0.0
    c = np.array([port.decenter_x_mm, port.decenter_y_mm, port.center_z_mm])
    reach = np.linalg.norm(pts - c, axis=1)
    return (reach > port.radius_mm + port.thickness_mm) & (pts[:, 2] < c[2])


def orthonormal_basis(k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return two unit vectors square to each unit vector k and to each other (any k).

    Duff et al., "Building an orthonormal basis, revisited", JCGT 6(1), 2017.

    :param k: ``(N, 3)`` unit vectors.
    :return: ``(e1, e2)``, each ``(N, 3)``.
    """
    x, y, z = k[:, 0], k[:, 1], k[:, 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    e1 = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    e2 = np.stack([b, sign + y * y * a, -y], axis=1)
    return e1, e2


class _Launch:
    """
    The rays whose aiming unknowns are ``u`` (N, 2): from scene points or at infinity.

    A scene point P: the ray P + s k, u = (k_x / k_z, k_y / k_z). A scene at infinity, the
    direction k fixed: the ray through O + u_1 e_1 + u_2 e_2 (O on the axis, e_1, e_2 square
    to k: :func:`orthonormal_basis`), any point of its line.
    """

    def __init__(self, points: np.ndarray | None, directions: np.ndarray | None,
                 origin_z_mm: float = 0.0) -> None:
        self.points = points
        self.directions = directions
        self.origin = np.array([0.0, 0.0, origin_z_mm])
        if directions is not None:
            self.e1, self.e2 = orthonormal_basis(directions)
            # Unknowns in mm: the finite-difference step moves the ray 1e-7 mm.
            self.eps = np.full((directions.shape[0], 1), 1e-7)
        else:
            # Unknowns are slopes: a step of 1e-7 moves the ray at the pupil by 1e-7 times
            # the point's distance, so far points (1e6 mm and beyond) get a smaller step.
            reach = np.abs(origin_z_mm - points[:, 2])
            with np.errstate(**_ERRSTATE):
                self.eps = (1e-7 * np.minimum(1.0, 1e3 / reach))[:, None]
            self.eps[~np.isfinite(self.eps)] = 1e-7

    def rays(self, rows: np.ndarray, u: np.ndarray) -> tuple[tuple[np.ndarray, ...], ...]:
        """Return the starting points and directions of the given rows at unknowns ``u``."""
        if self.directions is None:
            pts = self.points[rows]
            return (pts[:, 0], pts[:, 1], pts[:, 2]), _unit(u[:, 0], u[:, 1])
        k = self.directions[rows]
        p = self.origin + u[:, :1] * self.e1[rows] + u[:, 1:] * self.e2[rows]
        return (p[:, 0], p[:, 1], p[:, 2]), (k[:, 0], k[:, 1], k[:, 2])

    def unknowns(self, rows: np.ndarray, p: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Return the unknowns of rays (p, k) (N, 3 each): the aiming's start."""
        if self.directions is None:
            with np.errstate(**_ERRSTATE):
                return np.stack([k[:, 0] / k[:, 2], k[:, 1] / k[:, 2]], axis=1)
        rel = p - self.origin
        return np.stack([np.sum(rel * self.e1[rows], axis=1),
                         np.sum(rel * self.e2[rows], axis=1)], axis=1)


def trace_scene_points(lens: Prescription, port: Port, medium_index: float,
                       points: np.ndarray, sensor_z_mm: float,
                       start: np.ndarray | None = None, *,
                       with_slopes: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """
    Return where the chief rays of scene points cross the sensor plane (exact, 3-D).

    A point not in the water (behind the port's outer face, :func:`in_medium`) has no ray.
    The chief ray is not clipped by the lens's clear semi-diameters (only by its edges): it
    stands for the beam's centre, and a beam whose centre passes just outside a clear
    aperture still forms an image (the meridional trace's semi-diameters were set on the
    symmetric chief rays; a tilt or decentring moves them by microns).

    :param lens: the lens in air (its frame: first vertex at z = 0).
    :param port: the port (tilted, decentred or not).
    :param medium_index: n of the scene's medium.
    :param points: ``(N, 3)`` scene points x, y, z (lens frame, in front of the port).
    :param sensor_z_mm: z of the sensor plane (lens frame).
    :param start: ``(N, 2)`` starting slopes (k_x / k_z, k_y / k_z) of the aiming; default
        the line toward the paraxial entrance pupil.
    :param with_slopes: also return the chief rays' slopes in the medium.
    :return: ``(N, 2)`` physical x, y on the sensor (mm; inverted image), NaN where no chief
        ray passes; with ``with_slopes``, also the ``(N, 2)`` slopes (k_x / k_z, k_y / k_z).
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if start is None:
        z_e = entrance_pupil_z(lens)
        with np.errstate(**_ERRSTATE):
            slopes = np.stack([-pts[:, 0] / (z_e - pts[:, 2]), -pts[:, 1] / (z_e - pts[:, 2])],
                              axis=1)
    else:
        slopes = np.array(start, dtype=float).reshape(-1, 2)
    launch = _Launch(pts, None, entrance_pupil_z(lens))
    out, slopes = _chief_rays(lens, port, medium_index, launch, sensor_z_mm, slopes)
    out[~in_medium(port, pts)] = np.nan
    return (out, slopes) if with_slopes else out


def trace_scene_directions(lens: Prescription, port: Port, medium_index: float,
                           directions: np.ndarray, sensor_z_mm: float,
                           start: np.ndarray | None = None) -> np.ndarray:
    """
    Return where the chief rays of a scene at infinity cross the sensor plane (exact, 3-D).

    A direction at infinity has an exact image through any port: its rays are parallel in
    the medium (direction k), and the chief ray is the one of them that crosses the stop's
    centre; the aiming moves the ray square to k (2-D Newton) instead of turning it.

    :param lens: the lens in air (its frame: first vertex at z = 0).
    :param port: the port (tilted, decentred or not).
    :param medium_index: n of the scene's medium.
    :param directions: ``(N, 3)`` unit directions of the rays in the medium, travelling
        toward the lens (lens frame: a scene direction (X, Y, Z) of the optical frame is the
        ray direction (-X, -Y, Z)).
    :param sensor_z_mm: z of the sensor plane (lens frame).
    :param start: ``(N, 3)`` a point on each starting ray (the symmetric port's chief ray);
        default the line through the lens's paraxial entrance pupil.
    :return: ``(N, 2)`` physical x, y on the sensor (mm; inverted image), NaN where no chief
        ray passes.
    """
    k = np.asarray(directions, dtype=float).reshape(-1, 3)
    k = k / np.linalg.norm(k, axis=1, keepdims=True)
    launch = _Launch(None, k, entrance_pupil_z(lens))
    rows = np.arange(k.shape[0])
    if start is None:
        u = np.zeros((k.shape[0], 2))
    else:
        u = launch.unknowns(rows, np.asarray(start, dtype=float).reshape(-1, 3), k)
    out, _ = _chief_rays(lens, port, medium_index, launch, sensor_z_mm, u)
    return out


def _chief_rays(lens: Prescription, port: Port, medium_index: float, launch: _Launch,
                sensor_z_mm: float, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Aim the rays of ``launch`` at the stop centre and trace them to the sensor.

    A start whose ray fails (a tilted port's total reflection near the critical angle, where
    the symmetric port's chief ray is reflected but the tilted one's is not) is continued:
    aimed through the port with a quarter, half, three quarters of its tilt and decentring,
    each solution starting the next.

    :return: ``(N, 2)`` sensor x, y (NaN where none passes) and the unknowns.
    """
    system = lens_system(lens, 0.0, stop_surface=None).without_semi_diameters()
    stop_system = _prefix(system, float(lens.stop_z_mm))
    rows = np.arange(u.shape[0])
    u = np.array(u, dtype=float)
    value = _stop_xy(port, medium_index, launch, rows, u, stop_system)
    failed = rows[~np.isfinite(value).all(axis=1)]
    if failed.size and not port.symmetric:
        for fraction in (0.0, 0.25, 0.5, 0.75):
            part = _scaled(port, fraction)
            u_f, v_f, ok = _newton(part, medium_index, launch, failed, u[failed],
                                   _stop_xy(part, medium_index, launch, failed, u[failed],
                                            stop_system), stop_system)
            u[failed[ok]] = u_f[ok]
        value[failed] = _stop_xy(port, medium_index, launch, failed, u[failed], stop_system)
    u, value, ok = _newton(port, medium_index, launch, rows, u, value, stop_system)
    p, k = launch.rays(rows, u)
    forward = launch.directions is None
    p, k = _through_port(port, medium_index, p, k, forward=forward)
    passed, (x, y, z, kx, ky, kz) = trace_pass(system, *p, *k)
    with np.errstate(**_ERRSTATE):
        s = (sensor_z_mm - z) / kz
        out = np.stack([x + s * kx, y + s * ky], axis=1)
    out[~(ok & passed & (kz > 0))] = np.nan
    return out, u


def _scaled(port: Port, fraction: float) -> Port:
    """Return the port with its tilts and decentring scaled by ``fraction``."""
    return replace(port, tilt_x_rad=fraction * port.tilt_x_rad,
                   tilt_y_rad=fraction * port.tilt_y_rad,
                   decenter_x_mm=fraction * port.decenter_x_mm,
                   decenter_y_mm=fraction * port.decenter_y_mm)


def _newton(port: Port, medium_index: float, launch: _Launch, rows: np.ndarray,
            u: np.ndarray, value: np.ndarray, stop_system: System
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return the unknowns that put the rays on the stop centre, the miss and which converged.

    2-D Newton, finite-difference Jacobian, backtracking (halving) while the miss grows.
    """
    u, value = np.array(u, dtype=float), np.array(value, dtype=float)
    active = np.isfinite(value).all(axis=1)
    for _ in range(MAX_ITERATIONS):
        err = np.hypot(value[:, 0], value[:, 1])
        todo = np.flatnonzero(active & (err > STOP_TOLERANCE_MM))
        if todo.size == 0:
            break
        s0 = u[todo]
        eps = launch.eps[rows[todo]]
        zero = np.zeros_like(eps)
        fx = _stop_xy(port, medium_index, launch, rows[todo], s0 + np.hstack([eps, zero]),
                      stop_system)
        fy = _stop_xy(port, medium_index, launch, rows[todo], s0 + np.hstack([zero, eps]),
                      stop_system)
        j = np.stack([(fx - value[todo]) / eps, (fy - value[todo]) / eps], axis=2)
        with np.errstate(**_ERRSTATE):
            det = j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]
            vx, vy = value[todo, 0], value[todo, 1]
            step = np.stack([(j[:, 1, 1] * vx - j[:, 0, 1] * vy) / det,
                             (-j[:, 1, 0] * vx + j[:, 0, 0] * vy) / det], axis=1)
        lam = np.ones(todo.size)
        pending = np.arange(todo.size)
        for _ in range(12):
            trial = s0[pending] - lam[pending, None] * step[pending]
            new = _stop_xy(port, medium_index, launch, rows[todo[pending]], trial, stop_system)
            good = np.isfinite(new).all(axis=1) & (
                np.hypot(new[:, 0], new[:, 1]) < err[todo[pending]])
            u[todo[pending[good]]] = trial[good]
            value[todo[pending[good]]] = new[good]
            lam[pending[~good]] *= 0.5
            pending = pending[~good]
            if pending.size == 0:
                break
        active[todo[pending]] = False
    # A ray that stalled below 1e3 x the tolerance (a far point's slope has no more digits)
    # has converged as far as doubles allow.
    err = np.hypot(value[:, 0], value[:, 1])
    return u, value, err <= 1e3 * STOP_TOLERANCE_MM


def _prefix(system: System, z_stop: float) -> System:
    """Return the elements up to and including the stop plane (the aiming's system)."""
    elements = []
    for e in system.elements:
        elements.append(e)
        if e.is_stop:
            break
    return System(tuple(elements))


def _stop_xy(port: Port, medium_index: float, launch: _Launch, rows: np.ndarray,
             u: np.ndarray, stop_system: System) -> np.ndarray:
    """Return (x, y) where the rays of unknowns ``u`` cross the stop plane (NaN: failed)."""
    p, k = launch.rays(rows, u)
    p, k = _through_port(port, medium_index, p, k, forward=launch.directions is None)
    stop = stop_system.elements[-1]
    if len(stop_system.elements) > 1:
        passed, (x, y, z, kx, ky, kz) = trace_pass(System(stop_system.elements[:-1]), *p, *k)
    else:
        passed, (x, y, z), (kx, ky, kz) = np.isfinite(p[0]), p, k
    with np.errstate(**_ERRSTATE):
        s = (stop.z_mm - z) / kz
        out = np.stack([x + s * kx, y + s * ky], axis=1)
    out[~(passed & np.isfinite(out).all(axis=1))] = np.nan
    return out
