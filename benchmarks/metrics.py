# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The accuracy benchmark's metric: the paper's radii mean error (Lim & Furukawa 2008, eq. 35-37).

:mod:`benchmarks.accuracy` scores the mechanistic model and the Brown calibration with it;
the model's round-trip tests use it too. Pure numpy.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


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
