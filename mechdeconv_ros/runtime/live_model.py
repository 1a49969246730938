# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The node's live lens model: values, generations, validation, rebuilds, the atomic swap.

No ROS import: ``correct_node`` wires it to rclpy, the tests drive it directly with an
injected builder that can block (``test/test_live_model.py``).

Lifecycle of a parameter set (``validate`` -> ``commit`` -> ``start_requested_rebuild``):

* :meth:`LiveModel.validate` merges the proposed values into the current ones, checks each
  with the schema (:func:`mechdeconv_ros.schema.params.coerce`) and, when a model parameter
  changes, builds the candidate :class:`~mechdeconv_ros.model.model.LensModel` for the current
  image size (raises ``ValueError`` with the model's reason; nothing is changed then).
* :meth:`LiveModel.commit` stores an accepted set. A set that changes a model parameter's value
  increments ``values_generation``; the same values again change nothing (no rebuild, no new
  revision).
* :meth:`LiveModel.start_requested_rebuild` wakes the rebuild thread once per request (a
  multi-parameter request is committed one parameter at a time). The thread builds the
  newest values (reusing the validated candidate) and the remap tables, then swaps ONE
  reference (:class:`ActiveModel`, frozen). Sets arriving while it builds are coalesced: the
  next build takes the newest values, and a build never replaces a model of a newer
  generation of the same size (``values_generation`` orders them). A failed build leaves the
  old model in use and is reported (``rebuild_failures``, ``rebuild_error``) until the next
  successful install.

Frame-size following (:meth:`LiveModel.model_for_frame`): a frame of a new size (the first
frame, or a camera that changed resolution) gets a model built synchronously in the caller's
thread for that size; frames of the size in use just read the reference. When
``sensor.width_px``/``sensor.height_px`` fix the size and a frame disagrees, the frame is
refused (:class:`FrameDropped`). A size whose build failed is not rebuilt on every frame.

Threading rule (the one rule; every shared field follows it):

* **executor thread** (the thread spinning the node: parameter callbacks, frame callback,
  timers): the only caller of ``validate``, ``commit``, ``start_requested_rebuild``,
  ``model_for_frame`` and ``status``; it owns the ``extras`` objects of the active model
  (e.g. it stamps the CameraInfo headers).
* **rebuild thread** (``mechdeconv-rebuild``, started by :meth:`LiveModel.start`): builds from
  a snapshot taken under the lock, installs under the lock and warms the allocator; it calls
  nothing but the injected builders and the ``log`` function.
* **summary thread** (``mechdeconv-summary``, started with it): computes the summary of the
  model in use for diagnostics (``model.report()``: seconds for a fisheye or a long
  prescription) and logs its warnings once, so a parameter set never waits for a summary.
  It starts a new model's summary once two frames have taken that model, or after
  ``SUMMARY_DEFER_S``: the summary is 15 to 40 ms of mostly GIL-holding Python for the thick
  lens at 1080p, which would otherwise run during the first frame of the new model and delay
  it at every GIL hand-over (the parameter set -> first new frame latency).
* **signal path**: never touches the model; it only sets the spin loop's stop flag, and the
  executor thread then calls :meth:`LiveModel.stop` (through ``destroy_node``).

Every field that two threads use is read and written under the one lock (a Condition),
except the ``active`` reference, which a frame reads once without the lock (one atomic read;
the record is immutable), so a frame never mixes two models. Fields only one thread uses
(``_failed_build``: executor; ``_warmed_size``: rebuild thread; ``_logged_warnings``: summary
thread, after the constructor) need no lock.

Warnings: a model's warnings (unusual but possible values, docs/design.md section 7, and the
summary's depth-of-field and valid-field notes) go to ``log`` once, when they appear: the start-up
model's in the constructor, later ones when the summary thread summarises a new model.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
import math
import threading
import time
from typing import Any, Callable, Iterable, Mapping

from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model, LensModel
from mechdeconv_ros.schema.params import (
    coerce, MAX_TABLE_ROWS, MECHANISMS, MODEL_PARAMS, ParamSpec, ParamValue, SPECS)

#: Image size used to validate parameters before the first frame, when the sensor size is not
#: set (the paper's Case 2 sensor).
NOMINAL_SIZE = (640, 480)
#: Most surfaces a prescription (``lens.surfaces.*``) may have: as many as ``lens.stop_surface``
#: can index. Validating a set traces every surface in the executor thread (about 0.2 ms per
#: surface), so an unbounded array would stall the frames for as long as the sender likes.
MAX_SURFACES = int(SPECS['lens.stop_surface'].maximum) + 1
#: Names of the rebuild thread and of the summary thread.
THREAD_NAME = 'mechdeconv-rebuild'
SUMMARY_THREAD_NAME = 'mechdeconv-summary'
#: The longest the summary of a new model waits for two frames to take that model, s.
SUMMARY_DEFER_S = 0.25
#: How often the waiting summary thread looks (it is not woken by the frame path).
SUMMARY_POLL_S = 0.005

#: ``build_model(values, width, height) -> LensModel`` (may raise ValueError).
ModelBuilder = Callable[[Mapping[str, Any], int, int], Any]
#: ``build_maps(model) -> Rectifier`` (the remap tables).
MapsBuilder = Callable[[Any], Any]
#: ``log(level, message)``, level one of ``'info'``, ``'warning'``, ``'error'``.
LogFunction = Callable[[str, str], None]


@dataclass(frozen=True)
class ActiveModel:
    """
    What a frame is corrected with: swapped as ONE reference, read once per frame.

    ``values_generation`` counts accepted parameter sets that changed the model, so an older
    build never replaces a newer one. ``extras`` is what the injected ``extras`` function made
    of the model (the node: its two CameraInfo messages).
    """

    model: LensModel
    rectifier: Rectifier
    revision: int
    values_generation: int
    build_ms: float
    extras: Any = None


@dataclass(frozen=True)
class LiveStatus:
    """A consistent snapshot of the lifecycle for diagnostics (see :meth:`LiveModel.status`)."""

    active: ActiveModel | None
    revision: int
    rebuilds: int
    rebuild_failures: int
    last_rebuild_ms: float
    rebuild_pending: bool
    input_size: tuple[int, int] | None
    rebuild_error: str
    report: dict[str, Any] | None     # the active model's summary; None while being computed


class FrameDropped(Exception):
    """A frame that cannot be corrected; ``repeat`` is True for an already reported cause."""

    def __init__(self, kind: str, reason: str, hint: str = '', repeat: bool = False) -> None:
        """
        Keep the reason.

        :param kind: ``'size'`` (the sensor size disagrees) or ``'build'`` (no model).
        :param reason: why (for ``last_error`` and the log).
        :param hint: what the user can do (for the log only).
        :param repeat: the cause was reported before: count the frame, do not log again.
        """
        super().__init__(reason)
        self.kind, self.reason, self.hint, self.repeat = kind, reason, hint, repeat

    @property
    def log_line(self) -> str:
        """Return the log line: the reason and the hint."""
        return f'dropping frames: {self.reason}' + (f'; {self.hint}' if self.hint else '')


def plain(value: Any) -> Any:
    """Return a parameter value with arrays as lists (rclpy gives array.array for doubles)."""
    if hasattr(value, 'tolist') and not isinstance(value, (str, bytes)):
        return value.tolist()
    return value


def check_length(spec: ParamSpec, value: Any) -> None:
    """Refuse an array longer than its limit (before reading it): see :func:`max_length`."""
    if spec.type in ('double_array', 'integer_array', 'string_array') and \
            hasattr(value, '__len__') and len(value) > max_length(spec.name):
        if spec.name.endswith('.thickness_mm') and spec.name.startswith(_TABLES):
            raise ValueError(f'{spec.name}: {len(value)} values, more than the '
                             f'{max_length(spec.name)} a moving-group table may have '
                             f'({MAX_TABLE_ROWS} rows of {MAX_TABLE_GAPS} gaps)')
        raise ValueError(f'{spec.name}: {len(value)} values, more than the {MAX_SURFACES} '
                         'surfaces a prescription may have')


#: Prefixes of the moving-group tables (issue 19).
_TABLES = tuple(f'lens.{m}.' for m in MECHANISMS)
#: Most gaps one mechanism may move (its table: at most MAX_TABLE_ROWS rows of them).
MAX_TABLE_GAPS = 16


def max_length(name: str) -> int:
    """Return the most values an array parameter may hold (a table: rows x gaps)."""
    if name.startswith(_TABLES) and name.endswith('.thickness_mm'):
        return MAX_TABLE_ROWS * MAX_TABLE_GAPS
    return MAX_SURFACES


def sensor_size_fixed(values: Mapping[str, Any]) -> bool:
    """Return True when ``sensor.width_px`` and ``sensor.height_px`` both fix the image size."""
    return bool(values['sensor.width_px']) and bool(values['sensor.height_px'])


def _model_key(values: Mapping[str, Any], size: tuple[int, int]) -> tuple[Any, ...]:
    """Return a hashable key of the model parameters and the image size."""
    return (size,) + tuple(
        (name, tuple(values[name]) if isinstance(values[name], list) else values[name])
        for name in MODEL_PARAMS)


def _no_log(level: str, message: str) -> None:
    pass


def name_native_thread(name: str) -> None:
    """
    Give the calling OS thread a name (Linux ``prctl(PR_SET_NAME)``, 15 characters).

    Python 3.11 names only its own thread objects; with the OS name the rebuild and summary
    threads show up as themselves in ``top -H``, py-spy and ``/proc/PID/task/*/comm`` (the
    stage benchmark's per-thread CPU). Does nothing where it is not available.
    """
    try:
        ctypes.CDLL(None).prctl(15, name.encode()[:15], 0, 0, 0)
    except (OSError, AttributeError):
        pass


class LiveModel:
    """The parameter values and the model built from them, kept live (see the module doc)."""

    def __init__(self, values: Mapping[str, ParamValue], *,
                 build_model: ModelBuilder = build_model,
                 build_maps: MapsBuilder = Rectifier,
                 warm_maps: MapsBuilder | None = None,
                 extras: Callable[[Any], Any] | None = None,
                 log: LogFunction = _no_log) -> None:
        """
        Validate the start-up values and, when the sensor size is fixed, install their model.

        :param values: every schema parameter's value (already coerced).
        :param build_model: builds a LensModel (injectable: the tests block it).
        :param build_maps: builds the remap tables of a model (injectable likewise).
        :param warm_maps: builds the throw-away tables of the allocator warm-up: a plain
            :class:`~mechdeconv_ros.imaging.remap.Rectifier` unless injected (the node's
            ``build_maps`` also logs and caches, which a warm-up must not repeat).
        :param extras: makes the per-model extras the frame path publishes (e.g. CameraInfo).
        :param log: receives log lines as ``(level, message)``.
        :raises ValueError: when the start-up values describe no model (the model's reason).
        """
        self._build_model = build_model
        self._build_maps = build_maps
        self._warm_maps = Rectifier if warm_maps is None else warm_maps
        self._extras = extras
        self._log = log
        self._lock = threading.Condition()
        self._values: dict[str, ParamValue] = dict(values)
        self._values_generation = 0
        self._rebuild_requested = False
        self._rebuild_pending = False
        self._report_wanted = False
        self._warm_wanted = False
        self._busy = False
        self._summarizing = False
        self._stopping = False
        self._input_size: tuple[int, int] | None = None
        self._active: ActiveModel | None = None
        self._revision = 0
        self._rebuilds = 0
        self._rebuild_failures = 0
        self._rebuild_error = ''
        self._last_rebuild_ms = math.nan
        self._validated: tuple[tuple[Any, ...], Any] | None = None
        self._report: tuple[int, dict[str, Any]] | None = None
        # (revision, frames that took it): written by the executor without the lock (one
        # tuple reference, read whole), read by the summary thread to defer its work.
        self._frames_of_revision: tuple[int, int] = (0, 0)
        self._failed_build: tuple[int, int, int] | None = None    # executor thread only
        self._warmed_size: tuple[int, int] | None = None          # rebuild thread only
        self._threads: list[threading.Thread] = []
        self.startup_model = self._build_model(self._values, *self._validation_size())
        # Warnings (unusual but possible values) are logged once, when they appear: those of
        # the start-up values now, later ones when the summary thread summarises a new model.
        self._logged_warnings: tuple[str, ...] = tuple(
            getattr(self.startup_model, 'warnings', ()))           # summary thread after start
        for warning in self._logged_warnings:
            self._say('warning', warning)
        if sensor_size_fixed(self._values):
            # The size is known: build the maps now, so the first frame is not late.
            with self._lock:
                self._input_size = _image_size(self.startup_model)
                self._install_locked(self._finish(self.startup_model, 0, 0.0))

    def _say(self, level: str, message: str) -> None:
        """Log through the injected function; a failing logger must not stop a thread."""
        try:
            self._log(level, message)
        except Exception:           # noqa: B902 - logging is never worth a dead thread
            pass

    # -- parameters (executor thread) ----------------------------------------------------------

    def values(self) -> dict[str, ParamValue]:
        """Return a copy of the current values."""
        with self._lock:
            return dict(self._values)

    def value(self, name: str) -> ParamValue:
        """Return one current value."""
        with self._lock:
            return self._values[name]

    @property
    def active(self) -> ActiveModel | None:
        """Return the record frames use now (one reference read: it is immutable)."""
        return self._active

    @property
    def values_generation(self) -> int:
        """Return the generation of the committed values (sets that changed the model)."""
        with self._lock:
            return self._values_generation

    def validate(self, changes: Mapping[str, Any]) -> None:
        """
        Check a proposed set; build its candidate model when a model parameter changes.

        :param changes: name -> proposed value (names outside the schema are ignored).
        :raises ValueError: naming the parameter at fault (the model's reason for a set that
            describes no lens); the current values stay as they are.
        """
        values, changed = self._merge(changes)
        if changed & set(MODEL_PARAMS):
            size = self._validation_size()
            model = self._build_model(values, *size)
            with self._lock:
                self._validated = (_model_key(values, size), model)

    def commit(self, changes: Mapping[str, Any]) -> set[str]:
        """
        Store an accepted set (validated before); a model change asks for a rebuild.

        :param changes: name -> value, as validated.
        :return: the schema names in the set.
        :raises ValueError: when a value does not check (cannot happen after ``validate``).
        """
        values, changed = self._merge(changes)
        with self._lock:
            model_changed = any(values[name] != self._values[name]
                                for name in changed & set(MODEL_PARAMS))
            self._values = values
            if model_changed:               # setting a parameter to its value rebuilds nothing
                self._values_generation += 1
                self._rebuild_requested = True
        return changed

    def start_requested_rebuild(self) -> bool:
        """
        Wake the rebuild thread if a committed set asked for a rebuild; call once per request.

        :return: True when the thread was woken.
        """
        with self._lock:
            if not self._rebuild_requested:
                return False
            self._rebuild_requested = False
            self._rebuild_pending = True
            self._lock.notify_all()
            return True

    def _merge(self, changes: Mapping[str, Any]) -> tuple[dict[str, ParamValue], set[str]]:
        with self._lock:
            values = dict(self._values)
        changed = set()
        for name, value in changes.items():
            spec = SPECS.get(name)
            if spec is None:
                continue
            check_length(spec, value)
            values[name] = coerce(spec, plain(value))
            changed.add(name)
        return values, changed

    def _validation_size(self) -> tuple[int, int]:
        """Return the image size to build a candidate for (build_model's width, height)."""
        with self._lock:
            size = self._input_size
        return size if size is not None else NOMINAL_SIZE

    # -- frames (executor thread) --------------------------------------------------------------

    def model_for_frame(self, width: int, height: int) -> ActiveModel:
        """
        Return the model to correct a frame of this size with, building it if needed.

        :param width: the frame's width.
        :param height: the frame's height.
        :return: the model.
        :raises FrameDropped: when the frame must be dropped (the reason says why).
        """
        active = self._active                       # read the reference once
        if active is not None and _image_size(active.model) == (width, height):
            revision, frames = self._frames_of_revision
            if revision != active.revision or frames < 2:
                self._frames_of_revision = (active.revision,
                                            frames + 1 if revision == active.revision else 1)
            return active
        with self._lock:
            values, generation = dict(self._values), self._values_generation
        fixed_w, fixed_h = int(values['sensor.width_px']), int(values['sensor.height_px'])
        if (fixed_w and fixed_w != width) or (fixed_h and fixed_h != height):
            raise FrameDropped(
                'size', f'frame is {width}x{height} px but sensor.width_px x sensor.height_px is '
                f'{fixed_w or width}x{fixed_h or height}',
                hint='set both to 0 to follow the images, or fix the camera resolution')
        if self._failed_build == (generation, width, height):
            raise FrameDropped('build', '', repeat=True)     # known to fail: do not retry
        with self._lock:
            previous_size, self._input_size = self._input_size, (width, height)
        try:
            candidate = self._build(values, generation, (width, height))
        except Exception as err:        # noqa: B902 - drop the frame, never the caller
            with self._lock:
                # No model of this size exists: parameter sets and rebuilds keep following
                # the frames the node does correct, not the one it could not.
                if self._input_size == (width, height):
                    self._input_size = previous_size
            self._failed_build = (generation, width, height)
            raise FrameDropped('build', f'no model for {width}x{height} px: {err}') from err
        self._say('info', f'input is {width}x{height} px: model built in '
                          f'{candidate.build_ms:.1f} ms')
        with self._lock:
            if self._input_size != (width, height):
                return candidate        # yet another size came in meanwhile: use, not install
            return self._install_locked(candidate)

    # -- diagnostics (executor thread) ---------------------------------------------------------

    def status(self) -> LiveStatus:
        """
        Return a snapshot for diagnostics; ask the summary thread for a missing summary.

        The summary (tolerance propagation, depth of field, ...) costs a few ms for the thick
        lens but grows with the surfaces of a prescription (about 2.4 s for 256), so it is
        computed only in the summary thread, after the swap: never on the path from a parameter
        set to the first corrected frame, and never in the executor, where it would hold up the
        frames.

        :return: the snapshot.
        """
        with self._lock:
            active = self._active
            report = None
            if active is not None:
                if self._report is not None and self._report[0] == active.revision:
                    report = self._report[1]
                else:
                    self._report_wanted = True
                    self._lock.notify_all()
            return LiveStatus(
                active=active, revision=self._revision, rebuilds=self._rebuilds,
                rebuild_failures=self._rebuild_failures, last_rebuild_ms=self._last_rebuild_ms,
                rebuild_pending=self._rebuild_pending, input_size=self._input_size,
                rebuild_error=self._rebuild_error, report=report)

    # -- the rebuild and summary threads ---------------------------------------------------------

    def start(self) -> None:
        """Start the rebuild and summary threads (daemons: they never keep the process alive)."""
        self._threads = [threading.Thread(target=loop, name=name, daemon=True)
                         for loop, name in ((self._rebuild_loop, THREAD_NAME),
                                            (self._summary_loop, SUMMARY_THREAD_NAME))]
        for thread in self._threads:
            thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        """
        Stop the threads after their current work, and join them for at most ``timeout``.

        The summary thread may be computing a summary for diagnostics (seconds for a fisheye
        or a 256-surface prescription), which a stopping node does not need: the threads are
        daemons that write nothing outside this object, so the node does not wait for them
        (a node must exit within a few seconds of SIGINT/SIGTERM, as ``ros2 launch`` expects).

        :param timeout: longest wait for both joins together, s.
        """
        with self._lock:
            self._stopping = True
            self._lock.notify_all()
        deadline = time.monotonic() + timeout
        for thread in self._threads:
            thread.join(timeout=max(0.0, deadline - time.monotonic()))

    def wait_idle(self, timeout: float) -> bool:
        """
        Wait until both threads have no work left (for tests and tools).

        :param timeout: longest wait, s.
        :return: True when idle, False on timeout.
        """
        with self._lock:
            return self._lock.wait_for(
                lambda: self._stopping or not (
                    self._rebuild_pending or self._report_wanted or self._warm_wanted
                    or self._busy or self._summarizing), timeout)

    def _rebuild_loop(self) -> None:
        """Rebuild the model whenever an accepted set asks for it; coalesce bursts."""
        name_native_thread(THREAD_NAME)
        while True:
            with self._lock:
                self._busy = False
                self._lock.notify_all()
                while not (self._rebuild_pending or self._warm_wanted or self._stopping):
                    self._lock.wait()
                if self._stopping:
                    return
                self._busy = True
                rebuild, self._rebuild_pending = self._rebuild_pending, False
                self._warm_wanted = False
                values, generation = dict(self._values), self._values_generation
                size, active = self._input_size, self._active
            if rebuild:
                self._rebuild(values, generation, size, active)
            self._warm_allocator(self._active)

    def _summary_loop(self) -> None:
        """Summarise the model in use whenever a new one is installed or diagnostics ask."""
        name_native_thread(SUMMARY_THREAD_NAME)
        while True:
            with self._lock:
                self._summarizing = False
                self._lock.notify_all()
                while not (self._report_wanted or self._stopping):
                    self._lock.wait()
                if self._stopping:
                    return
                self._summarizing = True
                self._report_wanted = False
                active = self._active
            self._wait_for_frames(active)
            # Cached per revision: free when the model in use has its summary already.
            self._summarize(active)

    def _wait_for_frames(self, active: ActiveModel | None) -> None:
        """Wait until two frames took ``active`` (or SUMMARY_DEFER_S, or the stop)."""
        if active is None:
            return
        deadline = time.monotonic() + SUMMARY_DEFER_S
        while time.monotonic() < deadline:
            revision, frames = self._frames_of_revision
            if revision > active.revision or (revision == active.revision and frames >= 2):
                return
            with self._lock:
                if self._stopping or (self._report is not None
                                      and self._report[0] == active.revision):
                    return
                self._lock.wait(SUMMARY_POLL_S)

    def _rebuild(self, values: dict[str, ParamValue], generation: int,
                 size: tuple[int, int] | None, active: ActiveModel | None) -> None:
        """Build and install the model of the newest accepted values (rebuild thread)."""
        if active is not None and active.values_generation == generation \
                and _image_size(active.model) == size:
            return          # a burst was coalesced into a build that is already in use
        if size is None and not sensor_size_fixed(values):
            return          # no frame yet: the first frame builds with the newest values
        size = size or NOMINAL_SIZE
        try:
            candidate = self._build(values, generation, size)
        except Exception as err:    # noqa: B902 - keep the thread and the old model alive
            with self._lock:
                self._rebuild_failures += 1
                self._rebuild_error = str(err)
            self._say('error', f'rebuild failed, the previous model stays in use: {err}')
            return
        with self._lock:
            if self._input_size is not None and self._input_size != size:
                # A frame of another size arrived meanwhile and built its own model; make sure
                # the newest values get built for that size too.
                if generation >= self._values_generation:
                    self._rebuild_pending = True
                return
            self._install_locked(candidate)

    def _summarize(self, active: ActiveModel | None) -> None:
        """Compute the summary of the model in use, once per revision (summary thread)."""
        if active is None:
            return
        with self._lock:
            if self._report is not None and self._report[0] == active.revision:
                return
        try:
            report = active.model.report()
        except Exception as err:    # noqa: B902 - a summary must not stop the rebuilds
            self._say('warning', f'model summary failed: {err!r}')
            return
        with self._lock:
            self._report = (active.revision, report)
        # Log each warning once: not again for the next model that still has it (another
        # frame size, an unrelated parameter), again if it goes away and comes back.
        warnings = tuple(report.get('warnings', ()))
        for warning in warnings:
            if warning not in self._logged_warnings:
                self._say('warning', warning)
        self._logged_warnings = warnings

    def _warm_allocator(self, active: ActiveModel | None) -> None:
        """
        Build and drop one set of remap tables once per frame size (rebuild thread).

        The first rebuild after a new size is installed otherwise takes its buffers (tens of
        MB at 1080p: maps and their intermediates) from fresh pages while the active tables
        hold the others: measured 40-65 ms instead of 8-10 ms at 1920x1080, which made the
        first parameter sets after start-up miss two frame periods. With the malloc settings
        of :func:`mechdeconv_ros.node.process_env.keep_large_buffers`, the dropped buffers stay in
        the heap for that rebuild.
        """
        if active is None or self._warmed_size == _image_size(active.model):
            return
        self._warmed_size = _image_size(active.model)
        try:
            self._warm_maps(active.model)
        except Exception as err:    # noqa: B902 - an optimisation must never stop the thread
            self._say('warning', f'allocator warm-up failed: {err!r}')

    # -- building and installing (either thread) -----------------------------------------------

    def _build(self, values: Mapping[str, Any], generation: int,
               size: tuple[int, int]) -> ActiveModel:
        """Build a model and its tables, reusing the validated candidate if it fits."""
        start = time.perf_counter()
        with self._lock:
            validated = self._validated
        if validated is not None and validated[0] == _model_key(values, size):
            model = validated[1]
        else:
            model = self._build_model(values, *size)
        return self._finish(model, generation, (time.perf_counter() - start) * 1e3)

    def _finish(self, model: Any, generation: int, build_ms: float) -> ActiveModel:
        """Build the remap tables and the extras of a model (not installed: revision 0)."""
        start = time.perf_counter()
        rectifier = self._build_maps(model)
        total_ms = build_ms + (time.perf_counter() - start) * 1e3
        extras = self._extras(model) if self._extras is not None else None
        return ActiveModel(model=model, rectifier=rectifier, revision=0,
                           values_generation=generation, build_ms=total_ms, extras=extras)

    def _install_locked(self, candidate: ActiveModel) -> ActiveModel:
        """
        Swap a freshly built model in, unless the same or a newer one of its size is active.

        (The same one: when two builds of the newest values race, say the rebuild thread's
        and a frame's of a new size, the second is not a new revision.) Call with the lock
        held. When the model installed is older than the newest accepted values, the rebuild
        thread is asked to build those.

        :param candidate: the model to install.
        :return: the model frames of this size now use.
        """
        current = self._active
        if (current is not None and current.values_generation >= candidate.values_generation
                and _image_size(current.model) == _image_size(candidate.model)):
            return current
        self._revision += 1
        self._rebuilds += 1
        installed = ActiveModel(
            model=candidate.model, rectifier=candidate.rectifier, revision=self._revision,
            values_generation=candidate.values_generation, build_ms=candidate.build_ms,
            extras=candidate.extras)
        self._active = installed                # the one atomic swap frames see
        self._last_rebuild_ms = candidate.build_ms
        self._rebuild_error = ''
        self._report_wanted = True              # the summary thread summarises it
        self._warm_wanted = True                # the rebuild thread warms a new size
        if installed.values_generation < self._values_generation:
            self._rebuild_pending = True
        self._lock.notify_all()
        return installed


def _image_size(model: Any) -> tuple[int, int]:
    """Return the (width, height) in px a model was built for."""
    return (int(model.width), int(model.height))


def changes_of(parameters: Iterable[Any]) -> dict[str, Any]:
    """
    Return ``{name: value}`` of parameter objects (anything with ``name`` and ``value``).

    :param parameters: e.g. rclpy Parameters.
    :return: the mapping (a later duplicate wins).
    """
    return {param.name: param.value for param in parameters}
