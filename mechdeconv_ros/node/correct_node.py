# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
correct_node: live lens-distortion correction from the lens's physical description.

Topics (relative names: namespaces and remaps apply; ``/diagnostics`` is absolute): in,
``image_raw`` (sensor_msgs/Image) or, with ``image_transport:=compressed`` (read at start-up,
as image_proc's), the RESOLVED ``image_raw`` + ``/compressed`` (sensor_msgs/CompressedImage,
decoded by :mod:`~mechdeconv_ros.node.frame_input`), subscribed only while an output has a
subscriber unless ``lazy_subscription`` is false; out, ``image_rect`` (the input's encoding and
header; Bayer input is demosaiced first, by ``debayer``, and published as rgb8 / rgb16),
``camera_info`` (raw K and the equivalent D), ``camera_info_rect`` (K_new, D = 0),
``image_rect/compressed`` (only while subscribed) and ``/diagnostics`` (1 Hz,
:mod:`~mechdeconv_ros.node.diagnostics`). README "Node API" has the details.

Wiring only: :mod:`~mechdeconv_ros.node.ros_params` declares the schema,
:mod:`~mechdeconv_ros.node.param_services` hardens the set services,
:class:`~mechdeconv_ros.runtime.live_model.LiveModel` holds values, validation, the rebuild
thread, the atomic swap and frame-size following (its docstring: which thread touches what),
:class:`~mechdeconv_ros.imaging.model_maps.ModelMaps` decides how each model's maps are built
(static, moving, colour, gain) and what is logged about them, :mod:`~mechdeconv_ros.node.topics`
creates the outputs and the lazy input subscription (polled every :data:`LAZY_POLL_S` on an rmw
without matched events), :mod:`~mechdeconv_ros.node.check_thread` checks a copy of a frame
for straight edges (at most ``check.rate_hz``), and :mod:`~mechdeconv_ros.node.node_main` runs
it until a signal. A SingleThreadedExecutor (on 2 vCPUs the MultiThreadedExecutor's wait loop
cost 640x480 output 30 -> 5 fps); the frames have their own mutually exclusive callback group.

Frame path (``image_raw`` or its ``/compressed`` -> ``_on_frame`` -> ``_correct``; executor
thread only, one frame at a time), in order, with the stage names of the stage clock
(:mod:`~mechdeconv_ros.node.stage_clock`, ``MECHDECONV_STAGE_TIMES``; ``make bench`` times each):

1. ``read``: the message's pixels as a numpy view (:mod:`~mechdeconv_ros.node.frame_input`; a
   compressed frame is decoded here). New input kinds (e.g. Bayer) add their conversion here.
2. ``model``: ONE read of the active model (``LiveModel.model_for_frame``: the reference, or
   a synchronous build for a new frame size) and the output message from the pool. Everything
   after this uses that record only, so a frame never mixes two models; per-frame state that
   depends on the model (zoom, colour planes) belongs in the record, built by the rebuild
   thread, not computed here.
3. ``remap``: ``Rectifier.correct`` into the output message's buffer (and the vignetting gain).
4. ``publish_image``: ``image_rect`` with the input's header; everything after it is off the
   image's latency.
5. ``publish_info`` / ``publish_info_rect``: the model's prebuilt CameraInfos, restamped.
6. ``bookkeeping``: the channel hint for the rebuild thread, counters and frame time.
7. ``compressed``: only while ``image_rect/compressed`` has a subscriber.

State on the frame path and its owner: the counters (``_stats``), the output pool, the
channel hint, the cached ``image_rect.compressed.*`` settings (refreshed by the post-set
callback, same thread) and whether the compressed output has a subscriber (refreshed on the
outputs' matched events, same thread) belong to the executor thread; the active model record
and its CameraInfos are built by the rebuild thread and read here through one reference.
"""

from __future__ import annotations

import time
from typing import Any, Callable

from mechdeconv_ros.imaging.debayer import Demosaicer
from mechdeconv_ros.imaging.model_maps import ModelMaps
from mechdeconv_ros.imaging.moving_maps import MovingRectifier
from mechdeconv_ros.imaging.remap import set_remap_threads
from mechdeconv_ros.model.lateral_color import COLOUR_ORDER
from mechdeconv_ros.node.check_thread import CheckThread
from mechdeconv_ros.node.diagnostics import FrameStats, publish_diagnostics
from mechdeconv_ros.node.frame_input import (
    compressed_output, COMPRESSED_PARAMS, compressed_settings, demosaic_frame, FrameRefused)
from mechdeconv_ros.node.image_msgs import camera_infos_from_model, Encoding, OutputImagePool
from mechdeconv_ros.node.lens_follower import LensFollower
from mechdeconv_ros.node.node_main import log_function, run_node
from mechdeconv_ros.node.param_services import guard_parameter_services, validation_result
from mechdeconv_ros.node.ros_params import declare_schema
from mechdeconv_ros.node.stage_clock import stage_clock_from_env, StageClock
from mechdeconv_ros.node.topics import create_outputs, LazyInput
from mechdeconv_ros.runtime.live_model import (  # noqa: F401 - MAX_SURFACES: the node's limit
    changes_of, FrameDropped, LiveModel, MAX_SURFACES)
from mechdeconv_ros.schema.params import SCHEMA
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter

#: Seconds between checks of the output subscriber counts, only on an rmw without matched events.
LAZY_POLL_S = 0.5
#: Seconds between diagnostics messages.
DIAGNOSTICS_PERIOD_S = 1.0
#: Minimum seconds between two log lines of the same per-frame problem.
LOG_THROTTLE_S = 5.0


class CorrectNode(Node):
    """The lens-correction node: parameters -> lens model -> remap of every frame."""

    def __init__(self, **kwargs: Any) -> None:
        """
        Declare the parameters, validate them, create the topics and start the rebuild thread.

        :param kwargs: forwarded to :class:`rclpy.node.Node` (``context``, ``cli_args``, ...).
        :raises ValueError: when the start-up parameters are invalid (the message names them).
        """
        self._live: LiveModel | None = None
        self._stats = FrameStats()
        self._pool = OutputImagePool()
        self._demosaicer = Demosaicer()     # Bayer input (issue #20)
        self._compressed_wanted = False     # image_rect/compressed has a subscriber
        self._stage_clock = stage_clock_from_env()    # None unless MECHDECONV_STAGE_TIMES is set
        super().__init__('correct_node', **kwargs)
        self._maps = ModelMaps(log_function(self))    # how each model's maps are built
        self._live = LiveModel(
            declare_schema(self, SCHEMA), extras=camera_infos_from_model, log=log_function(self),
            build_maps=self._maps.build)
        self._follower = LensFollower(self, self._stats)    # issue 19: lens_state (JointState)
        self._follower.configure(self._live.values())
        guard_parameter_services(self, self._live.start_requested_rebuild,
                                 bool(kwargs.get('allow_undeclared_parameters', False)))
        set_remap_threads(int(self._live.value('remap_threads')))
        self._compressed_settings = compressed_settings(self._live.value)
        self._debayer = str(self._live.value('debayer'))    # read on set, not per frame
        self._stats.image_transport = str(self._live.value('image_transport'))
        self._check = CheckThread(self, self._live, self._stats.extra, log_function(self))
        self._input = LazyInput(self, self._stats.image_transport,
                                self._check.holding(self._on_frame),    # issue 36
                                MutuallyExclusiveCallbackGroup(), self._frame_error)
        self._stats.input_topic = self._input.topic
        self._pub_diag, self._outputs, events = create_outputs(self, self._update_subscription)
        self._pub_image, self._pub_info, self._pub_info_rect, self._pub_compressed = \
            self._outputs
        self._check.start()     # its apply is set on this executor (check_thread.py)
        self._rebuild_trigger = self.create_guard_condition(self._live.start_requested_rebuild)
        self._live.start()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._post_set_parameters)
        self._update_subscription()
        if not events:
            self.create_timer(LAZY_POLL_S, self._update_subscription)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        lazy = 'lazy subscription' if self._live.value('lazy_subscription') else 'subscribed'
        self.get_logger().info(f'ready: f = {self._live.startup_model.focal_length_mm:.4g} mm, '
                               f'{lazy} to {self._stats.input_topic}')

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate a set by building the candidate model; never raises."""
        return validation_result(self._live.validate, changes_of(parameters))

    def _post_set_parameters(self, parameters: list[Parameter]) -> None:
        """Commit an accepted set; a model change is built after the request (one per request)."""
        try:
            changed = self._live.commit(changes_of(parameters))
        except ValueError as err:       # cannot happen after on-set; never raise from here
            self.get_logger().error(f'accepted parameters do not check: {err}')
            return
        # The hardened services start it after the request; this covers other sets.
        self._rebuild_trigger.trigger()
        self._check.user_set(changes_of(parameters))    # moves check.apply's bounds
        if 'remap_threads' in changed:
            set_remap_threads(int(self._live.value('remap_threads')))
        if 'lazy_subscription' in changed:
            self._update_subscription()
        if any(name.startswith(('lens.zoom.', 'lens.focus.')) for name in changed):
            self._follower.configure(self._live.values())
        if changed & set(COMPRESSED_PARAMS):
            self._compressed_settings = compressed_settings(self._live.value)
        if 'debayer' in changed:
            self._debayer = str(self._live.value('debayer'))

    def _publish_diagnostics(self) -> None:
        """Publish /diagnostics (timer), the check's entries as of now (their age)."""
        self._stats.check = self._check.entries()
        publish_diagnostics(self, self._pub_diag, self._live, self._stats,
                            lambda: self._input.subscription is not None, LOG_THROTTLE_S)

    def _on_frame(self, msg: Any, read: Callable[[Any, FrameStats], Any]) -> None:
        """
        Run the frame path of a message (executor thread only; module docstring, "Frame path").

        The input subscription (:class:`~mechdeconv_ros.node.topics.LazyInput`) calls it with
        the message's reader (a compressed frame is decoded there); it never raises.

        Each ``clock`` test is one ``is None`` when the stage clock is off (the default).
        """
        start = time.perf_counter()
        clock = self._stage_clock
        if clock is not None:
            clock.start(msg.header.stamp)
        self._stats.frames_in += 1
        try:
            pixels, encoding = read(msg, self._stats)
            # --- Bayer input (issue #20): demosaic, then correct as rgb8 / rgb16 ---
            if encoding.bayer:
                pixels, encoding, note = demosaic_frame(
                    pixels, encoding, self._demosaicer, self._debayer, self._stats)
                if note:
                    self.get_logger().info(note)
        except FrameRefused as refused:
            return self._frame_error(refused.kind, refused.error, refused.line)
        if clock is not None:
            clock.mark('read')
        self._correct(msg.header, pixels, encoding, start, clock)
        if clock is not None:
            clock.end()

    def _correct(self, header: Any, pixels: Any, encoding: Encoding, start: float,
                 clock: StageClock | None) -> None:
        """Correct one frame's pixels and publish them with both CameraInfos; never raises."""
        stats = self._stats
        height, width = pixels.shape[:2]
        try:
            # ONE read of the active model: everything below uses this record only.
            active = self._live.model_for_frame(int(width), int(height))
        except FrameDropped as drop:
            stats.frames_dropped += 1
            if not drop.repeat:
                self._frame_error(drop.kind, drop.reason, drop.log_line)
            return
        try:
            model = active.model
            out = self._pool.get(model.out_width, model.out_height, encoding.name)
            infos = active.extras
            if isinstance(active.rectifier, MovingRectifier):
                # Issue 19: the map, K, D and P of the lens state at this frame's stamp.
                infos = self._follower.prepare(header, active.rectifier)
            if clock is not None:
                clock.mark('model')
            # Depth is never gain-corrected (a distance divided by RI means nothing).
            colours = COLOUR_ORDER.get(encoding.name)
            active.rectifier.correct(pixels, out.pixels, nearest=encoding.depth,
                                     gain=not encoding.depth, colours=colours)
            if clock is not None:
                clock.mark('remap')
            # The image first: what comes after it is off the image's latency.
            out.msg.header = header
            self._pub_image.publish(out.msg)
            if clock is not None:
                clock.mark('publish_image')
            info_raw, info_rect = infos
            info_raw.header = header
            self._pub_info.publish(info_raw)
            if clock is not None:
                clock.mark('publish_info')
            info_rect.header = header
            self._pub_info_rect.publish(info_rect)
            if clock is not None:
                clock.mark('publish_info_rect')
            if not isinstance(active.rectifier, MovingRectifier):
                self._check.offer(out.pixels, model)    # a copy, at most check.rate_hz
            self._maps.frame_done(active.rectifier, encoding.name,
                                  1 if pixels.ndim == 2 else int(pixels.shape[2]), colours,
                                  bool(encoding.depth))
            if clock is not None:
                clock.mark('bookkeeping')
            if self._compressed_wanted:
                self._pub_compressed.publish(compressed_output(
                    out.pixels, encoding, header, self._compressed_settings))
                stats.frames_out_compressed += 1
                if clock is not None:
                    clock.mark('compressed')
        except FrameRefused as refused:     # the compressed output only: image_rect is out
            self._frame_error(refused.kind, refused.error)
        except Exception as err:        # noqa: B902 - one bad frame must not stop the stream
            stats.frames_failed += 1
            return self._frame_error('correction', f'correction failed: {err}')
        stats.frames_out += 1
        stats.add_time((time.perf_counter() - start) * 1e3)
        if clock is not None:
            clock.mark('bookkeeping')

    def _frame_error(self, kind: str, error: str, line: str = '') -> None:
        """Record a problem for diagnostics; log it at most every LOG_THROTTLE_S per kind."""
        if self._stats.record_error(kind, error, LOG_THROTTLE_S):
            self.get_logger().error(line or error)

    def _update_subscription(self) -> None:
        """Subscribe to image_raw while it is needed (lazy), unsubscribe when it is not."""
        self._compressed_wanted = self._pub_compressed.get_subscription_count() > 0
        self._input.update(bool(self._live.value('lazy_subscription')), self._outputs)

    def destroy_node(self) -> None:
        """Stop the check and rebuild threads, then destroy the node."""
        for worker in filter(None, (getattr(self, '_check', None), self._live)):  # None: failed
            worker.stop()
        if self._stage_clock is not None:
            self._stage_clock.dump()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """
    Run the node until SIGINT/SIGTERM (exit 0), or exit 1 on invalid start-up parameters.

    :param args: command-line arguments for rclpy (``--ros-args ...``); default ``sys.argv``.
    """
    run_node(CorrectNode, 'correct_node', args)


if __name__ == '__main__':
    main()
