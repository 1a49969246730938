# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A lens behind a port, looking into water: the lens source of issue 27 (docs/underwater.md).

Pure numpy, no ROS. :class:`PortedSource` wraps the traced lens of the ``lens.*`` values (in
air) with the port of the ``port.*`` values and the medium of the ``scene.*`` values:

- the scene convention is unchanged: a scene point (X, Y, Z) in the camera's optical frame,
  Z from the front principal plane H of the lens alone (in air), the field angle
  tan(theta) = hypot(X, Y) / Z, the scene plane at z_H - l (lens frame, first lens vertex at
  z = 0; ``scene.distance_mm`` = l). A scene at infinity is a direction in the medium.
- the trace: the port (untilted, centred) and the lens are one prescription
  (:func:`mechdeconv_ros.optics.ports.ported_prescription`), object space of index n_w; its
  meridional chief rays are those of the same scene points: the combined prescription's own
  H_c gives the distance l_c = z_Hc - z_scene and tan(theta_c) = l tan(theta) / l_c.
- the sensor: the paraxial image of the scene through medium, port and lens, or
  ``lens.image_distance_mm`` behind the last vertex; the raw pinhole's focal length is the
  paraxial chief ray's height there per unit tan(theta) (so K is the in-water camera's):
  v = v_c l / l_c (v_c per unit tan(theta_c), :func:`sensor_plane.chief_ray_scale`).
- a tilted flat port or a decentred dome breaks the symmetry: the radial map is that of the
  symmetric port, and :meth:`PortedSource.sensor_points` traces scene points exactly in 3-D
  (:func:`mechdeconv_ros.optics.ports.trace_scene_points`), a scene at infinity its
  directions (:func:`mechdeconv_ros.optics.ports.trace_scene_directions`).
- ``scene.medium_index`` 1 is air written out: no port path (:func:`has_port`).

Refusals (each names its parameter): a datasheet lens (no surfaces), a moving lens, a port
thickness, distance or radius <= 0, a dome whose inner sphere meets a lens surface, a scene
inside the port, a medium index below 1, water outside the index formula's range.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from mechdeconv_ros.lenses.lens_errors import FloatArray, is_prescription_mode, ModelError
from mechdeconv_ros.lenses.lens_source import (
    FirstOrder, LensSource, NotApplicable, PrescriptionSource, ThickLensSource, TracedSource)
from mechdeconv_ros.lenses.refusals import check_surfaces
from mechdeconv_ros.lenses.sensor_plane import blur_diameter_mm, chief_ray_scale, sensor_plane
from mechdeconv_ros.optics.glass import GlassError, lookup
from mechdeconv_ros.optics.ports import (
    entrance_pupil_z, Port, ported_prescription, trace_scene_directions, trace_scene_points)
from mechdeconv_ros.optics.prescription import paraxial, Prescription, vertex_z
from mechdeconv_ros.optics.raytrace import aim_chief_rays, trace_field, trace_field_rays
from mechdeconv_ros.optics.surfaces import sag
from mechdeconv_ros.optics.water import SEAWATER_SALINITY_PSU, water_index, WaterError
from mechdeconv_ros.schema.params import scene_in_air
import numpy as np

#: A flat port's chief rays beyond the critical angle by this much are not aimed (rad).
CRITICAL_MARGIN_RAD = math.radians(3.0)
#: Field angles of the ladder that starts the 3-D aiming (PortedSource.symmetric_slopes).
LADDER_SAMPLES = 257
#: Radii sampled on each lens surface when checking that a dome clears it.
_CLEARANCE_SAMPLES = 33


def has_port(values: Mapping[str, Any]) -> bool:
    """
    Return True when the values put a port or a medium other than air before the lens.

    ``scene.medium_index`` 1.0 is air written out (:func:`scene_in_air`): no port path.
    """
    return str(values.get('port.type', 'none')) != 'none' or not scene_in_air(values)


def medium_index(values: Mapping[str, Any], wavelength_nm: float) -> float:
    """
    Return the index of the scene's medium relative to air.

    :param values: checked parameter values.
    :param wavelength_nm: the wavelength (``lens.wavelength_nm`` or a channel's).
    :return: ``scene.medium_index`` when > 0, else 1 (air) or the water's (Quan & Fry).
    :raises ModelError: naming ``scene.medium_index`` below 1, or the water parameter (or
        wavelength) outside the formula's range.
    """
    given = float(values.get('scene.medium_index', 0.0))
    if given > 0.0:
        if given < 1.0:
            raise ModelError('scene.medium_index', f'{given:g} is below 1: no medium has an '
                                                   'index below that of air (0 = from '
                                                   'scene.medium)')
        return given
    medium = str(values.get('scene.medium', 'air'))
    if medium == 'air':
        return 1.0
    salinity = (float(values.get('scene.salinity_psu', SEAWATER_SALINITY_PSU))
                if medium == 'seawater' else 0.0)
    try:
        return water_index(wavelength_nm, float(values.get('scene.temperature_c', 20.0)),
                           salinity)
    except WaterError as err:
        raise ModelError(err.parameter, err.detail) from None


def port_index(values: Mapping[str, Any], wavelength_nm: float) -> float:
    """
    Return the port's index: ``port.glass`` at the wavelength, else ``port.refractive_index``.

    :raises ModelError: naming ``port.glass`` for an unknown name or an uncovered wavelength.
    """
    name = str(values.get('port.glass', '') or '').strip()
    if not name:
        return float(values.get('port.refractive_index', 1.4906))
    try:
        return float(lookup(name).index(wavelength_nm))
    except GlassError as err:
        raise ModelError('port.glass', str(err)) from None


def port_from_values(values: Mapping[str, Any], lens: Prescription,
                     wavelength_nm: float) -> Port | None:
    """
    Return the port the ``port.*`` values describe, checked against the lens; None without.

    :param values: checked parameter values.
    :param lens: the lens in air (its frame).
    :param wavelength_nm: the wavelength of the port's index.
    :return: the port.
    :raises ModelError: naming the parameter at fault.
    """
    kind = str(values.get('port.type', 'none'))
    if kind == 'none':
        return None
    thickness = float(values['port.thickness_mm'])
    if not thickness > 0.0:
        raise ModelError('port.thickness_mm', f'{thickness:g} mm: a port needs a thickness > 0')
    index = port_index(values, wavelength_nm)
    if kind == 'flat':
        distance = float(values['port.distance_mm'])
        if not distance > 0.0:
            raise ModelError('port.distance_mm', f'{distance:g} mm puts the port inner face '
                                                 'on or behind the lens first vertex: it '
                                                 'must be > 0')
        port = Port('flat', thickness, index, distance_mm=distance,
                    tilt_x_rad=math.radians(float(values['port.tilt_x_deg'])),
                    tilt_y_rad=math.radians(float(values['port.tilt_y_deg'])))
        _check_flat_clearance(port, lens)
        return port
    radius = float(values['port.radius_mm'])
    if not radius > 0.0:
        raise ModelError('port.radius_mm', f'{radius:g} mm: a dome needs an inner radius > 0')
    centre = entrance_pupil_z(lens) - float(values['port.center_offset_mm'])
    port = Port('dome', thickness, index, radius_mm=radius, center_z_mm=centre,
                decenter_x_mm=float(values['port.decenter_x_mm']),
                decenter_y_mm=float(values['port.decenter_y_mm']))
    _check_dome_clearance(port, lens, values)
    return port


def _lens_points(lens: Prescription) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """Return, per surface with a semi-diameter, sample radii and the surface's z there."""
    out = []
    for i, (surface, z_v) in enumerate(zip(lens.surfaces, vertex_z(lens))):
        semi = float(surface.semi_diameter_mm)
        r = np.linspace(0.0, semi, _CLEARANCE_SAMPLES) if semi > 0 else np.zeros(1)
        out.append((i, r, z_v + sag(surface, r * r)))
    return out


def _check_flat_clearance(port: Port, lens: Prescription) -> None:
    """Refuse a (tilted) flat port whose inner face cuts a lens surface's clear aperture."""
    n = port.normal()
    for i, r, z in _lens_points(lens):
        # The worst azimuth: the face comes closest along the direction of its tilt.
        tilt = math.hypot(n[0], n[1])
        # Signed distance of (r along the tilt direction, z) from the inner plane, toward
        # the lens: (p - q) . n with q = (0, 0, -d).
        clearance = np.min(-r * tilt + (z + port.distance_mm) * n[2])
        if clearance <= 0.0:
            raise ModelError('port.distance_mm',
                             f'{port.distance_mm:g} mm: the port inner face cuts lens surface '
                             f'{i} within its clear aperture (by {-clearance:.3g} mm)')


def _check_dome_clearance(port: Port, lens: Prescription, values: Mapping[str, Any]) -> None:
    """Refuse a dome whose inner sphere meets a lens surface's clear aperture."""
    for i, r, z in _lens_points(lens):
        # The rim points of the surface along +-x and +-y (the decentring's worst azimuths).
        for ux, uy in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
            reach = np.sqrt((ux * r - port.decenter_x_mm) ** 2 + (uy * r - port.decenter_y_mm) ** 2
                            + (z - port.center_z_mm) ** 2)
            if np.max(reach) >= port.radius_mm:
                raise ModelError(
                    'port.radius_mm',
                    f'{port.radius_mm:g} mm: the dome inner sphere (centre '
                    f'{float(values["port.center_offset_mm"]):g} mm in front of the entrance '
                    f'pupil) meets lens surface {i} within its clear aperture: the lens must '
                    f'fit inside the dome (it reaches {np.max(reach):.4g} mm from the centre)')


class PortedSource(LensSource):
    """The lens of the ``lens.*`` values behind the port, the scene in the medium."""

    def __init__(self, values: Mapping[str, Any], wavelength_nm: float | None = None,
                 base: PortedSource | None = None) -> None:
        """
        Make the ported lens.

        :param values: checked parameter values.
        :param wavelength_nm: trace at this wavelength instead of ``lens.wavelength_nm`` (a
            colour channel: glasses, port and water at it).
        :param base: the source whose sensor plane and K this one keeps (a colour channel).
        :raises ModelError: naming the parameter at fault.
        """
        if any(values.get(f'lens.{m}.joint') for m in ('zoom', 'focus')):
            raise ModelError('port.type', 'a port or water in front of a lens whose groups '
                                          'move (lens.zoom/focus.joint) is not traced yet')
        wavelength = float(values['lens.wavelength_nm'] if wavelength_nm is None
                           else wavelength_nm)
        self.raw_values = dict(values)
        lens_values = dict(values, **{'lens.wavelength_nm': wavelength})
        lens: TracedSource = (PrescriptionSource(lens_values) if is_prescription_mode(lens_values)
                              else ThickLensSource(lens_values))
        self.lens = lens
        self.values = lens.values
        self.mode = lens.mode
        self.lens_parameter = lens.lens_parameter
        self.stop_parameter = lens.stop_parameter
        self.wavelength_nm = wavelength
        self.medium_index = medium_index(values, wavelength)
        self.port = port_from_values(values, lens.prescription, wavelength)
        if self.port is not None and not self.port.symmetric and (
                float(values.get('sensor.tilt_x_deg', 0.0))
                or float(values.get('sensor.tilt_y_deg', 0.0))):
            name = 'port.tilt_x_deg' if self.port.kind == 'flat' else 'port.decenter_x_mm'
            raise ModelError(name, 'a tilted flat port or a decentred dome with a tilted sensor '
                                   '(sensor.tilt_*_deg) is not traced yet: one of them must be '
                                   'square to the lens axis')
        air_lens = lens.prescription
        if self.port is None:
            self.combined = Prescription(air_lens.surfaces, air_lens.stop_z_mm,
                                         self.medium_index, air_lens.stop_semi_diameter_mm)
            self.shift_mm = 0.0
        else:
            self.combined = ported_prescription(air_lens, self.port, self.medium_index)
            self.shift_mm = self.port.shift_mm
        try:
            self._combined_h = paraxial(self.combined).front_principal_z_mm
        except ValueError as err:
            raise ModelError(self.lens_parameter, str(err)) from None
        self._base = base
        self._planes: dict[float, tuple[float, float, float]] = {}

    # --- the frames ---
    def combined_distance(self, distance_mm: float) -> float:
        """
        Return the scene's distance from the combined prescription's own H (``l_c``).

        :param distance_mm: l from the lens's H (``math.inf`` allowed).
        :raises ModelError: naming ``scene.distance_mm`` when the scene is not in front of
            the port.
        """
        if math.isinf(distance_mm):
            return math.inf
        z_scene = self.lens.first_order().front_principal_z_mm - distance_mm + self.shift_mm
        if not z_scene < 0.0:
            raise ModelError('scene.distance_mm',
                             f'{distance_mm:g} mm from the front principal plane puts the scene '
                             f'{z_scene:.4g} mm behind the port outer face: it must lie in '
                             'front of the port, in the water')
        return self._combined_h - z_scene

    def first_order(self) -> FirstOrder:
        """Return the lens's own (in air) focal length and principal planes, lens frame."""
        return self.lens.first_order()

    def _plane(self, distance_mm: float) -> tuple[float, float, float]:
        """Return (sensor z in the combined frame, v, paraxial image z in it)."""
        if self._base is not None:
            return self._base._plane(distance_mm)
        if distance_mm not in self._planes:
            d_c = self.combined_distance(distance_mm)
            try:
                plane = sensor_plane(self.combined, d_c, self._combined_h,
                                     float(self.values.get('lens.image_distance_mm', 0.0)),
                                     float(self.values['lens.aperture_diameter_mm']))
            except ModelError:
                raise
            except ValueError as err:
                raise ModelError('scene.distance_mm', str(err)) from None
            scale = chief_ray_scale(self.combined, d_c, self._combined_h, plane.z_mm)
            v = scale if math.isinf(distance_mm) else scale * distance_mm / d_c
            self._planes[distance_mm] = (plane.z_mm, v, plane.image_z_mm)
        return self._planes[distance_mm]

    def image_plane(self, distance_mm: float) -> tuple[float, float]:
        """Return the sensor's z (combined frame) and the in-water raw pinhole's v."""
        z, v, _ = self._plane(distance_mm)
        return z, v

    def sensor_z_lens_frame(self, distance_mm: float) -> float:
        """Return the sensor's z in the lens frame (first lens vertex at 0)."""
        return self._plane(distance_mm)[0] - self.shift_mm

    # --- the trace ---
    def _combined_angles(self, theta: FloatArray, distance_mm: float) -> FloatArray:
        theta = np.asarray(theta, dtype=float)
        if math.isinf(distance_mm):
            return theta
        d_c = self.combined_distance(distance_mm)
        with np.errstate(invalid='ignore'):
            return np.arctan(np.tan(theta) * (distance_mm / d_c))

    def real_heights(self, field_angle_rad: FloatArray, distance_mm: float,
                     guide: Any = None) -> tuple[FloatArray, FloatArray]:
        """Trace the chief rays through medium, port and lens (symmetric port)."""
        heights, _, offsets = self.chief_lines(field_angle_rad, distance_mm, guide)
        return heights, offsets

    def chief_lines(self, field_angle_rad: FloatArray, distance_mm: float,
                    guide: Any = None) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Trace the chief rays to the sensor plane: heights and slopes (sign-flipped)."""
        sensor_z, _ = self.image_plane(distance_mm)
        if guide is not None:
            guide = (self._combined_angles(guide[0], distance_mm), guide[1])
        theta = self._combined_angles(field_angle_rad, distance_mm)
        beyond = self._beyond_critical(theta, distance_mm)
        heights = np.full(theta.shape, np.nan)
        slopes = np.full(theta.shape, np.nan)
        offsets = np.full(theta.shape, np.nan)
        if (~beyond).any():
            rays, aimed = trace_field_rays(self.combined, self.combined_distance(distance_mm),
                                           sensor_z, theta[~beyond], guide)
            heights[~beyond], slopes[~beyond] = -rays.y, -rays.dy / rays.dz
            offsets[~beyond] = aimed
        return heights, slopes, offsets

    def _beyond_critical(self, theta_c: FloatArray, distance_mm: float) -> np.ndarray:
        """
        Return where a flat port surely stops the chief ray (no aiming there: it is slow).

        In the water the chief ray runs at about alpha to the axis, tan(alpha) = Y / (z_E -
        z_P), toward the apparent entrance pupil E; it passes into the air only below the
        critical angle asin(1 / n_w) to the port's normal. Beyond it by MARGIN (the pupil's
        aberration and the tilt) the angle is left out (NaN, the end of the field).
        """
        theta_c = np.asarray(theta_c, dtype=float)
        port = self.port
        if port is None or port.kind != 'flat' or self.medium_index <= 1.0:
            return np.zeros(theta_c.shape, dtype=bool)
        critical = math.asin(1.0 / self.medium_index)
        margin = CRITICAL_MARGIN_RAD + math.hypot(port.tilt_x_rad, port.tilt_y_rad)
        if math.isinf(distance_mm):
            alpha = np.abs(theta_c)
        else:
            d_c = self.combined_distance(distance_mm)
            z_scene = self._combined_h - d_c
            to_pupil = entrance_pupil_z(self.combined) - z_scene
            with np.errstate(invalid='ignore', over='ignore'):
                alpha = np.arctan(np.abs(np.tan(theta_c)) * d_c / to_pupil)
        return alpha > critical + margin

    def heights_to_sensor(self, tan_theta: FloatArray, distance_mm: float,
                          sensor_z_mm: float) -> FloatArray:
        """
        Return the real heights of scene points at another distance on a given sensor plane.

        :param tan_theta: tan of the field angles seen from the lens's H (>= 0, increasing).
        :param distance_mm: their distance l from H.
        :param sensor_z_mm: the sensor (combined frame).
        :return: heights (positive for a real inverted image), NaN where none passes.
        """
        theta = np.arctan(np.asarray(tan_theta, dtype=float))
        real, _ = trace_field(self.combined, self.combined_distance(distance_mm), sensor_z_mm,
                              self._combined_angles(theta, distance_mm))
        return -real

    def sensor_points(self, tx: FloatArray, ty: FloatArray, distance_mm: float
                      ) -> tuple[FloatArray, FloatArray]:
        """
        Trace scene directions (tx, ty) = (X/Z, Y/Z) exactly in 3-D to the sensor.

        :param tx: X / Z of the scene points (Z = l from the lens's H), any shape.
        :param ty: Y / Z.
        :param distance_mm: l (``math.inf``: a scene at infinity, the direction in the
            medium).
        :return: ``(a, b)``: the read-out offsets from the axis on the sensor, mm (upright:
            the inverted physical image turned 180 deg, a = -x, b = -y); NaN where none passes.
        """
        tx, ty = np.broadcast_arrays(np.asarray(tx, dtype=float), np.asarray(ty, dtype=float))
        return self.sensor_directions(np.stack([tx, ty, np.ones(tx.shape)], axis=-1),
                                      distance_mm)

    def sensor_directions(self, directions: FloatArray, distance_mm: float
                          ) -> tuple[FloatArray, FloatArray]:
        """
        Trace scene directions (optical frame, X right, Y down, Z ahead) exactly in 3-D.

        A finite scene: the point at Z = l on each direction (none for Z <= 0: the scene
        plane does not reach 90 deg), traced from there; it must lie in the water, in front
        of the port's outer face. At infinity: the direction in the medium, its parallel rays'
        chief ray (:func:`mechdeconv_ros.optics.ports.trace_scene_directions`), at any angle
        to the axis the lens passes.

        :param directions: ``(..., 3)``, need not be unit.
        :param distance_mm: l from the lens's H (``math.inf`` allowed).
        :return: ``(a, b)`` as :meth:`sensor_points`, shape ``directions.shape[:-1]``.
        """
        d = np.asarray(directions, dtype=float)
        shape = d.shape[:-1]
        d = d.reshape(-1, 3)
        port = self.port if self.port is not None else Port('flat', 0.0, 1.0, distance_mm=0.0)
        sensor_z = self.sensor_z_lens_frame(distance_mm)
        if math.isinf(distance_mm):
            with np.errstate(invalid='ignore', divide='ignore'):
                k = np.stack([-d[:, 0], -d[:, 1], d[:, 2]], axis=1)
                k /= np.linalg.norm(k, axis=1, keepdims=True)
            out = np.full((k.shape[0], 2), np.nan)
            good = np.isfinite(k).all(axis=1)
            if good.any():
                out[good] = trace_scene_directions(
                    self.lens.prescription, port, self.medium_index, k[good], sensor_z,
                    self._symmetric_points(k[good]))
        else:
            with np.errstate(invalid='ignore', divide='ignore'):
                tx = np.where(d[:, 2] > 0.0, d[:, 0] / d[:, 2], np.nan)
                ty = np.where(d[:, 2] > 0.0, d[:, 1] / d[:, 2], np.nan)
            z_scene = self.lens.first_order().front_principal_z_mm - distance_mm
            points = np.stack([tx * distance_mm, ty * distance_mm,
                               np.full(tx.size, z_scene)], axis=1)
            out = trace_scene_points(self.lens.prescription, port, self.medium_index, points,
                                     sensor_z, self.symmetric_slopes(tx, ty, distance_mm))
        return -out[:, 0].reshape(shape), -out[:, 1].reshape(shape)

    def _symmetric_points(self, k: np.ndarray) -> np.ndarray:
        """
        Return a point (lens frame) on the symmetric port's chief ray of each direction k.

        At infinity: the meridional chief ray of the field angle acos(k_z) (aimed with
        continuation over a ladder), turned to the direction's azimuth.

        :param k: ``(N, 3)`` unit ray directions in the medium (lens frame).
        :return: ``(N, 3)`` (NaN where the symmetric trace fails).
        """
        theta = np.arccos(np.clip(k[:, 2], -1.0, 1.0))
        order = np.argsort(theta, kind='stable')
        ladder = np.linspace(0.0, float(np.max(theta)), LADDER_SAMPLES)
        _, offsets = trace_field_rays(self.combined, math.inf, self.image_plane(math.inf)[0],
                                      ladder)
        rays = aim_chief_rays(self.combined, math.inf, field_angle_rad=theta[order],
                              guide=(ladder, offsets))
        height = np.empty(theta.shape)
        z = np.empty(theta.shape)
        height[order], z[order] = rays.y, rays.z - self.shift_mm
        # The meridional ray of a field above the axis runs down (k_y < 0): its azimuth is
        # that of -k.
        phi = np.arctan2(-k[:, 1], -k[:, 0])
        return np.stack([height * np.cos(phi), height * np.sin(phi), z], axis=1)

    def symmetric_slopes(self, tx: FloatArray, ty: FloatArray,
                         distance_mm: float) -> np.ndarray:
        """
        Return the slopes in the medium of the symmetric port's chief rays (the 3-D start).

        The meridional chief ray of the point's field (aimed with continuation, so a wide
        lens converges) turned to the point's azimuth: (k_x, k_y) / k_z = s (cos phi, sin phi).

        :return: ``(N, 2)``.
        """
        radius = np.hypot(tx, ty)
        order = np.argsort(radius, kind='stable')
        theta = self._combined_angles(np.arctan(radius[order]), distance_mm)
        d_c = self.combined_distance(distance_mm)
        # A dense ladder aimed by continuation first (a wide lens's chief rays move far from
        # the paraxial ones), its offsets then guide the points' own aiming.
        top = float(np.nanmax(theta)) if theta.size else 0.0
        ladder = np.linspace(0.0, top, LADDER_SAMPLES)
        _, offsets = trace_field_rays(self.combined, d_c, self.image_plane(distance_mm)[0],
                                      ladder)
        rays = aim_chief_rays(self.combined, d_c, field_angle_rad=theta,
                              guide=(ladder, offsets))
        slope = np.empty(radius.shape)
        slope[order] = rays.dy / rays.dz
        phi = np.arctan2(ty, tx)
        # The meridional ray of a point above the axis runs down toward it (dy < 0): in 3-D
        # toward the axis from the point's azimuth.
        return np.stack([slope * np.cos(phi), slope * np.sin(phi)], axis=1)

    # --- the rest of the seam ---
    @property
    def prescription(self) -> Prescription:
        """Return the port and the lens as one prescription, the scene in the medium."""
        return self.combined

    @property
    def stop_z_mm(self) -> float:
        """Return z of the aperture stop (combined frame)."""
        return float(self.combined.stop_z_mm)

    def pupil_scale(self) -> float:
        """Return the lens's own entrance pupil / stop diameter (in air)."""
        return self.lens.pupil_scale()

    def check_physical(self, distance_mm: float, sensor_z_mm: float) -> list[str]:
        """Apply the lens's surface rules (in air) and refuse a scene inside the port."""
        self.combined_distance(distance_mm)
        image_z = self._plane(distance_mm)[2] - self.shift_mm
        return check_surfaces(self.lens.values, self.lens.prescription, self.lens.paraxial(),
                              distance_mm, image_z)

    def defocus(self, distance_mm: float) -> dict[str, float]:
        """Return the sensor's distance from the paraxial image in the water, and the blur."""
        z, _, image_z = self._plane(distance_mm)
        blur = blur_diameter_mm(self.combined, self.combined_distance(distance_mm),
                                self._combined_h, z,
                                float(self.values['lens.aperture_diameter_mm']))
        return {'defocus_mm': z - image_z, 'blur_diameter_mm': blur,
                'paraxial_image_distance_mm': self._plane(distance_mm)[1]}

    def channel_source(self, wavelength_nm: float) -> PortedSource:
        """Return this lens, port and water at another wavelength, on this sensor plane."""
        return PortedSource(self.raw_values, wavelength_nm, base=self)

    def relative_illumination(self, model: Any, *, with_fraction: bool = True,
                              known: Any = None) -> Any:
        """Not traced through a port (yet): :class:`NotApplicable`."""
        raise NotApplicable('the relative illumination is not traced through a port yet')
