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
from types import SimpleNamespace
from typing import Any, Mapping

from mechdeconv_ros.lenses import refusals
from mechdeconv_ros.lenses.lens_errors import FloatArray, half_diagonal_mm, ModelError
from mechdeconv_ros.lenses.lens_params import make_prescription
from mechdeconv_ros.lenses.lens_source import LensSource
from mechdeconv_ros.lenses.sources import source_for
from mechdeconv_ros.model import lateral_color, underwater
from mechdeconv_ros.model.assembly import check_pose
from mechdeconv_ros.model.camera_info_fit import (
    bound_warning, boundary_points, choose_equivalent, EQUIVALENT_MAX_ERROR_PX, EquivalentFit,
    fit_equivalent, raw_probe_points)
from mechdeconv_ros.model.camera_info_tilt import fit_tilted
from mechdeconv_ros.model.lateral_color import LateralColor
from mechdeconv_ros.model.projection import raw_from_normalised, unproject_angles
from mechdeconv_ros.model.radial_map import (
    COARSE_SAMPLES, CURVE_SAMPLES, field_cap_rad, projected, RadialMap, resample, trace_curve)
from mechdeconv_ros.model.summary import summarize
from mechdeconv_ros.optics.illumination import Illumination
from mechdeconv_ros.optics.pose import SensorPose
from mechdeconv_ros.optics.prescription import Prescription
from mechdeconv_ros.schema.params import check_values, INTERPOLATIONS, MAX_FRAME_PIXELS, ParamValue
import numpy as np

#: The names callers import from here (some live in the modules the model is made of).
__all__ = [
    'build_model', 'CV_INTERPOLATION', 'EQUIVALENT_MAX_ERROR_PX', 'EquivalentFit', 'LensModel',
    'make_prescription', 'ModelError', 'RadialMap']

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

    def _published_fit(self) -> EquivalentFit:
        """Return the fit camera_info carries (one of ``equivalent_fits``)."""
        return next(fit for fit in self.equivalent_fits
                    if fit.distortion_model == self.distortion_model)

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
        return np.stack(raw_from_normalised(self, xn, yn), axis=-1)

    def rect_from_raw(self, points_px: FloatArray) -> FloatArray:
        """
        Map raw-image pixel coordinates to corrected-image pixel coordinates.

        :param points_px: ``(..., 2)`` x, y in the raw image.
        :return: ``(..., 2)`` x, y in the corrected image; NaN outside the valid field.
        """
        points_px = np.asarray(points_px, dtype=np.float64)
        if SensorPose.from_values(self.values).tilted:
            theta, phi = unproject_angles(self, points_px[..., 0], points_px[..., 1])
            radius = projected(theta, self.projection)
            return np.stack([self.K_new[0, 2] + self.K_new[0, 0] * radius * np.cos(phi),
                             self.K_new[1, 2] + self.K_new[1, 1] * radius * np.sin(phi)],
                            axis=-1)
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
            # The field angle D is fitted and measured to, and the share of the raw image past
            # 90 deg, where no camera_info consumer has a direction (camera_info_fit.py).
            'equivalent_reach_deg': self._published_fit().reach_deg,
            'equivalent_beyond_90deg_fraction': self._published_fit().beyond_fraction,
            'equivalent_models': {fit.distortion_model: {'max_error_px': fit.max_error_px,
                                                         'rms_error_px': fit.rms_error_px}
                                  for fit in self.equivalent_fits},
            'max_displacement_px': self.max_displacement_px,
            'relative_illumination': illumination,
            'lateral_color': colour,
        })
        out.update(underwater.noncentral_errors(self))
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


def _scale_k(boundary_ideal: FloatArray, principal: tuple[float, float], disk: float,
             size: tuple[int, int], fx: float, fy: float, alpha: float) -> float:
    """
    Choose the zoom ``k`` of ``K_new`` from the raw image outline in ideal normalised coords.

    The outline is relative to the lens axis, which the output puts at ``principal``. The
    output of ``size`` (w, h) reaches ``(c' + 1/2) / (k f)`` left of the axis and
    ``(w - 1/2 - c') / (k f)`` right of it (likewise up and down). ``alpha = 0``: the output
    shows only valid source pixels (inside the outline's inner rectangle, and its corners
    inside the valid disk); ``alpha = 1``: every source pixel is in view (outer rectangle).
    """
    x, y = boundary_ideal[:, 0], boundary_ideal[:, 1]
    n = len(x) // 4
    top, bottom, left, right = (slice(0, n), slice(n, 2 * n), slice(2 * n, 3 * n),
                                slice(3 * n, 4 * n))
    reach = (principal[0] + 0.5, size[0] - 0.5 - principal[0],
             principal[1] + 0.5, size[1] - 0.5 - principal[1])
    corner = math.hypot(max(reach[0], reach[1]) / fx, max(reach[2], reach[3]) / fy)
    k0 = max(reach[0] / (fx * -np.max(x[left])), reach[1] / (fx * np.min(x[right])),
             reach[2] / (fy * -np.max(y[top])), reach[3] / (fy * np.min(y[bottom])),
             corner / disk)
    k1 = min(reach[0] / (fx * max(np.max(-x), 1e-300)), reach[1] / (fx * max(np.max(x), 1e-300)),
             reach[2] / (fy * max(np.max(-y), 1e-300)), reach[3] / (fy * max(np.max(y), 1e-300)))
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
    vals = _checked(values)
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
    # The principal point is where the lens axis meets the sensor (sensor.axis_offset_*).
    cx, cy = SensorPose.from_values(vals).axis_pixel(w, h, (px, py))
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    projection = str(vals['output.projection'])
    coarse = _trace_field(source, distance, v, half_diagonal_mm(w, h, (px, py)))
    camera = SimpleNamespace(values=vals, K=K, pixel_mm=(px, py), field_curve=coarse,
                             source=source)
    check_pose(vals, source, camera, w, h, sensor_z)
    outline = _raw_outline(camera, w, h, projection)
    K_new = _corrected_camera(outline, (ow, oh), fx, fy, float(vals['output.alpha']))
    k, principal = K_new[0, 0] / fx, (K_new[0, 2], K_new[1, 2])

    # Pass 2: the dense curve in the output projection from 0 to just past the output corner
    # (and the raw image edge).
    out_corner = math.hypot(max(principal[0] + 0.5, ow - 0.5 - principal[0]) / (k * fx),
                            max(principal[1] + 0.5, oh - 0.5 - principal[1]) / (k * fy)) * v
    raw_corner_ideal = float(np.nanmax(np.hypot(*outline.ideal.T))) * v
    reach = min(1.02 * max(out_corner, raw_corner_ideal), outline.disk * v * 1.001)
    curve = resample(coarse, v, reach, CURVE_SAMPLES, projection)

    fits, chosen = _equivalent(camera, v, w, h, warnings)
    # How far the lens moves the outline from where the pinhole K puts its directions.
    disp = outline.ideal * np.array([fx, fy]) + K[:2, 2] - outline.points
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


def _checked(values: Mapping[str, Any]) -> dict[str, ParamValue]:
    """Return the checked values; a value the schema refuses becomes a ModelError naming it."""
    try:
        return check_values(values)
    except ValueError as err:
        name = str(err).split(':', 1)[0].split('[', 1)[0].strip(" '")
        raise ModelError(name, str(err).split(':', 1)[-1].strip()) from None


def _trace_field(source: LensSource, distance: float, v: float, edge_real: float) -> RadialMap:
    """
    Pass 1: trace the field by angle (theta uniform) far enough to cover the raw image.

    That is to its edge (``edge_real``, not the pixel centre), or to the end of the field the
    lens passes.

    :raises ModelError: naming the lens when not even the axial ray passes, the stop when
        the field is blocked close to the axis.
    """
    cap = field_cap_rad(distance)
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
    return coarse


@dataclass(frozen=True)
class _Outline:
    """The raw image's outline (pixels) and centre as ideal normalised coordinates."""

    points: FloatArray      # (N, 2) raw pixels on the outer edge
    ideal: FloatArray       # (N, 2) their directions, normalised in the output projection
    centre: tuple[float, float]     # the raw image centre's direction, likewise
    disk: float             # the valid field's edge in the output projection (normalised)


def _raw_outline(camera: Any, w: int, h: int, projection: str) -> _Outline:
    """
    Return the raw image's outline through the traced directions of its pixels.

    The sensor's offset and tilt are included (:func:`mechdeconv_ros.model.assembly.
    unproject_angles`); a pixel beyond the valid field takes its edge.
    """
    coarse = camera.field_curve
    boundary = boundary_points(w, h)
    theta, phi = unproject_angles(camera, boundary[:, 0], boundary[:, 1])
    theta = np.where(np.isfinite(theta), theta, coarse.max_field_angle_rad)
    radius = projected(theta, projection)
    ideal = np.stack([radius * np.cos(phi), radius * np.sin(phi)], axis=1)
    c_theta, c_phi = unproject_angles(camera, np.array([(w - 1) / 2.0]),
                                      np.array([(h - 1) / 2.0]))
    c_radius = projected(np.nan_to_num(c_theta), projection)
    centre = (float(c_radius[0] * np.cos(c_phi[0])), float(c_radius[0] * np.sin(c_phi[0])))
    disk = float(projected(np.array(coarse.max_field_angle_rad), projection))
    return _Outline(boundary, ideal, centre, disk)


def _corrected_camera(outline: _Outline, size: tuple[int, int], fx: float, fy: float,
                      alpha: float) -> FloatArray:
    """
    Return K_new: the zoom of ``output.alpha`` and the principal point framing the raw image.

    The raw centre's direction lands near the output centre; the principal point (where the
    lens axis projects) is rounded to half a pixel, so the maps mirror about it
    (imaging/remap.py), and the zoom is then chosen for that point (docs/design.md s. 2.16).
    """
    ow, oh = size
    middle = ((ow - 1) / 2.0, (oh - 1) / 2.0)
    centre = outline.centre
    k = _scale_k(outline.ideal - np.array(centre), middle, outline.disk, size, fx, fy, alpha)
    principal = (round(2.0 * (middle[0] - k * fx * centre[0])) / 2.0,
                 round(2.0 * (middle[1] - k * fy * centre[1])) / 2.0)
    if principal != middle:
        k = _scale_k(outline.ideal, principal, outline.disk, size, fx, fy, alpha)
    return np.array([[k * fx, 0.0, principal[0]], [0.0, k * fy, principal[1]],
                     [0.0, 0.0, 1.0]])


def _equivalent(camera: Any, v: float, w: int, h: int,
                warnings: list[str]) -> tuple[list[EquivalentFit], EquivalentFit]:
    """
    Fit camera_info's models: radially (section 2.8), or in 2-D for a tilted sensor.

    A lens or tilt no model represents within EQUIVALENT_MAX_ERROR_PX adds a warning
    (``info``, ``/diagnostics``): the best fit is published with its error.
    """
    if not SensorPose.from_values(camera.values).tilted:
        fits = fit_equivalent(camera.field_curve, v, camera.K, w, h)
        chosen = choose_equivalent(fits)
        warnings += bound_warning(chosen, 'camera_info', 'this lens')
        return fits, chosen
    # No rotational symmetry: the consumer models in two dimensions, with their tangential
    # terms, on the traced directions of the probe pixels (model/camera_info_tilt.py).
    probe = raw_probe_points(w, h)
    theta, phi = unproject_angles(camera, probe[:, 0], probe[:, 1])
    fits = fit_tilted(theta, phi, probe[:, 0], probe[:, 1], camera.K)
    chosen = choose_equivalent(fits)
    warnings += bound_warning(chosen, 'sensor.tilt_x_deg/tilt_y_deg', 'this tilt')
    return fits, chosen
