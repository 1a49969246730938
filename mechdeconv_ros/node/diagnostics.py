# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The node's /diagnostics: frame counters and one DiagnosticStatus from the live model's state.

The status is named after the node's fully qualified name (``/left/correct_node: lens
correction``), so two cameras' nodes are told apart. Its values are the model revision and
rebuild counters (:class:`mechdeconv_ros.runtime.live_model.LiveStatus`), the frame counters and
timings (:class:`FrameStats`, per diagnostics period) and the lens summary
(``LensModel.report()`` flattened to dotted keys, e.g. ``fov_deg.horizontal``, and the corner
relative illumination ``relative_illumination.corner_ri``), and whether the vignetting
correction is on (``vignetting_correction``; its gain-limit warning joins the model's
warnings). The input is named by ``image_transport`` and ``input_topic``; with compressed
input, ``frames_undecodable`` counts refused payloads and ``decode_time_ms_{mean,max,last}``
time the JPEG/PNG decoding (included in ``frame_time_ms_*``); ``frames_out_compressed`` counts
the frames published on ``image_rect/compressed``; ``FrameStats.extra`` adds the entries of
the ``lens_state`` input of a moving lens (:mod:`mechdeconv_ros.node.lens_follower`). Level: ERROR
while the last rebuild failed (the previous model stays in use), WARN for the model's warnings
or frames that all fail, OK otherwise.
"""

from __future__ import annotations

import json
import math
import time
from typing import Any, Callable, Iterable, Mapping

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mechdeconv_ros.runtime.live_model import LiveStatus
from rclpy.node import Node


class FrameStats:
    """Frame counters and timings, written by the frame callback, read by diagnostics."""

    def __init__(self) -> None:
        """Start all counters at zero."""
        self.frames_in = 0
        self.frames_out = 0
        self.frames_dropped = 0
        self.frames_failed = 0
        self.rejected_encodings = 0
        self.last_rejected_encoding = ''
        self.last_error = ''
        self.frame_ms_last = math.nan
        self.frame_ms_max = 0.0         # since the last diagnostics message
        self.frame_ms_sum = 0.0         # since the last diagnostics message
        self.frame_count = 0            # since the last diagnostics message
        self.image_transport = 'raw'
        self.input_topic = ''
        self.frames_undecodable = 0
        self.frames_out_compressed = 0
        self.decode_ms_last = math.nan
        self.decode_ms_max = 0.0        # since the last diagnostics message
        self.decode_ms_sum = 0.0        # since the last diagnostics message
        self.decode_count = 0           # since the last diagnostics message
        #: More entries for /diagnostics (the lens_state input's, lens_follower.py).
        self.extra: dict[str, Any] = {}
        #: The straight-edge check's entries (runtime/check_session.py), replaced whole by
        #: the diagnostics timer before each message.
        self.check: dict[str, Any] = {}
        self._logged: dict[str, float] = {}     # kind of error -> time last logged, s

    def record_error(self, kind: str, error: str, throttle_s: float) -> bool:
        """
        Keep a frame problem as ``last_error``; return whether to log it (throttled per kind).

        (rclpy's ``throttle_duration_sec`` is per call site: one site would mute other kinds.)

        :param kind: the kind of problem (``'size'``, ``'correction'``, ...).
        :param error: what went wrong.
        :param throttle_s: least seconds between two log lines of one kind.
        :return: True when this kind was not logged in the last ``throttle_s``.
        """
        self.last_error = error
        now = time.monotonic()
        if now - self._logged.get(kind, -throttle_s) >= throttle_s:
            self._logged[kind] = now
            return True
        return False

    def add_decode_time(self, ms: float) -> None:
        """Record the decoding time of one compressed frame."""
        self.decode_ms_last = ms
        self.decode_ms_max = max(self.decode_ms_max, ms)
        self.decode_ms_sum += ms
        self.decode_count += 1

    def take_decode_period(self) -> tuple[float, float]:
        """Return ``(mean ms, max ms)`` of decoding since the last call; restart the period."""
        count = self.decode_count
        mean = self.decode_ms_sum / count if count else math.nan
        peak = self.decode_ms_max if count else math.nan
        self.decode_ms_sum, self.decode_ms_max, self.decode_count = 0.0, 0.0, 0
        return mean, peak

    def add_time(self, ms: float) -> None:
        """Record the processing time of one published frame."""
        self.frame_ms_last = ms
        self.frame_ms_max = max(self.frame_ms_max, ms)
        self.frame_ms_sum += ms
        self.frame_count += 1

    def take_period(self) -> tuple[float, float, int]:
        """Return ``(mean ms, max ms, frames)`` since the last call and restart the period."""
        count = self.frame_count
        mean = self.frame_ms_sum / count if count else math.nan
        peak = self.frame_ms_max if count else math.nan
        self.frame_ms_sum, self.frame_ms_max, self.frame_count = 0.0, 0.0, 0
        return mean, peak, count


def status_name(node: Node) -> str:
    """Return the DiagnosticStatus name of a node: its fully qualified name + the task."""
    return f'{node.get_fully_qualified_name()}: lens correction'


def publish_diagnostics(node: Node, publisher: Any, live: Any, stats: FrameStats,
                        subscribed: Callable[[], bool], throttle_s: float) -> None:
    """
    Publish the node's diagnostics now (its 1 Hz timer); never raises.

    :param node: the node (its name, clock and logger).
    :param publisher: the ``/diagnostics`` publisher.
    :param live: the live model (its :meth:`status` is read once).
    :param stats: the frame counters.
    :param subscribed: whether the node is subscribed to image_raw now.
    :param throttle_s: the least time between two logged failures.
    """
    try:
        publisher.publish(diagnostics_message(node, live.status(), stats, subscribed()))
    except Exception as err:        # noqa: B902 - diagnostics must not stop the node
        node.get_logger().error(f'diagnostics failed: {err!r}', throttle_duration_sec=throttle_s)


def diagnostics_message(node: Node, live: LiveStatus, stats: FrameStats,
                        subscribed: bool) -> DiagnosticArray:
    """
    Return the node's diagnostics: one status with the lens summary and the counters.

    :param node: the node (its name and clock).
    :param live: the live model's snapshot.
    :param stats: the frame counters (their period restarts).
    :param subscribed: whether the node is subscribed to image_raw now.
    :return: the message, stamped now.
    """
    mean_ms, max_ms, period_frames = stats.take_period()
    entries: dict[str, Any] = {
        'model_revision': live.revision,
        'rebuilds': live.rebuilds,
        'rebuild_failures': live.rebuild_failures,
        'last_rebuild_ms': live.last_rebuild_ms,
        'rebuild_pending': live.rebuild_pending,
        'input_size_px': ('none yet' if live.input_size is None
                          else '{}x{}'.format(*live.input_size)),
        'subscribed': subscribed,
        'frames_in': stats.frames_in,
        'frames_out': stats.frames_out,
        'frames_dropped': stats.frames_dropped,
        'frames_failed': stats.frames_failed,
        'rejected_encodings': stats.rejected_encodings,
        'last_rejected_encoding': stats.last_rejected_encoding,
        'frames_in_last_period': period_frames,
        'frame_time_ms_mean': mean_ms,
        'frame_time_ms_max': max_ms,
        'frame_time_ms_last': stats.frame_ms_last,
        'last_error': stats.last_error,
        'image_transport': stats.image_transport,
        'input_topic': stats.input_topic,
        'frames_out_compressed': stats.frames_out_compressed,
    }
    if stats.image_transport == 'compressed':
        decode_mean, decode_max = stats.take_decode_period()
        entries.update({'frames_undecodable': stats.frames_undecodable,
                        'decode_time_ms_mean': decode_mean,
                        'decode_time_ms_max': decode_max,
                        'decode_time_ms_last': stats.decode_ms_last})
    entries.update(stats.extra)
    entries.update(stats.check)
    status = DiagnosticStatus(name=status_name(node), hardware_id='')
    warnings: list[str] = []
    summary_pending = live.active is not None and live.report is None
    if live.active is not None:
        entries['model_values_generation'] = live.active.values_generation
        if live.report is not None:
            entries.update(_flatten_report(live.report))
            warnings = list(live.report.get('warnings', []))
        rectifier = live.active.rectifier
        entries['vignetting_correction'] = getattr(rectifier, 'gain', None) is not None
        if getattr(rectifier, 'vignetting_warning', None):
            warnings.append(rectifier.vignetting_warning)
        entries['summary_pending'] = summary_pending
    if live.rebuild_error:
        status.level = DiagnosticStatus.ERROR
        status.message = f'rebuild failed, previous model in use: {live.rebuild_error}'
    elif live.active is None:
        status.level = DiagnosticStatus.OK
        status.message = 'waiting for the first frame'
    elif warnings + _check_warning(stats.check):
        warnings += _check_warning(stats.check)
        status.level = DiagnosticStatus.WARN
        status.message = '; '.join(warnings)
    elif stats.last_error and period_frames == 0 and stats.frames_in > stats.frames_out:
        status.level = DiagnosticStatus.WARN
        status.message = stats.last_error
    else:
        status.level = DiagnosticStatus.OK
        status.message = f'correcting, model revision {live.revision}'
        if summary_pending:
            status.message += ' (lens summary being computed)'
    status.values = [KeyValue(key=key, value=_text(value)) for key, value in entries.items()]
    array = DiagnosticArray()
    array.header.stamp = node.get_clock().now().to_msg()
    array.status = [status]
    return array


def _check_warning(check: Mapping[str, Any]) -> list[str]:
    """Return the straight-edge check's warning, if its verdict is description_off."""
    if check.get('verdict') != 'description_off':
        return []
    return ['check: description_off: straight edges come out '
            f"{_text(check.get('straightness_rms_px'))} px rms from straight (see estimate.*; "
            f"{_text(check.get('check_age_s'))} s ago, model revision "
            f"{_text(check.get('check_model_revision'))})"]


#: Curves of the model report that /diagnostics leaves out (the scalars stay: e.g.
#: ``relative_illumination.corner_ri``); ``mechdeconv info --json`` has them.
BULKY = ('distortion_curve', 'warnings', 'relative_illumination.image_height_mm',
         'relative_illumination.ri', 'relative_illumination.pupil_pass_fraction')


def _flatten_report(report: Mapping[str, Any], prefix: str = '') -> Iterable[tuple[str, Any]]:
    """Yield ``(dotted key, value)`` of a model report, skipping the bulky curves."""
    for key, value in report.items():
        if f'{prefix}{key}' in BULKY:
            continue
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            yield from _flatten_report(value, name + '.')
        else:
            yield name, value


def _text(value: Any) -> str:
    """Format a diagnostics value: compact floats, JSON for lists."""
    if isinstance(value, bool) or value is None:
        return str(value).lower() if isinstance(value, bool) else 'none'
    if isinstance(value, float):
        return f'{value:.6g}'
    if isinstance(value, (list, tuple)):
        return json.dumps(value, default=float)
    return str(value)
