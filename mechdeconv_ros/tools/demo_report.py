# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
What the demo shows: its progress lines, the PNGs it writes and the numbers it prints.

No ROS import (messages are converted by :mod:`mechdeconv_ros.node.image_msgs`). Latency is receive
time minus ``header.stamp`` (the camera stamps a frame when it publishes it), in ms.
"""

from __future__ import annotations

import json
from pathlib import Path
import threading
import time
from typing import Any, Callable, Mapping, Sequence

import cv2
import numpy as np

_T0 = time.monotonic()

#: The node's diagnostics the demo prints, in this order.
DIAGNOSTIC_KEYS = ('model_revision', 'last_rebuild_ms', 'focal_length_mm', 'distortion_model',
                   'D', 'fit_rms_px', 'max_displacement_px', 'frames_in', 'frames_out',
                   'frames_dropped', 'frame_time_ms_mean', 'frame_time_ms_max',
                   'decode_time_ms_mean', 'frames_undecodable')


class DemoError(Exception):
    """Something went wrong that the demo reports in one line (exit status 1)."""


def in_background(fn: Callable[[], Any]) -> Callable[[], Any]:
    """
    Start ``fn()`` in a daemon thread; return a function that waits for it and returns its result.

    The demo's printed lens report traces for seconds (a fisheye's relative illumination, the
    tolerance sigmas): started before the children, it runs while they start up (their own
    processes) instead of after the first frame. The waiting function raises what ``fn``
    raised.

    :param fn: the work.
    :return: the waiting function.
    """
    outcome: dict[str, Any] = {}

    def work() -> None:
        try:
            outcome['result'] = fn()
        except BaseException as err:     # handed to the waiting thread, not printed here
            outcome['error'] = err

    thread = threading.Thread(target=work, name='demo-report', daemon=True)
    thread.start()

    def wait() -> Any:
        thread.join()
        if 'error' in outcome:
            raise outcome['error']
        return outcome['result']
    return wait


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
    Copy a sensor_msgs/Image (or decode a CompressedImage) into a BGR or grey array.

    :param msg: the Image or CompressedImage.
    :return: ``(H, W, 3)`` or ``(H, W)`` uint8/uint16, as cv2.imwrite takes it.
    """
    if hasattr(msg, 'format'):
        from mechdeconv_ros.node.compressed import decode
        decoded = decode(msg.format, msg.data)
        pixels, encoding = decoded.pixels, decoded.encoding
    else:
        from mechdeconv_ros.node.image_msgs import image_to_array
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


def first_air_gap(values: Mapping[str, Any]) -> int | None:
    """
    Return the index of the first air gap of a prescription, None when it has none.

    The gap after surface ``i`` is ``lens.surfaces.thickness_mm[i]`` with
    ``lens.surfaces.refractive_index[i] == 1.0`` (air after that surface); the last surface's
    thickness is the back focal distance, not a gap between surfaces.

    :param values: the parameter values.
    :return: the index, or None.
    """
    indices = list(values.get('lens.surfaces.refractive_index') or [])
    return next((i for i, n in enumerate(indices[:-1]) if n == 1.0), None)


def lens_change(values: Mapping[str, Any], width: int, height: int, stop_offset: float,
                thickness: float) -> tuple[dict[str, Any], Any, str]:
    """
    Choose the demo's lens change and build the model it gives.

    Thick-lens mode sets ``lens.stop_offset_mm`` and ``lens.thickness_mm``. Prescription mode
    (non-empty ``lens.surfaces.radius_mm``, where those two do nothing) lengthens the first
    air gap by 5 %; when :func:`mechdeconv_ros.model.model.build_model` refuses that (or there is
    no gap) it says why and changes ``output.alpha`` to 1 (0 if it is 1 already) instead.

    :param values: the parameter values of the params file.
    :param width: image width in px.
    :param height: image height in px.
    :param stop_offset: the new ``lens.stop_offset_mm`` (thick lens).
    :param thickness: the new ``lens.thickness_mm`` (thick lens).
    :return: (parameter name -> new value, the new model, what changed in words).
    :raises DemoError: when the thick-lens change describes no usable camera.
    """
    from mechdeconv_ros.model.model import build_model, ModelError

    if not values.get('lens.surfaces.radius_mm'):
        change: dict[str, Any] = {'lens.stop_offset_mm': stop_offset,
                                  'lens.thickness_mm': thickness}
        try:
            after = build_model({**values, **change}, width, height)
        except ModelError as err:
            raise DemoError(f'the new lens describes no usable camera: {err}') from None
        return change, after, (
            f"lens.stop_offset_mm {values['lens.stop_offset_mm']:g} -> {stop_offset:g} mm, "
            f"lens.thickness_mm {values['lens.thickness_mm']:g} -> {thickness:g} mm")
    gap = first_air_gap(values)
    if gap is None:
        refused = 'the prescription has no air gap between surfaces to lengthen'
    else:
        gaps = [float(t) for t in values['lens.surfaces.thickness_mm']]
        old, gaps[gap] = gaps[gap], round(gaps[gap] * 1.05, 6)
        change = {'lens.surfaces.thickness_mm': gaps}
        try:
            return change, build_model({**values, **change}, width, height), (
                f'lens.surfaces.thickness_mm[{gap}] (the first air gap, after surface {gap}) '
                f'{old:g} -> {gaps[gap]:g} mm (+5 %)')
        except ModelError as err:
            refused = f'lengthening the first air gap by 5 % is refused: {err}'
    alpha = float(values['output.alpha'])
    change = {'output.alpha': 0.0 if alpha == 1.0 else 1.0}
    say(f"{refused}; changing output.alpha instead (the node's choice, not the lens)")
    after = build_model({**values, **change}, width, height)
    return change, after, f"output.alpha {alpha:g} -> {change['output.alpha']:g}"


def lens_text(model: Any) -> str:
    """
    Return the lens of a model in one caption: what the demo changes, focal length, alpha.

    :param model: a :class:`mechdeconv_ros.model.model.LensModel`.
    :return: the text.
    """
    values = model.values
    if values['lens.surfaces.radius_mm']:
        gap = first_air_gap(values)
        lens = f"{len(values['lens.surfaces.radius_mm'])} surfaces"
        if gap is not None:
            lens += f", air gap {gap} {values['lens.surfaces.thickness_mm'][gap]:g} mm"
    else:
        lens = (f"stop offset {values['lens.stop_offset_mm']:g} mm, "
                f"t = {values['lens.thickness_mm']:g} mm")
    return f"{lens}, f = {model.focal_length_mm:.3f} mm, alpha {values['output.alpha']:g}"


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
    :param children: :class:`mechdeconv_ros.node.process_env.Child` processes that must stay alive.
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


def measure(monitor: Any, seconds: float, label: str, rate_hz: float,
            children: Sequence[Any]) -> None:
    """
    Print the throughput and latency of image_rect over the next ``seconds``.

    :param monitor: the :class:`mechdeconv_ros.tools.demo_monitor.Monitor`.
    :param seconds: the window.
    :param label: what is measured, for the progress line.
    :param rate_hz: the camera rate.
    :param children: the processes that must stay alive.
    """
    say(f'measuring image_rect for {seconds:g} s ({label}) ...')
    start = time.monotonic()
    wait_for(lambda: time.monotonic() - start >= seconds, seconds + 5.0, 'end of window',
             children)
    say(window_line(*monitor.window(start, time.monotonic()), rate_hz))


def newest_rect(monitor: Any) -> Any:
    """
    Return the newest image_rect the monitor received.

    :param monitor: the :class:`mechdeconv_ros.tools.demo_monitor.Monitor`.
    :return: the Image.
    """
    with monitor.lock:
        return monitor.last_rect


def stop_children(children: Sequence[Any]) -> None:
    """
    Stop the processes with SIGINT, newest first, and check that each exits with status 0.

    :param children: the :class:`mechdeconv_ros.node.process_env.Child` processes.
    :raises DemoError: naming each that did not, with the tail of its log.
    """
    say('stopping ' + ' and '.join(c.name for c in reversed(children)) + ' with SIGINT ...')
    failed = []
    for child in reversed(children):
        status = child.stop(log=say)
        say(f'  {child.name} exited with status {status}')
        if status != 0:
            failed.append(f'{child.name} exited with status {status}; its log:\n'
                          + child.tail(indent='    '))
    if failed:
        raise DemoError('\n'.join(failed))
