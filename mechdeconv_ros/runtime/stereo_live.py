# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
stereo_node's live pair: values, validation, the background rebuild and the atomic swap.

No ROS import (the node wires it to rclpy; test/test_stereo_live.py drives it directly).
Lifecycle of a parameter set, as the single camera's
(:mod:`~mechdeconv_ros.runtime.live_model`):

* :meth:`StereoLive.validate` merges the proposed values into the current ones and, when a
  ``left.``, ``right.``, ``rig.`` or ``output.`` value changes, builds the candidate
  :class:`~mechdeconv_ros.model.stereo.StereoModel` (both lens models, the rig, the rectified
  camera: a fraction of a second); a refusal raises ``ValueError`` naming the parameter
  (``rig.baseline_mm``, ``left.lens.r1_mm``, cameras whose fields do not overlap) and changes
  nothing.
* :meth:`StereoLive.commit` stores an accepted set; a model change increments the
  generation and wakes the rebuild thread (``mechdeconv-stereo-rebuild``), which traces both
  cameras' maps (:class:`~mechdeconv_ros.imaging.stereo_remap.StereoRectifier`: seconds at
  720p), builds the node's extras (the four CameraInfos) and swaps ONE reference to an
  immutable :class:`StereoActive` (model, rectifier, extras, generation). Sets arriving while
  it builds are coalesced (the next build takes the newest values); a failed build leaves the
  pair in use and is reported (``rebuild_failures``, ``rebuild_error``).

A pair of frames reads :attr:`StereoLive.active` once and uses that record only, so no
published pair mixes two models. Threads: the executor thread calls ``validate``, ``commit``
and reads ``active`` and ``status``; the rebuild thread builds and installs under the lock.
The start-up pair is built synchronously in the constructor (a refusal there is the node's
exit 1 with the parameter named).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from typing import Any, Callable, Mapping

from mechdeconv_ros.imaging.stereo_remap import StereoRectifier
from mechdeconv_ros.model.stereo import build_stereo, StereoModel
from mechdeconv_ros.schema.stereo_params import check_stereo_values

#: Prefixes of the parameters that change the pair's model (and so its maps).
MODEL_PREFIXES = ('left.', 'right.', 'rig.', 'output.')


@dataclasses.dataclass(frozen=True)
class StereoActive:
    """One immutable pair: the model, its rectifier and the node's extras (CameraInfos)."""

    stereo: StereoModel
    rectifier: StereoRectifier
    extras: Any
    generation: int


@dataclasses.dataclass(frozen=True)
class StereoStatus:
    """A snapshot for /diagnostics."""

    generation: int
    active_generation: int
    rebuilds: int
    rebuild_failures: int
    rebuild_error: str
    last_rebuild_ms: float
    rebuild_pending: bool


def _is_model_change(name: str) -> bool:
    return name.startswith(MODEL_PREFIXES)


class StereoLive:
    """The live stereo pair of a node (module docstring)."""

    def __init__(self, values: Mapping[str, Any], extras: Callable[[StereoModel], Any],
                 log: Callable[[str, str], None] = lambda level, message: None,
                 build: Callable[..., StereoModel] = build_stereo,
                 rectifier: Callable[[StereoModel], Any] = StereoRectifier) -> None:
        """
        Check the start-up values and build the first pair synchronously.

        :param values: the node's start-up values (every STEREO_SCHEMA name).
        :param extras: builds the node's per-model extras (the CameraInfos), rebuild thread.
        :param log: ``log(level, message)``.
        :param build: the stereo model builder (tests inject a slow one).
        :param rectifier: the rectifier factory.
        :raises ValueError: naming the parameter when the start-up pair is refused.
        """
        self._values = check_stereo_values(values)
        self._extras, self._log, self._build, self._rectifier = extras, log, build, rectifier
        self._lock = threading.Condition()
        self._generation = 0
        self._candidate: tuple[int, StereoModel] | None = None
        self._stopping = False
        self._wanted = False
        self.rebuilds = 0
        self.rebuild_failures = 0
        self.rebuild_error = ''
        self.last_rebuild_ms = float('nan')
        stereo = self._build(self._values)
        self.active: StereoActive = StereoActive(stereo, self._rectifier(stereo),
                                                 self._extras(stereo), 0)
        self._thread = threading.Thread(target=self._run, name='mechdeconv-stereo-rebuild',
                                        daemon=True)

    def start(self) -> None:
        """Start the rebuild thread."""
        self._thread.start()

    def stop(self) -> None:
        """Stop the rebuild thread (after the build it is in)."""
        with self._lock:
            self._stopping = True
            self._lock.notify_all()
        if self._thread.is_alive():
            self._thread.join(timeout=30.0)

    def values(self) -> dict[str, Any]:
        """
        Return a copy of the current values.

        :return: name -> value.
        """
        with self._lock:
            return dict(self._values)

    def value(self, name: str) -> Any:
        """
        Return one current value.

        :param name: the parameter.
        :return: its value.
        """
        with self._lock:
            return self._values[name]

    def validate(self, changes: Mapping[str, Any]) -> None:
        """
        Check a proposed set; build the candidate pair when a model parameter changes.

        :param changes: name -> proposed value.
        :raises ValueError: naming the parameter (schema or model refusal); nothing changes.
        """
        with self._lock:
            merged = dict(self._values)
        proposed = check_stereo_values(dict(changes), partial=True)
        moved = [n for n, v in proposed.items() if merged.get(n) != v and _is_model_change(n)]
        merged.update(proposed)
        if moved:
            stereo = self._build(check_stereo_values(merged))
            with self._lock:
                self._candidate = (self._generation + 1, stereo)

    def commit(self, changes: Mapping[str, Any]) -> set[str]:
        """
        Store an accepted set; wake the rebuild thread when the pair's model changed.

        :param changes: name -> accepted value.
        :return: the names whose value changed.
        """
        proposed = check_stereo_values(dict(changes), partial=True)
        with self._lock:
            changed = {n for n, v in proposed.items() if self._values.get(n) != v}
            self._values.update(proposed)
            if any(_is_model_change(n) for n in changed):
                self._generation += 1
                candidate = self._candidate
                if candidate is None or candidate[0] != self._generation or \
                        dict(candidate[1].values or {}) != self._values:
                    self._candidate = None
                self._wanted = True
                self._lock.notify_all()
        return changed

    def status(self) -> StereoStatus:
        """
        Return a snapshot for /diagnostics.

        :return: the status.
        """
        with self._lock:
            return StereoStatus(self._generation, self.active.generation, self.rebuilds,
                                self.rebuild_failures, self.rebuild_error, self.last_rebuild_ms,
                                self._wanted or self.active.generation != self._generation)

    def _run(self) -> None:
        while True:
            with self._lock:
                while not (self._wanted or self._stopping):
                    self._lock.wait()
                if self._stopping:
                    return
                self._wanted = False
                generation, values = self._generation, dict(self._values)
                candidate, self._candidate = self._candidate, None
            self._install(generation, values, candidate)

    def _install(self, generation: int, values: dict[str, Any],
                 candidate: tuple[int, StereoModel] | None) -> None:
        """Build one generation's pair and swap it in (rebuild thread); never raises."""
        start = time.perf_counter()
        try:
            stereo = candidate[1] if candidate is not None and candidate[0] == generation \
                else self._build(values)
            record = StereoActive(stereo, self._rectifier(stereo), self._extras(stereo),
                                  generation)
        except Exception as err:        # noqa: B902 - a failed build keeps the old pair
            with self._lock:
                self.rebuild_failures += 1
                self.rebuild_error = str(err)
            self._log('error', f'stereo rebuild failed, previous pair in use: {err}')
            return
        with self._lock:
            if generation >= self.active.generation:
                self.active = record        # the one atomic swap
                self.rebuilds += 1
                self.rebuild_error = ''
                self.last_rebuild_ms = (time.perf_counter() - start) * 1e3
        self._log('info', f'stereo pair rebuilt (generation {generation}) in '
                          f'{(time.perf_counter() - start):.2f} s')
