# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Scene constraints of a camera: resolution, field of view, f-number, hyperfocal, depth of field.

Lim & Furukawa (2008), eq. 10-25, with f_d the (nominal) focal length in mm:

- sensor size (11): ``s_a = p_r * p_s`` (pixel count times pixel pitch), per axis;
- feature resolution (10): the smallest resolvable scene feature at distance ``l`` is
  ``(b1 - b2)_min >= l * p_s / f_d``, per axis;
- field of view (12)-(14): ``theta_d = 2 atan(s_d / (2 f_d))`` for the horizontal, vertical and
  diagonal sensor extents ``s_d``;
- footprint (15): the scene extent seen at distance ``l`` is ``(b1 - b2)_max <= l * s_a / f_d``;
- f-number (16)-(18): ``n_f = sqrt(2 / q) * f_d / d_a`` with the exposure constant ``q``
  (q = 2 gives the usual ``f_d / d_a``);
- hyperfocal distance (22): ``h = f_d**2 / (n_f * c)`` with the circle of confusion ``c``
  (the paper's default is 0.1 % of ``f_d``);
- depth of field (19)-(21) when focused at ``l``: near limit ``h l / (h + l)``, far limit
  ``h l / (h - l)``, infinite when ``l >= h``.

Distances are in mm and measured from the front principal plane; angles are returned in
degrees because that is how people read a field of view.
"""

from __future__ import annotations

import math


def sensor_size_mm(pixels: int, pixel_pitch_um: float) -> float:
    """
    Return the sensor extent along one axis (eq. 11).

    :param pixels: pixel count along the axis.
    :param pixel_pitch_um: pixel pitch in micrometres.
    :return: the extent in mm.
    """
    return pixels * pixel_pitch_um * 1e-3


def feature_resolution_mm(distance_mm: float, pixel_pitch_um: float, focal_mm: float) -> float:
    """
    Return the smallest scene feature one pixel resolves at a distance (eq. 10).

    :param distance_mm: scene distance ``l``; ``math.inf`` gives ``inf``.
    :param pixel_pitch_um: pixel pitch ``p_s`` in micrometres.
    :param focal_mm: focal length ``f_d``.
    :return: ``l * p_s / f_d`` in mm.
    """
    return distance_mm * pixel_pitch_um * 1e-3 / focal_mm


def field_of_view_deg(extent_mm: float, focal_mm: float) -> float:
    """
    Return the full field of view across a sensor extent (eq. 12-14).

    :param extent_mm: sensor extent ``s_d`` (width, height or diagonal).
    :param focal_mm: focal length ``f_d``.
    :return: ``2 atan(s_d / (2 f_d))`` in degrees.
    """
    return math.degrees(2.0 * math.atan(extent_mm / (2.0 * focal_mm)))


def footprint_mm(distance_mm: float, extent_mm: float, focal_mm: float) -> float:
    """
    Return the scene extent imaged onto a sensor extent at a distance (eq. 15).

    :param distance_mm: scene distance ``l``.
    :param extent_mm: sensor extent ``s_a``.
    :param focal_mm: focal length ``f_d``.
    :return: ``l * s_a / f_d`` in mm.
    """
    return distance_mm * extent_mm / focal_mm


def f_number(focal_mm: float, aperture_diameter_mm: float, q: float = 2.0) -> float:
    """
    Return the f-number (eq. 16-18).

    :param focal_mm: focal length ``f_d``.
    :param aperture_diameter_mm: aperture diameter ``d_a``.
    :param q: exposure constant; 2 gives ``f_d / d_a``.
    :return: ``sqrt(2 / q) * f_d / d_a``.
    """
    return math.sqrt(2.0 / q) * focal_mm / aperture_diameter_mm


def circle_of_confusion_mm(focal_mm: float, circle_mm: float = 0.0) -> float:
    """
    Return the circle of confusion in force.

    :param focal_mm: focal length ``f_d``.
    :param circle_mm: the configured value; 0 selects the paper's default, 0.1 % of ``f_d``.
    :return: ``c`` in mm.
    """
    return circle_mm if circle_mm > 0.0 else 1e-3 * focal_mm


def hyperfocal_mm(focal_mm: float, n_f: float, circle_mm: float) -> float:
    """
    Return the hyperfocal distance (eq. 22).

    :param focal_mm: focal length ``f_d``.
    :param n_f: f-number.
    :param circle_mm: circle of confusion ``c`` in mm (already resolved, > 0).
    :return: ``f_d**2 / (n_f c)`` in mm.
    """
    return focal_mm * focal_mm / (n_f * circle_mm)


def depth_of_field_mm(hyperfocal: float, focus_mm: float) -> tuple[float, float]:
    """
    Return the near and far limits of the depth of field (eq. 19-21).

    :param hyperfocal: hyperfocal distance ``h`` in mm.
    :param focus_mm: distance the lens is focused at, ``l``; ``math.inf`` is allowed.
    :return: ``(near, far)`` in mm; ``far`` is ``math.inf`` when ``l >= h``.
    """
    if math.isinf(focus_mm):
        return hyperfocal, math.inf
    near = hyperfocal * focus_mm / (hyperfocal + focus_mm)
    far = math.inf if focus_mm >= hyperfocal else hyperfocal * focus_mm / (hyperfocal - focus_mm)
    return near, far
