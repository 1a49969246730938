# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The frame path's load and the check's gate (imaging/frame_load.py): closed forms, no ROS."""

import math

from mechdeconv_ros.imaging.frame_load import FrameLoad, LoadGate, RESUME_FRACTION
import pytest


def _stream(load: FrameLoad, busy_s: float, period_s: float, seconds: float,
            start: float = 0.0) -> float:
    t, value = start, 0.0
    while t < start + seconds:
        t += period_s
        value = load.add(busy_s, t)
    return value


@pytest.mark.parametrize('busy_ms,rate_hz', [(12.0, 30.0), (6.0, 120.0), (30.0, 33.0)])
def test_steady_stream_reads_its_duty_cycle(busy_ms: float, rate_hz: float) -> None:
    load = FrameLoad(tau_s=1.0)
    period = 1.0 / rate_hz
    value = _stream(load, busy_ms * 1e-3, period, 10.0)
    # The closed form of the module docstring, and the duty cycle b / T within 2 %.
    exact = (busy_ms * 1e-3 / 1.0) / (1.0 - math.exp(-period / 1.0))
    assert value == pytest.approx(exact, rel=1e-4)     # 10 tau: converged to e^-10
    assert value == pytest.approx(busy_ms * 1e-3 * rate_hz, rel=0.02)


def test_load_decays_by_e_per_tau_without_frames() -> None:
    load = FrameLoad(tau_s=0.5)
    value = load.add(0.2, 10.0)
    assert value == pytest.approx(0.4)
    assert load.value(10.5) == pytest.approx(value / math.e, rel=1e-12)
    assert load.value(10.0) == value
    assert load.value(9.0) == value     # a clock read before the frame does not grow it
    # A second frame adds to the decayed value.
    assert load.add(0.1, 10.5) == pytest.approx(0.4 / math.e + 0.2, rel=1e-12)


def test_empty_load_and_bad_tau() -> None:
    assert FrameLoad().value(123.0) == 0.0
    with pytest.raises(ValueError, match='tau_s'):
        FrameLoad(0.0)


def test_gate_defers_above_the_limit_and_counts() -> None:
    gate = LoadGate()
    assert gate.may_start(0.59, 0.6)
    assert not gate.may_start(0.61, 0.6)
    assert not gate.may_start(0.99, 0.6)
    assert gate.deferred == 2
    assert gate.may_start(5.0, 1.0)     # 1 = never held back
    assert gate.deferred == 2


def test_pause_has_hysteresis() -> None:
    limit = 0.6
    assert not LoadGate.should_pause(0.6, limit, paused=False)
    assert LoadGate.should_pause(0.61, limit, paused=False)
    # Paused: it stays paused down to RESUME_FRACTION of the limit.
    assert LoadGate.should_pause(0.5, limit, paused=True)
    assert not LoadGate.should_pause(RESUME_FRACTION * limit - 1e-9, limit, paused=True)
    assert not LoadGate.should_pause(3.0, 1.0, paused=True)
