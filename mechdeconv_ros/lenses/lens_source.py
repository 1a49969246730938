# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Lens sources: where a LensModel's lens comes from (the seam of docs/design.md section 6.1).

Pure Python and numpy, no ROS. :func:`mechdeconv_ros.model.model.build_model` asks a
:class:`LensSource` two things and derives everything else (K, the radial map, K_new, D, the
summary) itself:

1. its paraxial data (:meth:`LensSource.first_order`): the focal length f and the principal
   planes H, H' (z from the first vertex, mm), and the paraxial image plane of a scene at l
   from H (:meth:`LensSource.image_plane`); by default the Gaussian image distance in air

       v = f l / (l - f)        (v = f for l = inf),   z_image = z_H' + v;

2. the real image height of the chief ray of each field angle theta (object space, seen from
   H), positive for a real inverted image, NaN where no ray passes
   (:meth:`LensSource.real_heights`).

Where it can, a source also gives the relative illumination over the sensor
(:meth:`LensSource.relative_illumination`), the entrance pupil (:meth:`LensSource.pupil_scale`,
for the f-number ``n_f = sqrt(2/q) f / D``), its tolerances for propagation
(:meth:`LensSource.tolerances`, :meth:`LensSource.perturbed`) and the rules that need its
surfaces (:meth:`LensSource.check_physical`). The defaults say that these do not apply
(:class:`NotApplicable`, None, no rules), so a source that knows only a table of real heights
implements three methods.

Two sources trace a prescription exactly (:mod:`mechdeconv_ros.optics.raytrace`): the paper's
thick lens (:class:`ThickLensSource`) and a surface prescription (:class:`PrescriptionSource`).
A new source goes in its own module that imports only this one (every name it needs is here,
:data:`__all__`), and one line of :func:`mechdeconv_ros.lenses.sources.source_for` (the one
place that picks the source of the ``lens.*`` values) picks it (or
:func:`~mechdeconv_ros.model.model.build_model` gets it as ``source=``).
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
import math
from typing import Any, Mapping

from mechdeconv_ros.lenses import refusals
from mechdeconv_ros.lenses.lens_errors import FloatArray, lens_param, ModelError, stop_param
from mechdeconv_ros.lenses.lens_params import (
    make_prescription, tolerance_keys, with_glass_indices, with_overrides)
from mechdeconv_ros.lenses.sensor_plane import blur_diameter_mm, sensor_plane, SensorPlane
from mechdeconv_ros.optics import illumination
from mechdeconv_ros.optics.illumination import Illumination
from mechdeconv_ros.optics.prescription import Paraxial, paraxial, Prescription, Surface, vertex_z
from mechdeconv_ros.optics.raytrace import trace_field

#: A sensor off the image plane is noted in the warnings when its blur circle is wider (px).
DEFOCUS_WARNING_PX = 2.0

#: Everything a new source may need, importable from here.
__all__ = [
    'FirstOrder', 'FloatArray', 'Illumination', 'LensSource', 'make_prescription', 'ModelError',
    'NotApplicable', 'Prescription', 'PrescriptionSource', 'Surface', 'ThickLensSource',
    'TracedSource', 'vertex_z', 'with_overrides']


class NotApplicable(ValueError):
    """A quantity the lens source cannot give (a table has no surfaces to trace or to check)."""


@dataclass(frozen=True)
class FirstOrder:
    """A lens's paraxial data: focal length and principal planes (z from the first vertex)."""

    efl_mm: float
    front_principal_z_mm: float
    rear_principal_z_mm: float


#: The guide of a trace: field angles already traced and the state a source keeps per angle
#: (a traced source: the chief rays' aiming offsets), which a later trace starts from.
Guide = tuple[FloatArray, FloatArray]


class LensSource(abc.ABC):
    """
    A lens as the model needs it: paraxial data and real image heights by field angle.

    ``mode`` names the source in the summary; ``lens_parameter`` is the parameter blamed when
    the lens as a whole forms no image, ``stop_parameter`` the one blamed when its field is
    blocked. ``values`` are the checked parameter values it was made from.
    """

    mode: str = ''
    lens_parameter: str = ''
    stop_parameter: str = ''
    values: Mapping[str, Any]

    @abc.abstractmethod
    def first_order(self) -> FirstOrder:
        """
        Return the focal length and principal planes.

        :raises ModelError: naming the parameter when the lens has no focal length.
        """

    @abc.abstractmethod
    def real_heights(self, field_angle_rad: FloatArray, distance_mm: float,
                     guide: Guide | None = None) -> tuple[FloatArray, FloatArray | None]:
        """
        Return the real image heights of field angles on the paraxial image plane.

        :param field_angle_rad: theta (rad), increasing from 0, 1-D.
        :param distance_mm: scene distance l from H (``math.inf`` allowed).
        :param guide: field angles traced before with their state (the second return value
            of an earlier call), a hint a source may start from; None when there is none.
        :return: ``(heights_mm, state)``: positive heights, NaN where no ray passes; a state
            per angle for later guides, or None.
        :raises ValueError: when the scene distance is impossible for this lens.
        """

    def image_plane(self, distance_mm: float) -> tuple[float, float]:
        """
        Return the paraxial image plane of a scene: (its z, the image distance v from H').

        :param distance_mm: l from H, > f (``math.inf`` allowed).
        :return: ``(z_image_mm, v_mm)``.
        :raises ValueError: when the scene forms no real image (l <= f).
        """
        first = self.first_order()
        f = first.efl_mm
        if math.isinf(distance_mm):
            v = f
        elif distance_mm > f:
            v = f * distance_mm / (distance_mm - f)
        else:
            raise ValueError(f'a scene at {distance_mm:g} mm is inside the focal length '
                             f'{f:.4g} mm: the lens forms no real image of it')
        return first.rear_principal_z_mm + v, v

    @property
    def prescription(self) -> Prescription | None:
        """Return the surfaces, for what traces them (vignetting, plots); None without."""
        return None

    @property
    def stop_z_mm(self) -> float | None:
        """Return z of the aperture stop, or None when the source has no stop."""
        return None

    def pupil_scale(self) -> float:
        """Return entrance pupil diameter / ``lens.aperture_diameter_mm`` (1 by default)."""
        return 1.0

    def check_physical(self, distance_mm: float, sensor_z_mm: float) -> list[str]:
        """
        Refuse what cannot exist beyond the paraxial rules; return warnings (none by default).

        :param distance_mm: scene distance from H.
        :param sensor_z_mm: z of the image plane.
        :return: warnings about possible but unusual values.
        :raises ModelError: naming the parameter and the limit.
        """
        return []

    def tolerances(self) -> tuple[dict[str, float], dict[str, float]] | None:
        """Return (nominal values, 1-sigmas) by parameter name, or None: they do not apply."""
        return None

    def defocus(self, distance_mm: float) -> dict[str, float] | None:
        """
        Return how far the sensor is from the image of the scene, or None.

        :param distance_mm: scene distance from H.
        :return: None by default: the sensor is on the image of the scene.
        """
        return None

    def perturbed(self, scalars: Mapping[str, float]) -> LensSource:
        """
        Return the source with some parameters changed (tolerance propagation).

        :param scalars: parameter name (or ``name[i]``) -> value, keys of :meth:`tolerances`.
        :return: the changed source.
        :raises NotApplicable: by default.
        """
        raise NotApplicable(f'{self.mode or "this"} lens has no tolerances')

    def relative_illumination(self, model: Any, *, with_fraction: bool = True,
                              known: Illumination | None = None) -> Illumination:
        """
        Return the relative illumination over the sensor of a model of this lens.

        :param model: the :class:`~mechdeconv_ros.model.model.LensModel`.
        :param with_fraction: also give ``pupil_pass_fraction``.
        :param known: the curve given before without the fraction.
        :return: the curve.
        :raises ValueError: when it cannot (:class:`NotApplicable` by default).
        """
        raise NotApplicable(f'the {self.mode or "this"} lens gives no relative illumination')


class TracedSource(LensSource):
    """A lens traced exactly through its prescription (the base of the two sources here)."""

    def __init__(self, values: Mapping[str, Any],
                 prescription: Prescription | None = None) -> None:
        """
        Make the lens of checked parameter values.

        :param values: checked parameter values (``lens.*`` describe the lens).
        :param prescription: the lens to trace instead of the one ``values`` describe (a
            subclass's: a moving or per-wavelength prescription).
        :raises ModelError: when the values describe no lens that focuses.
        """
        # Named glasses become indices at lens.wavelength_nm (lens_params.with_glass_indices):
        # the source keeps the resolved values, so perturbing an index perturbs the glass's.
        values = with_glass_indices(values)
        self.values = values
        self.lens_parameter = lens_param(values)
        self.stop_parameter = stop_param(values)
        self._prescription = (make_prescription(values) if prescription is None
                              else prescription)
        self._paraxial: Paraxial | None = None
        self._planes: dict[float, SensorPlane] = {}

    @property
    def prescription(self) -> Prescription:
        """Return the traced lens."""
        return self._prescription

    @property
    def stop_z_mm(self) -> float:
        """Return z of the aperture stop."""
        return self._prescription.stop_z_mm

    def paraxial(self) -> Paraxial:
        """
        Return the prescription's full paraxial data (focal planes, last vertex, indices).

        :raises ModelError: naming the lens parameter for an afocal lens.
        """
        if self._paraxial is None:
            try:
                self._paraxial = paraxial(self._prescription)
            except ValueError as err:
                raise ModelError(self.lens_parameter, str(err)) from None
        return self._paraxial

    def first_order(self) -> FirstOrder:
        """Return the focal length and principal planes (ABCD matrices)."""
        para = self.paraxial()
        return FirstOrder(para.efl_mm, para.front_principal_z_mm, para.rear_principal_z_mm)

    def sensor_plane(self, distance_mm: float) -> SensorPlane:
        """
        Return the sensor plane: the paraxial image plane or ``lens.image_distance_mm``.

        :param distance_mm: scene distance from H.
        :return: the plane (:mod:`mechdeconv_ros.lenses.sensor_plane`), with the image plane.
        :raises ValueError: when the scene forms no real image.
        :raises ModelError: naming ``lens.image_distance_mm`` for a sensor in the lens.
        """
        if distance_mm not in self._planes:
            self._planes[distance_mm] = sensor_plane(
                self._prescription, distance_mm, self.first_order().front_principal_z_mm,
                float(self.values.get('lens.image_distance_mm', 0.0)),
                float(self.values['lens.aperture_diameter_mm']))
        return self._planes[distance_mm]

    def image_plane(self, distance_mm: float) -> tuple[float, float]:
        """
        Return the sensor's z and the raw pinhole's image distance there.

        On the paraxial image plane (``lens.image_distance_mm`` = 0): ``n'/v = Phi - n_0/l``
        (module prescription); else the sensor ``lens.image_distance_mm`` behind the last vertex
        and the paraxial chief ray's scale there (:mod:`mechdeconv_ros.lenses.sensor_plane`).
        """
        plane = self.sensor_plane(distance_mm)
        return plane.z_mm, plane.v_mm

    def defocus(self, distance_mm: float) -> dict[str, float]:
        """
        Return how far the sensor is from the image of the scene, and its blur circle.

        :param distance_mm: scene distance from H.
        :return: ``{'defocus_mm': dz, 'blur_diameter_mm': B, 'paraxial_image_distance_mm': v}``.
        """
        plane = self.sensor_plane(distance_mm)
        blur = blur_diameter_mm(self._prescription, distance_mm,
                                self.first_order().front_principal_z_mm, plane.z_mm,
                                float(self.values['lens.aperture_diameter_mm']))
        return {'defocus_mm': plane.defocus_mm, 'blur_diameter_mm': blur,
                'paraxial_image_distance_mm': plane.image_v_mm}

    def real_heights(self, field_angle_rad: FloatArray, distance_mm: float,
                     guide: Guide | None = None) -> tuple[FloatArray, FloatArray]:
        """Trace the chief rays (the state is their aiming offsets; heights sign-flipped)."""
        sensor_z, _ = self.image_plane(distance_mm)
        real, offsets = trace_field(self._prescription, distance_mm, sensor_z,
                                    field_angle_rad, guide)
        return -real, offsets

    def pupil_scale(self) -> float:
        """Return entrance pupil / stop diameter (:func:`refusals.pupil_scale`)."""
        return refusals.pupil_scale(self.values, self._prescription)

    def check_physical(self, distance_mm: float, sensor_z_mm: float) -> list[str]:
        """Apply the rules on surfaces (:func:`mechdeconv_ros.lenses.refusals.check_surfaces`)."""
        # The lens rules hold for the paraxial image plane of the scene (a lens that images
        # the scene inside its glass stays refused however far the sensor stands).
        image_z = self.sensor_plane(distance_mm).image_z_mm
        warnings = refusals.check_surfaces(self.values, self._prescription, self.paraxial(),
                                           distance_mm, image_z)
        blur = self.defocus(distance_mm)['blur_diameter_mm']
        pixel = min(float(self.values['sensor.pixel_size_x_um']),
                    float(self.values['sensor.pixel_size_y_um'])) * 1e-3
        if blur > DEFOCUS_WARNING_PX * pixel:
            warnings.append(
                f'lens.image_distance_mm: the sensor is '
                f'{self.sensor_plane(distance_mm).defocus_mm:+.4g} mm from the image of the '
                f'scene: blur circle {blur * 1e3:.3g} um ({blur / pixel:.3g} px) across')
        return warnings

    def tolerances(self) -> tuple[dict[str, float], dict[str, float]]:
        """Return the lens parameters with their ``lens.tolerance.*`` sigmas."""
        return tolerance_keys(self.values)

    def perturbed(self, scalars: Mapping[str, float]) -> TracedSource:
        """
        Return the lens of the values with ``scalars`` overriding them.

        A subclass whose constructor takes more than the values (a joint position, a
        wavelength) overrides this.
        """
        return type(self)(with_overrides(self.values, scalars))

    def relative_illumination(self, model: Any, *, with_fraction: bool = True,
                              known: Illumination | None = None) -> Illumination:
        """Trace it (:func:`mechdeconv_ros.optics.illumination.relative_illumination`)."""
        return illumination.relative_illumination(model, with_fraction=with_fraction,
                                                  known=known)


class ThickLensSource(TracedSource):
    """The paper's thick lens (``lens.r1_mm``, ``lens.r2_mm`` or ``lens.focal_length_mm``)."""

    mode = 'thick_lens'


class PrescriptionSource(TracedSource):
    """A surface prescription (``lens.surfaces.*``, stop on ``lens.stop_surface``)."""

    mode = 'prescription'
