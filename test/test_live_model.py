# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The live model's lifecycle, without ROS, with builders the test blocks and releases.

The model builder is a stand-in (no optics): a model records the values and the size it was
built for, and refuses ``lens.stop_offset_mm`` >= :data:`BAD_OFFSET` (as a lens the model
cannot trace). The maps builder blocks each call until the test releases it by index, so a
set, a frame of a new size or a failure can be placed exactly while a rebuild runs. Nothing
sleeps to synchronise: the test waits on conditions (:meth:`Gate.wait_started`,
:meth:`LiveModel.wait_idle`).
"""

from __future__ import annotations

import threading
from typing import Any, Iterator, Mapping

from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.runtime.live_model import (
    FrameDropped, LiveModel, MAX_SURFACES, NOMINAL_SIZE, THREAD_NAME)
from mechdeconv_ros.schema.params import defaults
import pytest

OFFSET = 'lens.stop_offset_mm'
#: Offsets from here on describe no lens (the stand-in builder refuses them).
BAD_OFFSET = 50.0
#: Offsets from here on build a model whose maps fail (e.g. out of memory).
FAILING_MAPS_OFFSET = 40.0
#: Offsets from here on build with a warning (a stop far from the lens).
FAR_OFFSET = 10.0
WAIT_S = 5.0


class FakeModel:
    """What the stand-in builder returns: the values and size it was built for."""

    def __init__(self, values: Mapping[str, Any], width: int, height: int) -> None:
        """Keep a copy of the values; the sensor size wins over the frame size."""
        self.values = dict(values)
        self.width = int(values['sensor.width_px']) or width
        self.height = int(values['sensor.height_px']) or height

    @property
    def offset(self) -> float:
        """Return the stop offset the model was built with."""
        return float(self.values[OFFSET])

    @property
    def warnings(self) -> tuple[str, ...]:
        """Return the build-time warnings: a stop at FAR_OFFSET or more is 'far'."""
        return (f'{OFFSET}: far',) if self.offset >= FAR_OFFSET else ()

    def report(self) -> dict[str, Any]:
        """Return a summary, as LensModel.report does."""
        return {'offset': self.offset, 'warnings': list(self.warnings)}


class Gate:
    """A maps builder whose calls block until released (by call index), counted."""

    def __init__(self, hold: bool = True) -> None:
        """Start with no call released (``hold=False``: never block)."""
        self.cond = threading.Condition()
        self.hold = hold
        self.started: list[FakeModel] = []
        self.released: set[int] = set()
        self.model_builds: list[tuple[float, int, int]] = []

    def build_model(self, values: Mapping[str, Any], width: int, height: int) -> FakeModel:
        """Build the stand-in model (never blocks)."""
        if float(values[OFFSET]) >= BAD_OFFSET:
            raise ValueError(f'{OFFSET}: the chief ray misses the stop')
        with self.cond:
            self.model_builds.append((float(values[OFFSET]), width, height))
        return FakeModel(values, width, height)

    def __call__(self, model: FakeModel) -> tuple[str, FakeModel]:
        """Build the 'maps' of a model once released."""
        with self.cond:
            index = len(self.started)
            self.started.append(model)
            self.cond.notify_all()
            assert self.cond.wait_for(lambda: not self.hold or index in self.released, WAIT_S)
        if model.offset >= FAILING_MAPS_OFFSET:
            raise MemoryError('no memory for the maps')
        return ('maps', model)

    def release(self, *indices: int) -> None:
        """Let the calls with these indices complete (also calls that have not started)."""
        with self.cond:
            self.released.update(indices)
            self.cond.notify_all()

    def wait_started(self, count: int) -> None:
        """Wait until ``count`` calls have started."""
        with self.cond:
            assert self.cond.wait_for(lambda: len(self.started) >= count, WAIT_S), \
                f'{len(self.started)} builds started, expected {count}'


def values_with(**changes: Any) -> dict[str, Any]:
    """Return the schema defaults with some values changed (``x__y`` stands for ``x.y``)."""
    values = defaults()
    values.update({name.replace('__', '.'): value for name, value in changes.items()})
    return values


def make_live(gate: Gate, **changes: Any) -> LiveModel:
    """Return a started LiveModel on ``gate`` (the tests stop it)."""
    logs: list[tuple[str, str]] = []
    live = LiveModel(values_with(**changes), build_model=gate.build_model, build_maps=gate,
                     warm_maps=gate,
                     extras=lambda model: ('info', model.offset), log=lambda *a: logs.append(a))
    live.logs = logs            # type: ignore[attr-defined]
    live.start()
    return live


def set_params(live: LiveModel, **changes: Any) -> bool:
    """Validate, commit and hand over one request; return whether a rebuild was started."""
    request = {name.replace('__', '.'): value for name, value in changes.items()}
    live.validate(request)
    live.commit(request)
    return live.start_requested_rebuild()


@pytest.fixture
def gate() -> Iterator[Gate]:
    gate = Gate()
    yield gate
    gate.hold = False
    with gate.cond:
        gate.cond.notify_all()


@pytest.fixture
def live(gate: Gate) -> Iterator[LiveModel]:
    """Return a live model following the frames (no sensor size), before its first frame."""
    live = make_live(gate)
    yield live
    live.stop()


def first_frame(live: LiveModel, gate: Gate, size: tuple[int, int] = (64, 48)) -> Any:
    """
    Correct a first frame and let the thread settle; return the frame's model.

    Its maps build (call 0) and the thread's allocator warm-up for the new size (call 1) are
    released, so the rebuilds of a test start at call 2.
    """
    first = len(gate.started)
    gate.release(first, first + 1)
    active = live.model_for_frame(*size)
    assert live.wait_idle(WAIT_S)
    return active


# ---------------------------------------------------------------------------------------------

def test_startup_validates_and_a_fixed_sensor_installs_at_once() -> None:
    gate = Gate(hold=False)
    with pytest.raises(ValueError, match=OFFSET):
        LiveModel(values_with(lens__stop_offset_mm=BAD_OFFSET), build_model=gate.build_model,
                  build_maps=gate, warm_maps=gate)
    live = LiveModel(values_with(sensor__width_px=32, sensor__height_px=24),
                     build_model=gate.build_model, build_maps=gate, warm_maps=gate)
    status = live.status()
    assert status.active is not None and status.revision == 1
    assert status.input_size == (32, 24)
    assert live.model_for_frame(32, 24) is status.active
    with pytest.raises(FrameDropped, match='sensor.width_px'):
        live.model_for_frame(64, 48)
    assert live.status().revision == 1


def test_first_frame_builds_for_its_size_and_sets_before_it_only_store(
        live: LiveModel, gate: Gate) -> None:
    assert live.status().active is None
    assert set_params(live, lens__stop_offset_mm=0.3)
    assert live.wait_idle(WAIT_S)
    assert gate.started == [], 'no frame yet: nothing to build the maps for'
    assert gate.model_builds == [(0.2, *NOMINAL_SIZE), (0.3, *NOMINAL_SIZE)], \
        'start-up and on-set validation only'
    active = first_frame(live, gate)
    assert (active.model.width, active.model.height, active.model.offset) == (64, 48, 0.3)
    assert active.revision == 1 and active.extras == ('info', 0.3)
    assert live.model_for_frame(64, 48) is active, 'the same size reuses the model'


def test_set_during_a_rebuild_is_coalesced_and_newest_values_win(
        live: LiveModel, gate: Gate) -> None:
    first_frame(live, gate)
    set_params(live, lens__stop_offset_mm=0.3)
    gate.wait_started(3)                        # the rebuild thread builds 0.3 ...
    set_params(live, lens__stop_offset_mm=0.4)  # ... while these arrive
    set_params(live, lens__stop_offset_mm=0.5)
    assert live.status().active.model.offset == 0.2, 'frames keep the old model meanwhile'
    gate.release(2)
    gate.wait_started(4)
    assert gate.started[3].offset == 0.5, 'the next build takes the newest values'
    assert live.status().active.model.offset == 0.3     # 0.3 was installed meanwhile
    gate.release(3)
    assert live.wait_idle(WAIT_S)
    status = live.status()
    assert status.active.model.offset == 0.5 and status.active.values_generation == 3
    assert status.revision == 3 and len(gate.started) == 4, '0.4 must not have been built'
    assert not status.rebuild_pending


def test_an_older_build_never_replaces_a_newer_one(live: LiveModel, gate: Gate) -> None:
    first_frame(live, gate)
    set_params(live, lens__stop_offset_mm=0.3)
    gate.wait_started(3)                         # the thread builds 0.3 (generation 1)
    set_params(live, lens__stop_offset_mm=0.4)   # generation 2
    # A frame of a new size builds the newest values for itself and installs them ...
    gate.release(3)
    newer = live.model_for_frame(80, 60)
    assert (newer.model.offset, newer.values_generation) == (0.4, 2)
    # ... so the thread's older build, for the old size, must not be installed after it.
    gate.release(2)
    gate.release(*range(4, 9))
    assert live.wait_idle(WAIT_S)
    status = live.status()
    assert status.active is newer, 'the older build replaced the newer model'
    assert status.input_size == (80, 60)


def test_new_frame_size_during_a_rebuild(live: LiveModel, gate: Gate) -> None:
    first_frame(live, gate)
    set_params(live, lens__stop_offset_mm=0.3)
    gate.wait_started(3)                    # the thread builds 0.3 for 64x48
    gate.release(3)
    bigger = live.model_for_frame(96, 72)   # the frame gets the newest values at its size
    assert (bigger.model.width, bigger.model.offset) == (96, 0.3)
    gate.release(2)
    gate.release(*range(4, 9))
    assert live.wait_idle(WAIT_S)
    status = live.status()
    assert status.active is bigger and status.input_size == (96, 72)
    assert live.model_for_frame(96, 72) is bigger
    # Later sets follow the new size.
    set_params(live, lens__stop_offset_mm=0.6)
    assert live.wait_idle(WAIT_S)
    active = live.status().active
    assert (active.model.width, active.model.height, active.model.offset) == (96, 72, 0.6)


def test_failing_build_keeps_the_old_model_and_the_next_good_set_works(
        live: LiveModel, gate: Gate) -> None:
    gate.hold = False
    old = first_frame(live, gate)
    set_params(live, lens__stop_offset_mm=FAILING_MAPS_OFFSET)   # validates, maps fail
    assert live.wait_idle(WAIT_S)
    status = live.status()
    assert status.active is old and status.rebuild_failures == 1
    assert 'no memory' in status.rebuild_error
    assert any(level == 'error' and 'previous model' in text
               for level, text in live.logs)            # type: ignore[attr-defined]
    set_params(live, lens__stop_offset_mm=0.7)
    assert live.wait_idle(WAIT_S)
    status = live.status()
    assert status.active.model.offset == 0.7 and status.rebuild_error == ''
    assert status.rebuild_failures == 1


def test_failing_build_for_a_frame_size_drops_without_rebuilding_every_frame(
        gate: Gate) -> None:
    gate.hold = False
    live = make_live(gate, lens__stop_offset_mm=FAILING_MAPS_OFFSET)
    try:
        with pytest.raises(FrameDropped, match='no model for 64x48') as first:
            live.model_for_frame(64, 48)
        assert not first.value.repeat
        builds = len(gate.started)
        with pytest.raises(FrameDropped) as again:
            live.model_for_frame(64, 48)
        assert again.value.repeat and len(gate.started) == builds
        assert live.status().input_size is None, 'a size without a model is not followed'
    finally:
        live.stop()


def test_burst_of_sets_is_coalesced_into_few_builds(live: LiveModel, gate: Gate) -> None:
    first_frame(live, gate)
    set_params(live, lens__stop_offset_mm=0.21)
    gate.wait_started(3)
    for step in range(2, 40):
        set_params(live, lens__stop_offset_mm=round(0.2 + step / 100, 2))
    gate.release(*range(2, 10))
    assert live.wait_idle(WAIT_S)
    rebuilds = [model.offset for model in gate.started[2:]]
    assert rebuilds == [0.21, 0.59], rebuilds       # the first, then only the newest
    assert live.status().active.model.offset == 0.59
    assert live.status().active.values_generation == 39


def test_rejected_set_leaves_values_and_model_untouched(live: LiveModel, gate: Gate) -> None:
    gate.hold = False
    active = first_frame(live, gate)
    before = live.values()
    for bad in ({OFFSET: BAD_OFFSET}, {OFFSET: 'wide'}, {OFFSET: float('nan')},
                {'lens.surfaces.radius_mm': [1.0] * (MAX_SURFACES + 1)}):
        name = next(iter(bad))
        with pytest.raises(ValueError, match=name.replace('.', r'\.')):
            live.validate(bad)
    assert live.values() == before
    assert not live.start_requested_rebuild()
    assert live.status().active is active


def test_same_values_twice_make_no_new_revision(live: LiveModel, gate: Gate) -> None:
    gate.hold = False
    first_frame(live, gate)
    assert set_params(live, lens__stop_offset_mm=0.3)
    assert live.wait_idle(WAIT_S)
    revision = live.status().revision
    assert not set_params(live, lens__stop_offset_mm=0.3), 'the same value rebuilt'
    assert not set_params(live, remap_threads=2), 'a non-model parameter rebuilt'
    assert live.value('remap_threads') == 2
    assert live.wait_idle(WAIT_S)
    assert live.status().revision == revision


def test_one_rebuild_per_request_of_several_parameters(live: LiveModel, gate: Gate) -> None:
    gate.hold = False
    first_frame(live, gate)
    # rclpy commits a multi-parameter set_parameters one parameter at a time.
    for name, value in ((OFFSET, 0.3), ('lens.thickness_mm', 3.5)):
        live.validate({name: value})
        live.commit({name: value})
    assert live.start_requested_rebuild()
    assert not live.start_requested_rebuild(), 'one wake per request'
    assert live.wait_idle(WAIT_S)
    active = live.status().active
    assert active.revision == 2 and active.values_generation == 2
    assert active.model.values['lens.thickness_mm'] == 3.5


def test_summary_is_computed_by_the_thread_once_per_revision(
        live: LiveModel, gate: Gate) -> None:
    gate.hold = False
    first_frame(live, gate)
    assert live.wait_idle(WAIT_S)
    assert live.status().report == {'offset': 0.2, 'warnings': []}
    set_params(live, lens__stop_offset_mm=0.3)
    assert live.wait_idle(WAIT_S)
    assert live.status().report['offset'] == 0.3


def warnings_logged(live: LiveModel) -> list[str]:
    """Return the warning lines logged so far."""
    return [text for level, text in live.logs if level == 'warning']  # type: ignore[attr-defined]


def test_warnings_are_logged_once_when_they_appear(live: LiveModel, gate: Gate) -> None:
    gate.hold = False
    first_frame(live, gate)
    assert warnings_logged(live) == []
    set_params(live, lens__stop_offset_mm=20.0)
    assert live.wait_idle(WAIT_S)
    assert warnings_logged(live) == [f'{OFFSET}: far']
    # The same warning on the next models (another size, an unrelated change): not again.
    live.model_for_frame(80, 60)
    set_params(live, output__alpha=0.5)
    assert live.wait_idle(WAIT_S)
    assert live.status().active.revision >= 4
    assert warnings_logged(live) == [f'{OFFSET}: far']
    # Gone, then back: logged again.
    set_params(live, lens__stop_offset_mm=0.3)
    assert live.wait_idle(WAIT_S)
    set_params(live, lens__stop_offset_mm=21.0)
    assert live.wait_idle(WAIT_S)
    assert warnings_logged(live) == [f'{OFFSET}: far'] * 2


def test_start_up_warnings_are_logged_once(gate: Gate) -> None:
    gate.hold = False
    live = make_live(gate, lens__stop_offset_mm=20.0)
    try:
        assert warnings_logged(live) == [f'{OFFSET}: far']
        first_frame(live, gate)
        assert live.status().report['warnings'] == [f'{OFFSET}: far']
        assert warnings_logged(live) == [f'{OFFSET}: far']
    finally:
        live.stop()


def test_a_failing_logger_does_not_stop_the_rebuild_thread(gate: Gate) -> None:
    """E.g. rclpy's "Logger severity cannot be changed between calls" from a shared line."""
    def log(level: str, message: str) -> None:
        if level == 'warning':
            raise ValueError('Logger severity cannot be changed between calls.')

    gate.hold = False
    live = LiveModel(values_with(), build_model=gate.build_model, build_maps=gate,
                     warm_maps=gate, log=log)
    live.start()
    try:
        first_frame(live, gate)
        set_params(live, lens__stop_offset_mm=20.0)        # a warning: the logger raises
        assert live.wait_idle(WAIT_S)
        set_params(live, lens__stop_offset_mm=0.3)
        assert live.wait_idle(WAIT_S)
        assert live.status().active.model.offset == 0.3
    finally:
        live.stop()


class SlowSummaryModel(FakeModel):
    """A model whose summary blocks until the test releases it."""

    release = threading.Event()
    started = threading.Event()

    def report(self) -> dict[str, Any]:
        """Block (as a fisheye's seconds-long summary would), then summarise."""
        SlowSummaryModel.started.set()
        assert SlowSummaryModel.release.wait(WAIT_S)
        return super().report()


def test_a_set_is_built_while_a_summary_is_being_computed(gate: Gate) -> None:
    """A seconds-long summary (its own thread) never holds up the next rebuild."""
    gate.hold = False
    SlowSummaryModel.release.clear()
    SlowSummaryModel.started.clear()
    live = LiveModel(values_with(), build_model=lambda v, w, h: SlowSummaryModel(v, w, h),
                     build_maps=gate, warm_maps=gate, extras=lambda model: None,
                     log=lambda *a: None)
    live.start()
    try:
        live.model_for_frame(640, 480)
        assert SlowSummaryModel.started.wait(WAIT_S)        # the summary thread is blocked
        live.validate({OFFSET: 0.3})
        live.commit({OFFSET: 0.3})
        assert live.start_requested_rebuild()
        with live._lock:
            assert live._lock.wait_for(
                lambda: live._active is not None and live._active.model.offset == 0.3, WAIT_S)
        assert not SlowSummaryModel.release.is_set(), 'built while the summary still ran'
    finally:
        SlowSummaryModel.release.set()
        live.stop()


def test_stop_ends_the_thread_even_during_a_build(gate: Gate) -> None:
    live = make_live(gate)
    first_frame(live, gate)
    set_params(live, lens__stop_offset_mm=0.3)
    gate.wait_started(3)                            # the thread is inside a build
    workers = [t for t in threading.enumerate() if t.name == THREAD_NAME]
    assert workers and all(t.daemon for t in workers)
    stopper = threading.Thread(target=live.stop)
    stopper.start()
    gate.release(2)
    stopper.join(WAIT_S)
    assert not stopper.is_alive()
    assert not any(t.is_alive() for t in live._threads), 'stop must end both threads'
    assert live.status().active.model.offset == 0.3     # the build under way was installed


def test_the_allocator_warm_up_builds_a_plain_rectifier_not_the_nodes_maps() -> None:
    """The node's maps builder logs and caches: the warm-up must not call it a second time."""
    calls: list[Any] = []

    def node_maps(model: Any) -> Rectifier:
        calls.append(model)
        return Rectifier(model)

    live = LiveModel(values_with(), build_maps=node_maps)
    live.start()
    try:
        active = live.model_for_frame(64, 48)
        assert live.wait_idle(WAIT_S)
        assert isinstance(active.rectifier, Rectifier)
        assert calls == [active.model], 'one maps build by the node builder, for the frame'
        assert live._warmed_size == (64, 48), 'the warm-up ran, with its own plain Rectifier'
    finally:
        live.stop()
