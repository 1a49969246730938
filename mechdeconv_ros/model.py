# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
LensModel: from a physical lens description to raw intrinsics, a radial map and an equivalent D.

The model (Lim & Furukawa 2008, with the distortion traced instead of approximated):

1. The lens is a thick lens (two spherical surfaces, eq. 7-8) or a general prescription. Its
   paraxial data give the focal length ``f``, the principal planes ``H``, ``H'`` and, for a scene
   at distance ``l`` in front of ``H``, the image distance ``v = f l / (l - f)`` behind ``H'``
   (``v = f`` for ``l = inf``). The sensor sits at that paraxial image plane.
2. The raw camera is the pinhole that the paraxial lens is: ``f_x = v / p_x``, ``f_y = v / p_y``
   (pixel pitches in mm), principal point at the image centre ``((W-1)/2, (H-1)/2)``.
3. Distortion is radial (the paper's assumption 3). The exact chief ray of a scene point at
   field ``tan(theta)`` (seen from ``H``) lands at the real height ``rho_real`` on the sensor,
   where the pinhole puts it at ``rho_ideal = v tan(theta)``. Sampling gives the radial map
   ``rho_real = R(rho_ideal)``; it ends where a ray fails (miss, TIR, vignetting) or ``R`` stops
   increasing, and beyond that nothing is valid.
4. The corrected image is a pinhole with camera matrix ``K_new = diag(k f_x, k f_y, 1)`` centred
   on the output image; ``k`` interpolates between the zoom that keeps only valid pixels
   (``alpha = 0``) and the one that keeps every source pixel (``alpha = 1``), as OpenCV's
   getOptimalNewCameraMatrix does (but with one scale for both axes, so the pixel aspect is
   kept).
5. The equivalent calibration (``camera_info``'s D) is one of the models ROS consumers read,
   fitted to the traced field: plumb_bob ``r_d = r_u (1 + k1 r_u^2 + k2 r_u^4 + k3 r_u^6)``,
   rational_polynomial ``r_d (1 + k4 r_u^2 + k5 r_u^4 + k6 r_u^6) = r_u (1 + k1 r_u^2 +
   k2 r_u^4 + k3 r_u^6)`` (``r_u = tan(theta)``) or equidistant (Kannala-Brandt, cv2.fisheye)
   ``r_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``, with
   ``r_d = rho_real / v``. Each is fitted by least squares refined towards the minimax, then
   measured by its LARGEST displacement over the raw image (where a consumer's rectification
   map puts each raw pixel against the trace); the first in that order within 0.05 px is
   published, else the one with the smallest error (``equivalent_max_error_px``). Pinhole
   models cannot describe a field of 90 deg or more.
6. The field is traced by angle: the chief-ray angle theta of every sample is kept, and
   ``output.projection`` makes the corrected image a pinhole (``rho_ideal = v tan(theta)``, at
   most 85 deg) or an ideal fisheye (``equidistant``, ``rho_ideal = v theta``, any field, past
   90 deg for a scene at infinity). Where the real height folds back or a ray fails the valid
   field ends (a fold is reported as a warning).
7. Before any of it, :func:`build_model` refuses a parameter set that describes no camera that
   can exist (a focus distance inside f, a stop behind the image plane or in front of the
   scene, an aperture wider than the surfaces, crossing surfaces, an image inside the glass, a
   circle of confusion wider than the sensor) with a :class:`ModelError` that names the
   parameter and the limit, and notes unusual but possible values (a far stop, f/0.7) in
   ``LensModel.warnings``. The rules and their formulas: docs/design.md section 7.

Pixel coordinates follow OpenCV and ROS (REP-103 optical frame): x right, y down, origin at the
centre of the top-left pixel.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import functools
import math
from typing import Any, Callable, Mapping

from mechdeconv_ros import constraints
from mechdeconv_ros.illumination import Illumination, relative_illumination
from mechdeconv_ros.optics import biconvex_for_focal_length, propagate_sigma, thick_lens
from mechdeconv_ros.params import (
    ASPHERE_POWERS, check_values, INTERPOLATIONS, MAX_FRAME_PIXELS, ParamValue)
from mechdeconv_ros.raytrace import (
    image_plane, paraxial, Prescription, Surface, trace_field, trace_field_angles, vertex_z)
from mechdeconv_ros.surfaces import domain_limit_mm, is_spherical
import numpy as np
import numpy.typing as npt
import yaml

FloatArray = npt.NDArray[np.float64]

#: Samples of the angle-uniform trace that finds the field, K_new and the equivalent
#: calibration (its linear interpolation is good to ~1e-7 rad; it also guides the dense trace).
COARSE_SAMPLES = 512
#: Samples of the radial map (at least 1024 from 0 to past the output corner: docs/design.md
#: section 2.5).
CURVE_SAMPLES = 2048
#: Largest field angle a pinhole (rectilinear) output shows: its radial magnification
#: 1/cos^2(theta) grows without bound towards 90 deg (11x at 73, 130x at 85 deg).
PINHOLE_MAX_FIELD_DEG = 85.0
#: Largest field angle traced for a scene at infinity (a fisheye sees behind its front
#: vertex; 180 deg would be the axis behind the camera), and for a finite scene plane (whose
#: height l tan(theta) is infinite at 90 deg).
MAX_FIELD_DEG_INFINITE = 179.0
MAX_FIELD_DEG_FINITE = 89.5
#: OpenCV interpolation flags by the names ``output.interpolation`` accepts.
CV_INTERPOLATION = {'nearest': 0, 'linear': 1, 'cubic': 2, 'lanczos4': 4}
assert tuple(CV_INTERPOLATION) == INTERPOLATIONS


class ModelError(ValueError):
    """
    A parameter set that describes no usable camera.

    ``parameter`` names the parameter at fault; ``str(err)`` starts with it and says why in
    words a person understands.
    """

    def __init__(self, parameter: str, reason: str) -> None:
        """
        Create the error.

        :param parameter: the parameter at fault, e.g. ``'scene.distance_mm'``.
        :param reason: why, without the parameter name.
        """
        super().__init__(f'{parameter}: {reason}')
        self.parameter = parameter
        self.reason = reason


@dataclass(frozen=True)
class RadialMap:
    """
    The traced radial map ``rho_real = R(rho_ideal)`` on the sensor, in mm.

    ``ideal_mm`` is uniformly spaced from 0: the ideal height in the map's projection, v tan
    theta (pinhole) or v theta (equidistant); ``real_mm`` is strictly increasing and
    ``field_angle_rad`` holds the object-space chief-ray angle theta of each sample. Beyond
    ``ideal_mm[-1]`` (``valid_ideal_mm``) the field is not valid; ``folded`` says that it ends
    because the real height stops increasing (a fold), not because a ray fails.
    """

    ideal_mm: FloatArray
    real_mm: FloatArray
    field_angle_rad: FloatArray | None = None
    folded: bool = False
    aim_offsets: FloatArray | None = None

    @property
    def valid_ideal_mm(self) -> float:
        """Return the largest valid ideal radius."""
        return float(self.ideal_mm[-1])

    @property
    def valid_real_mm(self) -> float:
        """Return the largest valid real radius."""
        return float(self.real_mm[-1])

    def real_from_ideal(self, ideal_mm: FloatArray) -> FloatArray:
        """
        Interpolate real radii; NaN beyond the valid field.

        :param ideal_mm: ideal radii, mm, any shape.
        :return: real radii, mm.
        """
        ideal_mm = np.asarray(ideal_mm, dtype=np.float64)
        out = np.interp(ideal_mm, self.ideal_mm, self.real_mm)
        return np.where(ideal_mm <= self.valid_ideal_mm, out, np.nan)

    @property
    def max_field_angle_rad(self) -> float:
        """Return the field angle of the last valid sample."""
        return float(self.field_angle_rad[-1]) if self.field_angle_rad is not None else math.nan

    def angle_from_real(self, real_mm: FloatArray) -> FloatArray:
        """
        Return the field angle theta (rad) imaged at real radii; NaN beyond the valid field.

        :param real_mm: real radii, mm, any shape.
        :return: theta in rad.
        """
        real_mm = np.asarray(real_mm, dtype=np.float64)
        out = np.interp(real_mm, self.real_mm, self.field_angle_rad)
        return np.where(real_mm <= self.valid_real_mm, out, np.nan)

    def ideal_from_real(self, real_mm: FloatArray) -> FloatArray:
        """
        Invert the map by interpolation (it is monotonic); NaN beyond the valid field.

        :param real_mm: real radii, mm, any shape.
        :return: ideal radii, mm.
        """
        real_mm = np.asarray(real_mm, dtype=np.float64)
        out = np.interp(real_mm, self.real_mm, self.ideal_mm)
        return np.where(real_mm <= self.valid_real_mm, out, np.nan)


@dataclass(frozen=True)
class LensModel:
    """
    Everything derived from one parameter set and one image size.

    Build it with :func:`build_model`. Matrices are float64; ``K`` and ``D`` describe the raw
    camera, ``K_new`` and ``P`` the corrected image.
    """

    values: dict[str, ParamValue]
    prescription: Prescription
    width: int
    height: int
    out_width: int
    out_height: int
    pixel_mm: tuple[float, float]
    focal_length_mm: float
    image_distance_mm: float
    curve: RadialMap
    K: FloatArray
    K_new: FloatArray
    D: tuple[float, ...]
    distortion_model: str
    fit_rms_px: float
    max_displacement_px: float
    equivalent_max_error_px: float
    equivalent_fits: tuple[EquivalentFit, ...]
    interpolation: int
    #: Physically possible but unusual values (a stop far from the lens, f/0.7 or faster),
    #: found while building; the summary's ``warnings`` start with them.
    warnings: tuple[str, ...] = ()
    projection: str = 'pinhole'
    field_curve: RadialMap | None = None
    _summary_cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)
    _illumination_cache: dict[bool, Illumination] = field(default_factory=dict, repr=False,
                                                          compare=False)

    def illumination(self, with_fraction: bool = True) -> Illumination:
        """
        Return the relative illumination traced over the sensor, computed on first use.

        :param with_fraction: also trace the stop-only beam (``pupil_pass_fraction``), which
            doubles the cost; the gain map does not need it.
        :return: the curve (:func:`mechdeconv_ros.illumination.relative_illumination`).
        :raises ValueError: when not even the axial beam passes the lens.
        """
        cached = self._illumination_cache.get(True) or self._illumination_cache.get(
            with_fraction)
        if cached is None:
            # The gain map's curve (no fraction) needs only the stop-only beam added.
            cached = relative_illumination(self, with_fraction=with_fraction,
                                           known=self._illumination_cache.get(False))
            self._illumination_cache[with_fraction] = cached
        return cached

    @property
    def summary(self) -> dict[str, Any]:
        """
        Return the scene constraints and tolerance sigmas (eq. 9-25), computed on first use.

        They cost a few extra traces (tolerance propagation), so a model built to validate a
        parameter set or to correct frames does not pay for them until someone asks.
        """
        if not self._summary_cache:
            self._summary_cache.update(_summary(self))
        return self._summary_cache

    @property
    def P(self) -> FloatArray:  # noqa: N802 - the ROS CameraInfo field name
        """Return the 3x4 projection matrix ``[K_new | 0]`` of the corrected image."""
        return np.hstack([self.K_new, np.zeros((3, 1))])

    def raw_from_rect(self, points_px: FloatArray) -> FloatArray:
        """
        Map corrected-image pixel coordinates to raw-image pixel coordinates.

        :param points_px: ``(..., 2)`` x, y in the corrected image.
        :return: ``(..., 2)`` x, y in the raw image; NaN outside the valid field.
        """
        points_px = np.asarray(points_px, dtype=np.float64)
        xn = (points_px[..., 0] - self.K_new[0, 2]) / self.K_new[0, 0]
        yn = (points_px[..., 1] - self.K_new[1, 2]) / self.K_new[1, 1]
        scale = self._scale(np.hypot(xn, yn) * self.image_distance_mm)
        return np.stack([self.K[0, 2] + self.K[0, 0] * xn * scale,
                         self.K[1, 2] + self.K[1, 1] * yn * scale], axis=-1)

    def rect_from_raw(self, points_px: FloatArray) -> FloatArray:
        """
        Map raw-image pixel coordinates to corrected-image pixel coordinates.

        :param points_px: ``(..., 2)`` x, y in the raw image.
        :return: ``(..., 2)`` x, y in the corrected image; NaN outside the valid field.
        """
        points_px = np.asarray(points_px, dtype=np.float64)
        x_mm = (points_px[..., 0] - self.K[0, 2]) * self.pixel_mm[0]
        y_mm = (points_px[..., 1] - self.K[1, 2]) * self.pixel_mm[1]
        real = np.hypot(x_mm, y_mm)
        ideal = self.curve.ideal_from_real(real)
        with np.errstate(invalid='ignore', divide='ignore'):
            ratio = np.where(real > 0.0, ideal / real, 1.0)
        xn = x_mm * ratio / self.image_distance_mm
        yn = y_mm * ratio / self.image_distance_mm
        return np.stack([self.K_new[0, 2] + self.K_new[0, 0] * xn,
                         self.K_new[1, 2] + self.K_new[1, 1] * yn], axis=-1)

    def _scale(self, ideal_mm: FloatArray) -> FloatArray:
        """Return ``rho_real / rho_ideal`` (1 on the axis); NaN outside the valid field."""
        real = self.curve.real_from_ideal(ideal_mm)
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(ideal_mm > 0.0, real / ideal_mm, 1.0)

    def report(self) -> dict[str, Any]:
        """
        Return every derived quantity as a JSON-ready dict (infinite distances are ``None``).

        :return: the summary with K, D, P and the distortion curve over the whole field the
            lens passes (``field_angle_deg``, ``ideal_height_mm`` = v tan(theta), None from
            90 deg, ``real_height_mm``), at most 257 samples.
        """
        out = dict(self.summary)
        try:
            illumination: dict[str, Any] | None = self.illumination().report()
        except ValueError as err:
            illumination = None
            out['warnings'] = list(out['warnings']) + [f'relative illumination: {err}']
        out.update({
            'width_px': self.width, 'height_px': self.height,
            'out_width_px': self.out_width, 'out_height_px': self.out_height,
            'K': self.K.round(10).tolist(), 'D': list(self.D),
            'distortion_model': self.distortion_model,
            'K_new': self.K_new.round(10).tolist(), 'P': self.P.round(10).tolist(),
            'fit_rms_px': self.fit_rms_px,
            'equivalent_max_error_px': self.equivalent_max_error_px,
            'equivalent_models': {fit.distortion_model: {'max_error_px': fit.max_error_px,
                                                         'rms_error_px': fit.rms_error_px}
                                  for fit in self.equivalent_fits},
            'max_displacement_px': self.max_displacement_px,
            'relative_illumination': illumination,
        })
        field = out.pop('_field_curve')
        theta, real = field['theta_rad'], field['real_mm']
        pick = np.unique(np.linspace(0, theta.size - 1, min(theta.size, 257)).round()
                         .astype(int))
        with np.errstate(invalid='ignore', over='ignore'):
            ideal = np.where(theta[pick] < 0.5 * math.pi,
                             self.image_distance_mm * np.tan(theta[pick]), np.nan)
        out['distortion_curve'] = {
            'field_angle_deg': np.degrees(theta[pick]).tolist(),
            'ideal_height_mm': ideal.tolist(),
            'real_height_mm': real[pick].tolist(),
        }
        return _json_safe(out)


def _json_safe(value: Any) -> Any:
    """Replace NaN and inf (undefined or infinite quantities) by None, recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


def radii_mean_error_percent(estimated_px: FloatArray, true_px: FloatArray,
                             center_px: tuple[float, float]) -> float:
    """
    Return the paper's radii mean error (eq. 35-37), in percent.

    For each point the radius from the principal point of the estimated (corrected) position is
    compared with that of the true position: ``e = mean(|r_est - r_true| / r_true) * 100``.
    Points on the axis (``r_true = 0``) carry no radius and are skipped.

    :param estimated_px: ``(N, 2)`` estimated positions.
    :param true_px: ``(N, 2)`` true positions.
    :param center_px: the principal point both radii are measured from.
    :return: the mean relative radius error in percent; NaN if no point qualifies.
    """
    center = np.asarray(center_px, dtype=np.float64)
    r_est = np.hypot(*(np.asarray(estimated_px, dtype=np.float64) - center).T)
    r_true = np.hypot(*(np.asarray(true_px, dtype=np.float64) - center).T)
    keep = r_true > 1e-9
    if not np.any(keep):
        return math.nan
    return float(np.mean(np.abs(r_est[keep] - r_true[keep]) / r_true[keep]) * 100.0)


# ---------------------------------------------------------------------------------------------
# Building
# ---------------------------------------------------------------------------------------------

def _is_prescription_mode(values: Mapping[str, Any]) -> bool:
    return len(values['lens.surfaces.radius_mm']) > 0


def make_prescription(values: Mapping[str, Any]) -> Prescription:
    """
    Build the lens from the ``lens.*`` values.

    :param values: checked parameter values.
    :return: the thick lens (two surfaces, stop at ``z_H - m_a``) or the prescription.
    :raises ModelError: when the description is not a lens that focuses.
    """
    if _is_prescription_mode(values):
        return _surface_prescription(values)
    n = float(values['lens.refractive_index'])
    t = float(values['lens.thickness_mm'])
    if n <= 1.0:
        raise ModelError('lens.refractive_index',
                         f'n = {n:g} is not glass: a lens needs an index above 1 (air)')
    f_nominal = float(values['lens.focal_length_mm'])
    r1, r2 = float(values['lens.r1_mm']), float(values['lens.r2_mm'])
    if f_nominal > 0.0:
        try:
            radius = biconvex_for_focal_length(f_nominal, n, t)
        except ValueError as err:
            raise ModelError('lens.focal_length_mm', str(err)) from None
        r1, r2 = radius, -radius
    try:
        return thick_lens(n, r1, r2, t, float(values['lens.stop_offset_mm']),
                          float(values['lens.aperture_diameter_mm']))
    except ValueError as err:
        raise ModelError('lens.r1_mm', f'r1 = {r1:g} mm, r2 = {r2:g} mm, t = {t:g} mm: {err}'
                         ) from None


def _surface_prescription(values: Mapping[str, Any]) -> Prescription:
    radii = list(values['lens.surfaces.radius_mm'])
    count = len(radii)
    arrays = {}
    for name in ('thickness_mm', 'refractive_index', 'semi_diameter_mm'):
        key = f'lens.surfaces.{name}'
        array = list(values[key])
        if name == 'semi_diameter_mm' and not array:
            array = [0.0] * count
        if len(array) != count:
            raise ModelError(key, f'has {len(array)} values but lens.surfaces.radius_mm has '
                                  f'{count}: give one per surface')
        arrays[name] = array
    stop = int(values['lens.stop_surface'])
    if not 0 <= stop < count:
        raise ModelError('lens.stop_surface',
                         f'{stop} is not a surface index (the prescription has {count} '
                         f'surfaces: 0 to {count - 1})')
    if arrays['refractive_index'][-1] != 1.0:
        raise ModelError('lens.surfaces.refractive_index',
                         'the last surface must end in air (index 1.0): the sensor is in air')
    conics = _per_surface(values, 'lens.surfaces.conic', count)
    terms = [_per_surface(values, f'lens.surfaces.asphere_a{p}', count) for p in ASPHERE_POWERS]
    surfaces = tuple(
        Surface(float(r), float(t), float(n), float(s), conics[i],
                tuple(term[i] for term in terms))
        for i, (r, t, n, s) in enumerate(zip(radii, arrays['thickness_mm'],
                                             arrays['refractive_index'],
                                             arrays['semi_diameter_mm'])))
    for i, surface in enumerate(surfaces):
        limit = domain_limit_mm(surface)
        # (A sphere wider than its hemisphere is the semi-diameter's fault: checked below.)
        if surface.conic != 0.0 and 0.0 < surface.semi_diameter_mm and \
                limit < surface.semi_diameter_mm:
            raise ModelError('lens.surfaces.conic',
                             f'surface {i}: k = {surface.conic:g} with radius '
                             f'{surface.radius_mm:g} mm leaves the sag undefined beyond r = '
                             f'{limit:.4g} mm, inside its semi-diameter '
                             f'{surface.semi_diameter_mm:g} mm')
    try:
        probe = Prescription(surfaces, 0.0)
        return Prescription(surfaces, float(vertex_z(probe)[stop]))
    except ValueError as err:
        raise ModelError('lens.surfaces.radius_mm', str(err)) from None


def _per_surface(values: Mapping[str, Any], key: str, count: int) -> list[float]:
    """Return the array ``key`` with one value per surface (empty = all 0)."""
    array = [float(v) for v in values.get(key, [])]
    if not array:
        return [0.0] * count
    if len(array) != count:
        raise ModelError(key, f'has {len(array)} values but lens.surfaces.radius_mm has '
                              f'{count}: give one per surface, or none for all 0')
    for i, value in enumerate(array):
        if not math.isfinite(value):
            raise ModelError(key, f'value {i} is {value}: coefficients must be finite')
    return array


def _scene_distance(values: Mapping[str, Any]) -> float:
    distance = float(values['scene.distance_mm'])
    return math.inf if distance == 0.0 else distance


def _image_size(values: Mapping[str, Any], width: int, height: int) -> tuple[int, int, int, int]:
    w = int(values['sensor.width_px']) or int(width)
    h = int(values['sensor.height_px']) or int(height)
    if w <= 0 or h <= 0:
        raise ModelError('sensor.width_px',
                         f'the image size {w}x{h} px is empty; set sensor.width_px and '
                         'sensor.height_px or feed images')
    ow = int(values['output.width_px']) or w
    oh = int(values['output.height_px']) or h
    for name, (a, b) in (('sensor.width_px', (w, h)), ('output.width_px', (ow, oh))):
        if a * b > MAX_FRAME_PIXELS:
            raise ModelError(name, f'{a}x{b} px ({a * b / 1e6:.1f} Mpx) is more than the '
                                   f'{MAX_FRAME_PIXELS / 1e6:.1f} Mpx a model may use (the '
                                   'memory bound of its maps)')
    return w, h, ow, oh


def _trace_curve(prescription: Prescription, distance: float, sensor_z: float, v: float,
                 ideal_max_mm: float, samples: int, projection: str = 'pinhole',
                 guide: RadialMap | None = None) -> RadialMap:
    """
    Trace ``samples`` chief rays from 0 to ``ideal_max_mm`` and keep the valid prefix.

    The ideal heights are uniform in the projection: v tan(theta) for ``pinhole``, v theta for
    ``equidistant`` (which reaches past 90 deg for a scene at infinity). A ``guide`` (an
    earlier curve of the same lens and scene) starts the ray aiming from its solutions.
    """
    ideal = np.linspace(0.0, ideal_max_mm, samples)
    theta = np.arctan(ideal / v) if projection == 'pinhole' else ideal / v
    known = None
    if guide is not None and guide.aim_offsets is not None:
        known = (guide.field_angle_rad, guide.aim_offsets)
    real, offsets = trace_field(prescription, distance, sensor_z, theta, known)
    real = -real
    good = np.isfinite(real)
    rising = np.ones_like(good)
    rising[1:] = np.diff(real) > 0.0
    good &= rising
    # The valid field is the prefix up to the first failed ray or the first non-increase.
    end = int(np.argmin(good)) if not good.all() else samples
    folded = end < samples and bool(np.isfinite(real[end])) and not rising[end]
    return RadialMap(ideal[:end], real[:end], theta[:end], folded, offsets[:end])


def _resample(field: RadialMap, v: float, ideal_max_mm: float, samples: int,
              projection: str) -> RadialMap:
    """
    Return the radial map in a projection, uniform in its ideal height, from the field trace.

    The real heights at the new field angles are the cubic Hermite interpolation of the
    angle-uniform trace, with slopes from fourth-order differences: on every lens we tried
    (Case 2 to 4000x3000 px, aspheric double Gauss, fisheyes to 102 deg) within 2e-7 px of
    tracing those angles exactly, at a quarter of the cost (the map needs no more rays).
    """
    ideal = np.linspace(0.0, ideal_max_mm, samples)
    theta = np.arctan(ideal / v) if projection == 'pinhole' else ideal / v
    inside = theta <= field.max_field_angle_rad
    real = np.full(samples, np.nan)
    real[inside] = hermite(field.field_angle_rad, field.real_mm, theta[inside])
    good = np.isfinite(real)
    good[1:] &= np.diff(real) > 0.0
    end = int(np.argmin(good)) if not good.all() else samples
    return RadialMap(ideal[:end], real[:end], theta[:end], field.folded and end == samples)


def hermite(x: FloatArray, y: FloatArray, query: FloatArray) -> FloatArray:
    """
    Interpolate uniformly spaced samples by cubic Hermite with fourth-order slopes.

    :param x: uniformly spaced abscissae (at least 5), increasing.
    :param y: values.
    :param query: where to interpolate, within ``[x[0], x[-1]]``.
    :return: the interpolated values (error O(h^4)).
    """
    h = float(x[1] - x[0])
    n = y.size
    d = np.empty(n)
    d[2:-2] = (y[:-4] - 8.0 * y[1:-3] + 8.0 * y[3:-1] - y[4:]) / (12.0 * h)
    d[0] = (-25.0 * y[0] + 48.0 * y[1] - 36.0 * y[2] + 16.0 * y[3] - 3.0 * y[4]) / (12.0 * h)
    d[1] = (-3.0 * y[0] - 10.0 * y[1] + 18.0 * y[2] - 6.0 * y[3] + y[4]) / (12.0 * h)
    d[-1] = (25.0 * y[-1] - 48.0 * y[-2] + 36.0 * y[-3] - 16.0 * y[-4] + 3.0 * y[-5]) / (12.0 * h)
    d[-2] = (3.0 * y[-1] + 10.0 * y[-2] - 18.0 * y[-3] + 6.0 * y[-4] - y[-5]) / (12.0 * h)
    k = np.clip(((query - x[0]) / h).astype(np.int64), 0, n - 2)
    t = (query - x[k]) / h
    t2 = t * t
    t3 = t2 * t
    return ((2.0 * t3 - 3.0 * t2 + 1.0) * y[k] + (t3 - 2.0 * t2 + t) * h * d[k]
            + (3.0 * t2 - 2.0 * t3) * y[k + 1] + (t3 - t2) * h * d[k + 1])


def _projected(theta: FloatArray, projection: str) -> FloatArray:
    """Return the normalised ideal radius of field angles: tan(theta) or theta."""
    if projection == 'pinhole':
        with np.errstate(invalid='ignore'):
            return np.tan(np.minimum(theta, math.radians(PINHOLE_MAX_FIELD_DEG)))
    return np.asarray(theta, dtype=np.float64)


def _boundary_points(w: int, h: int, per_side: int = 64) -> FloatArray:
    """Return points on the outer edges of a w x h pixel image (pixel-edge coordinates)."""
    xs = np.linspace(-0.5, w - 0.5, per_side)
    ys = np.linspace(-0.5, h - 0.5, per_side)
    return np.concatenate([
        np.stack([xs, np.full_like(xs, -0.5)], axis=1),
        np.stack([xs, np.full_like(xs, h - 0.5)], axis=1),
        np.stack([np.full_like(ys, -0.5), ys], axis=1),
        np.stack([np.full_like(ys, w - 0.5), ys], axis=1),
    ])


#: The equivalent calibration is the simplest model whose largest displacement error over
#: the raw image is at most this (px); when none reaches it, the one with the smallest.
EQUIVALENT_MAX_ERROR_PX = 0.05
#: Consumer models in order of preference: the most widely read first (plumb_bob and
#: rational_polynomial are read by every ROS consumer, equidistant by cv2.fisheye-based
#: ones: image_geometry C++, Isaac ROS; ROS's Python image_geometry has no fisheye support).
EQUIVALENT_MODELS = ('plumb_bob', 'rational_polynomial', 'equidistant')
#: Samples of the fit and reweighting passes of the minimax (Lawson) refinement.
FIT_SAMPLES = 256
LAWSON_PASSES = 12


@dataclass(frozen=True)
class EquivalentFit:
    """One fitted consumer model: coefficients and its errors over the raw image (px)."""

    distortion_model: str
    D: tuple[float, ...]
    max_error_px: float
    rms_error_px: float


def equivalent_radius(distortion_model: str, D: tuple[float, ...] | FloatArray,
                      theta: FloatArray) -> FloatArray:
    """
    Return the distorted normalised radius a consumer model gives a field angle.

    plumb_bob: r = t (1 + k1 t^2 + k2 t^4 + k3 t^6), t = tan(theta); rational_polynomial:
    r = t (1 + k1 t^2 + k2 t^4 + k3 t^6) / (1 + k4 t^2 + k5 t^4 + k6 t^6); equidistant
    (Kannala-Brandt, as cv2.fisheye): r = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 +
    k4 theta^8). The pinhole models are NaN from 90 deg.

    :param distortion_model: one of :data:`EQUIVALENT_MODELS`.
    :param D: the coefficients in camera_info order.
    :param theta: field angles, rad.
    :return: radii in normalised (x/f) units.
    """
    theta = np.asarray(theta, dtype=np.float64)
    d = [float(x) for x in D]
    if distortion_model == 'equidistant':
        t2 = theta * theta
        return theta * (1.0 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3]))))
    with np.errstate(invalid='ignore', over='ignore'):
        t = np.where(theta < 0.5 * math.pi, np.tan(theta), np.nan)
        r2 = t * t
        num = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]))
        if distortion_model == 'rational_polynomial':
            num = num / (1.0 + r2 * (d[5] + r2 * (d[6] + r2 * d[7])))
        return t * num


@functools.lru_cache(maxsize=8)
def _raw_probe_points(width: int, height: int) -> FloatArray:
    """Return the raw pixels the consumer error is measured on: edges, corners and a grid."""
    xs = np.linspace(-0.5, width - 0.5, 41)
    ys = np.linspace(-0.5, height - 0.5, 31)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    return np.concatenate([_boundary_points(width, height), grid])


def fit_equivalent(field: RadialMap, v: float, K: FloatArray, width: int, height: int,
                   every: bool = False) -> list[EquivalentFit]:
    """
    Fit every consumer model to the traced field and measure it over the raw image.

    The fit is least squares in pixels on FIT_SAMPLES field angles up to the raw image corner
    (or the end of the field), refined towards the minimax by Lawson's reweighting; the error
    of a model at a raw pixel is the distance (px) between that pixel and where the model
    projects the pixel's true (traced) direction, which is what a consumer's rectification map
    (cv2.initUndistortRectifyMap, cv2.fisheye.initUndistortRectifyMap) is off by there.
    Raw pixels outside the image circle carry no direction and are skipped.

    :param field: the field traced by angle (``LensModel.field_curve``).
    :param v: image distance, mm (normalised radius = real / v).
    :param K: raw camera matrix.
    :param width: raw width, px.
    :param height: raw height, px.
    :param every: fit every model; by default the fits stop at the first model within
        EQUIVALENT_MAX_ERROR_PX (the one published: the rest would cost rebuild time).
    :return: one :class:`EquivalentFit` per model fitted, in :data:`EQUIVALENT_MODELS` order.
    """
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    points = _raw_probe_points(width, height)
    xn, yn = (points[:, 0] - cx) / fx, (points[:, 1] - cy) / fy
    rn = np.hypot(xn, yn)
    theta_p = field.angle_from_real(rn * v)
    inside = np.isfinite(theta_p)
    xn, yn, rn, theta_p = xn[inside], yn[inside], rn[inside], theta_p[inside]
    # Pixels per unit of normalised radius along each probe's direction.
    with np.errstate(invalid='ignore', divide='ignore'):
        gain = np.where(rn > 0, np.hypot(xn * fx, yn * fy) / rn, max(fx, fy))
    limit = float(np.max(theta_p)) if theta_p.size else 0.0
    theta = np.linspace(0.0, limit, FIT_SAMPLES + 1)[1:]
    target = np.interp(theta, field.field_angle_rad, field.real_mm) / v
    scale = max(fx, fy)
    fits: list[EquivalentFit] = []
    for name in EQUIVALENT_MODELS:
        if fits and fits[-1].max_error_px <= EQUIVALENT_MAX_ERROR_PX and not every:
            break       # the simpler model is chosen: the others are not needed
        coefficients = _fit_model(name, theta, target, scale)
        if coefficients is None and name == 'rational_polynomial' and fits[0].D != _zero_d(
                'plumb_bob') and math.isfinite(fits[0].max_error_px):
            # A degenerate rational fit (small fields): plumb_bob is its special case.
            coefficients = fits[0].D + (0.0, 0.0, 0.0)
        if coefficients is None:
            fits.append(EquivalentFit(name, _zero_d(name), math.inf, math.inf))
            continue
        error = np.abs(equivalent_radius(name, coefficients, theta_p) - rn) * gain
        error = np.where(np.isfinite(error), error, np.inf)
        worst = float(np.max(error)) if error.size else 0.0
        rms = float(np.sqrt(np.mean(error * error))) if error.size else 0.0
        fits.append(EquivalentFit(name, coefficients, worst, rms))
    return fits


def _zero_d(name: str) -> tuple[float, ...]:
    return (0.0,) * {'plumb_bob': 5, 'rational_polynomial': 8, 'equidistant': 4}[name]


def _fit_model(name: str, theta: FloatArray, target: FloatArray,
               scale: float) -> tuple[float, ...] | None:
    """Fit one model to r(theta) = target (normalised); None where it cannot represent it."""
    if theta.size < 8:
        return _zero_d(name)
    if name == 'equidistant':
        t2 = theta * theta
        basis = theta[:, None] * np.stack([t2, t2 ** 2, t2 ** 3, t2 ** 4], axis=1)
        rhs = target - theta
    else:
        if not theta[-1] < math.radians(89.0):
            return None     # a pinhole model cannot reach 90 deg (tan is infinite)
        t = np.tan(theta)
        r2 = t * t
        powers = np.stack([r2, r2 * r2, r2 * r2 * r2], axis=1)
        basis = t[:, None] * powers
        rhs = target - t
        if name == 'rational_polynomial':
            # r (1 + den) = t (1 + num): linear in (num, den) (equation error, reweighted by
            # the denominator below so the residual is the radius error).
            basis = np.hstack([basis, -target[:, None] * powers])
    # Columns scaled to unit norm (the powers of small radii are tiny and nearly collinear).
    norms = np.linalg.norm(basis, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    basis = basis / norms
    weights = np.ones(theta.size)
    row_scale = np.ones(theta.size)
    best, best_error = None, math.inf
    ridge = 0.0
    for _ in range(LAWSON_PASSES):
        w = np.sqrt(weights) * row_scale * scale
        matrix = basis * w[:, None]
        while True:
            coef = _ridge_lstsq(matrix, rhs * w, ridge * float(np.sum(w * w)))
            if name != 'rational_polynomial':
                break
            den = 1.0 + powers @ (coef[3:] / norms[3:])
            if np.all(den > 0) or ridge >= 1e-2:
                break
            # A pole inside the field: the equation-error fit is ill-conditioned here;
            # damp it (ridge regression) until the denominator stays positive.
            ridge = max(100.0 * ridge, 1e-12)
        if not np.all(np.isfinite(coef)):
            break
        if name == 'rational_polynomial':
            if not np.all(den > 0):
                break
            row_scale = 1.0 / den
            # Reweighted by 1/den the fit is better conditioned: relax the damping again.
            ridge = ridge / 100.0 if ridge > 1e-12 else 0.0
        residual = np.abs(basis @ coef - rhs) * row_scale
        worst = float(np.max(residual))
        if worst * scale <= 0.1 * EQUIVALENT_MAX_ERROR_PX:
            best = coef / norms
            break       # well within the bound: the minimax refinement is not needed
        if worst < best_error:
            if worst > 0.98 * best_error and best is not None:
                best = coef / norms
                break   # Lawson has converged (under 2 % gained)
            best, best_error = coef / norms, worst
        total = float(np.sum(weights * residual))
        if not total > 0:
            break
        # Lawson: weight each sample by its share of the error (towards the minimax fit).
        weights = np.maximum(weights * residual / total * theta.size, 1e-12)
    if best is None:
        return None
    coef = best
    c = [float(x) for x in coef]
    if name == 'plumb_bob':
        return (c[0], c[1], 0.0, 0.0, c[2])
    if name == 'rational_polynomial':
        return (c[0], c[1], 0.0, 0.0, c[2], c[3], c[4], c[5])
    return tuple(c)


def _ridge_lstsq(matrix: FloatArray, rhs: FloatArray, damping: float) -> FloatArray:
    """Solve min |A x - b|^2 + damping |x|^2 (plain least squares for damping 0)."""
    if damping > 0.0:
        size = matrix.shape[1]
        matrix = np.vstack([matrix, math.sqrt(damping) * np.eye(size)])
        rhs = np.concatenate([rhs, np.zeros(size)])
    return np.linalg.lstsq(matrix, rhs, rcond=None)[0]


def choose_equivalent(fits: list[EquivalentFit]) -> EquivalentFit:
    """
    Return the first model (in preference order) within EQUIVALENT_MAX_ERROR_PX, else the best.

    :param fits: from :func:`fit_equivalent`.
    :return: the chosen fit.
    """
    for fit in fits:
        if fit.max_error_px <= EQUIVALENT_MAX_ERROR_PX:
            return fit
    return min(fits, key=lambda fit: fit.max_error_px)


def _scale_k(boundary_ideal: FloatArray, disk: float, half_w: float, half_h: float,
             fx: float, fy: float, alpha: float) -> float:
    """
    Choose the zoom ``k`` of ``K_new`` from the raw image outline in ideal normalised coords.

    ``alpha = 0``: the output shows only valid source pixels (inner rectangle of the outline,
    and inside the valid disk); ``alpha = 1``: every source pixel is in view (outer rectangle).
    """
    x, y = boundary_ideal[:, 0], boundary_ideal[:, 1]
    n = len(x) // 4
    top, bottom, left, right = (slice(0, n), slice(n, 2 * n), slice(2 * n, 3 * n),
                                slice(3 * n, 4 * n))
    inner_x = min(-np.max(x[left]), np.min(x[right]))
    inner_y = min(-np.max(y[top]), np.min(y[bottom]))
    k0 = max(half_w / (fx * inner_x), half_h / (fy * inner_y),
             math.hypot(half_w / fx, half_h / fy) / disk)
    k1 = min(half_w / (fx * np.max(np.abs(x))), half_h / (fy * np.max(np.abs(y))))
    return float(k0 * (1.0 - alpha) + k1 * alpha)


def build_model(values: Mapping[str, Any], width: int = 0, height: int = 0) -> LensModel:
    """
    Build the model of one parameter set for one image size.

    :param values: parameter name -> value; missing names take their defaults.
    :param width: the incoming image width, used when ``sensor.width_px`` is 0.
    :param height: the incoming image height, used when ``sensor.height_px`` is 0.
    :return: the model.
    :raises ModelError: naming the parameter at fault when the values describe no camera.
    """
    try:
        vals = check_values(values)
    except ValueError as err:
        name = str(err).split(':', 1)[0].split('[', 1)[0].strip(" '")
        raise ModelError(name, str(err).split(':', 1)[-1].strip()) from None
    prescription = make_prescription(vals)
    try:
        para = paraxial(prescription)
    except ValueError as err:
        raise ModelError(_lens_param(vals), str(err)) from None
    f = para.efl_mm
    if f <= 0.0:
        raise ModelError(_lens_param(vals),
                         f'the lens diverges (f = {f:.4g} mm): it forms no real image of the '
                         'scene on a sensor')
    distance = _scene_distance(vals)
    if distance <= f:
        raise ModelError('scene.distance_mm',
                         f'{distance:g} mm is inside the focal length {f:.4g} mm: the lens '
                         'forms no real image of it')
    if math.isfinite(distance) and para.front_principal_z_mm - distance >= 0.0:
        raise ModelError('scene.distance_mm',
                         f'{distance:g} mm from the front principal plane puts the scene inside '
                         'the lens')
    try:
        sensor_z, v = image_plane(prescription, distance)
    except ValueError as err:
        raise ModelError('scene.distance_mm', str(err)) from None
    warnings = _check_physical(vals, prescription, para, distance, sensor_z)
    w, h, ow, oh = _image_size(vals, width, height)
    px = float(vals['sensor.pixel_size_x_um']) * 1e-3
    py = float(vals['sensor.pixel_size_y_um']) * 1e-3
    _check_circle_of_confusion(vals, f, w * px, h * py)
    fx, fy = v / px, v / py
    K = np.array([[fx, 0.0, (w - 1) / 2.0], [0.0, fy, (h - 1) / 2.0], [0.0, 0.0, 1.0]])

    projection = str(vals['output.projection'])
    cap = _field_cap_rad(distance)

    # Pass 1: trace the field by angle (theta uniform) far enough to cover the raw image (its
    # edge, not the pixel centre), or to the end of the field the lens passes.
    edge_real = math.hypot(w / 2.0 * px, h / 2.0 * py)
    theta_max = min(cap, 1.5 * edge_real / v)
    for _ in range(12):
        coarse = _trace_curve(prescription, distance, sensor_z, v, theta_max * v, COARSE_SAMPLES,
                              'equidistant')
        if (coarse.ideal_mm.size < COARSE_SAMPLES or coarse.valid_real_mm >= 1.05 * edge_real
                or theta_max >= cap):
            break
        theta_max = min(cap, 2.0 * theta_max)
    if coarse.ideal_mm.size == 0:
        raise ModelError(_lens_param(vals), 'not even the axial ray passes through this lens: '
                                            'a surface misses it or reflects it totally')
    reached = max(0.0, coarse.valid_real_mm)
    if coarse.ideal_mm.size < 16 or reached < 0.05 * edge_real:
        raise ModelError(_stop_param(vals),
                         f'no chief ray reaches the sensor beyond {reached:.3g} mm of the '
                         f'{edge_real:.3g} mm half-diagonal: the stop position or the lens '
                         'blocks the field, or the sensor is far larger than the image the '
                         'lens forms')
    boundary = _boundary_points(w, h)
    bx = (boundary[:, 0] - K[0, 2]) * px
    by = (boundary[:, 1] - K[1, 2]) * py
    b_real = np.hypot(bx, by)
    b_theta = coarse.angle_from_real(np.minimum(b_real, coarse.valid_real_mm))
    ratio = _projected(b_theta, projection) / b_real
    boundary_ideal = np.stack([bx * ratio, by * ratio], axis=1)
    disk = float(_projected(np.array(coarse.max_field_angle_rad), projection))
    k = _scale_k(boundary_ideal, disk, ow / 2.0, oh / 2.0, fx, fy, float(vals['output.alpha']))
    K_new = np.array([[k * fx, 0.0, (ow - 1) / 2.0], [0.0, k * fy, (oh - 1) / 2.0],
                      [0.0, 0.0, 1.0]])

    # Pass 2: the dense curve in the output projection from 0 to just past the output corner
    # (and the raw image edge).
    out_corner = math.hypot(ow / 2.0 / (k * fx), oh / 2.0 / (k * fy)) * v
    raw_corner_ideal = float(np.nanmax(ratio * b_real)) * v
    reach = min(1.02 * max(out_corner, raw_corner_ideal), disk * v * 1.001)
    curve = _resample(coarse, v, reach, CURVE_SAMPLES, projection)

    fits = fit_equivalent(coarse, v, K, w, h)
    chosen = choose_equivalent(fits)
    disp = (boundary_ideal * v - np.stack([bx, by], axis=1)) / np.array([px, py])
    max_disp = float(np.nanmax(np.hypot(disp[:, 0], disp[:, 1])))

    model = LensModel(
        values=vals, prescription=prescription, width=w, height=h, out_width=ow,
        out_height=oh, pixel_mm=(px, py), focal_length_mm=f, image_distance_mm=v, curve=curve,
        K=K, K_new=K_new, D=chosen.D, distortion_model=chosen.distortion_model,
        fit_rms_px=chosen.rms_error_px, equivalent_max_error_px=chosen.max_error_px,
        equivalent_fits=tuple(fits),
        max_displacement_px=max_disp,
        interpolation=CV_INTERPOLATION[str(vals['output.interpolation'])],
        projection=projection, field_curve=coarse, warnings=tuple(warnings))
    return model


def _field_cap_rad(distance: float) -> float:
    """Return the largest field angle traced for a scene at ``distance`` (rad)."""
    return math.radians(MAX_FIELD_DEG_INFINITE if math.isinf(distance)
                        else MAX_FIELD_DEG_FINITE)


# ---------------------------------------------------------------------------------------------
# Physical checks: a parameter set must describe a camera that can exist (docs/design.md s. 7)
# ---------------------------------------------------------------------------------------------

#: f-numbers below this are accepted with a warning (few production lenses are faster).
FAST_F_NUMBER = 0.7
#: A stop farther than this many focal lengths outside the lens is accepted with a warning.
FAR_STOP_FOCAL_LENGTHS = 1.0
#: Relative slack of the aperture and edge-thickness limits (rounding of given values).
LIMIT_SLACK = 1e-9


def _sag(surface: Surface, height_mm: float) -> float:
    """
    Return the sagitta of a surface at height ``a``: ``c a^2 / (1 + sqrt(1 - (1 + k) c^2 a^2))``.

    For a sphere that is ``r - sign(r) sqrt(r^2 - a^2)``; even asphere terms ``a4 a^4 + ...``
    are added. Beyond its rim (:func:`~mechdeconv_ros.surfaces.domain_limit_mm`) a surface is
    continued by a flat bevel, so the sagitta stays at its rim value there. (Scalar, and
    clamped at the rim where :func:`mechdeconv_ros.surfaces.sag` would round to NaN.)
    """
    c = surface.curvature_per_mm
    k = surface.conic
    a = min(abs(height_mm), domain_limit_mm(surface))
    out = c * a * a / (1.0 + math.sqrt(max(0.0, 1.0 - (1.0 + k) * c * c * a * a)))
    for power, coefficient in enumerate(surface.asphere, start=2):
        out += float(coefficient) * a ** (2 * power)
    return out


def _shape(surface: Surface) -> str:
    """Name a surface's shape for a reason: 'a spherical surface of radius 4 mm'."""
    if is_spherical(surface):
        return f'a spherical surface of radius {surface.radius_mm:g} mm'
    return f'a conic surface (k = {surface.conic:g}) of radius ' \
           f'{surface.radius_mm:g} mm'


def _paraxial_height(prescription: Prescription, h: float, u: float, z_end: float) -> float:
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


def _marginal_ray(prescription: Prescription, distance: float, front_principal_z: float
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
        at_stop = _paraxial_height(prescription, 1.0, 0.0, z_stop)
        return (1.0 / at_stop if at_stop != 0.0 else math.inf), 0.0
    z_scene = front_principal_z - distance
    at_stop = _paraxial_height(prescription, -z_scene, 1.0, z_stop)
    u = 1.0 / at_stop if at_stop != 0.0 else math.inf
    return -z_scene * u, u


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
    if not _is_prescription_mode(values):
        return 1.0
    a = abs(_paraxial_height(prescription, 1.0, 0.0, prescription.stop_z_mm))
    return 1.0 / a if a > 0.0 and math.isfinite(a) else 1.0


def _elements(prescription: Prescription) -> list[list[int]]:
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
        edge = (float(z_vertices[j]) + _sag(surfaces[j], semi_aperture)
                - float(z_vertices[i]) - _sag(surfaces[i], semi_aperture))
        if edge < -LIMIT_SLACK * max(1.0, semi_aperture):
            return i, j, edge, semi_aperture
    return None


def _check_physical(vals: Mapping[str, Any], prescription: Prescription, para: Any,
                    distance: float, sensor_z: float) -> list[str]:
    """
    Refuse a lens that cannot exist; return warnings for an unusual one.

    The rules, each with its parameter, formula and limit, are listed in docs/design.md section 7.

    :raises ModelError: naming the parameter, why, and the limit.
    :return: warnings about physically possible but unusual values.
    """
    f = para.efl_mm
    prescription_mode = _is_prescription_mode(vals)
    warnings: list[str] = []
    # Focus distance: the same rules as the scene distance.
    focus = float(vals['scene.focus_distance_mm'])
    if focus > 0.0:
        if focus <= f:
            raise ModelError('scene.focus_distance_mm',
                             f'{focus:g} mm is inside the focal length {f:.4g} mm: the lens '
                             'cannot be focused there (it forms no real image of it; the '
                             f'focus distance must be above {f:.4g} mm, or 0 = the scene '
                             'distance)')
        if para.front_principal_z_mm - focus >= 0.0:
            raise ModelError('scene.focus_distance_mm',
                             f'{focus:g} mm from the front principal plane puts the plane in '
                             f'focus inside the lens (it must be above '
                             f'{para.front_principal_z_mm:.4g} mm)')
    # The image plane (the sensor) must lie behind the last surface, in air.
    z_last = para.last_vertex_z_mm
    if sensor_z <= z_last:
        name = 'lens.surfaces.thickness_mm' if prescription_mode else 'lens.thickness_mm'
        raise ModelError(name, f'the image plane falls at z = {sensor_z:.4g} mm, not behind '
                               f'the last surface at z = {z_last:.4g} mm: the sensor would '
                               'have to sit inside the lens (the back focal distance must be '
                               'positive)')
    # The stop: between the scene and the image plane.
    z_stop = prescription.stop_z_mm
    stop_name = _stop_param(vals)
    stop_value = vals[stop_name]
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
    # Clear apertures: a sphere is at most 2|r| wide; a given semi-diameter bounds its surface.
    surfaces = prescription.surfaces
    for i, surface in enumerate(surfaces):
        semi, rim = surface.semi_diameter_mm, domain_limit_mm(surface)
        if semi > rim * (1.0 + LIMIT_SLACK):
            raise ModelError('lens.surfaces.semi_diameter_mm',
                             f'surface {i}: a clear semi-diameter of {semi:g} mm is wider than '
                             f'{_shape(surface)} can be (at most '
                             + (f'|r| = {rim:.6g} mm, a hemisphere)' if is_spherical(surface)
                                else f'{rim:.6g} mm, its rim)'))
    d_a = float(vals['lens.aperture_diameter_mm'])
    h, u = _marginal_ray(prescription, distance, para.front_principal_z_mm)
    if not (math.isfinite(h) and math.isfinite(u)):
        raise ModelError(stop_name, f'{where} sits at an image of the scene (the axial beam '
                                    'focuses there): it would bound the field, not the '
                                    'aperture')
    z_vertices = vertex_z(prescription)
    # Beam heights per unit aperture radius (d_a / 2 = 1).
    heights = [abs(_paraxial_height(prescription, h, u, float(z))) for z in z_vertices]
    if not all(math.isfinite(y) for y in heights):
        raise ModelError(stop_name, f'{where}: the axial beam through it cannot be traced '
                                    '(the paraxial marginal ray overflows): the stop is at or '
                                    'next to an image of the scene')
    elements = _elements(prescription)
    real = {i for element in elements for i in element}
    bound, culprit, at = math.inf, '', 0
    for i, surface in enumerate(surfaces):
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
                         f'wider than {culprit}; with the stop where {stop_name} = '
                         f'{stop_value:g} puts it (z = {z_stop:.4g} mm) the largest aperture is '
                         f'{2.0 * bound:.4g} mm (paraxial marginal ray)')
    # Edge thickness of every glass element at its clear semi-aperture.
    thickness_name = 'lens.surfaces.thickness_mm' if prescription_mode else 'lens.thickness_mm'
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
                 'centre)' if prescription_mode else f'the lens ({centre:g} mm thick at the '
                 'centre)')
        raise ModelError(thickness_name,
                         f'{which} has an edge thickness of {edge:.4g} mm at its '
                         f'{semi_aperture:.4g} mm clear semi-aperture: its surfaces cross '
                         f'(t - sag1(a) + sag2(a) < 0). It must be at least '
                         f'{centre - edge:.4g} mm thick at the centre, or {smaller}')
    # Unusual but possible: a stop far outside the lens, a very fast aperture.
    outside = max(-z_stop, z_stop - z_last, 0.0)
    if outside > FAR_STOP_FOCAL_LENGTHS * f:
        side = 'in front of the first' if z_stop < 0.0 else 'behind the last'
        warnings.append(f'{stop_name}: the stop is {outside:.4g} mm {side} surface, farther '
                        f'than the focal length {f:.4g} mm: an unusual design (strong '
                        'distortion and vignetting)')
    n_f = constraints.f_number(f, d_a * pupil_scale(vals, prescription),
                               float(vals['lens.exposure_constant_q']))
    if n_f < FAST_F_NUMBER:
        warnings.append(f'lens.aperture_diameter_mm: f/{n_f:.3g} is faster than '
                        f'f/{FAST_F_NUMBER:g}; few real lenses are (f/0.5 is the limit of an '
                        'aplanatic lens in air)')
    return warnings


def _check_circle_of_confusion(vals: Mapping[str, Any], f: float, width_mm: float,
                               height_mm: float) -> None:
    """
    Refuse a circle of confusion larger than the sensor diagonal of the model's image size.

    :raises ModelError: naming ``scene.circle_of_confusion_mm``.
    """
    c_set = float(vals['scene.circle_of_confusion_mm'])
    c = constraints.circle_of_confusion_mm(f, c_set)
    diagonal = math.hypot(width_mm, height_mm)
    if c > diagonal * (1.0 + LIMIT_SLACK):
        value = f'{c:g} mm' if c_set > 0.0 else f'0 (0.1 % of f = {c:.4g} mm)'
        raise ModelError('scene.circle_of_confusion_mm',
                         f'{value} is larger than the {diagonal:.4g} mm diagonal of the '
                         f'{width_mm:.4g} x {height_mm:.4g} mm sensor: a blur wider than the '
                         f'image defines no depth of field (it must be at most '
                         f'{diagonal:.4g} mm)')


def _lens_param(values: Mapping[str, Any]) -> str:
    if _is_prescription_mode(values):
        return 'lens.surfaces.radius_mm'
    return 'lens.focal_length_mm' if float(values['lens.focal_length_mm']) > 0 else 'lens.r1_mm'


def _stop_param(values: Mapping[str, Any]) -> str:
    return 'lens.stop_surface' if _is_prescription_mode(values) else 'lens.stop_offset_mm'


def _finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _tolerance_keys(values: Mapping[str, Any]) -> tuple[dict[str, float], dict[str, float]]:
    """Return the scalar lens quantities with their 1-sigma tolerances, for propagation."""
    tol = {'r': float(values['lens.tolerance.r1_mm']),
           't': float(values['lens.tolerance.thickness_mm']),
           'n': float(values['lens.tolerance.refractive_index'])}
    nominal: dict[str, float] = {}
    sigmas: dict[str, float] = {}
    if _is_prescription_mode(values):
        # Every surface gets the tolerance class of the thick-lens parameters.
        for kind, key, sigma in (('radius_mm', 'r', tol['r']), ('thickness_mm', 't', tol['t']),
                                 ('refractive_index', 'n', tol['n'])):
            for i, value in enumerate(values[f'lens.surfaces.{kind}']):
                if kind == 'radius_mm' and value == 0.0:
                    continue
                if kind == 'refractive_index' and value == 1.0:
                    continue
                nominal[f'lens.surfaces.{kind}[{i}]'] = float(value)
                sigmas[f'lens.surfaces.{kind}[{i}]'] = sigma
    else:
        for name, sigma_name in (('lens.r1_mm', 'lens.tolerance.r1_mm'),
                                 ('lens.r2_mm', 'lens.tolerance.r2_mm'),
                                 ('lens.thickness_mm', 'lens.tolerance.thickness_mm'),
                                 ('lens.refractive_index', 'lens.tolerance.refractive_index')):
            if name in ('lens.r1_mm', 'lens.r2_mm') and (
                    float(values['lens.focal_length_mm']) > 0.0 or values[name] == 0.0):
                continue
            nominal[name] = float(values[name])
            sigmas[name] = float(values[sigma_name])
    return nominal, sigmas


def _with(values: Mapping[str, Any], scalars: Mapping[str, float]) -> dict[str, Any]:
    """Return a copy of ``values`` with scalar (and ``name[i]`` array element) overrides."""
    out = {k: (list(v) if isinstance(v, list) else v) for k, v in values.items()}
    for key, value in scalars.items():
        if key.endswith(']'):
            name, index = key[:-1].split('[')
            out[name][int(index)] = value
        else:
            out[key] = value
    return out


def _summary(model: LensModel) -> dict[str, Any]:
    """Derive the scene constraints (eq. 9-25) and the tolerance sigmas."""
    vals = model.values
    distance = _scene_distance(vals)
    edge_real = math.hypot(model.width / 2.0 * model.pixel_mm[0],
                           model.height / 2.0 * model.pixel_mm[1])
    f = model.focal_length_mm
    nominal, sigmas = _tolerance_keys(vals)

    def efl(p: Mapping[str, float]) -> float:
        return paraxial(make_prescription(_with(vals, p))).efl_mm

    sigma_f = _sigma_or_nan(efl, nominal, sigmas)
    w_mm = constraints.sensor_size_mm(model.width, vals['sensor.pixel_size_x_um'])
    h_mm = constraints.sensor_size_mm(model.height, vals['sensor.pixel_size_y_um'])
    q = float(vals['lens.exposure_constant_q'])
    # The f-number's aperture is the entrance pupil (pupil_scale: 1 for the paper's thick lens).
    d_a = float(vals['lens.aperture_diameter_mm']) * pupil_scale(vals, model.prescription)
    n_f = constraints.f_number(f, d_a, q)
    c = constraints.circle_of_confusion_mm(f, float(vals['scene.circle_of_confusion_mm']))
    h = constraints.hyperfocal_mm(f, n_f, c)
    c_set = float(vals['scene.circle_of_confusion_mm'])

    def hyper(p: Mapping[str, float]) -> float:
        scal = dict(p)
        f_p = efl({k: v for k, v in scal.items() if k != 'd_a'})
        n_fp = constraints.f_number(f_p, scal['d_a'], q)
        c_p = constraints.circle_of_confusion_mm(f_p, c_set)
        return constraints.hyperfocal_mm(f_p, n_fp, c_p)

    sigma_d_a = float(vals['lens.tolerance.aperture_diameter_mm']) \
        * pupil_scale(vals, model.prescription)
    sigma_h = _sigma_or_nan(hyper, {**nominal, 'd_a': d_a}, {**sigmas, 'd_a': sigma_d_a})
    focus = float(vals['scene.focus_distance_mm']) or distance
    focus = math.inf if focus == 0.0 else focus
    near, far = constraints.depth_of_field_mm(h, focus)
    warnings = list(model.warnings)
    if not near <= distance <= far:
        warnings.append(f'scene distance {distance:g} mm is outside the depth of field '
                        f'[{near:.4g}, {far:.4g}] mm of the focus distance {focus:g} mm')
    field = _full_field(model)
    if field['folded']:
        warnings.append(f"the real image height folds back at {field['max_field_angle_deg']:.4g} "
                        f"deg (r = {field['image_circle_radius_mm']:.4g} mm): the valid field "
                        'ends before the fold')
    if model.curve.valid_real_mm < edge_real:
        warnings.append(f'the valid field ends at {model.curve.valid_real_mm:.4g} mm, inside '
                        f'the sensor half-diagonal {edge_real:.4g} mm: corners stay black')
    corner_sigma = _corner_sigma_px(model, vals, nominal, sigmas, distance)
    return {
        'mode': 'prescription' if _is_prescription_mode(vals) else 'thick_lens',
        'focal_length_mm': f,
        'focal_length_sigma_mm': sigma_f,
        'image_distance_mm': model.image_distance_mm,
        'principal_planes_mm': {
            'front': paraxial(model.prescription).front_principal_z_mm,
            'rear': paraxial(model.prescription).rear_principal_z_mm},
        'stop_z_mm': model.prescription.stop_z_mm,
        'scene_distance_mm': _finite_or_none(distance),
        'sensor_size_mm': {'x': w_mm, 'y': h_mm, 'diagonal': math.hypot(w_mm, h_mm)},
        'fov_deg': {'horizontal': constraints.field_of_view_deg(w_mm, f),
                    'vertical': constraints.field_of_view_deg(h_mm, f),
                    'diagonal': constraints.field_of_view_deg(math.hypot(w_mm, h_mm), f)},
        'footprint_mm': {'x': _finite_or_none(constraints.footprint_mm(distance, w_mm, f)),
                         'y': _finite_or_none(constraints.footprint_mm(distance, h_mm, f))},
        'feature_resolution_mm': {
            'x': _finite_or_none(constraints.feature_resolution_mm(
                distance, vals['sensor.pixel_size_x_um'], f)),
            'y': _finite_or_none(constraints.feature_resolution_mm(
                distance, vals['sensor.pixel_size_y_um'], f))},
        'f_number': n_f,
        'entrance_pupil_diameter_mm': d_a,
        'circle_of_confusion_mm': c,
        'hyperfocal_mm': h,
        'hyperfocal_sigma_mm': sigma_h,
        'focus_distance_mm': _finite_or_none(focus),
        'depth_of_field_mm': {'near': near, 'far': _finite_or_none(far)},
        'valid_field_mm': model.curve.valid_real_mm,
        'projection': model.projection,
        'max_field_angle_deg': field['max_field_angle_deg'],
        'covered_field': _covered_field(model, field),
        '_field_curve': field,
        'corner_sigma_px': corner_sigma,
        'warnings': warnings,
    }


#: Samples of the field traced beyond the sensor, to the lens's limit (for the report).
BEYOND_SAMPLES = 128


def _full_field(model: LensModel) -> dict[str, Any]:
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
    distance = _scene_distance(model.values)
    cap = _field_cap_rad(distance)
    sensor_z, _ = image_plane(model.prescription, distance)
    theta, real = curve.field_angle_rad, curve.real_mm
    guide = curve
    step = float(theta[1] - theta[0])
    if curve.ideal_mm.size == COARSE_SAMPLES and curve.max_field_angle_rad < cap:
        # The lens passes more than the sensor needs: trace on to the cap.
        beyond = np.linspace(theta[-1], cap, BEYOND_SAMPLES + 1)[1:]
        grid = np.concatenate((theta, beyond))
        traced = _trace_angles(model, sensor_z, grid, guide)
        theta, real, folded = traced.field_angle_rad, traced.real_mm, traced.folded
        guide = traced
        if traced.ideal_mm.size == grid.size:
            return _field_dict(theta, real, folded, cap)
        step = float(grid[traced.ideal_mm.size] - theta[-1])
    # Refine the last interval: where exactly the field ends.
    fine = np.concatenate((theta[-4:], theta[-1] + step * np.arange(1, 65) / 64.0))
    refined = _trace_angles(model, sensor_z, fine, guide)
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


def _trace_angles(model: LensModel, sensor_z: float, theta: FloatArray,
                  guide: RadialMap | None = None) -> RadialMap:
    """Trace the chief rays of the field angles ``theta`` (increasing); keep the valid prefix."""
    known = None
    if guide is not None and guide.aim_offsets is not None:
        known = (guide.field_angle_rad, guide.aim_offsets)
    real, offsets = trace_field(model.prescription, _scene_distance(model.values), sensor_z,
                                theta, known)
    real = -real
    good = np.isfinite(real)
    rising = np.ones_like(good)
    rising[1:] = np.diff(real) > 0.0
    good &= rising
    end = int(np.argmin(good)) if not good.all() else theta.size
    folded = end < theta.size and bool(np.isfinite(real[end])) and not rising[end]
    return RadialMap(theta[:end] * model.image_distance_mm, real[:end], theta[:end], folded,
                     offsets[:end])


def _covered_field(model: LensModel, field: Mapping[str, Any]) -> dict[str, Any]:
    """Return the field the raw image and the corrected image cover, in degrees."""
    theta, real = field['theta_rad'], field['real_mm']
    circle = field['image_circle_radius_mm']

    def angle(radius_mm: float) -> float | None:
        if not radius_mm <= circle:
            return None
        return math.degrees(float(np.interp(radius_mm, real, theta)))

    half_w = model.width / 2.0 * model.pixel_mm[0]
    half_h = model.height / 2.0 * model.pixel_mm[1]
    corner = math.hypot(half_w, half_h)
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


def _corner_sigma_px(model: LensModel, vals: Mapping[str, Any], nominal: Mapping[str, float],
                     sigmas: Mapping[str, float], distance: float) -> float:
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
    # continuation from the smaller angles (raytrace._aim_continued).
    ladder = theta * np.array([0.25, 0.5, 0.75, 1.0])

    def height(p: Mapping[str, float]) -> float:
        lens = make_prescription(_with(vals, p))
        z, _ = image_plane(lens, distance)
        return float(-trace_field_angles(lens, distance, z, ladder)[-1])

    return _sigma_or_nan(height, nominal, sigmas) / min(model.pixel_mm)


def _sigma_or_nan(fn: Callable[[Mapping[str, float]], float], nominal: Mapping[str, float],
                  sigmas: Mapping[str, float]) -> float:
    """
    Propagate tolerances, or return NaN where a perturbed lens is no lens at all.

    Near the edge of the parameter space (an almost afocal lens, a thickness at 0) a
    perturbation by one sigma can leave it; the sigma is then undefined, not an error.
    """
    try:
        sigma = propagate_sigma(fn, dict(nominal), dict(sigmas))
    except (ValueError, ZeroDivisionError, FloatingPointError, OverflowError):
        return math.nan
    return float(sigma) if math.isfinite(sigma) else math.nan


def camera_info_yaml(model: LensModel, camera_name: str = 'mechdeconv') -> str:
    """
    Write the raw camera as camera_calibration_parsers YAML (what camera_info_manager loads).

    K and D describe the raw camera (D = the equivalent coefficients), R is the identity and
    P = ``[K_new | 0]``: the same content the node publishes on ``camera_info``.

    :param model: the lens model.
    :param camera_name: the ``camera_name`` field.
    :return: YAML text.
    """
    def matrix(rows: int, cols: int, data: Any) -> dict[str, Any]:
        return {'rows': rows, 'cols': cols,
                'data': [float(x) for x in np.asarray(data, dtype=np.float64).ravel()]}

    document = {
        'image_width': model.width,
        'image_height': model.height,
        'camera_name': camera_name,
        'camera_matrix': matrix(3, 3, model.K),
        'distortion_model': model.distortion_model,
        'distortion_coefficients': matrix(1, len(model.D), model.D),
        'rectification_matrix': matrix(3, 3, np.eye(3)),
        'projection_matrix': matrix(3, 4, model.P),
    }
    return yaml.safe_dump(document, sort_keys=False, default_flow_style=None)
