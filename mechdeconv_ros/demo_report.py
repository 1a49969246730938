# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
What the demo shows: its progress lines, the PNGs it writes and the numbers it prints.

No ROS import (messages are converted by :mod:`mechdeconv_ros.image_msgs`). Latency is receive
time minus ``header.stamp`` (the camera stamps a frame when it publishes it), in ms.
"""

from __future__ import annotations

import json
from pathlib import Path
import time
from typing import Any, Callable, Mapping, Sequence

import cv2
import numpy as np

_T0 = time.monotonic()

#: The node's diagnostics the demo prints, in this order.
DIAGNOSTIC_KEYS = ('model_revision', 'last_rebuild_ms', 'focal_length_mm', 'distortion_model',
                   'D', 'fit_rms_px', 'max_displacement_px', 'frames_in', 'frames_out',
                   'frames_dropped', 'frame_time_ms_mean', 'frame_time_ms_max')


class DemoError(Exception):
    """Something went wrong that the demo reports in one line (exit status 1)."""


def say(text: str) -> None:
    """
    Print one progress line, prefixed with the seconds since the demo started.

    :param text: the line.
    """
    print(f'[demo {time.monotonic() - _T0:5.1f} s] {text}', flush=True)


def stamp_ns(stamp: Any) -> int:
    """
    Return a builtin_interfaces/Time in nanoseconds.

    :param stamp: the message field.
    :return: nanoseconds since the epoch.
    """
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def to_bgr(msg: Any) -> np.ndarray:
    """
    Copy a sensor_msgs/Image into a BGR (or grey) array that cv2.imwrite takes.

    :param msg: the Image.
    :return: ``(H, W, 3)`` or ``(H, W)`` uint8/uint16.
    """
    from mechdeconv_ros.image_msgs import image_to_array
    pixels, encoding = image_to_array(msg)
    conversions = {'rgb8': cv2.COLOR_RGB2BGR, 'rgba8': cv2.COLOR_RGBA2BGR,
                   'bgra8': cv2.COLOR_BGRA2BGR}
    if encoding.name in conversions:
        return cv2.cvtColor(pixels, conversions[encoding.name])
    return np.ascontiguousarray(pixels)


def percentile(values: Sequence[float], q: float) -> float:
    """
    Return the q-th percentile, NaN for no values.

    :param values: the samples.
    :param q: percent, 0-100.
    :return: the percentile.
    """
    return float(np.percentile(values, q)) if len(values) else float('nan')


def window_line(fps: float, latencies_ms: Sequence[float], node_fps: float,
                rate_hz: float) -> str:
    """
    Return the throughput and latency line of one measuring window.

    :param fps: image_rect frames per second received.
    :param latencies_ms: their latencies.
    :param node_fps: the node's input rate over the window (its diagnostics; NaN: unknown).
    :param rate_hz: the camera rate.
    :return: the line.
    """
    return (f'  throughput {fps:.1f} fps of image_rect (camera {rate_hz:g} Hz, node input '
            f'{node_fps:.1f} fps); latency camera -> image_rect p50 '
            f'{percentile(latencies_ms, 50):.1f} ms, p95 {percentile(latencies_ms, 95):.1f} ms '
            f'({len(latencies_ms)} frames)')


def diagnostics_lines(diag: Mapping[str, str], message: str) -> str:
    """
    Return the node's own summary from /diagnostics, two lines.

    :param diag: key -> value of the node's status.
    :param message: the status message.
    :return: the text.
    """
    diag = dict(diag)
    if 'D' in diag:
        try:
            diag['D'] = '[' + ', '.join(f'{d:.5g}' for d in json.loads(diag['D'])) + ']'
        except (ValueError, TypeError):
            pass
    return (f'node diagnostics ({message}):\n  '
            + ', '.join(f'{k} {diag[k]}' for k in DIAGNOSTIC_KEYS if k in diag))


def caption(image: np.ndarray, text: str) -> np.ndarray:
    """
    Put a caption strip above an image.

    :param image: BGR (or grey) uint8.
    :param text: the caption.
    :return: the captioned BGR image.
    """
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    strip = np.full((30, image.shape[1], 3), 255, np.uint8)
    cv2.putText(strip, text, (8, 21), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1,
                cv2.LINE_AA)
    return np.vstack([strip, image])


def write_png(path: Path, image: np.ndarray) -> None:
    """
    Write a PNG and say so.

    :param path: the file.
    :param image: what cv2.imwrite takes.
    :raises DemoError: when it cannot be written.
    """
    if not cv2.imwrite(str(path), image):
        raise DemoError(f'cannot write {path}')
    say(f'wrote {path}')


def lens_text(model: Any) -> str:
    """
    Return the lens of a model in one caption: stop offset, thickness, focal length.

    :param model: a :class:`mechdeconv_ros.model.LensModel`.
    :return: the text.
    """
    return (f"stop offset {model.values['lens.stop_offset_mm']:g} mm, "
            f"t = {model.values['lens.thickness_mm']:g} mm, f = {model.focal_length_mm:.3f} mm")


def summary_image(raw: np.ndarray, corrected: np.ndarray, raw_after: np.ndarray,
                  corrected_after: np.ndarray, before: Any, after: Any) -> np.ndarray:
    """
    Return the four frames of the demo, captioned, as a 2 x 2 grid (``summary.png``).

    :param raw: image_raw through the first lens (BGR).
    :param corrected: its correction.
    :param raw_after: image_raw through the new lens.
    :param corrected_after: its correction by the new model.
    :param before: the first lens's model.
    :param after: the new lens's model.
    :return: the BGR image.
    """
    return np.vstack([
        np.hstack([caption(raw, f'image_raw: {lens_text(before)}'),
                   caption(corrected, 'image_rect (corrected)')]),
        np.hstack([caption(raw_after, f'image_raw: {lens_text(after)}'),
                   caption(corrected_after, 'image_rect after the parameter set')])])


def wait_for(condition: Callable[[], bool], timeout_s: float, what: str,
             children: Sequence[Any] = ()) -> None:
    """
    Poll ``condition`` until it holds.

    :param condition: the predicate.
    :param timeout_s: how long to wait.
    :param what: what is awaited, for the error message.
    :param children: :class:`mechdeconv_ros.graph_env.Child` processes that must stay alive.
    :raises DemoError: on timeout or when a child exits.
    """
    deadline = time.monotonic() + timeout_s
    while not condition():
        for child in children:
            if not child.running():
                raise DemoError(f'{child.name} exited with status {child.proc.returncode} '
                                f"while waiting for {what}; its log:\n{child.tail(indent='    ')}")
        if time.monotonic() > deadline:
            raise DemoError(f'no {what} within {timeout_s:g} s')
        time.sleep(0.02)
