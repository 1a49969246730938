# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
LensModel: from a physical lens description to raw intrinsics, a radial map and an equivalent D.

The model (Lim & Furukawa 2008, with the distortion traced instead of approximated):

1. The lens comes from a lens source (:mod:`mechdeconv_ros.lenses.lens_source`: the paper's thick
   lens, eq. 7-8, or a general prescription, both traced exactly). Its paraxial data give the
   focal length ``f``, the principal planes ``H``, ``H'`` and, for a scene at distance ``l`` in
   front of ``H``, the image distance ``v = f l / (l - f)`` behind ``H'`` (``v = f`` for
   ``l = inf``). The sensor sits at that paraxial image plane.
2. The raw camera is the pinhole that the paraxial lens is: ``f_x = v / p_x``, ``f_y = v / p_y``
   (pixel pitches in mm), principal point at the image centre ``((W-1)/2, (H-1)/2)``.
3. Distortion is radial (the paper's assumption 3). The exact chief ray of a scene point at
   field ``tan(theta)`` (seen from ``H``) lands at the real height ``rho_real`` on the sensor,
   where the pinhole puts it at ``rho_ideal = v tan(theta)``. Sampling gives the radial map
   ``rho_real = R(rho_ideal)`` (:mod:`mechdeconv_ros.model.radial_map`); it ends where a ray fails
   (miss, TIR, vignetting) or ``R`` stops increasing, and beyond that nothing is valid.
4. The corrected image is a pinhole with camera matrix ``K_new = diag(k f_x, k f_y, 1)`` centred
   on the output image; ``k`` interpolates between the zoom that keeps only valid pixels
   (``alpha = 0``) and the one that keeps every source pixel (``alpha = 1``), as OpenCV's
   getOptimalNewCameraMatrix does (but with one scale for both axes, so the pixel aspect is
   kept).
5. The equivalent calibration (``camera_info``'s D) is the consumer model (plumb_bob,
   rational_polynomial or equidistant) fitted to the traced field whose largest displacement
   over the raw image is within 0.05 px, else the best
   (:mod:`mechdeconv_ros.model.camera_info_fit`).
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
   ``LensModel.warnings``. The rules and their formulas: :mod:`mechdeconv_ros.lenses.refusals`,
   docs/design.md section 7.

The summary (scene constraints, the whole field, tolerances) is
:mod:`mechdeconv_ros.model.summary`. Pixel coordinates follow OpenCV and ROS (REP-103 optical
frame): x right, y down, origin at the centre of the top-left pixel.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Mapping

from mechdeconv_ros.lenses import refusals
from mechdeconv_ros.lenses.lens_errors import FloatArray, half_diagonal_mm, ModelError
from mechdeconv_ros.lenses.lens_params import make_prescription
from mechdeconv_ros.lenses.lens_source import LensSource
from mechdeconv_ros.lenses.sources import source_for
from mechdeconv_ros.model import lateral_color
from mechdeconv_ros.model.camera_info_fit import (
    boundary_points, choose_equivalent, EQUIVALENT_MAX_ERROR_PX, EquivalentFit, fit_equivalent)
from mechdeconv_ros.model.lateral_color import LateralColor
from mechdeconv_ros.model.radial_map import (
    COARSE_SAMPLES, CURVE_SAMPLES, field_cap_rad, projected, RadialMap, resample, trace_curve)
from mechdeconv_ros.model.summary import summarize
from mechdeconv_ros.optics.illumination import Illumination
from mechdeconv_ros.optics.prescription import Prescription
from mechdeconv_ros.schema.params import check_values, INTERPOLATIONS, MAX_FRAME_PIXELS, ParamValue
import numpy as np
import yaml

#: The names callers import from here (some live in the modules the model is made of).
__all__ = [
    'build_model', 'camera_info_yaml', 'CV_INTERPOLATION', 'EQUIVALENT_MAX_ERROR_PX',
    'EquivalentFit', 'LensModel', 'make_prescription', 'ModelError', 'radii_mean_error_percent',
    'RadialMap']

#: OpenCV interpolation flags by the names ``output.interpolation`` accepts.
CV_INTERPOLATION = {'nearest': 0, 'linear': 1, 'cubic': 2, 'lanczos4': 4}
assert tuple(CV_INTERPOLATION) == INTERPOLATIONS


@dataclass(frozen=True)
class LensModel:
    """
    Everything derived from one parameter set and one image size.

    Build it with :func:`build_model`. Matrices are float64; ``K`` and ``D`` describe the raw
    camera, ``K_new`` and ``P`` the corrected image.
    """

    values: dict[str, ParamValue]
    source: LensSource
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
    _lateral_cache: dict[str, LateralColor] = field(default_factory=dict, repr=False,
                                                    compare=False)

    def lateral_color(self) -> LateralColor:
        """
        Return the three colour channels traced to the sensor plane, computed on first use.

        :return: :func:`mechdeconv_ros.model.lateral_color.trace_channels` of this model.
        :raises ModelError: when the lens has no glass names or a glass does not cover a
            channel's wavelength.
        """
        cached = self._lateral_cache.get('traces')
        if cached is None:
            cached = self._lateral_cache['traces'] = lateral_color.trace_channels(self)
        return cached

    def illumination(self, with_fraction: bool = True) -> Illumination:
        """
        Return the relative illumination traced over the sensor, computed on first use.

        :param with_fraction: also trace the stop-only beam (``pupil_pass_fraction``), which
            doubles the cost; the gain map does not need it.
        :return: the curve (the lens source's, :meth:`LensSource.relative_illumination`).
        :raises ValueError: when not even the axial beam passes the lens, or the source gives
            none (:class:`~mechdeconv_ros.lenses.lens_source.NotApplicable`).
        """
        cached = self._illumination_cache.get(True) or self._illumination_cache.get(
            with_fraction)
        if cached is None:
            # The gain map's curve (no fraction) needs only the stop-only beam added.
            cached = self.source.relative_illumination(
                self, with_fraction=with_fraction, known=self._illumination_cache.get(False))
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
            self._summary_cache.update(summarize(self))
        return self._summary_cache

    @property
    def half_diagonal_mm(self) -> float:
        """Return the raw image's half-diagonal on the sensor (to the outer pixel edges), mm."""
        return half_diagonal_mm(self.width, self.height, self.pixel_mm)

    @property
    def prescription(self) -> Prescription | None:
        """Return the lens source's surfaces (None for a source without them)."""
        return self.source.prescription

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
        colour = None
        if lateral_color.has_dispersion(self.values):
            try:
                colour = self.lateral_color().report(self)
            except ModelError as err:
                out['warnings'] = list(out['warnings']) + [f'lateral colour: {err}']
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
            'lateral_color': colour,
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


def build_model(values: Mapping[str, Any], width: int = 0, height: int = 0, *,
                source: LensSource | None = None) -> LensModel:
    """
    Build the model of one parameter set for one image size.

    :param values: parameter name -> value; missing names take their defaults.
    :param width: the incoming image width, used when ``sensor.width_px`` is 0.
    :param height: the incoming image height, used when ``sensor.height_px`` is 0.
    :param source: the lens; by default the one the ``lens.*`` values describe
        (:func:`mechdeconv_ros.lenses.sources.source_for`).
    :return: the model.
    :raises ModelError: naming the parameter at fault when the values describe no camera.
    """
    try:
        vals = check_values(values)
    except ValueError as err:
        name = str(err).split(':', 1)[0].split('[', 1)[0].strip(" '")
        raise ModelError(name, str(err).split(':', 1)[-1].strip()) from None
    if source is None:
        source = source_for(vals)
    # The rules of every source (paraxial), then the ones on its surfaces (docs/design.md s. 7).
    f, distance, sensor_z, v = refusals.check_first_order(vals, source)
    lateral_color.check_switch(vals)
    warnings = source.check_physical(distance, sensor_z)
    w, h, ow, oh = _image_size(vals, width, height)
    px = float(vals['sensor.pixel_size_x_um']) * 1e-3
    py = float(vals['sensor.pixel_size_y_um']) * 1e-3
    refusals.check_circle_of_confusion(vals, f, w * px, h * py)
    fx, fy = v / px, v / py
    K = np.array([[fx, 0.0, (w - 1) / 2.0], [0.0, fy, (h - 1) / 2.0], [0.0, 0.0, 1.0]])

    projection = str(vals['output.projection'])
    cap = field_cap_rad(distance)

    # Pass 1: trace the field by angle (theta uniform) far enough to cover the raw image (its
    # edge, not the pixel centre), or to the end of the field the lens passes.
    edge_real = half_diagonal_mm(w, h, (px, py))
    theta_max = min(cap, 1.5 * edge_real / v)
    for _ in range(12):
        coarse = trace_curve(source, distance, v, theta_max * v, COARSE_SAMPLES, 'equidistant')
        if (coarse.ideal_mm.size < COARSE_SAMPLES or coarse.valid_real_mm >= 1.05 * edge_real
                or theta_max >= cap):
            break
        theta_max = min(cap, 2.0 * theta_max)
    if coarse.ideal_mm.size == 0:
        raise ModelError(source.lens_parameter, 'not even the axial ray passes through this '
                                                'lens: a surface misses it or reflects it totally')
    reached = max(0.0, coarse.valid_real_mm)
    if coarse.ideal_mm.size < 16 or reached < 0.05 * edge_real:
        raise ModelError(source.stop_parameter,
                         f'no chief ray reaches the sensor beyond {reached:.3g} mm of the '
                         f'{edge_real:.3g} mm half-diagonal: the stop position or the lens '
                         'blocks the field, or the sensor is far larger than the image the '
                         'lens forms')
    boundary = boundary_points(w, h)
    bx = (boundary[:, 0] - K[0, 2]) * px
    by = (boundary[:, 1] - K[1, 2]) * py
    b_real = np.hypot(bx, by)
    b_theta = coarse.angle_from_real(np.minimum(b_real, coarse.valid_real_mm))
    ratio = projected(b_theta, projection) / b_real
    boundary_ideal = np.stack([bx * ratio, by * ratio], axis=1)
    disk = float(projected(np.array(coarse.max_field_angle_rad), projection))
    k = _scale_k(boundary_ideal, disk, ow / 2.0, oh / 2.0, fx, fy, float(vals['output.alpha']))
    K_new = np.array([[k * fx, 0.0, (ow - 1) / 2.0], [0.0, k * fy, (oh - 1) / 2.0],
                      [0.0, 0.0, 1.0]])

    # Pass 2: the dense curve in the output projection from 0 to just past the output corner
    # (and the raw image edge).
    out_corner = math.hypot(ow / 2.0 / (k * fx), oh / 2.0 / (k * fy)) * v
    raw_corner_ideal = float(np.nanmax(ratio * b_real)) * v
    reach = min(1.02 * max(out_corner, raw_corner_ideal), disk * v * 1.001)
    curve = resample(coarse, v, reach, CURVE_SAMPLES, projection)

    fits = fit_equivalent(coarse, v, K, w, h)
    chosen = choose_equivalent(fits)
    disp = (boundary_ideal * v - np.stack([bx, by], axis=1)) / np.array([px, py])
    max_disp = float(np.nanmax(np.hypot(disp[:, 0], disp[:, 1])))

    model = LensModel(
        values=vals, source=source, width=w, height=h, out_width=ow,
        out_height=oh, pixel_mm=(px, py), focal_length_mm=f, image_distance_mm=v, curve=curve,
        K=K, K_new=K_new, D=chosen.D, distortion_model=chosen.distortion_model,
        fit_rms_px=chosen.rms_error_px, equivalent_max_error_px=chosen.max_error_px,
        equivalent_fits=tuple(fits),
        max_displacement_px=max_disp,
        interpolation=CV_INTERPOLATION[str(vals['output.interpolation'])],
        projection=projection, field_curve=coarse, warnings=tuple(warnings))
    if vals['output.lateral_color_correction']:
        model.lateral_color()       # its three traces: a channel no ray passes is refused now
    return model


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
