# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The demo's client node: subscribes to what correct_node publishes and sets the lens.

It subscribes ``image_rect`` (receive time and latency of every frame, the newest frames),
``camera_info`` (to see D change: the first frame corrected by a new model) and
``/diagnostics`` (the node's own figures), takes one ``image_raw`` frame on request, and calls
``/<node>/set_parameters_atomically`` of ``correct_node`` and ``demo_camera``. Import it after
the graph's environment is set: Fast DDS reads its profile at the first participant.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from mechdeconv_ros.tools.demo_report import DemoError, stamp_ns, wait_for
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState

#: How many times a lens change is requested before the demo gives up (see set_lens): a CI
#: run lost three replies in a row (10 s) while the camera applied all three requests.
SET_ATTEMPTS = 6


class Monitor(Node):
    """Subscribes to the node's outputs and keeps what the demo prints and saves."""

    def __init__(self, transport: str = 'raw') -> None:
        """
        Create the subscriptions and the parameter clients.

        :param transport: what the camera publishes: ``raw`` (image_raw) or ``compressed``
            (image_raw/compressed); :meth:`grab_raw` takes a frame from there.
        """
        super().__init__('mechdeconv_demo')
        self.transport = transport
        self.lock = threading.Lock()
        self.frames: list[tuple[float, float]] = []     # (receive monotonic s, latency ms)
        self.last_rect: Image | None = None
        self._recent_rects: list[Image] = []            # the last few, for a raw's pair
        self.info_d: tuple[float, ...] | None = None
        self.d_changed_from: tuple[float, ...] | None = None
        self.d_changed_at: float | None = None          # monotonic s
        self.d_changed_stamp: int | None = None
        self.diag: dict[str, str] = {}
        self.diag_message = ''
        self.frames_in: list[tuple[float, int]] = []    # (receive monotonic s, node input)
        self.raw_wanted: list[Image | CompressedImage] = []
        self.lens_states: dict[int, dict[str, float]] = {}     # stamp ns -> joint positions
        qos = qos_profile_sensor_data
        self.create_subscription(Image, 'image_rect', self._on_rect, qos)
        self.create_subscription(CameraInfo, 'camera_info', self._on_info, qos)
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, qos)
        self.create_subscription(JointState, 'lens_state', self._on_lens_state, 10)
        self.param_clients = {
            name: self.create_client(SetParametersAtomically,
                                     f'/{name}/set_parameters_atomically')
            for name in ('correct_node', 'demo_camera')}

    def _on_rect(self, msg: Image) -> None:
        latency_ms = (self.get_clock().now().nanoseconds - stamp_ns(msg.header.stamp)) / 1e6
        with self.lock:
            self.frames.append((time.monotonic(), latency_ms))
            self.last_rect = msg
            self._recent_rects = self._recent_rects[-15:] + [msg]

    def _on_info(self, msg: CameraInfo) -> None:
        d = tuple(float(v) for v in msg.d)
        with self.lock:
            if (self.d_changed_from is not None and self.d_changed_at is None
                    and d != self.d_changed_from):
                self.d_changed_at = time.monotonic()
                self.d_changed_stamp = stamp_ns(msg.header.stamp)
            self.info_d = d

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith('correct_node: lens correction'):
                with self.lock:
                    self.diag = {kv.key: kv.value for kv in status.values}
                    self.diag_message = status.message
                    if self.diag.get('frames_in', '').isdigit():
                        self.frames_in.append((time.monotonic(), int(self.diag['frames_in'])))

    def _on_lens_state(self, msg: JointState) -> None:
        with self.lock:
            self.lens_states[stamp_ns(msg.header.stamp)] = dict(zip(msg.name, msg.position))
            if len(self.lens_states) > 512:
                for stamp in sorted(self.lens_states)[:256]:
                    del self.lens_states[stamp]

    def recent_rects(self) -> list[Image]:
        """Return the last 16 image_rect frames, oldest first."""
        with self.lock:
            return list(self._recent_rects)

    def lens_state_at(self, stamp: int) -> dict[str, float] | None:
        """Return the joint positions the camera published with a frame's stamp, if seen."""
        with self.lock:
            return self.lens_states.get(stamp)

    def _on_raw(self, msg: Image | CompressedImage) -> None:
        with self.lock:
            self.raw_wanted.append(msg)

    def watch_d(self) -> None:
        """Start watching camera_info for a D other than the current one."""
        with self.lock:
            self.d_changed_from, self.d_changed_at = self.info_d, None

    def grab_raw(self, timeout_s: float) -> Image | CompressedImage:
        """
        Subscribe to image_raw (or image_raw/compressed) until one frame arrives.

        :param timeout_s: how long to wait.
        :return: the frame.
        """
        with self.lock:
            self.raw_wanted = []
        compressed = self.transport == 'compressed'
        topic = self.resolve_topic_name('image_raw') + ('/compressed' if compressed else '')
        sub = self.create_subscription(CompressedImage if compressed else Image, topic,
                                       self._on_raw, qos_profile_sensor_data)
        try:
            wait_for(lambda: bool(self.raw_wanted), timeout_s, f'a frame on {topic}')
            with self.lock:
                return self.raw_wanted[-1]
        finally:
            self.destroy_subscription(sub)

    def window(self, start: float, end: float) -> tuple[float, list[float], float]:
        """
        Return the image_rect fps and latencies (ms) received in a window.

        Also the node's input fps over the same window, from the frames_in counter of its
        diagnostics (1 Hz, so over the whole seconds inside the window; NaN if unknown).

        :param start: monotonic s.
        :param end: monotonic s.
        :return: (fps, latencies, node input fps).
        """
        with self.lock:
            lat = [ms for t, ms in self.frames if start <= t < end]
            counts = [(t, n) for t, n in self.frames_in if start <= t <= end]
        node_fps = float('nan')
        if len(counts) >= 2 and counts[-1][0] > counts[0][0]:
            node_fps = (counts[-1][1] - counts[0][1]) / (counts[-1][0] - counts[0][0])
        return len(lat) / max(end - start, 1e-9), lat, node_fps

    def set_lens(self, node: str, values: dict[str, Any],
                 timeout_s: float) -> tuple[Any, float, float]:
        """
        Call ``/<node>/set_parameters_atomically``.

        :param node: ``correct_node`` or ``demo_camera``.
        :param values: parameter name -> value (a float, or a list of floats: a DOUBLE_ARRAY).
        :param timeout_s: how long to wait for the service and for the reply.
        :return: (SetParametersResult, request monotonic s, reply monotonic s).
        :raises DemoError: when the service is missing or does not answer (after
            :data:`SET_ATTEMPTS` requests).
        """
        client = self.param_clients[node]
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise DemoError(f'/{node}/set_parameters_atomically is not available')
        request = SetParametersAtomically.Request()
        request.parameters = [
            (Parameter(name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in value])
             if isinstance(value, (list, tuple)) else Parameter(name, value=float(value)))
            .to_parameter_msg() for name, value in values.items()]
        # A reply lost on the way was seen once in a loaded test run (the camera had applied
        # the lens, the reply never came): the same request is sent again, at most
        # SET_ATTEMPTS times within timeout_s; setting the same values twice is harmless.
        replied: list[tuple[float, Any]] = []
        sent = time.monotonic()
        for attempt in range(SET_ATTEMPTS):
            future = client.call_async(request)
            future.add_done_callback(lambda done: replied.append((time.monotonic(), done)))
            try:
                wait_for(lambda: bool(replied), timeout_s / SET_ATTEMPTS, f'the reply of /{node}')
                break
            except DemoError:
                if attempt == SET_ATTEMPTS - 1:
                    raise
        reply_time, done = replied[0]
        return done.result().result, sent, reply_time


def spin(executor: Any) -> None:
    """Spin an executor until it or its context shuts down (the demo's spin thread)."""
    from rclpy.executors import ExternalShutdownException
    try:
        executor.spin()
    except (ExternalShutdownException, KeyboardInterrupt):
        pass
    except Exception as err:    # noqa: B902 - a context shut down under the executor
        if not any(word in str(err).lower() for word in ('shutdown', 'destruction')):
            raise
