# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
stereo_node's ROS-free parts: the stamp pairing and the live pair's validation, rebuild, swap.

The live pair is driven with an injected builder (a blocking one where a test needs a build
in progress) and a cheap rectifier; the real ones are tested in test_stereo.py and, through
the node, in test_stereo_node.py.
"""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

from mechdeconv_ros.model.model import ModelError
from mechdeconv_ros.runtime.stereo_live import StereoLive
from mechdeconv_ros.runtime.stereo_sync import QUEUE, StampPairer
from mechdeconv_ros.schema.stereo_params import check_stereo_values
import pytest

SLOP = 10_000_000     # ns
MS = 1_000_000


# --- pairing ---------------------------------------------------------------------------------

def test_frames_within_the_slop_pair_and_others_are_counted_unpaired():
    pairer = StampPairer()
    assert pairer.push('left', 1000 * MS, 'l1', SLOP) is None
    assert pairer.push('right', 1010 * MS, 'r1', SLOP) == ('l1', 'r1')      # inclusive
    assert pairer.push('left', 2000 * MS, 'l2', SLOP) is None
    assert pairer.push('right', 2011 * MS, 'r2', SLOP) is None               # 11 ms apart
    assert pairer.push('left', 3000 * MS, 'l3', SLOP) is None
    assert pairer.push('right', 3002 * MS, 'r3', SLOP) == ('l3', 'r3')
    assert pairer.unpaired == {'left': 1, 'right': 1}
    assert pairer.pairs == 2
    assert pairer.pending() == {'left': 0, 'right': 0}


def test_the_closest_partner_is_taken_and_the_order_of_arrival_does_not_matter():
    pairer = StampPairer()
    for k, stamp in enumerate((1000, 1033, 1066)):
        assert pairer.push('right', stamp * MS, f'r{k}', 20 * MS) is None
    assert pairer.push('left', 1040 * MS, 'l', 20 * MS) == ('l', 'r1')
    assert pairer.unpaired == {'left': 0, 'right': 1}      # r0 can no longer pair
    assert pairer.pending() == {'left': 0, 'right': 1}      # r2 waits


def test_a_full_queue_and_a_stamp_going_back_are_unpaired():
    pairer = StampPairer()
    for k in range(QUEUE + 2):
        pairer.push('left', k * 1000 * MS, k, SLOP)
    assert pairer.unpaired['left'] == 2 and pairer.pending()['left'] == QUEUE
    pairer.push('right', 100_000 * MS, 'r', SLOP)
    pairer.push('right', 99_000 * MS, 'r', SLOP)
    assert pairer.unpaired['right'] == 1


# --- the live pair ---------------------------------------------------------------------------

class Builder:
    """A stereo builder that records its calls, refuses a baseline of 0 and can block."""

    def __init__(self) -> None:
        self.calls: list[dict] = []
        self.gate = threading.Event()
        self.gate.set()

    def __call__(self, values):
        values = check_stereo_values(values)
        self.calls.append(values)
        self.gate.wait(10.0)
        if float(values['rig.rotation_x_deg']) > 10.0:
            raise ModelError('rig.rotation_x_deg', "the two cameras' fields do not overlap")
        return SimpleNamespace(values=values, pitch=values['rig.rotation_x_deg'])


def wait_for(predicate, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


@pytest.fixture
def live():
    builder = Builder()
    pair = StereoLive(check_stereo_values({}), extras=lambda s: {'infos_of': s.pitch},
                      build=builder, rectifier=lambda s: ('maps', s.pitch))
    pair.start()
    yield pair, builder
    builder.gate.set()
    pair.stop()


def test_a_refused_set_names_the_parameter_and_changes_nothing(live):
    pair, _ = live
    with pytest.raises(ValueError, match='rig.baseline_mm'):
        pair.validate({'rig.baseline_mm': 0.0})
    with pytest.raises(ValueError, match='rig.rotation_x_deg'):
        pair.validate({'rig.rotation_x_deg': 20.0})
    assert pair.value('rig.rotation_x_deg') == 0.0
    assert pair.active.generation == 0 and pair.active.stereo.pitch == 0.0


def test_a_rig_set_is_built_in_the_background_and_swapped_whole(live):
    pair, builder = live
    pair.validate({'rig.rotation_x_deg': 0.2})
    builds = len(builder.calls)
    pair.commit({'rig.rotation_x_deg': 0.2})
    assert wait_for(lambda: pair.active.generation == 1)
    active = pair.active
    # One record: the model, its maps and its CameraInfos of the same values.
    assert active.stereo.pitch == active.rectifier[1] == active.extras['infos_of'] == 0.2
    assert len(builder.calls) == builds        # the validated candidate was reused
    assert pair.status().rebuilds == 1 and not pair.status().rebuild_pending


def test_sets_during_a_build_are_coalesced_and_the_newest_wins(live):
    pair, builder = live
    builder.gate.clear()                        # the next build blocks
    pair.commit({'rig.rotation_x_deg': 0.1})
    assert wait_for(lambda: len(builder.calls) >= 1)
    pair.commit({'rig.rotation_x_deg': 0.2})
    pair.commit({'rig.rotation_x_deg': 0.3})
    assert pair.active.generation == 0          # frames keep the old pair meanwhile
    assert pair.status().rebuild_pending
    builder.gate.set()
    assert wait_for(lambda: pair.active.generation == 3)
    assert pair.active.stereo.pitch == 0.3
    assert len(builder.calls) == 2              # 0.1, then 0.3 (0.2 never built)


def test_a_set_that_changes_no_model_value_builds_nothing(live):
    pair, builder = live
    builds = len(builder.calls)
    assert pair.commit({'sync.slop_s': 0.02}) == {'sync.slop_s'}
    assert pair.commit({'rig.rotation_x_deg': 0.0}) == set()
    time.sleep(0.1)
    assert len(builder.calls) == builds and pair.active.generation == 0
    assert pair.value('sync.slop_s') == 0.02


# --- the check's child process ---------------------------------------------------------------

def test_the_check_child_pools_its_window_pauses_and_stops():
    """Protocol: values once per generation, the window grows to its size; SIGSTOP, exit."""
    import cv2
    import numpy as np
    from mechdeconv_ros.runtime.stereo_check_worker import StereoCheckWorker

    size = (320, 240)
    values = check_stereo_values({f'{s}.{k}': v for s in ('left', 'right') for k, v in (
        ('sensor.width_px', size[0]), ('sensor.height_px', size[1]),
        ('sensor.pixel_size_x_um', 12.0), ('sensor.pixel_size_y_um', 12.0),
        ('scene.distance_mm', 0.0))})
    rng = np.random.default_rng(0)
    image = cv2.GaussianBlur(rng.integers(0, 256, (size[1], size[0]), dtype=np.uint8),
                             (0, 0), 1.5)
    worker = StereoCheckWorker()
    worker.start()
    try:
        replies = [worker.check(image, image, values, (size, size), 0, 2) for _ in range(3)]
        assert [r['pairs'] for r in replies] == [1, 2, 2], replies
        assert replies[-1]['result']['verdict'] in ('ok', 'not_enough_matches')
        stat = f'/proc/{worker.process.pid}/stat'

        def state() -> str:
            with open(stat) as f:
                return f.read().rsplit(')', 1)[1].split()[0]

        worker.pause(True)
        assert worker.paused and wait_for(lambda: state() == 'T', 5.0)
        worker.pause(False)
        assert not worker.paused and wait_for(lambda: state() != 'T', 5.0)
        process = worker.process
    finally:
        worker.stop()
    assert process.returncode is not None and worker.process is None
