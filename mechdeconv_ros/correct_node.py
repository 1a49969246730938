# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
correct_node: live lens-distortion correction from the lens's physical description.

Topics (relative names, so namespaces and remaps apply; ``/diagnostics`` is absolute):

* subscribes ``image_raw`` (sensor_msgs/Image) -- only while an output has a subscriber,
  unless ``lazy_subscription`` is false; with ``image_transport:=compressed`` (read at
  start-up, as image_proc's) it subscribes ``image_raw/compressed``
  (sensor_msgs/CompressedImage) instead, named as image_transport names it: the RESOLVED
  ``image_raw`` plus ``/compressed``, so ``-r image_raw:=/cam/image_raw`` moves it to
  ``/cam/image_raw/compressed``. Each frame is decoded by :mod:`mechdeconv_ros.compressed`
  (JPEG/PNG, 8/16 bit, image_transport's and cv_bridge's format strings) and ``image_rect``
  is published raw, in the decoded encoding; a payload that does not decode, or names an
  encoding the node cannot produce, is refused, counted and logged (throttled);
* publishes ``image_rect`` (same encoding, the input header), ``camera_info`` (the raw camera:
  K and the equivalent D of the traced lens, R = I, P = [K_new | 0]) and ``camera_info_rect``
  (the corrected image: K = K_new, D = 0, R = I, the same P), each with the input header.
  A big-endian 16-bit or float input is published in the host's byte order (``is_bigendian``
  says which), with the same values;
* publishes ``image_rect/compressed`` (sensor_msgs/CompressedImage, the resolved
  ``image_rect`` plus ``/compressed``) only while it has a subscriber: the corrected image
  encoded as image_transport's compressed plugin does (``image_rect.compressed.format``,
  ``.jpeg_quality``, ``.png_level``); 8-bit colour and mono8/mono16 images only;
* publishes ``/diagnostics`` (DiagnosticArray, 1 Hz: :mod:`mechdeconv_ros.diagnostics`).

Wiring only: :mod:`~mechdeconv_ros.ros_params` declares the schema,
:mod:`~mechdeconv_ros.param_services` hardens the set services, and
:class:`~mechdeconv_ros.live_model.LiveModel` holds values, validation, the rebuild thread,
the atomic swap and frame-size following (its docstring: which thread touches what). The node
spins in a SingleThreadedExecutor (on 2 vCPUs the MultiThreadedExecutor's wait loop cost 640x480
output 30 -> 5 fps); the frames have their own mutually exclusive callback group.

Lazy subscription follows the outputs' publisher matched events: with the shipped Fast DDS
profile they came within 1 ms of a remote subscription's creation or removal, like the
subscriber count. An rmw without them falls back to a poll every :data:`LAZY_POLL_S`.
"""

from __future__ import annotations

import array
import signal
import sys
import threading
import time
from typing import Any

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from mechdeconv_ros.compressed import decode, encode, UnsupportedCompressedFormatError
from mechdeconv_ros.diagnostics import diagnostics_message, FrameStats
from mechdeconv_ros.graph_env import keep_large_buffers
from mechdeconv_ros.image_msgs import (
    camera_infos_from_model, Encoding, image_to_array, MalformedImageError, OutputImagePool,
    UnsupportedEncodingError)
from mechdeconv_ros.live_model import (  # noqa: F401 - MAX_SURFACES: the node's limit
    changes_of, FrameDropped, LiveModel, MAX_SURFACES)
from mechdeconv_ros.param_services import guard_parameter_services
from mechdeconv_ros.params import SCHEMA
from mechdeconv_ros.remap import Rectifier
from mechdeconv_ros.ros_params import declare_schema
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.event_handler import PublisherEventCallbacks, UnsupportedEventTypeError
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

#: Seconds between checks of the output subscriber counts, only on an rmw without matched events.
LAZY_POLL_S = 0.5
#: Seconds between diagnostics messages.
DIAGNOSTICS_PERIOD_S = 1.0
#: Minimum seconds between two log lines of the same per-frame problem.
LOG_THROTTLE_S = 5.0
#: Longest wait of the spin loop before it looks at the stop flag of SIGINT/SIGTERM, s.
STOP_POLL_S = 0.1


def sensor_qos() -> QoSProfile:
    """
    Return the default QoS of the image and camera-info topics.

    Best effort, keep last 1, volatile: a live stream wants the newest frame, never a queue of
    old ones, and a best-effort subscription matches reliable and best-effort publishers. Users
    can change history, depth and reliability per topic with the ``qos_overrides.*`` parameters.

    :return: a new profile.
    """
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


class CorrectNode(Node):
    """The lens-correction node: parameters -> lens model -> remap of every frame."""

    def __init__(self, **kwargs: Any) -> None:
        """
        Declare the parameters, validate them, create the topics and start the rebuild thread.

        :param kwargs: forwarded to :class:`rclpy.node.Node` (``context``,
            ``parameter_overrides``, ``cli_args``, ...).
        :raises ValueError: when the start-up parameters are invalid (the message names them).
        """
        self._live: LiveModel | None = None
        self._stats = FrameStats()
        self._pool = OutputImagePool()
        self._subscription: Subscription | None = None
        self._logged: dict[str, float] = {}         # kind of error -> time last logged, s
        self._channels = 1          # of the last frame: the rebuild prepares its gain map
        self._depth_gain_noted = False
        self._warned_model: Any = None
        super().__init__('correct_node', **kwargs)
        self._live = LiveModel(
            declare_schema(self, SCHEMA), extras=camera_infos_from_model, log=self._log_line,
            build_maps=self._build_maps)
        guard_parameter_services(self, self._live.start_requested_rebuild,
                                 bool(kwargs.get('allow_undeclared_parameters', False)))
        self._apply_threads()
        self._stats.image_transport = str(self._live.value('image_transport'))
        self._stats.input_topic = self.resolve_topic_name('image_raw') + (
            '/compressed' if self._stats.image_transport == 'compressed' else '')
        self._frame_group = MutuallyExclusiveCallbackGroup()
        # Probe for matched events on /diagnostics: it has no QoS override parameters, which
        # a second try at creating an output would declare twice.
        try:
            self._pub_diag = self.create_publisher(
                DiagnosticArray, '/diagnostics', 10,
                event_callbacks=PublisherEventCallbacks(matched=lambda info: None))
            events = PublisherEventCallbacks(matched=lambda info: self._update_subscription())
        except UnsupportedEventTypeError:
            self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
            events = None
        self._outputs = tuple(
            self.create_publisher(msg_type, topic, sensor_qos(), event_callbacks=events,
                                  qos_overriding_options=QoSOverridingOptions.
                                  with_default_policies())
            for msg_type, topic in ((Image, 'image_rect'), (CameraInfo, 'camera_info'),
                                    (CameraInfo, 'camera_info_rect'),
                                    (CompressedImage,
                                     self.resolve_topic_name('image_rect') + '/compressed')))
        self._pub_image, self._pub_info, self._pub_info_rect, self._pub_compressed = \
            self._outputs
        self._rebuild_trigger = self.create_guard_condition(self._live.start_requested_rebuild)
        self._live.start()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._post_set_parameters)
        self._update_subscription()
        if events is None:
            self.create_timer(LAZY_POLL_S, self._update_subscription)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        lazy = 'lazy subscription' if self._live.value('lazy_subscription') else 'subscribed'
        self.get_logger().info(f'ready: f = {self._live.startup_model.focal_length_mm:.4g} mm, '
                               f'{lazy} to {self._stats.input_topic}')

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate a set by building the candidate model; never raises."""
        try:
            self._live.validate(changes_of(parameters))
        except Exception as err:        # noqa: B902 - a callback must never raise
            return SetParametersResult(successful=False, reason=str(err) if isinstance(
                err, ValueError) else f'internal error while validating: {err!r}')
        return SetParametersResult(successful=True)

    def _post_set_parameters(self, parameters: list[Parameter]) -> None:
        """Commit an accepted set; a model change is built after the request (one per request)."""
        try:
            changed = self._live.commit(changes_of(parameters))
        except ValueError as err:       # cannot happen after on-set; never raise from here
            self.get_logger().error(f'accepted parameters do not check: {err}')
            return
        # The hardened services start it after the request; this covers other sets.
        self._rebuild_trigger.trigger()
        if 'remap_threads' in changed:
            self._apply_threads()
        if 'lazy_subscription' in changed:
            self._update_subscription()

    def _build_maps(self, model: Any) -> Rectifier:
        """
        Build the remap tables and, with ``output.vignetting_correction``, the gain map.

        Runs in the rebuild thread (or in the executor for a new frame size); the gain map is
        replicated here for the channel count of the last frame, so the first frame after
        the swap does not pay for it. A gain limit that ends the corrected field inside the
        image is logged once per model.
        """
        rectifier = Rectifier(model)
        if rectifier.gain is not None:
            rectifier.gain_for(self._channels)
            # (The allocator warm-up builds a model's maps again: warn once per model.)
            if rectifier.vignetting_warning and model is not self._warned_model:
                self._warned_model = model
                self.get_logger().warning(rectifier.vignetting_warning)
        return rectifier

    def _apply_threads(self) -> None:
        threads = int(self._live.value('remap_threads'))
        cv2.setNumThreads(threads if threads > 0 else -1)

    def _on_image(self, msg: Image) -> None:
        """Correct one frame and publish it with both CameraInfos; never raises."""
        start = time.perf_counter()
        stats = self._stats
        stats.frames_in += 1
        try:
            pixels, encoding = image_to_array(msg)
        except UnsupportedEncodingError as err:
            stats.rejected_encodings += 1
            stats.last_rejected_encoding = err.encoding
            return self._frame_error('encoding', str(err),
                                     f'{err} ({stats.rejected_encodings} frames so far)')
        except MalformedImageError as err:
            stats.frames_failed += 1
            error = f'malformed frame: {err}'
            return self._frame_error('malformed', error, f'{error} ({stats.frames_failed} so far)')
        except Exception as err:        # noqa: B902 - one bad frame must not stop the stream
            stats.frames_failed += 1
            return self._frame_error('unreadable', f'unreadable frame: {err!r}')
        self._correct(msg.header, pixels, encoding, start)

    def _on_compressed(self, msg: CompressedImage) -> None:
        """Decode one compressed frame, then correct and publish it; never raises."""
        start = time.perf_counter()
        stats = self._stats
        stats.frames_in += 1
        try:
            decoded = decode(msg.format, msg.data)
        except (UnsupportedCompressedFormatError, UnsupportedEncodingError) as err:
            stats.rejected_encodings += 1
            stats.last_rejected_encoding = err.encoding
            return self._frame_error('encoding', str(err),
                                     f'{err} ({stats.rejected_encodings} frames so far)')
        except MalformedImageError as err:      # UndecodableImageError included
            stats.frames_undecodable += 1
            error = f'undecodable frame: {err}'
            return self._frame_error('undecodable', error,
                                     f'{error} ({stats.frames_undecodable} so far)')
        except Exception as err:        # noqa: B902 - one bad frame must not stop the stream
            stats.frames_undecodable += 1
            return self._frame_error('undecodable', f'undecodable frame: {err!r}')
        stats.add_decode_time((time.perf_counter() - start) * 1e3)
        self._correct(msg.header, decoded.pixels, decoded.encoding, start)

    def _correct(self, header: Any, pixels: Any, encoding: Encoding, start: float) -> None:
        """Correct one frame's pixels and publish them with both CameraInfos; never raises."""
        stats = self._stats
        height, width = pixels.shape[:2]
        try:
            active = self._live.model_for_frame(int(width), int(height))
        except FrameDropped as drop:
            stats.frames_dropped += 1
            if not drop.repeat:
                self._frame_error(drop.kind, drop.reason, drop.log_line)
            return
        try:
            model = active.model
            out = self._pool.get(model.out_width, model.out_height, encoding.name)
            # Depth is never gain-corrected (a distance divided by RI means nothing).
            active.rectifier.correct(pixels, out.pixels, nearest=encoding.depth,
                                     gain=not encoding.depth)
            self._channels = 1 if pixels.ndim == 2 else int(pixels.shape[2])
            if encoding.depth and active.rectifier.gain is not None and \
                    not self._depth_gain_noted:
                self._depth_gain_noted = True
                self.get_logger().info(
                    f'output.vignetting_correction: {encoding.name} is a depth encoding; '
                    'depth images are remapped but never gain-corrected')
            info_raw, info_rect = active.extras
            out.msg.header = info_raw.header = info_rect.header = header
            self._pub_image.publish(out.msg)
            self._pub_info.publish(info_raw)
            self._pub_info_rect.publish(info_rect)
            if self._pub_compressed.get_subscription_count() > 0:
                self._publish_compressed(out.pixels, encoding, header)
        except Exception as err:        # noqa: B902 - one bad frame must not stop the stream
            stats.frames_failed += 1
            return self._frame_error('correction', f'correction failed: {err}')
        stats.frames_out += 1
        stats.add_time((time.perf_counter() - start) * 1e3)

    def _log_line(self, level: str, message: str) -> None:
        """
        Log a line of the live model at its level.

        One call site per level: rclpy refuses a second severity from the same line
        ("Logger severity cannot be changed between calls"), which a single
        ``getattr(logger, level)(message)`` would hit on the first warning after an info.
        """
        logger = self.get_logger()
        if level == 'error':
            logger.error(message)
        elif level == 'warning':
            logger.warning(message)
        else:
            logger.info(message)

    def _publish_compressed(self, pixels: Any, encoding: Encoding, header: Any) -> None:
        """Publish the corrected pixels on image_rect/compressed; log what cannot be encoded."""
        live = self._live
        try:
            fmt, data = encode(
                pixels, encoding.name, str(live.value('image_rect.compressed.format')),
                jpeg_quality=int(live.value('image_rect.compressed.jpeg_quality')),
                png_level=int(live.value('image_rect.compressed.png_level')))
        except Exception as err:        # noqa: B902 - e.g. 32FC1; image_rect is out already
            return self._frame_error('compressed output',
                                     f'image_rect/compressed not published: {err}')
        msg = CompressedImage(format=fmt)
        msg.header = header
        msg.data = array.array('B', data)
        self._pub_compressed.publish(msg)
        self._stats.frames_out_compressed += 1

    def _frame_error(self, kind: str, error: str, line: str = '') -> None:
        """Record a problem for diagnostics; log it at most every LOG_THROTTLE_S per kind."""
        # (rclpy's throttle_duration_sec is per call site: one site would mute other kinds.)
        self._stats.last_error = error
        now = time.monotonic()
        if now - self._logged.get(kind, -LOG_THROTTLE_S) >= LOG_THROTTLE_S:
            self._logged[kind] = now
            self.get_logger().error(line or error)

    def _update_subscription(self) -> None:
        """Subscribe to image_raw while it is needed (lazy), unsubscribe when it is not."""
        lazy = bool(self._live.value('lazy_subscription'))
        wanted = not lazy or any(pub.get_subscription_count() > 0 for pub in self._outputs)
        if wanted and self._subscription is None:
            topic = self._stats.input_topic
            compressed = self._stats.image_transport == 'compressed'
            try:
                self._subscription = self.create_subscription(
                    CompressedImage if compressed else Image, topic,
                    self._on_compressed if compressed else self._on_image, sensor_qos(),
                    callback_group=self._frame_group,
                    qos_overriding_options=QoSOverridingOptions.with_default_policies())
            except Exception as err:    # noqa: B902 - e.g. a bad qos_overrides value
                return self._frame_error('subscribe', f'cannot subscribe to {topic}: {err}')
            self.get_logger().debug(f'subscribed to {topic}')
        elif not wanted and self._subscription is not None:
            self.destroy_subscription(self._subscription)
            self._subscription = None
            self.get_logger().debug('no subscriber on the outputs: unsubscribed from image_raw')

    def _publish_diagnostics(self) -> None:
        try:
            self._pub_diag.publish(diagnostics_message(
                self, self._live.status(), self._stats, self._subscription is not None))
        except Exception as err:        # noqa: B902 - diagnostics must not stop the node
            self.get_logger().error(f'diagnostics failed: {err!r}',
                                    throttle_duration_sec=LOG_THROTTLE_S)

    def destroy_node(self) -> None:
        """Stop the rebuild thread, then destroy the node."""
        if self._live is not None:
            self._live.stop()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """
    Run the node until SIGINT/SIGTERM (exit code 0), or exit 1 on invalid parameters.

    SIGINT and SIGTERM only set a flag that the spin loop checks between callbacks: rclpy's
    KeyboardInterrupt, raised while a received image is converted to Python, becomes a
    RuntimeError, so Ctrl-C (or ``ros2 launch`` stopping the node) ended with a traceback and
    exit code 1. A second SIGINT is ignored: Ctrl-C on ``ros2 launch`` reaches the node from the
    terminal, and launch forwards one more (always when ``--noninteractive``), which used to
    interrupt the shutdown with a KeyboardInterrupt (exit code -2). Should shutdown hang, a third
    SIGINT, or a SIGTERM after the first signal (launch sends one after its timeout), stops the
    process the default way.

    :param args: command-line arguments for rclpy (``--ros-args ...``); default ``sys.argv``.
    """
    keep_large_buffers()
    stop = threading.Event()

    def request_stop(signum: int, frame: Any) -> None:
        stop.set()
        signal.signal(signal.SIGINT, ignore_once)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)

    def ignore_once(signum: int, frame: Any) -> None:
        signal.signal(signal.SIGINT, signal.default_int_handler)

    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous = {sig: signal.signal(sig, request_stop)
                    for sig in (signal.SIGINT, signal.SIGTERM)}
    node: CorrectNode | None = None
    failed = False
    try:
        node = CorrectNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not stop.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=STOP_POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as err:           # invalid start-up parameters (incl. ModelError)
        rclpy.logging.get_logger('correct_node').fatal(str(err))
        failed = True
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if failed:
        sys.exit(1)


if __name__ == '__main__':
    main()
