# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
What every part of the lens model shares: its errors, its array type, which parameter to blame.

Pure Python, no ROS, no other module of the package: the model (:mod:`mechdeconv_ros.model.model`),
its lens sources (:mod:`mechdeconv_ros.lenses.lens_source`), the refusal rules
(:mod:`mechdeconv_ros.lenses.refusals`), the equivalent calibration
(:mod:`mechdeconv_ros.model.camera_info_fit`) and the summary all import it, so none of them has to
import another to raise or annotate.

A scene distance of 0 in ``scene.distance_mm`` means infinity: read it with
:func:`mechdeconv_ros.schema.params.scene_distance`, the one reading of that sentinel.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


class ParameterError(ValueError):
    """``<parameter>: <reason>``: the parameter at fault and why (base of the two below)."""

    def __init__(self, parameter: str, reason: str) -> None:
        """
        Create the error.

        :param parameter: the parameter at fault, e.g. ``'scene.distance_mm'``.
        :param reason: why, without the parameter name.
        """
        super().__init__(f'{parameter}: {reason}')
        self.parameter = parameter
        self.reason = reason


class ModelError(ParameterError):
    """
    A parameter set that describes no usable camera.

    ``parameter`` names the parameter at fault; ``str(err)`` starts with it and says why in
    words a person understands.
    """


class TableError(ParameterError):
    """
    A table that describes no lens (a datasheet's, a moving group's): ``<parameter>: <reason>``.

    Raised by the table checks, which know nothing of the model; the lens source that reads
    the table turns it into a :class:`ModelError` naming the same parameter.
    """


def is_prescription_mode(values: Mapping[str, Any]) -> bool:
    """
    Return whether the values describe the lens by surfaces (``lens.surfaces.*``).

    :param values: checked parameter values.
    :return: True in prescription mode, False in thick-lens mode.
    """
    return len(values['lens.surfaces.radius_mm']) > 0


def lens_param(values: Mapping[str, Any]) -> str:
    """
    Return the parameter to blame when the lens as a whole forms no image.

    :param values: checked parameter values.
    :return: ``lens.surfaces.radius_mm``, ``lens.focal_length_mm`` or ``lens.r1_mm``.
    """
    if is_prescription_mode(values):
        return 'lens.surfaces.radius_mm'
    return 'lens.focal_length_mm' if float(values['lens.focal_length_mm']) > 0 else 'lens.r1_mm'


def stop_param(values: Mapping[str, Any]) -> str:
    """
    Return the parameter that places the aperture stop.

    :param values: checked parameter values.
    :return: ``lens.stop_surface`` or ``lens.stop_offset_mm``.
    """
    return 'lens.stop_surface' if is_prescription_mode(values) else 'lens.stop_offset_mm'


def half_diagonal_mm(width: int, height: int, pixel_mm: tuple[float, float]) -> float:
    """
    Return the raw image's half-diagonal on the sensor, to the outer pixel edges (mm).

    ``hypot(W/2 p_x, H/2 p_y)``: the real radius of the raw image's corner.

    :param width: raw width, px.
    :param height: raw height, px.
    :param pixel_mm: pixel pitches (x, y), mm.
    :return: the half-diagonal.
    """
    return math.hypot(width / 2.0 * pixel_mm[0], height / 2.0 * pixel_mm[1])


def finite_or_none(value: float) -> float | None:
    """
    Return the value, or None where it is infinite or undefined (JSON has no inf).

    :param value: a number.
    :return: the number or None.
    """
    return value if math.isfinite(value) else None
