# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Paraxial rays through a prescription: heights, the axial marginal ray, the pupil, the elements.

Pure Python, no ROS; what the refusal rules (:mod:`mechdeconv_ros.lenses.refusals`) measure a
lens with. Lengths in mm, z from the first vertex, light along +z (conventions of
:mod:`mechdeconv_ros.optics.prescription`). A paraxial ray (height ``y``, reduced slope
``n u``) is transferred over a distance d by ``y += d (n u) / n`` and refracted at a vertex by
``n u -= (n' - n) c y`` (:func:`paraxial_height`). The axial marginal ray through the rim of a
stop of unit radius (:func:`marginal_ray`) gives the beam height at every surface per unit
aperture radius; the entrance pupil is the stop imaged into object space
(:func:`entrance_pupil_scale`); the glass elements are the runs of surfaces joined by glass
(:func:`glass_elements`).
"""

from __future__ import annotations

import math

from mechdeconv_ros.optics.prescription import Prescription, vertex_z


def paraxial_height(prescription: Prescription, h: float, u: float, z_end: float) -> float:
    """
    Return the height at the plane ``z_end`` of a paraxial ray.

    The ray has height ``h`` at the first-vertex plane z = 0 and slope ``u`` in object space
    (a line there, so ``z_end < 0`` is on it); transfers are ``y += d (n u) / n`` and
    refractions ``n u -= (n' - n) c y`` at every vertex before ``z_end``.
    """
    index = prescription.object_index
    y, nu, z = h, index * u, 0.0
    if z_end <= 0.0:
        return h + u * z_end
    for z_vertex, surface, before in zip(vertex_z(prescription), prescription.surfaces,
                                         range(len(prescription.surfaces))):
        if z_vertex > z_end:
            break
        y += (float(z_vertex) - z) * nu / index
        nu -= (surface.refractive_index - prescription.index_before(before)) \
            * surface.curvature_per_mm * y
        z, index = float(z_vertex), surface.refractive_index
    return y + (z_end - z) * nu / index


def marginal_ray(prescription: Prescription, distance: float, front_principal_z: float
                 ) -> tuple[float, float]:
    """
    Return the axial marginal ray ``(h, u)`` through the rim of a stop of unit radius.

    ``lens.aperture_diameter_mm`` is the physical diameter of the stop (at
    ``lens.stop_surface`` in prescription mode), not its image in object space: the ray leaves
    the axial scene point (or comes parallel from infinity) and crosses the stop plane at
    height 1. The vignetting trace clips at the same stop.

    :return: height at z = 0 and object-space slope (``u`` is inf when the stop sits at an
        image of the scene, where the axial beam has no height).
    """
    z_stop = prescription.stop_z_mm
    if math.isinf(distance):
        at_stop = paraxial_height(prescription, 1.0, 0.0, z_stop)
        return (1.0 / at_stop if at_stop != 0.0 else math.inf), 0.0
    z_scene = front_principal_z - distance
    at_stop = paraxial_height(prescription, -z_scene, 1.0, z_stop)
    u = 1.0 / at_stop if at_stop != 0.0 else math.inf
    return -z_scene * u, u


def entrance_pupil_scale(prescription: Prescription) -> float:
    """
    Return entrance pupil diameter / stop diameter: the paraxial image of the stop in object space.

    A marginal ray entering parallel at height 1 crosses the stop at height ``a``; the entrance
    pupil is the stop's diameter divided by ``|a|`` (1 when ``a`` is 0 or not finite).

    :param prescription: the lens, its stop at ``stop_z_mm``.
    :return: the factor.
    """
    a = abs(paraxial_height(prescription, 1.0, 0.0, prescription.stop_z_mm))
    return 1.0 / a if a > 0.0 and math.isfinite(a) else 1.0


def glass_elements(prescription: Prescription) -> list[list[int]]:
    """
    Return the glass elements: runs of surfaces joined by glass (index > 1 between them).

    Surfaces with the same index on both sides refract nothing (dummy planes, such as a stop
    inside the glass) and are left out.
    """
    out: list[list[int]] = []
    current: list[int] = []
    for i, surface in enumerate(prescription.surfaces):
        if surface.refractive_index == prescription.index_before(i):
            continue
        current.append(i)
        if surface.refractive_index == 1.0:
            if len(current) > 1:
                out.append(current)
            current = []
    return out
