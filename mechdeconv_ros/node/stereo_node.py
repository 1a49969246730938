# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
stereo_node: a rectified stereo pair from two lenses' descriptions and the rig, no checkerboard.

Topics: :mod:`~mechdeconv_ros.node.stereo_io` (in ``left/image_raw``, ``right/image_raw``, raw
or compressed; out both ``image_rect``, ``camera_info`` and ``camera_info_rect``,
``/diagnostics``). Parameters: :data:`~mechdeconv_ros.schema.stereo_params.STEREO_SCHEMA`
(``left.*``, ``right.*``, ``rig.*``, ``output.*``, ``sync.slop_s``, ``stereo_check.*``),
declared with descriptors, set through the hardened services
(:mod:`~mechdeconv_ros.node.param_services`).

Wiring only: :class:`~mechdeconv_ros.runtime.stereo_live.StereoLive` validates a set by
building the candidate pair (a refusal names the parameter and changes nothing), rebuilds both
maps in its thread and swaps one immutable record;
:class:`~mechdeconv_ros.runtime.stereo_sync.StampPairer` pairs the frames by stamp within
``sync.slop_s``; :class:`~mechdeconv_ros.node.stereo_check_thread.StereoCheckThread` measures
the rig at idle time.

Frame path (executor thread; one callback group for both inputs, so the pairing is serial):
a frame is only queued until its partner comes; the frame that completes a pair runs, in
order: both messages read (compressed ones decoded, Bayer demosaiced), ONE read of the active
pair record (``StereoLive.active``: model, rectifier, CameraInfos; everything after uses it
only, so no published pair mixes two models), both images rectified into pooled output
messages, ``left/image_rect`` and ``right/image_rect`` published with their own inputs'
headers, then the four CameraInfos (restamped with their side's header), then the offer to the
check (references, at most ``stereo_check.rate_hz``). While a check is in its child process,
the child is stopped from before the remap to after the CameraInfos (SIGSTOP, SIGCONT).
"""

from __future__ import annotations

import time
from typing import Any, Callable

from mechdeconv_ros.imaging.debayer import Demosaicer
from mechdeconv_ros.imaging.remap import set_remap_threads
from mechdeconv_ros.model.lateral_color import COLOUR_ORDER
from mechdeconv_ros.node.diagnostics import FrameStats
from mechdeconv_ros.node.frame_input import demosaic_frame, FrameRefused
from mechdeconv_ros.node.image_msgs import OutputImagePool
from mechdeconv_ros.node.node_main import log_function, run_node
from mechdeconv_ros.node.param_services import guard_parameter_services, validation_result
from mechdeconv_ros.node.ros_params import declare_schema
from mechdeconv_ros.node.stereo_check_thread import StereoCheckThread
from mechdeconv_ros.node.stereo_io import (
    create_stereo_outputs, info_messages, stereo_diagnostics, subscribe_side)
from mechdeconv_ros.runtime.live_model import changes_of
from mechdeconv_ros.runtime.stereo_live import StereoLive
from mechdeconv_ros.runtime.stereo_sync import SIDES, StampPairer
from mechdeconv_ros.schema.stereo_params import STEREO_SCHEMA
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter

#: Seconds between diagnostics messages.
DIAGNOSTICS_PERIOD_S = 1.0
#: Minimum seconds between two log lines of the same per-frame problem.
LOG_THROTTLE_S = 5.0


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


class StereoNode(Node):
    """The stereo rectification node (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        """
        Declare the parameters, build the start-up pair, create the topics, start the threads.

        :param kwargs: forwarded to :class:`rclpy.node.Node`.
        :raises ValueError: when the start-up parameters are refused (naming the parameter).
        """
        self._live: StereoLive | None = None
        self._check: StereoCheckThread | None = None
        super().__init__('stereo_node', **kwargs)
        self._stats = FrameStats()
        self._pairer = StampPairer()
        self._pools = {side: OutputImagePool() for side in SIDES}
        self._demosaicers = {side: Demosaicer() for side in SIDES}
        values = declare_schema(self, STEREO_SCHEMA)
        try:
            self._live = StereoLive(values, info_messages, log_function(self))
        except ValueError as err:
            raise empty_size_hint(err) from None
        self._slop_ns = round(float(self._live.value('sync.slop_s')) * 1e9)
        guard_parameter_services(self, lambda: None,
                                 bool(kwargs.get('allow_undeclared_parameters', False)))
        set_remap_threads(int(self._live.value('left.remap_threads')))
        self._pub_diag, self._pub_images, self._pub_infos = create_stereo_outputs(self)
        self._check_entries: dict[str, Any] = {}
        self._check = StereoCheckThread(self, self._live.value,
                                        lambda e: setattr(self, '_check_entries', e))
        group = MutuallyExclusiveCallbackGroup()
        self._inputs = {side: subscribe_side(self, side, str(self._live.value(
            f'{side}.image_transport')), group, self._on_frame) for side in SIDES}
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._post_set_parameters)
        self._live.start()
        self._check.start()
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        stereo = self._live.active.stereo
        self.get_logger().info(
            f"ready: {stereo.width}x{stereo.height} rectified, f' = "
            f'{stereo.K_rect[0, 0]:.1f} px, B = {stereo.baseline_m * 1e3:.2f} mm; subscribed '
            f"to {self._inputs['left'][1]} and {self._inputs['right'][1]}")

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate a set by building the candidate pair; never raises."""
        return validation_result(self._live.validate, changes_of(parameters))

    def _post_set_parameters(self, parameters: list[Parameter]) -> None:
        """Commit an accepted set (the rebuild thread wakes for a model change)."""
        changes = changes_of(parameters)
        try:
            changed = self._live.commit(changes)
        except ValueError as err:       # cannot happen after on-set; never raise from here
            self.get_logger().error(f'accepted parameters do not check: {err}')
            return
        self._check.user_set(changes)
        if 'sync.slop_s' in changed:
            self._slop_ns = round(float(self._live.value('sync.slop_s')) * 1e9)
        if 'stereo_check.rate_hz' in changed:
            self._check.settings_changed()
        if 'left.remap_threads' in changed:
            set_remap_threads(int(self._live.value('left.remap_threads')))

    def _on_frame(self, side: str, msg: Any, read: Callable[[Any, FrameStats], Any]) -> None:
        """Queue a frame; rectify and publish the pair it completes (module docstring)."""
        start = time.perf_counter()
        self._stats.frames_in += 1
        pair = self._pairer.push(side, _stamp_ns(msg), (msg, read), self._slop_ns)
        if pair is None:
            return
        try:
            frames = [self._read(side, *frame) for side, frame in zip(SIDES, pair)]
        except FrameRefused as refused:
            return self._frame_error(refused.kind, refused.error, refused.line)
        self._rectify_and_publish(frames, start)

    def _read(self, side: str, msg: Any, read: Callable[[Any, FrameStats], Any]
              ) -> tuple[Any, Any, Any, bool]:
        pixels, encoding = read(msg, self._stats)
        demosaiced = bool(encoding.bayer)
        if demosaiced:
            pixels, encoding, _ = demosaic_frame(pixels, encoding, self._demosaicers[side],
                                                 str(self._live.value(f'{side}.debayer')),
                                                 self._stats)
        # A demosaiced frame lives in a buffer the next frame reuses: the check gets a copy.
        return msg.header, pixels, encoding, demosaiced

    def _rectify_and_publish(self, frames: list[tuple[Any, Any, Any, bool]],
                             start: float) -> None:
        """Rectify one pair with ONE pair record and publish it; never raises."""
        active = self._live.active      # the one read: everything below uses this record
        stats = self._stats
        try:
            (h_l, left, enc_l, reused_l), (h_r, right, enc_r, reused_r) = frames
            out_l = self._pools['left'].get(active.stereo.width, active.stereo.height,
                                            enc_l.name)
            out_r = self._pools['right'].get(active.stereo.width, active.stereo.height,
                                             enc_r.name)
            colours = COLOUR_ORDER.get(enc_l.name) if enc_l.name == enc_r.name else None
            self._check.hold()          # the check's child waits while a pair is made
            active.rectifier.rectify(left, right, colours=colours,
                                     dst=(out_l.pixels, out_r.pixels))
            out_l.msg.header, out_r.msg.header = h_l, h_r
            self._pub_images['left'].publish(out_l.msg)
            self._pub_images['right'].publish(out_r.msg)
            for key, info in active.extras.items():
                info.header = h_l if key.startswith('left') else h_r
                self._pub_infos[key].publish(info)
            self._check.release()
            self._check.offer(left, right, active, copy=(reused_l, reused_r))
        except ValueError as err:       # a frame size that is not its camera's
            self._check.release()
            stats.frames_dropped += 1
            return self._frame_error('size', f'pair dropped: {err}')
        except Exception as err:        # noqa: B902 - one bad pair must not stop the stream
            self._check.release()
            stats.frames_failed += 1
            return self._frame_error('rectification', f'rectification failed: {err!r}')
        stats.frames_out += 1
        stats.add_time((time.perf_counter() - start) * 1e3)

    def _frame_error(self, kind: str, error: str, line: str = '') -> None:
        """Record a problem for diagnostics; log it at most every LOG_THROTTLE_S per kind."""
        if self._stats.record_error(kind, error, LOG_THROTTLE_S):
            self.get_logger().error(line or error)

    def _publish_diagnostics(self) -> None:
        try:
            self._pub_diag.publish(stereo_diagnostics(
                self, self._live.status(), self._stats, self._pairer, self._check_entries))
        except Exception as err:        # noqa: B902 - diagnostics must not stop the node
            self.get_logger().error(f'diagnostics failed: {err!r}',
                                    throttle_duration_sec=LOG_THROTTLE_S)

    def destroy_node(self) -> None:
        """Stop the check and rebuild threads, then destroy the node."""
        for worker in (self._check, self._live):     # None: start-up failed
            if worker is not None:
                worker.stop()
        super().destroy_node()


def empty_size_hint(err: ValueError) -> ValueError:
    """
    Return the start-up refusal, with what to do when it is an empty sensor size.

    The single camera's "feed images" does not apply here: stereo_node builds the pair at
    start-up and does not follow the images' size. Both sizes 0 is what the node sees when
    its params file never reached it: rcl gives a ``stereo_node:`` section only to the node
    in the root namespace (``ros2 launch ... namespace:=x`` then passes nothing, silently).

    :param err: the refusal (a ParameterError names its parameter).
    :return: ``err``, or a ValueError naming the same parameter with the hint.
    """
    parameter = str(getattr(err, 'parameter', ''))
    if not parameter.endswith('sensor.width_px') or 'is empty' not in str(err):
        return err
    return ValueError(
        f'{parameter}: the sensor size is empty and stereo_node does not follow the images; '
        'set left.sensor.width_px, left.sensor.height_px and the right ones. If your params '
        'file sets them, it did not reach this node: key it "/**/stereo_node:" (any '
        'namespace) or "/**:", not "stereo_node:" (the root namespace only)')


def main(args: list[str] | None = None) -> None:
    """
    Run the node until SIGINT/SIGTERM (exit 0), or exit 1 on refused start-up parameters.

    :param args: command-line arguments for rclpy (``--ros-args ...``); default ``sys.argv``.
    """
    run_node(StereoNode, 'stereo_node', args)


if __name__ == '__main__':
    main()
