# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Lateral colour: each colour channel traced at its own wavelength to the one sensor plane.

Pure Python and numpy, no ROS. Glass disperses: its index n(lambda) falls from blue to red,
so the chief ray of one object point lands at a different height for each colour (lateral
colour, transverse chromatic aberration). The model (:mod:`mechdeconv_ros.model.model`) is the lens
at ``lens.wavelength_nm`` lambda_0, the wavelength it was focused at: the sensor sits at its
paraxial image plane z_s, and K, K_new, D and both CameraInfos are its own. Channel c (R, G,
B at ``lens.channel_wavelengths_nm``) is the SAME lens, with the same radii, thicknesses,
stop plane and object plane, and each glass at its index n_i(lambda_c) (``lens.surfaces.glass``
or, for the thick lens, ``lens.glass``; :func:`mechdeconv_ros.optics.glass.refractive_index`): a
per-wavelength lens source (:class:`ChannelSource`) on the lens-source seam. Its chief ray of
field angle theta (seen from H of the model) crosses the same plane z_s at the real height
h_c(theta).

The corrected image's pixel u shows the direction theta(u) through K_new, for every channel,
so channel c's source pixel is the model's remap (docs/design.md section 2.7) with h_c in
place of the model's real height:

    map_c(u) = c + f (x_n, y_n) h_c(theta(u)) / rho_ideal(u),   rho_ideal = v |(x_n, y_n)|

and the three corrected channels register on K_new by construction
(:class:`mechdeconv_ros.imaging.channel_remap.ChannelRemap` applies the three maps in one remap).

Finite scenes: the source places its object plane l from its own H, which moves with the
wavelength by dz_H. The channel is traced with l_c = l + dz_H and tan(theta_c) =
tan(theta) l / l_c, which is the same object point on the same plane. The stop plane is the
model's (a thick lens's stop is m_a in front of H at lambda_0, fixed in space).

The report (``mechdeconv info --json``, key ``lateral_color``): per channel the wavelength
and the real height against the field angle, and the largest red-blue separation on the raw
image: at a raw point at angle phi from the x axis, the R and B images of one object point lie
on one radius, |h_R - h_B| apart, which is |h_R - h_B| hypot(cos(phi) / p_x, sin(phi) / p_y)
pixels; its maximum over the raw image's edges, corners and a grid.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math
import time
from typing import Any, Mapping, Protocol, TypeVar

from mechdeconv_ros.lenses.lens_errors import is_prescription_mode
from mechdeconv_ros.lenses.lens_source import FloatArray, ModelError, Prescription, TracedSource
from mechdeconv_ros.model.radial_map import hermite, RadialMap, resample, trace_angles
from mechdeconv_ros.optics.glass import GlassError, lookup
from mechdeconv_ros.optics.raytrace import trace_field_rays
from mechdeconv_ros.schema.params import scene_distance
import numpy as np


class ModelView(Protocol):
    """
    What this module reads of a model: a :class:`mechdeconv_ros.model.model.LensModel`.

    The model imports this module (its ``lateral_color()`` traces the channels), so the
    dependency runs model -> lateral_color and this module names the attributes it uses
    instead of importing the class.
    """

    @property
    def values(self) -> Mapping[str, Any]:  # noqa: D102 - a protocol member
        ...

    @property
    def source(self) -> Any:  # noqa: D102 - a protocol member
        ...

    @property
    def width(self) -> int:  # noqa: D102 - a protocol member
        ...

    @property
    def height(self) -> int:  # noqa: D102 - a protocol member
        ...

    @property
    def pixel_mm(self) -> tuple[float, float]:  # noqa: D102 - a protocol member
        ...

    @property
    def image_distance_mm(self) -> float:  # noqa: D102 - a protocol member
        ...

    @property
    def K(self) -> FloatArray:  # noqa: D102, N802 - a protocol member, the ROS name
        ...

    @property
    def curve(self) -> RadialMap:  # noqa: D102 - a protocol member
        ...

    @property
    def field_curve(self) -> RadialMap | None:  # noqa: D102 - a protocol member
        ...

    @property
    def projection(self) -> str:  # noqa: D102 - a protocol member
        ...


#: A model of the kind given (``channel_model`` returns the same kind).
M = TypeVar('M', bound=ModelView)

#: The channels, in the order of ``lens.channel_wavelengths_nm``.
CHANNELS = ('R', 'G', 'B')
#: The switch and the wavelengths (parameter names).
SWITCH = 'output.lateral_color_correction'
WAVELENGTHS = 'lens.channel_wavelengths_nm'
#: The colour of each channel of an image encoding, as indices into CHANNELS; encodings not
#: listed (mono, depth, 8UC3 whose channel order nobody knows) ignore the correction.
COLOUR_ORDER: dict[str, tuple[int, ...]] = {
    'rgb8': (0, 1, 2), 'rgb16': (0, 1, 2), 'bgr8': (2, 1, 0), 'bgr16': (2, 1, 0),
    'rgba8': (0, 1, 2, 1), 'bgra8': (2, 1, 0, 1)}
#: Field angles of the report's height tables.
REPORT_SAMPLES = 33
#: Raw-image grid of the separation search (columns x rows), besides the edges.
SEPARATION_GRID = (65, 49)


def has_dispersion(values: Mapping[str, Any]) -> bool:
    """
    Return True when the lens names its glass, so its indices are known at every wavelength.

    :param values: checked parameter values.
    :return: prescription mode: a non-blank ``lens.surfaces.glass`` entry; thick lens: a
        non-blank ``lens.glass``.
    """
    if str(values.get('scene.medium', 'air')) != 'air' and not float(
            values.get('scene.medium_index', 0.0)):
        return True     # the water's own dispersion (Quan & Fry), docs/underwater.md
    if is_prescription_mode(values):
        return any(str(name).strip() for name in values.get('lens.surfaces.glass', []) or [])
    return bool(str(values.get('lens.glass', '') or '').strip())


def check_switch(values: Mapping[str, Any]) -> None:
    """
    Refuse lateral colour correction for a lens without dispersion (glass names).

    :param values: checked parameter values.
    :raises ModelError: naming ``output.lateral_color_correction``.
    """
    if not values.get(SWITCH, False):
        return
    if has_dispersion(values):
        # Every glass must cover every channel's wavelength (cheap: no trace).
        names = _glass_names(values, len(values.get('lens.surfaces.radius_mm', []) or [0, 0]))
        for i, name in enumerate(names):
            for wavelength in wavelengths(values) if name else ():
                _index(name, wavelength, values, i)
        return
    where = ('lens.surfaces.glass (one glass name per surface, blank for air)'
             if is_prescription_mode(values) else 'lens.glass')
    raise ModelError(SWITCH, f'the lens has no dispersion: lateral colour needs the glass '
                             f'names, set {where}; numeric indices hold at one wavelength only')


def _glass_names(values: Mapping[str, Any], count: int) -> list[str]:
    """Return the glass name after each surface ('' = keep the surface's index)."""
    if is_prescription_mode(values):
        names = [str(n).strip() for n in values.get('lens.surfaces.glass', []) or []]
        return (names + [''] * count)[:count]
    return [str(values.get('lens.glass', '') or '').strip()] + [''] * (count - 1)


def prescription_at(base: Prescription, values: Mapping[str, Any],
                    wavelength_nm: float) -> Prescription:
    """
    Return the lens with each named glass at its index at ``wavelength_nm``.

    Radii, thicknesses, semi-diameters, aspheres and the stop plane are the base's.

    :param base: the lens at ``lens.wavelength_nm``.
    :param values: checked parameter values (the glass names).
    :param wavelength_nm: the wavelength.
    :return: the prescription.
    :raises ModelError: naming ``lens.channel_wavelengths_nm`` when a glass's formula does
        not cover the wavelength, or the glass parameter when a name is unknown.
    """
    names = _glass_names(values, len(base.surfaces))
    surfaces = []
    for i, (surface, name) in enumerate(zip(base.surfaces, names)):
        if name:
            surface = replace(surface, refractive_index=_index(name, wavelength_nm, values, i))
        surfaces.append(surface)
    return replace(base, surfaces=tuple(surfaces))


def _index(name: str, wavelength_nm: float, values: Mapping[str, Any], surface: int) -> float:
    """Return a glass's index, refusing an unknown name or an uncovered wavelength."""
    try:
        found = lookup(name)
    except GlassError as err:
        raise ModelError('lens.surfaces.glass' if is_prescription_mode(values) else 'lens.glass',
                         f'surface {surface}: {err}') from None
    try:
        return float(found.index(wavelength_nm))
    except GlassError as err:
        raise ModelError(WAVELENGTHS, f'surface {surface}: {err}') from None


class ChannelSource(TracedSource):
    """
    The model's lens at another wavelength, imaging on the model's sensor plane.

    Same geometry, stop plane and object plane as ``base``; only the glass indices change.
    """

    def __init__(self, base: TracedSource, wavelength_nm: float,
                 values: Mapping[str, Any] | None = None) -> None:
        """
        Make the channel's lens.

        :param base: the model's lens source (a traced one).
        :param wavelength_nm: the channel's wavelength.
        :param values: the values naming the glasses (default: the base's).
        :raises ModelError: see :func:`prescription_at`.
        """
        values = base.values if values is None else values
        super().__init__(values, prescription_at(base.prescription, values, wavelength_nm))
        self.mode = base.mode
        self.wavelength_nm = float(wavelength_nm)
        self._base = base

    def image_plane(self, distance_mm: float) -> tuple[float, float]:
        """Return the model's image plane: the sensor is where the lens was focused."""
        return self._base.image_plane(distance_mm)

    def chief_lines(self, field_angle_rad: FloatArray, distance_mm: float,
                    guide: Any = None) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Trace the channel's chief rays of the model's object points (module docstring)."""
        sensor_z, _ = self._base.image_plane(distance_mm)
        theta, distance_c = np.asarray(field_angle_rad, dtype=np.float64), distance_mm
        if not math.isinf(distance_mm):
            distance_c += (self.first_order().front_principal_z_mm
                           - self._base.first_order().front_principal_z_mm)
            theta = np.arctan(np.tan(theta) * (distance_mm / distance_c))
        rays, offsets = trace_field_rays(self.prescription, distance_c, sensor_z, theta, guide)
        return -rays.y, -rays.dy / rays.dz, offsets


@dataclass(frozen=True)
class ChannelTrace:
    """One channel: its wavelength, its angle-uniform trace and its radial map."""

    name: str
    wavelength_nm: float
    #: Traced at the model's field angles (equidistant ideal heights v theta).
    field: RadialMap
    #: Resampled on the model's curve (the output projection's ideal heights), for the maps.
    curve: RadialMap

    def height_at(self, theta: FloatArray) -> FloatArray:
        """
        Return the real height at field angles (cubic Hermite of the trace; NaN beyond).

        :param theta: field angles, rad.
        :return: heights, mm.
        """
        theta = np.asarray(theta, dtype=np.float64)
        out = np.full(theta.shape, np.nan)
        inside = theta <= self.field.max_field_angle_rad
        out[inside] = hermite(self.field.field_angle_rad, self.field.real_mm, theta[inside])
        return out


@dataclass(frozen=True)
class LateralColor:
    """The three channel traces of a model and what they say about its lateral colour."""

    channels: tuple[ChannelTrace, ...]
    #: Wall time of the three traces, ms.
    trace_ms: float
    #: Largest red-blue separation on the raw image, px, and the raw pixel where it is.
    max_rb_separation_px: float
    max_rb_separation_at_px: tuple[float, float]
    #: The wavelength the lens is focused at (the model's).
    focus_wavelength_nm: float

    def report(self, model: ModelView) -> dict[str, Any]:
        """
        Return the JSON-ready report.

        :param model: the model traced (its raw corner ends the height tables).
        :return: ``channels`` (name, wavelength_nm, field_angle_deg, real_height_mm, from the
            axis to the raw corner's field angle of the green channel, or to the end of its
            field), ``max_rb_separation_px`` and where, ``trace_ms``, ``focus_wavelength_nm``.
        """
        green = self.channels[1].field
        corner = math.hypot(model.width / 2.0 * model.pixel_mm[0],
                            model.height / 2.0 * model.pixel_mm[1])
        end = float(np.interp(min(corner, green.valid_real_mm), green.real_mm,
                              green.field_angle_rad))
        theta = np.linspace(0.0, end, REPORT_SAMPLES)
        return {
            'focus_wavelength_nm': self.focus_wavelength_nm,
            'channels': [{
                'name': ch.name, 'wavelength_nm': ch.wavelength_nm,
                'field_angle_deg': [float(v) for v in np.degrees(theta)],
                'real_height_mm': [None if not math.isfinite(h) else float(h)
                                   for h in ch.height_at(theta)]} for ch in self.channels],
            'max_rb_separation_px': self.max_rb_separation_px,
            'max_rb_separation_at_px': list(self.max_rb_separation_at_px),
            'trace_ms': self.trace_ms,
        }


def channel_model(model: M, channel: ChannelTrace) -> M:
    """
    Return the model with a channel's radial map in place of its own (same K, K_new, size).

    :param model: the model.
    :param channel: one of its :meth:`~mechdeconv_ros.model.model.LensModel.lateral_color`
    channels.
    :return: a model whose remap tables and :meth:`rect_from_raw` are the channel's.
    """
    return replace(model, curve=channel.curve, _summary_cache={}, _illumination_cache={},
                   _lateral_cache={})


def wavelengths(values: Mapping[str, Any]) -> tuple[float, float, float]:
    """
    Return the channel wavelengths in nm: R, G, B.

    :param values: checked parameter values.
    :return: the three wavelengths.
    :raises ModelError: naming ``lens.channel_wavelengths_nm`` unless it holds three.
    """
    given = [float(v) for v in values.get(WAVELENGTHS, [610.0, 550.0, 465.0])]
    if len(given) != 3:
        raise ModelError(WAVELENGTHS, f'expected three wavelengths [R, G, B], got {len(given)}')
    return given[0], given[1], given[2]


def trace_channels(model: ModelView) -> LateralColor:
    """
    Trace the three channels of a model to its sensor plane.

    :param model: a model of a traced lens with dispersion.
    :return: the traces.
    :raises ModelError: when the lens has no glass names, is not traced, or a glass does not
        cover a channel's wavelength.
    """
    start = time.perf_counter()
    values = model.values
    if not has_dispersion(values):
        check_switch(dict(values, **{SWITCH: True}))
    base = model.source
    at_wavelength = getattr(base, 'channel_source', None)
    if not isinstance(base, TracedSource) and at_wavelength is None:
        raise ModelError(SWITCH, f'the {base.mode} lens source has no surfaces to trace at '
                                 'other wavelengths')
    distance = scene_distance(values)
    v = model.image_distance_mm
    field = model.field_curve
    traces = []
    focus = float(values.get('lens.wavelength_nm', math.nan))
    for name, wavelength in zip(CHANNELS, wavelengths(values)):
        if wavelength == focus:
            traced = field          # the model's own lens and trace (the glass at lambda_0)
        else:
            # A lens behind a port in water traces its own channels (lens, port and water at
            # the wavelength: lenses.port_source.PortedSource.channel_source).
            source = (at_wavelength(wavelength) if at_wavelength is not None
                      else ChannelSource(base, wavelength, values))
            traced = trace_angles(source, distance, v, field.field_angle_rad, field)
        if traced.ideal_mm.size < 16:
            raise ModelError(WAVELENGTHS, f'{name} at {wavelength:g} nm: no chief ray reaches '
                                          'the sensor')
        curve = resample(traced, v, model.curve.valid_ideal_mm, model.curve.ideal_mm.size,
                         model.projection)
        traces.append(ChannelTrace(name, wavelength, traced, curve))
    trace_ms = (time.perf_counter() - start) * 1e3
    separation, where = _max_separation(model, traces)
    return LateralColor(tuple(traces), trace_ms, separation, where, focus)


def _max_separation(model: ModelView, traces: list[ChannelTrace]
                    ) -> tuple[float, tuple[float, float]]:
    """Return the largest |h_R - h_B| in raw px over the raw image, and where."""
    w, h = model.width, model.height
    px, py = model.pixel_mm
    cols = np.concatenate([np.linspace(0.0, w - 1.0, SEPARATION_GRID[0]), [0.0, w - 1.0]])
    rows = np.concatenate([np.linspace(0.0, h - 1.0, SEPARATION_GRID[1]), [0.0, h - 1.0]])
    u, v = np.meshgrid(cols, rows)
    x = (u - model.K[0, 2]) * px
    y = (v - model.K[1, 2]) * py
    radius = np.hypot(x, y)
    green = traces[1].field
    theta = np.interp(radius, green.real_mm, green.field_angle_rad, right=np.nan)
    gap = np.abs(traces[0].height_at(theta) - traces[2].height_at(theta))
    with np.errstate(invalid='ignore', divide='ignore'):
        scale = np.where(radius > 0.0, np.hypot(x / px, y / py) / radius, 0.0)
    separation = gap * scale
    if not np.isfinite(separation).any():
        return math.nan, (math.nan, math.nan)
    k = int(np.nanargmax(separation))
    return float(separation.flat[k]), (float(u.flat[k]), float(v.flat[k]))
