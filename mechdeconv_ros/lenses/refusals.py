# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Refusals: the physical rules a parameter set must pass to describe a camera that can exist.

Pure Python and numpy, no ROS. Each rule names the parameter at fault and the limit in a
:class:`~mechdeconv_ros.lenses.lens_errors.ModelError`; unusual but possible values give warnings.
The rules, their formulas and limits are listed in docs/design.md section 7. Two kinds:

- rules every lens source obeys, which need only its paraxial data: a focus distance outside
  f and in front of H (:func:`check_focus_distance`), a circle of confusion no wider than the
  sensor (:func:`check_circle_of_confusion`);
- rules on surfaces (:func:`check_surfaces`), for a source with a prescription: the image plane
  behind the last surface, the stop between scene and image plane, semi-diameters within a
  surface's rim, an aperture the surfaces pass (paraxial marginal ray), edge thicknesses
  ``t - sag1(a) + sag2(a) >= 0``, and the warnings for a far stop and f/0.7 or faster.

The sagitta of a surface at height a is ``c a^2 / (1 + sqrt(1 - (1 + k) c^2 a^2))`` plus the
even asphere terms (:func:`mechdeconv_ros.optics.surfaces.sag_at_height`); the paraxial rays
(beam heights, the marginal ray, the entrance pupil, the glass elements) are
:mod:`mechdeconv_ros.optics.paraxial_rays`.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Mapping

from mechdeconv_ros.lenses.lens_errors import (
    FloatArray, is_prescription_mode, ModelError, stop_param)
from mechdeconv_ros.optics import scene_constraints
from mechdeconv_ros.optics.paraxial_rays import (
    entrance_pupil_scale, glass_elements, marginal_ray, paraxial_height)
from mechdeconv_ros.optics.prescription import Prescription, Surface, vertex_z
from mechdeconv_ros.optics.surfaces import domain_limit_mm, is_spherical, sag_at_height
from mechdeconv_ros.schema.params import scene_distance


#: f-numbers below this are accepted with a warning (few production lenses are faster).
FAST_F_NUMBER = 0.7
#: A stop farther than this many focal lengths outside the lens is accepted with a warning.
FAR_STOP_FOCAL_LENGTHS = 1.0
#: Relative slack of the aperture and edge-thickness limits (rounding of given values).
LIMIT_SLACK = 1e-9


def _shape(surface: Surface) -> str:
    """Name a surface's shape for a reason: 'a spherical surface of radius 4 mm'."""
    if is_spherical(surface):
        return f'a spherical surface of radius {surface.radius_mm:g} mm'
    return f'a conic surface (k = {surface.conic:g}) of radius ' \
           f'{surface.radius_mm:g} mm'


def pupil_scale(values: Mapping[str, Any], prescription: Prescription) -> float:
    """
    Return entrance pupil diameter / ``lens.aperture_diameter_mm`` (the f-number's aperture).

    ``lens.aperture_diameter_mm`` is the physical stop. The f-number ``n_f = sqrt(2/q) f / D``
    counts the entrance pupil D, the stop as seen from the scene. Thick-lens mode keeps the
    paper's D = d_a (its stop stands near the front principal plane; exact for a stop in
    front of the lens), so its constraints reproduce the paper. A prescription's stop may sit
    behind strong elements (a fisheye's stop is about 6x its entrance pupil), so there D is the
    paraxial image of the stop in object space: a marginal ray entering parallel at height 1
    crosses the stop at height ``a`` and D = d_a / |a|.

    :param values: checked parameter values.
    :param prescription: the lens of those values.
    :return: the factor, 1 in thick-lens mode.
    """
    if not is_prescription_mode(values):
        return 1.0
    return entrance_pupil_scale(prescription)


def _edge_crossing(surfaces: tuple[Surface, ...], z_vertices: FloatArray, element: list[int],
                   heights: list[float], d_a: float) -> tuple[int, int, float, float] | None:
    """
    Return where an element's surfaces cross at its clear semi-aperture, or None.

    The clear semi-aperture ``a`` is the widest of the axial beam (``heights`` per unit
    aperture radius times ``d_a / 2``) and the given semi-diameters on the element's surfaces;
    the edge thickness between consecutive surfaces is ``z_j + sag_j(a) - z_i - sag_i(a)``.

    :return: (i, j, edge thickness, a) of the first pair that crosses.
    """
    semi_aperture = max(max(heights[i] * d_a / 2.0 for i in element),
                        max(surfaces[i].semi_diameter_mm for i in element))
    for i, j in zip(element[:-1], element[1:]):
        edge = (float(z_vertices[j]) + sag_at_height(surfaces[j], semi_aperture)
                - float(z_vertices[i]) - sag_at_height(surfaces[i], semi_aperture))
        if edge < -LIMIT_SLACK * max(1.0, semi_aperture):
            return i, j, edge, semi_aperture
    return None


def check_focus_distance(vals: Mapping[str, Any], efl_mm: float,
                         front_principal_z_mm: float) -> None:
    """
    Refuse a focus distance the lens cannot be focused at: the rules of the scene distance.

    :param vals: checked parameter values (``scene.focus_distance_mm``, 0 = the scene).
    :param efl_mm: the focal length f.
    :param front_principal_z_mm: z of H.
    :raises ModelError: naming ``scene.focus_distance_mm`` for a focus inside f or the lens.
    """
    f = efl_mm
    focus = float(vals['scene.focus_distance_mm'])
    if focus > 0.0:
        if focus <= f:
            raise ModelError('scene.focus_distance_mm',
                             f'{focus:g} mm is inside the focal length {f:.4g} mm: the lens '
                             'cannot be focused there (it forms no real image of it; the '
                             f'focus distance must be above {f:.4g} mm, or 0 = the scene '
                             'distance)')
        if front_principal_z_mm - focus >= 0.0:
            raise ModelError('scene.focus_distance_mm',
                             f'{focus:g} mm from the front principal plane puts the plane in '
                             f'focus inside the lens (it must be above '
                             f'{front_principal_z_mm:.4g} mm)')


def check_surfaces(vals: Mapping[str, Any], prescription: Prescription, para: Any,
                   distance: float, sensor_z: float) -> list[str]:
    """
    Refuse surfaces that cannot exist; return warnings for an unusual lens.

    The rules, each with its parameter, formula and limit, are listed in docs/design.md section 7.
    They run in this order, the first that fails refuses: the image plane behind the last
    surface, the stop between scene and image plane, semi-diameters within their surfaces,
    an axial beam that can be traced, an aperture the surfaces pass, edge thicknesses.

    :param vals: checked parameter values.
    :param prescription: the lens of those values.
    :param para: its paraxial data (:func:`mechdeconv_ros.optics.prescription.paraxial`).
    :param distance: scene distance from H, mm (``math.inf`` allowed).
    :param sensor_z: z of the paraxial image plane (the sensor).
    :raises ModelError: naming the parameter, why, and the limit.
    :return: warnings about physically possible but unusual values.
    """
    _check_image_plane(vals, para, sensor_z)
    stop = _check_stop(vals, prescription, para, distance, sensor_z)
    _check_semi_diameters(prescription)
    d_a = float(vals['lens.aperture_diameter_mm'])
    heights = _beam_heights(prescription, para, distance, stop)
    elements = glass_elements(prescription)
    _check_aperture(prescription, heights, elements, d_a, stop)
    _check_edges(vals, prescription, heights, elements, d_a)
    return _unusual(vals, prescription, para, d_a, stop)


def _thickness_name(vals: Mapping[str, Any]) -> str:
    return 'lens.surfaces.thickness_mm' if is_prescription_mode(vals) else 'lens.thickness_mm'


def _check_image_plane(vals: Mapping[str, Any], para: Any, sensor_z: float) -> None:
    """Refuse an image plane (the sensor) that is not behind the last surface, in air."""
    z_last = para.last_vertex_z_mm
    if sensor_z <= z_last:
        raise ModelError(_thickness_name(vals),
                         f'the image plane falls at z = {sensor_z:.4g} mm, not behind '
                         f'the last surface at z = {z_last:.4g} mm: the sensor would '
                         'have to sit inside the lens (the back focal distance must be '
                         'positive)')


@dataclass(frozen=True)
class _Stop:
    """The stop as the reasons name it: its parameter and value, its z, where it is."""

    name: str
    value: Any
    z_mm: float
    where: str


def _check_stop(vals: Mapping[str, Any], prescription: Prescription, para: Any,
                distance: float, sensor_z: float) -> _Stop:
    """Refuse a stop that is not between the scene and the image plane; return the stop."""
    prescription_mode = is_prescription_mode(vals)
    z_stop = prescription.stop_z_mm
    stop_name = stop_param(vals)
    if prescription_mode:
        where = f'surface {int(vals["lens.stop_surface"])} at z = {z_stop:.4g} mm'
    else:
        where = f'{float(vals["lens.stop_offset_mm"]):g} mm puts the stop at z = {z_stop:.4g} mm'
    if z_stop >= sensor_z:
        limit = ('' if prescription_mode else
                 f' (the offset must be above {para.front_principal_z_mm - sensor_z:.4g} mm)')
        raise ModelError(stop_name, f'{where}, at or behind the image plane at z = '
                                    f'{sensor_z:.4g} mm: no light reaches the sensor through '
                                    f'an aperture behind it{limit}')
    z_scene = para.front_principal_z_mm - distance
    if z_stop <= z_scene:
        limit = ('' if prescription_mode else
                 f' (the offset must be below the scene distance {distance:g} mm)')
        raise ModelError(stop_name, f'{where}, at or in front of the scene at z = '
                                    f'{z_scene:.4g} mm: the aperture must lie between the '
                                    f'scene and the lens{limit}')
    return _Stop(stop_name, vals[stop_name], z_stop, where)


def _check_semi_diameters(prescription: Prescription) -> None:
    """Clear apertures: a sphere is at most 2|r| wide; a conic's rim bounds it likewise."""
    for i, surface in enumerate(prescription.surfaces):
        semi, rim = surface.semi_diameter_mm, domain_limit_mm(surface)
        if semi > rim * (1.0 + LIMIT_SLACK):
            raise ModelError('lens.surfaces.semi_diameter_mm',
                             f'surface {i}: a clear semi-diameter of {semi:g} mm is wider than '
                             f'{_shape(surface)} can be (at most '
                             + (f'|r| = {rim:.6g} mm, a hemisphere)' if is_spherical(surface)
                                else f'{rim:.6g} mm, its rim)'))


def _beam_heights(prescription: Prescription, para: Any, distance: float,
                  stop: _Stop) -> list[float]:
    """Return the axial beam's height at every vertex per unit aperture radius (d_a / 2 = 1)."""
    h, u = marginal_ray(prescription, distance, para.front_principal_z_mm)
    if not (math.isfinite(h) and math.isfinite(u)):
        raise ModelError(stop.name, f'{stop.where} sits at an image of the scene (the axial '
                                    'beam focuses there): it would bound the field, not the '
                                    'aperture')
    heights = [abs(paraxial_height(prescription, h, u, float(z)))
               for z in vertex_z(prescription)]
    if not all(math.isfinite(y) for y in heights):
        raise ModelError(stop.name, f'{stop.where}: the axial beam through it cannot be traced '
                                    '(the paraxial marginal ray overflows): the stop is at or '
                                    'next to an image of the scene')
    return heights


def _check_aperture(prescription: Prescription, heights: list[float],
                    elements: list[list[int]], d_a: float, stop: _Stop) -> None:
    """Refuse a stop whose axial beam does not pass every rim and given semi-diameter."""
    real = {i for element in elements for i in element}
    bound, culprit, at = math.inf, '', 0
    for i, surface in enumerate(prescription.surfaces):
        semi, rim = surface.semi_diameter_mm, domain_limit_mm(surface)
        if heights[i] <= 0.0:
            continue
        if i in real and rim / heights[i] < bound:
            bound, at = rim / heights[i], i
            culprit = (f'the {2 * rim:.6g} mm diameter '
                       f'{"(2|r|) " if is_spherical(surface) else ""}of surface {i}, '
                       f'{_shape(surface)}')
        if semi > 0.0 and semi / heights[i] < bound:
            bound, at = semi / heights[i], i
            culprit = (f'the {2 * semi:g} mm clear diameter of surface {i} (2 x '
                       f'lens.surfaces.semi_diameter_mm[{i}])')
    if d_a / 2.0 > bound * (1.0 + LIMIT_SLACK):
        raise ModelError('lens.aperture_diameter_mm',
                         f'{d_a:g} mm (stop diameter) is wider than the surfaces allow: its '
                         f'axial beam is {d_a * heights[at]:.4g} mm wide at surface {at}, '
                         f'wider than {culprit}; with the stop where {stop.name} = '
                         f'{stop.value:g} puts it (z = {stop.z_mm:.4g} mm) the largest aperture '
                         f'is {2.0 * bound:.4g} mm (paraxial marginal ray)')


def _check_edges(vals: Mapping[str, Any], prescription: Prescription, heights: list[float],
                 elements: list[list[int]], d_a: float) -> None:
    """Edge thickness of every glass element at its clear semi-aperture: no crossing surfaces."""
    surfaces = prescription.surfaces
    z_vertices = vertex_z(prescription)
    for element in elements:
        crossing = _edge_crossing(surfaces, z_vertices, element, heights, d_a)
        if crossing is None:
            continue
        i, j, edge, semi_aperture = crossing
        centre = float(z_vertices[j] - z_vertices[i])
        if _edge_crossing(surfaces, z_vertices, element, heights, 0.0) is not None:
            smaller = 'the semi-diameters lens.surfaces.semi_diameter_mm smaller'
        else:
            lo, hi = 0.0, d_a   # the largest aperture with a non-negative edge, by bisection
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (lo, mid) if _edge_crossing(surfaces, z_vertices, element, heights,
                                                     mid) else (mid, hi)
            smaller = f'lens.aperture_diameter_mm at most {lo:.4g} mm'
        which = (f'the glass between surfaces {i} and {j} ({centre:g} mm thick at the '
                 'centre)' if is_prescription_mode(vals) else f'the lens ({centre:g} mm thick '
                 'at the centre)')
        raise ModelError(_thickness_name(vals),
                         f'{which} has an edge thickness of {edge:.4g} mm at its '
                         f'{semi_aperture:.4g} mm clear semi-aperture: its surfaces cross '
                         f'(t - sag1(a) + sag2(a) < 0). It must be at least '
                         f'{centre - edge:.4g} mm thick at the centre, or {smaller}')


def _unusual(vals: Mapping[str, Any], prescription: Prescription, para: Any, d_a: float,
             stop: _Stop) -> list[str]:
    """Return the warnings: a stop far outside the lens, a very fast aperture."""
    f = para.efl_mm
    z_stop, z_last, stop_name = stop.z_mm, para.last_vertex_z_mm, stop.name
    warnings: list[str] = []
    outside = max(-z_stop, z_stop - z_last, 0.0)
    if outside > FAR_STOP_FOCAL_LENGTHS * f:
        side = 'in front of the first' if z_stop < 0.0 else 'behind the last'
        warnings.append(f'{stop_name}: the stop is {outside:.4g} mm {side} surface, farther '
                        f'than the focal length {f:.4g} mm: an unusual design (strong '
                        'distortion and vignetting)')
    n_f = scene_constraints.f_number(f, d_a * pupil_scale(vals, prescription),
                                     float(vals['lens.exposure_constant_q']))
    if n_f < FAST_F_NUMBER:
        warnings.append(f'lens.aperture_diameter_mm: f/{n_f:.3g} is faster than '
                        f'f/{FAST_F_NUMBER:g}; few real lenses are (f/0.5 is the limit of an '
                        'aplanatic lens in air)')
    return warnings


def check_circle_of_confusion(vals: Mapping[str, Any], f: float, width_mm: float,
                              height_mm: float) -> None:
    """
    Refuse a circle of confusion larger than the sensor diagonal of the model's image size.

    :raises ModelError: naming ``scene.circle_of_confusion_mm``.
    """
    c_set = float(vals['scene.circle_of_confusion_mm'])
    c = scene_constraints.circle_of_confusion_mm(f, c_set)
    diagonal = math.hypot(width_mm, height_mm)
    if c > diagonal * (1.0 + LIMIT_SLACK):
        value = f'{c:g} mm' if c_set > 0.0 else f'0 (0.1 % of f = {c:.4g} mm)'
        raise ModelError('scene.circle_of_confusion_mm',
                         f'{value} is larger than the {diagonal:.4g} mm diagonal of the '
                         f'{width_mm:.4g} x {height_mm:.4g} mm sensor: a blur wider than the '
                         f'image defines no depth of field (it must be at most '
                         f'{diagonal:.4g} mm)')


def check_first_order(vals: Mapping[str, Any], source: Any) -> tuple[float, float, float, float]:
    """
    Apply the paraxial rules of every lens source: a converging lens, a real image, a focus.

    :param vals: checked parameter values.
    :param source: the :class:`~mechdeconv_ros.lenses.lens_source.LensSource`.
    :return: ``(f, scene distance l, z of the image plane, image distance v)``, mm.
    :raises ModelError: naming the parameter (the lens, ``scene.distance_mm``,
        ``scene.focus_distance_mm``).
    """
    para = source.first_order()
    f = para.efl_mm
    if f <= 0.0:
        raise ModelError(source.lens_parameter,
                         f'the lens diverges (f = {f:.4g} mm): it forms no real image of the '
                         'scene on a sensor')
    distance = scene_distance(vals)
    if distance <= f:
        raise ModelError('scene.distance_mm',
                         f'{distance:g} mm is inside the focal length {f:.4g} mm: the lens '
                         'forms no real image of it')
    if math.isfinite(distance) and para.front_principal_z_mm - distance >= 0.0:
        raise ModelError('scene.distance_mm',
                         f'{distance:g} mm from the front principal plane puts the scene inside '
                         'the lens')
    try:
        sensor_z, v = source.image_plane(distance)
    except ModelError:
        raise       # already names its parameter (lens.image_distance_mm)
    except ValueError as err:
        raise ModelError('scene.distance_mm', str(err)) from None
    check_focus_distance(vals, f, para.front_principal_z_mm)
    return f, distance, sensor_z, v
