# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Where the sensor sits: the paraxial image plane, or ``lens.image_distance_mm`` behind the lens.

Pure numpy, no ROS. Conventions of docs/design.md section 1 (mm, z along the axis from the
first vertex, light towards +z). ``lens.image_distance_mm`` = d > 0 puts the sensor at
z_s = z_last + d (z_last the last vertex); d = 0 keeps it on the paraxial image plane of the
scene (in focus). Chief rays are traced to the sensor and land where they meet it.

Raw pinhole (the camera_info K): its focal length is the paraxial chief ray's height on the
sensor per unit tan(theta),

    v_K = -y_s(tan theta = 1),

the paraxial ray from the scene point through the centre of the stop, followed to z_s with
the ABCD matrices of :func:`mechdeconv_ros.optics.prescription.paraxial_matrix`. On the paraxial
image plane every ray of the point meets there, so v_K = v (the image distance from H', as
before); off it the image scales about the exit pupil: for a lens whose exit pupil lies at H'
(a thin lens with the stop at it) v_K = v + dz, i.e. heights scale by (v + dz) / v. So K
describes where near-axis rays actually land and the radial map keeps slope 1 at the axis:
defocus changes K, not the distortion.

Defocus (``mechdeconv info``): dz = z_s - z_image (z_image the paraxial image plane of the
scene); blur-circle diameter B = 2 |y_m(z_s)|, y_m the paraxial marginal ray from the axial
scene point through the rim of the stop (diameter ``lens.aperture_diameter_mm``, i.e. through
the rim of the entrance pupil): B = 0 in focus, B = D dz / v for a thin lens with its stop on
it, D the pupil diameter.

Refusals (``lens.image_distance_mm``): the sensor must clear the last surface's rim (d must
exceed that surface's sagitta at its clear semi-aperture when it bulges towards the sensor);
and v_K must be positive: v_K is linear in z_s, v on the image plane and 0 at the exit pupil
(where the chief rays cross the axis behind the lens), so a sensor across a real exit pupil
from the image would see the scene upright through a blur, no camera image.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from mechdeconv_ros.lenses.lens_errors import ModelError
from mechdeconv_ros.optics.prescription import (
    image_plane, paraxial_matrix, Prescription, surfaces_before, vertex_z)
from mechdeconv_ros.optics.surfaces import sag_at_height

PARAMETER = 'lens.image_distance_mm'


@dataclass(frozen=True)
class SensorPlane:
    """
    The sensor's plane for one scene distance.

    ``z_mm``: the sensor; ``v_mm``: the raw pinhole's focal length (image distance) there;
    ``image_z_mm``/``image_v_mm``: the paraxial image plane of the scene and its v from H';
    ``defocus_mm`` = z_mm - image_z_mm.
    """

    z_mm: float
    v_mm: float
    image_z_mm: float
    image_v_mm: float

    @property
    def defocus_mm(self) -> float:
        """Return the sensor's distance behind the paraxial image of the scene (mm)."""
        return self.z_mm - self.image_z_mm


def _ray_height(prescription: Prescription, z_start: float, y: float, nu: float,
                z_end: float) -> float:
    """Return the paraxial ray (height y, reduced slope n u at z_start) at the plane z_end."""
    a, b, _, _ = paraxial_matrix(prescription, surfaces_before(prescription, z_end), z_start,
                                 z_end)
    return a * y + b * nu


def _start_z(prescription: Prescription, distance: float, front_principal_z: float) -> float:
    """Return a plane in object space to start paraxial rays from (the scene when finite)."""
    if math.isfinite(distance):
        return front_principal_z - distance
    return min(0.0, prescription.stop_z_mm) - 1.0


def chief_ray_scale(prescription: Prescription, distance: float, front_principal_z: float,
                    z_mm: float) -> float:
    """
    Return the paraxial chief ray's height on a plane per unit tan(theta), image inverted > 0.

    :param prescription: the lens.
    :param distance: scene distance from H (``math.inf`` allowed).
    :param front_principal_z: z of H.
    :param z_mm: the plane (behind the lens).
    :return: v_K (mm); NaN when the stop sits at an image of the scene (no chief ray).
    """
    z0 = _start_z(prescription, distance, front_principal_z)
    z_stop = prescription.stop_z_mm
    n0 = prescription.object_index
    if math.isfinite(distance):
        # Scene point at height Y = l (tan theta = 1 seen from H); choose n u to hit the stop
        # centre: y_stop = A_s Y + B_s n u = 0.
        a_s = _ray_height(prescription, z0, 1.0, 0.0, z_stop)
        b_s = _ray_height(prescription, z0, 0.0, 1.0, z_stop)
        if b_s == 0.0:
            return math.nan
        y, nu = distance, -a_s * distance / b_s
    else:
        # Parallel rays from a scene point above the axis descend: slope u = -1 (tan theta =
        # 1); choose the height at z0 to hit the stop centre: A_s y - B_s n0 = 0.
        a_s = _ray_height(prescription, z0, 1.0, 0.0, z_stop)
        b_s = _ray_height(prescription, z0, 0.0, 1.0, z_stop)
        if a_s == 0.0:
            return math.nan
        y, nu = b_s * n0 / a_s, -n0
    return -_ray_height(prescription, z0, y, nu, z_mm)


def blur_diameter_mm(prescription: Prescription, distance: float, front_principal_z: float,
                     z_mm: float, stop_diameter_mm: float) -> float:
    """
    Return the geometric blur-circle diameter of the axial scene point on a plane.

    :param prescription: the lens.
    :param distance: scene distance from H (``math.inf`` allowed).
    :param front_principal_z: z of H.
    :param z_mm: the plane.
    :param stop_diameter_mm: the physical stop's diameter.
    :return: 2 |y_m(z)|, the marginal ray through the stop rim (mm); NaN when undefined.
    """
    z0 = _start_z(prescription, distance, front_principal_z)
    z_stop = prescription.stop_z_mm
    rim = stop_diameter_mm / 2.0
    if math.isfinite(distance):
        at_stop = _ray_height(prescription, z0, 0.0, 1.0, z_stop)
        ray = (0.0, rim / at_stop) if at_stop != 0.0 else None
    else:
        at_stop = _ray_height(prescription, z0, 1.0, 0.0, z_stop)
        ray = (rim / at_stop, 0.0) if at_stop != 0.0 else None
    if ray is None:
        return math.nan
    return 2.0 * abs(_ray_height(prescription, z0, ray[0], ray[1], z_mm))


def sensor_plane(prescription: Prescription, distance: float, front_principal_z: float,
                 image_distance_mm: float, stop_diameter_mm: float) -> SensorPlane:
    """
    Return the sensor plane a scene distance and ``lens.image_distance_mm`` give.

    :param prescription: the lens.
    :param distance: scene distance from H (``math.inf`` allowed).
    :param front_principal_z: z of H.
    :param image_distance_mm: last vertex to sensor; 0 = the paraxial image plane.
    :param stop_diameter_mm: the stop's diameter (``lens.aperture_diameter_mm``), which
        bounds the part of the last surface light uses when it has no semi-diameter.
    :return: the plane.
    :raises ValueError: when the scene forms no real image (from ``image_plane``).
    :raises ModelError: naming ``lens.image_distance_mm`` when the sensor would cut the last
        surface or sit in front of the exit pupil.
    """
    image_z, image_v = image_plane(prescription, distance)
    if image_distance_mm <= 0.0:
        return SensorPlane(image_z, image_v, image_z, image_v)
    z_last = float(vertex_z(prescription)[-1])
    last = prescription.surfaces[-1]
    semi = last.semi_diameter_mm
    if semi <= 0.0:
        # No clear semi-diameter given: the axial beam's height there bounds the glass used.
        semi = 0.5 * blur_diameter_mm(prescription, distance, front_principal_z, z_last,
                                      stop_diameter_mm)
    bulge = sag_at_height(last, semi) if math.isfinite(semi) else 0.0
    if image_distance_mm <= bulge:
        raise ModelError(PARAMETER, f'{image_distance_mm:g} mm puts the sensor inside the last '
                                    f'surface, which bulges {bulge:.4g} mm behind its vertex at '
                                    f'its {semi:.4g} mm clear semi-aperture: it must be more '
                                    f'than {bulge:.4g} mm')
    z_sensor = z_last + image_distance_mm
    v = chief_ray_scale(prescription, distance, front_principal_z, z_sensor)
    if not v > 0.0:
        # v_K is linear in z and equals v > 0 on the image plane: it vanishes where the chief
        # rays cross the axis behind the lens (the exit pupil).
        z_pupil = image_z - image_v * (z_sensor - image_z) / (v - image_v) \
            if v != image_v else math.nan
        raise ModelError(PARAMETER, f'{image_distance_mm:g} mm puts the sensor at z = '
                                    f'{z_sensor:.4g} mm, across the exit pupil (z = '
                                    f'{z_pupil:.4g} mm, where the chief rays cross the axis) '
                                    f'from the image of the scene (z = {image_z:.4g} mm): the '
                                    f'image scale there is {v:.4g} mm, no camera image forms')
    return SensorPlane(z_sensor, v, image_z, image_v)
