# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The check's gate on the machine's load (runtime/check_gate.py): closed forms, no ROS."""

from __future__ import annotations

from pathlib import Path

from mechdeconv_ros.runtime.check_gate import (
    busy_fraction, LoadGate, PROC_STAT, read_counters, RESUME_FRACTION)
import pytest


def _stat(path: Path, user: int, nice: int, system: int, idle: int, iowait: int = 0,
          irq: int = 0, softirq: int = 0, steal: int = 0) -> None:
    # The Linux layout: the all-CPU line first, guest columns after steal, per-CPU lines.
    path.write_text(f'cpu  {user} {nice} {system} {idle} {iowait} {irq} {softirq} {steal} 7 9\n'
                    'cpu0 1 2 3 4 5 6 7 8 0 0\nintr 12345\n')


def test_counters_count_nice_as_idle(tmp_path: Path) -> None:
    stat = tmp_path / 'stat'
    _stat(stat, user=100, nice=1000, system=20, idle=300, iowait=4, irq=1, softirq=2, steal=3)
    assert read_counters(str(stat)) == (100 + 20 + 1 + 2 + 3, 1430)


def test_busy_fraction_closed_form() -> None:
    assert busy_fraction((10, 100), (70, 200)) == pytest.approx(0.6)
    assert busy_fraction((10, 100), (10, 100)) is None      # no tick passed
    assert busy_fraction((10, 100), (500, 200)) == 1.0      # clamped


@pytest.mark.parametrize('text', ['', 'intr 1 2 3\n', 'cpu 1 2 three 4 5 6 7 8\n',
                                  'cpu 1 2 3\n'])
def test_unreadable_counters_read_none(tmp_path: Path, text: str) -> None:
    stat = tmp_path / 'stat'
    stat.write_text(text)
    assert read_counters(str(stat)) is None
    assert read_counters(str(tmp_path / 'missing')) is None


def test_gate_follows_the_busy_not_the_niced_time(tmp_path: Path) -> None:
    stat = tmp_path / 'stat'
    _stat(stat, user=0, nice=0, system=0, idle=0)
    gate = LoadGate(str(stat), period_s=0.5)
    assert gate.load == 0.0 and gate.may_start(0.75)
    # 0.5 s on 2 CPUs at 100 Hz: 100 ticks. A check process (nice 19) took 50 of the 60
    # not busy: the load stays 40/100.
    _stat(stat, user=30, nice=50, system=10, idle=10)
    assert gate.sample(0.5) == pytest.approx(0.4)
    _stat(stat, user=30 + 85, nice=50, system=10 + 5, idle=10 + 10)
    assert gate.sample(0.7) == pytest.approx(0.4)     # within the period: not read
    assert gate.sample(1.0) == pytest.approx(0.9)
    assert not gate.may_start(0.75) and gate.deferred == 1
    assert gate.may_start(1.0)          # 1 = never held back
    assert gate.should_pause(0.75, paused=False)
    # Hysteresis: paused until below RESUME_FRACTION of the limit.
    _stat(stat, user=115 + 70, nice=50, system=15, idle=20 + 30)
    assert gate.sample(1.5) == pytest.approx(0.7)
    assert not gate.should_pause(0.75, paused=False)
    assert gate.should_pause(0.75, paused=True)
    _stat(stat, user=185 + 59, nice=50, system=15, idle=50 + 41)
    assert gate.sample(2.0) == pytest.approx(0.59)
    assert 0.59 < RESUME_FRACTION * 0.75 and not gate.should_pause(0.75, paused=True)
    assert not gate.should_pause(1.0, paused=True)


def test_no_counters_never_hold_the_check_back(tmp_path: Path) -> None:
    gate = LoadGate(str(tmp_path / 'missing'))
    assert gate.sample(10.0) == 0.0 and gate.may_start(0.05)


def test_this_machine_reads() -> None:
    if not Path(PROC_STAT).exists():
        pytest.skip(f'{PROC_STAT} is Linux only')
    busy, total = read_counters()
    assert 0 <= busy <= total and total > 0


def test_a_running_check_is_stopped_to_read_the_load_without_it(tmp_path: Path) -> None:
    """A node the check slows uses less CPU: only a probe with the check stopped shows it."""
    stat = tmp_path / 'stat'
    _stat(stat, user=0, nice=0, system=0, idle=0)
    gate = LoadGate(str(stat), period_s=0.5)
    # Running: the frames take 60 of 100 ticks, the check the other 40 (niced): load 0.6.
    ticks = {'user': 0, 'nice': 0, 'system': 0, 'idle': 0}

    def advance(now: float, **add: int) -> float:
        for key, value in add.items():
            ticks[key] += value
        _stat(stat, **ticks)
        return gate.sample(now)

    for k, now in enumerate((0.5, 1.0, 1.5, 2.0)):
        assert advance(now, user=60, nice=40) == pytest.approx(0.6)
        assert not gate.should_pause(0.75, paused=False, now=now), k
    assert gate.probes == 0 and gate.busy_pauses == 0
    # 2 s of running: a probe stops it, whatever the load reads.
    assert advance(2.5, user=60, nice=40) == pytest.approx(0.6)
    assert gate.should_pause(0.75, paused=False, now=2.5) and gate.probes == 1
    # Within the probe's period the old reading does not decide.
    assert gate.should_pause(0.75, paused=True, now=2.7)
    # With the check stopped the frames take 85 of 100: it stays paused (a busy pause) ...
    assert advance(3.0, user=85, idle=15) == pytest.approx(0.85)
    assert gate.should_pause(0.75, paused=True, now=3.0) and gate.busy_pauses == 1
    # ... until the load is below RESUME_FRACTION of the limit.
    assert advance(3.5, user=70, idle=30) == pytest.approx(0.7)
    assert gate.should_pause(0.75, paused=True, now=3.5)
    assert advance(4.0, user=50, idle=50) == pytest.approx(0.5)
    assert not gate.should_pause(0.75, paused=True, now=4.0)
    # A probe that finds room lets the check go on at once, and is not a busy pause.
    assert advance(6.0, user=50, nice=50) == pytest.approx(0.5)
    assert gate.should_pause(0.75, paused=False, now=6.0) and gate.probes == 2
    assert advance(6.5, user=55, idle=45) == pytest.approx(0.55)
    assert not gate.should_pause(0.75, paused=True, now=6.5) and gate.busy_pauses == 1
    # A new check starts its own 2 s; 1 = never held back, not even by a probe.
    gate.check_ended()
    assert not gate.should_pause(0.75, paused=False, now=7.0)
    assert not gate.should_pause(1.0, paused=False, now=20.0)
