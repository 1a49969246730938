# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The model's summary: scene constraints (eq. 9-25), the whole traced field and the tolerances.

Pure numpy, no ROS. Computed on first use (:attr:`mechdeconv_ros.model.model.LensModel.summary`):
they cost a few extra traces, which a model built to validate a parameter set or to correct
frames does not pay for until someone asks.

- Scene constraints (:mod:`mechdeconv_ros.optics.scene_constraints`): FOV, footprint, feature
  resolution,
  f-number ``n_f = sqrt(2/q) f / D`` (D the entrance pupil), circle of confusion, hyperfocal
  distance and depth of field about the focus distance.
- The whole field the lens passes (``covered_field``): the angle-uniform trace continued to
  the lens's limit (179 deg at infinity, 89.5 deg for a finite scene), known to 1/64 of a step.
- Tolerance sigmas, first order: ``sigma_g = sqrt(sum_i (dg/dx_i sigma_i)^2)``
  (:func:`mechdeconv_ros.optics.thick_lens.propagate_sigma`) over the lens source's tolerances, for
  g = the focal length, the hyperfocal distance and the raw image position of the corner scene
  point; NaN where a source has none or a perturbed lens is no lens.
"""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any, Callable, Mapping

from mechdeconv_ros.lenses.lens_errors import finite_or_none, FloatArray
from mechdeconv_ros.lenses.lens_source import LensSource
from mechdeconv_ros.model.projection import project_angles, unproject_angles
from mechdeconv_ros.model.radial_map import COARSE_SAMPLES, field_cap_rad, trace_angles
from mechdeconv_ros.optics import scene_constraints
from mechdeconv_ros.optics.pose import POSE_PARAMS, SensorPose
from mechdeconv_ros.optics.raytrace import MAX_CONTINUATION_STEP_RAD
from mechdeconv_ros.optics.thick_lens import propagate_sigma
from mechdeconv_ros.schema.params import scene_distance
import numpy as np


def summarize(model: Any) -> dict[str, Any]:
    """
    Derive the scene constraints (eq. 9-25) and the tolerance sigmas.

    :param model: the :class:`~mechdeconv_ros.model.model.LensModel`.
    :return: the summary (``LensModel.summary``).
    """
    vals = model.values
    distance = scene_distance(vals)
    f = model.focal_length_mm
    source: LensSource = model.source
    tolerances = source.tolerances()
    nominal, sigmas = tolerances if tolerances is not None else ({}, {})
    depth = _depth(model, nominal, sigmas, tolerances is not None, distance)
    field = _full_field(model)
    warnings = _warnings(model, distance, depth, field)
    corner_sigma = _corner_sigma_px(model, nominal, sigmas, distance, tolerances is not None)
    first = source.first_order()
    return {
        'mode': source.mode,
        'wavelength_nm': float(vals['lens.wavelength_nm']),
        'surfaces': _surfaces(model),
        'sensor_plane': _sensor(model, distance),
        'focal_length_mm': f,
        'focal_length_sigma_mm': depth['sigma_f'],
        'image_distance_mm': model.image_distance_mm,
        'principal_planes_mm': {
            'front': first.front_principal_z_mm,
            'rear': first.rear_principal_z_mm},
        'stop_z_mm': source.stop_z_mm,
        'scene_distance_mm': finite_or_none(distance),
        **_scene_geometry(model, distance),
        'f_number': depth['n_f'],
        'entrance_pupil_diameter_mm': depth['d_a'],
        'circle_of_confusion_mm': depth['c'],
        'hyperfocal_mm': depth['h'],
        'hyperfocal_sigma_mm': depth['sigma_h'],
        'focus_distance_mm': finite_or_none(depth['focus']),
        'depth_of_field_mm': {'near': depth['near'], 'far': finite_or_none(depth['far'])},
        'valid_field_mm': model.curve.valid_real_mm,
        'projection': model.projection,
        'max_field_angle_deg': field['max_field_angle_deg'],
        'covered_field': _covered_field(model, field),
        '_field_curve': field,
        'corner_sigma_px': corner_sigma,
        'sensor_pose': _sensor_pose(model),
        'warnings': warnings,
    }


def _depth(model: Any, nominal: Mapping[str, float], sigmas: Mapping[str, float], known: bool,
           distance: float) -> dict[str, float]:
    """
    Return f's sigma, the f-number, circle of confusion, hyperfocal distance and depth of field.

    :return: ``sigma_f``, ``n_f``, ``d_a`` (the entrance pupil), ``c``, ``h``, ``sigma_h``,
        ``focus``, ``near``, ``far``.
    """
    vals = model.values
    source: LensSource = model.source
    f = model.focal_length_mm

    def efl(p: Mapping[str, float]) -> float:
        return source.perturbed(p).first_order().efl_mm

    sigma_f = _sigma_or_nan(efl, nominal, sigmas, known)
    q = float(vals['lens.exposure_constant_q'])
    # The f-number's aperture is the entrance pupil (pupil_scale: 1 for the paper's thick lens).
    d_a = float(vals['lens.aperture_diameter_mm']) * source.pupil_scale()
    n_f = scene_constraints.f_number(f, d_a, q)
    c = scene_constraints.circle_of_confusion_mm(f, float(vals['scene.circle_of_confusion_mm']))
    h = scene_constraints.hyperfocal_mm(f, n_f, c)
    c_set = float(vals['scene.circle_of_confusion_mm'])

    def hyper(p: Mapping[str, float]) -> float:
        scal = dict(p)
        f_p = efl({k: v for k, v in scal.items() if k != 'd_a'})
        n_fp = scene_constraints.f_number(f_p, scal['d_a'], q)
        c_p = scene_constraints.circle_of_confusion_mm(f_p, c_set)
        return scene_constraints.hyperfocal_mm(f_p, n_fp, c_p)

    sigma_d_a = float(vals['lens.tolerance.aperture_diameter_mm']) \
        * source.pupil_scale()
    sigma_h = _sigma_or_nan(hyper, {**nominal, 'd_a': d_a}, {**sigmas, 'd_a': sigma_d_a}, known)
    focus = float(vals['scene.focus_distance_mm']) or distance
    focus = math.inf if focus == 0.0 else focus
    near, far = scene_constraints.depth_of_field_mm(h, focus)
    return {'sigma_f': sigma_f, 'n_f': n_f, 'd_a': d_a, 'c': c, 'h': h, 'sigma_h': sigma_h,
            'focus': focus, 'near': near, 'far': far}


def _warnings(model: Any, distance: float, depth: Mapping[str, float],
              field: Mapping[str, Any]) -> list[str]:
    """Return the model's warnings and the summary's: depth of field, fold, valid field."""
    edge_real = model.half_diagonal_mm
    near, far, focus = depth['near'], depth['far'], depth['focus']
    warnings = list(model.warnings)
    if not near <= distance <= far:
        warnings.append(f'scene distance {distance:g} mm is outside the depth of field '
                        f'[{near:.4g}, {far:.4g}] mm of the focus distance {focus:g} mm')
    if field['folded']:
        warnings.append(f"the real image height folds back at {field['max_field_angle_deg']:.4g} "
                        f"deg (r = {field['image_circle_radius_mm']:.4g} mm): the valid field "
                        'ends before the fold')
    if model.curve.valid_real_mm < edge_real:
        warnings.append(f'the valid field ends at {model.curve.valid_real_mm:.4g} mm, inside '
                        f'the sensor half-diagonal {edge_real:.4g} mm: corners stay black')
    return warnings


def _scene_geometry(model: Any, distance: float) -> dict[str, Any]:
    """Return the sensor size, fields of view, footprint and feature resolution (eq. 9-14)."""
    vals = model.values
    f = model.focal_length_mm
    w_mm = scene_constraints.sensor_size_mm(model.width, vals['sensor.pixel_size_x_um'])
    h_mm = scene_constraints.sensor_size_mm(model.height, vals['sensor.pixel_size_y_um'])
    return {
        'sensor_size_mm': {'x': w_mm, 'y': h_mm, 'diagonal': math.hypot(w_mm, h_mm)},
        'fov_deg': {'horizontal': scene_constraints.field_of_view_deg(w_mm, f),
                    'vertical': scene_constraints.field_of_view_deg(h_mm, f),
                    'diagonal': scene_constraints.field_of_view_deg(math.hypot(w_mm, h_mm), f)},
        'footprint_mm': {'x': finite_or_none(scene_constraints.footprint_mm(distance, w_mm, f)),
                         'y': finite_or_none(scene_constraints.footprint_mm(distance, h_mm, f))},
        'feature_resolution_mm': {
            'x': finite_or_none(scene_constraints.feature_resolution_mm(
                distance, vals['sensor.pixel_size_x_um'], f)),
            'y': finite_or_none(scene_constraints.feature_resolution_mm(
                distance, vals['sensor.pixel_size_y_um'], f))},
    }


def _sensor_pose(model: Any) -> dict[str, Any]:
    """
    Return the sensor's pose and the 1-sigma pixel shift its tolerances cause at the corner.

    The scene direction the model images at the raw corner (W - 1, H - 1) is projected with
    each pose parameter off by its ``sensor.tolerance.*`` sigma (an offset moves the axis
    pixel, a tilt the plane); the shift of its pixel is that parameter's sigma, and ``total``
    their root sum of squares.
    """
    values = model.values
    theta, phi = unproject_angles(model, np.array([model.width - 1.0]),
                                  np.array([model.height - 1.0]))
    u0, v0 = project_angles(model, theta, phi)
    sigmas: dict[str, float] = {}
    for name in POSE_PARAMS:
        short = name.split('.', 1)[1]
        changed = dict(values, **{name: float(values[name])
                                  + float(values[f'sensor.tolerance.{short}'])})
        K = np.array(model.K, dtype=np.float64)
        K[0, 2], K[1, 2] = SensorPose.from_values(changed).axis_pixel(
            model.width, model.height, model.pixel_mm)
        moved = SimpleNamespace(values=changed, K=K, pixel_mm=model.pixel_mm,
                                field_curve=model.field_curve, source=model.source)
        u, v = project_angles(moved, theta, phi)
        sigmas[short] = float(np.hypot(u - u0, v - v0)[0])
    return {
        'axis_px': [float(model.K[0, 2]), float(model.K[1, 2])],
        **{name.split('.', 1)[1]: float(values[name]) for name in POSE_PARAMS},
        'corner_sigma_px': {**sigmas, 'total': float(math.sqrt(sum(
            x * x for x in sigmas.values())))},
    }


def _surfaces(model: Any) -> list[dict[str, Any]] | None:
    """
    Return each surface's medium after it: the glass named for it and the traced index.

    :param model: the model.
    :return: ``[{'glass': 'N-BK7' or None, 'refractive_index': n}, ...]``; None without
        surfaces (a datasheet lens).
    """
    prescription = model.source.prescription
    if prescription is None:
        return None
    vals = model.values
    names = [str(n).strip() for n in vals.get('lens.surfaces.glass', [])]
    if not names and str(vals.get('lens.glass', '')).strip():
        # The thick lens: its glass fills the gap between the two surfaces (and the stop
        # plane inside it, when there is one).
        names = [str(vals['lens.glass']).strip() if s.refractive_index != 1.0 else ''
                 for s in prescription.surfaces]
    return [{'glass': (names[i] if i < len(names) and names[i] else None),
             'refractive_index': float(surface.refractive_index)}
            for i, surface in enumerate(prescription.surfaces)]


def _sensor(model: Any, distance: float) -> dict[str, Any] | None:
    """
    Return where the sensor sits against the image of the scene (``lens.image_distance_mm``).

    :param model: the model.
    :param distance: scene distance from H.
    :return: ``image_distance_mm`` (the parameter, None = on the paraxial image),
        ``defocus_mm`` (dz from the paraxial image of the scene), the blur circle's diameter in
        um and px (x pitch) and the paraxial image distance; None when the source has no
        sensor plane of its own.
    """
    defocus = model.source.defocus(distance)
    if defocus is None:
        return None
    blur = float(defocus['blur_diameter_mm'])
    setting = float(model.values.get('lens.image_distance_mm', 0.0))
    return {'image_distance_mm': setting if setting > 0.0 else None,
            'defocus_mm': float(defocus['defocus_mm']),
            'blur_diameter_um': blur * 1e3,
            'blur_diameter_px': blur / model.pixel_mm[0],
            'paraxial_image_distance_mm': float(defocus['paraxial_image_distance_mm'])}


#: Samples of the field traced beyond the sensor, to the lens's limit (for the report).
BEYOND_SAMPLES = 128


def _full_field(model: Any) -> dict[str, Any]:
    """
    Return the chief-ray curve over the whole field the lens passes, to its limit.

    The model's angle-uniform trace (``field_curve``) covers the sensor. When it ends inside
    its range (a failed ray or a fold), the interval after its last sample is traced again 64
    times finer; otherwise the field is traced on to the cap (179 deg at infinity, 89.5 deg
    for a finite scene) and the interval where it ends refined likewise, so the limit is
    known to about 1/64 of a sample step. Every trace starts its aiming from the solutions
    already known (``guide``).
    """
    curve = model.field_curve
    distance = scene_distance(model.values)
    cap = field_cap_rad(distance)
    v = model.image_distance_mm
    theta, real = curve.field_angle_rad, curve.real_mm
    guide = curve
    step = float(theta[1] - theta[0])
    if curve.ideal_mm.size == COARSE_SAMPLES and curve.max_field_angle_rad < cap:
        # The lens passes more than the sensor needs: trace on to the cap.
        beyond = np.linspace(theta[-1], cap, BEYOND_SAMPLES + 1)[1:]
        grid = np.concatenate((theta, beyond))
        traced = trace_angles(model.source, distance, v, grid, guide)
        theta, real, folded = traced.field_angle_rad, traced.real_mm, traced.folded
        guide = traced
        if traced.ideal_mm.size == grid.size:
            return _field_dict(theta, real, folded, cap)
        step = float(grid[traced.ideal_mm.size] - theta[-1])
    # Refine the last interval: where exactly the field ends.
    fine = np.concatenate((theta[-4:], theta[-1] + step * np.arange(1, 65) / 64.0))
    refined = trace_angles(model.source, distance, v, fine, guide)
    if refined.ideal_mm.size > 4:
        theta = np.concatenate((theta, refined.field_angle_rad[4:]))
        real = np.concatenate((real, refined.real_mm[4:]))
    folded = refined.folded or (refined.ideal_mm.size == fine.size and curve.folded)
    return _field_dict(theta, real, folded, cap)


def _field_dict(theta: FloatArray, real: FloatArray, folded: bool, cap: float
                ) -> dict[str, Any]:
    return {'theta_rad': theta, 'real_mm': real, 'folded': folded,
            'max_field_angle_deg': math.degrees(float(theta[-1])),
            'at_cap': bool(theta[-1] >= cap * (1.0 - 1e-9)),
            'image_circle_radius_mm': float(real[-1])}


def _covered_field(model: Any, field: Mapping[str, Any]) -> dict[str, Any]:
    """Return the field the raw image and the corrected image cover, in degrees."""
    theta, real = field['theta_rad'], field['real_mm']
    circle = field['image_circle_radius_mm']

    def angle(radius_mm: float) -> float | None:
        if not radius_mm <= circle:
            return None
        return math.degrees(float(np.interp(radius_mm, real, theta)))

    half_w = model.width / 2.0 * model.pixel_mm[0]
    half_h = model.height / 2.0 * model.pixel_mm[1]
    corner = model.half_diagonal_mm
    ideal = math.hypot(model.out_width / 2.0 / model.K_new[0, 0],
                       model.out_height / 2.0 / model.K_new[1, 1]) * model.image_distance_mm
    curve = model.curve
    out_corner = (math.degrees(float(np.interp(ideal, curve.ideal_mm, curve.field_angle_rad)))
                  if ideal <= curve.valid_ideal_mm else None)

    def full(half: float | None) -> float | None:
        return None if half is None else 2.0 * half

    return {
        'max_field_angle_deg': field['max_field_angle_deg'],
        'max_field_is_trace_limit': field['at_cap'],
        'image_circle_radius_mm': circle,
        'corners_covered': corner <= circle,
        'corner_field_angle_deg': angle(corner),
        'horizontal_deg': full(angle(half_w)),
        'vertical_deg': full(angle(half_h)),
        'diagonal_deg': full(angle(corner)),
        'output_corner_field_angle_deg': out_corner,
    }


def _corner_sigma_px(model: Any, nominal: Mapping[str, float], sigmas: Mapping[str, float],
                     distance: float, applies: bool) -> float:
    """
    Propagate the lens tolerances to the raw image position of the corner scene point.

    The scene point that the nominal model images at the raw image corner is traced through
    each perturbed lens (refocused: the sensor at its own paraxial image plane); the spread of
    its real image height, in pixels of the smaller pitch, is the correction's uncertainty there.
    """
    corner = np.array([[model.width - 1.0, model.height - 1.0]])
    x_mm = (corner[0, 0] - model.K[0, 2]) * model.pixel_mm[0]
    y_mm = (corner[0, 1] - model.K[1, 2]) * model.pixel_mm[1]
    theta = float(model.field_curve.angle_from_real(np.array(math.hypot(x_mm, y_mm))))
    if not math.isfinite(theta):
        return math.nan
    # A ladder of angles up to the corner: a wide-angle lens's chief ray is aimed by
    # continuation from the smaller angles (raytrace._aim_continued), in steps of at most
    # MAX_CONTINUATION_STEP_RAD. The ladder has those steps itself, so that the nominal
    # offsets guide every step of every perturbed lens (one or two Newton steps each); a
    # sparse ladder left the steps between its rungs unguided (about 50 traces per lens).
    steps = max(4, math.ceil(abs(theta) / (0.99 * MAX_CONTINUATION_STEP_RAD)))
    ladder = theta * np.arange(1, steps + 1) / steps
    source: LensSource = model.source
    # Each perturbed lens starts its aiming from the nominal lens's offsets at the same angles
    # (a perturbation of 1e-3 sigma moves them by far less than an aiming step): one or two
    # iterations per ray instead of a continuation from the axis, for every partial.
    try:
        _, offsets = source.perturbed(dict(nominal)).real_heights(ladder, distance)
        guide = (ladder, offsets) if np.all(np.isfinite(offsets)) else None
    except ValueError:
        guide = None

    def height(p: Mapping[str, float]) -> float:
        return float(source.perturbed(p).real_heights(ladder, distance, guide)[0][-1])

    return _sigma_or_nan(height, nominal, sigmas, applies) / min(model.pixel_mm)


def _sigma_or_nan(fn: Callable[[Mapping[str, float]], float], nominal: Mapping[str, float],
                  sigmas: Mapping[str, float], applies: bool = True) -> float:
    """
    Propagate tolerances, or return NaN where a perturbed lens is no lens at all.

    Near the edge of the parameter space (an almost afocal lens, a thickness at 0) a
    perturbation by one sigma can leave it; the sigma is then undefined, not an error. It is
    NaN too where the lens source has no tolerances (``applies`` False).
    """
    if not applies:
        return math.nan
    try:
        sigma = propagate_sigma(fn, dict(nominal), dict(sigmas))
    except (ValueError, ZeroDivisionError, FloatingPointError, OverflowError):
        return math.nan
    return float(sigma) if math.isfinite(sigma) else math.nan
