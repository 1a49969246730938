# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
correct_node's lens_state input: JointState in, each frame's lens state and CameraInfos out.

While ``lens.zoom.joint`` or ``lens.focus.joint`` is set the node subscribes to ``lens_state``
(sensor_msgs/JointState, a relative name: remap it to ``/joint_states`` or a driver's topic; best
effort, depth 100, which matches reliable and best-effort publishers) and keeps the recent
positions (:class:`~mechdeconv_ros.imaging.lens_state.LensStateHistory`). For each frame
:meth:`LensFollower.prepare` first takes every lens_state message waiting (the executor alone would
fall behind a fast joint stream while frames keep it busy), then the state at the frame's header
stamp, clamps it into the tables (a throttled warning), makes the moving rectifier use that state's
map (:class:`~mechdeconv_ros.imaging.moving_maps.MovingRectifier`) and fills the frame's two
CameraInfos with that state's K, D and P. ``/diagnostics`` gets ``lens_state.<mechanism>`` (the
position a frame was last corrected with), ``lens_state_lag_ms`` (frame stamp minus the newest
state's; > 0: the frame is newer than every state), ``lens_states_received``,
``lens_states_ignored`` (no followed joint, or NaN) and ``lens_states_last_ignored``,
``lens_state_clamped_frames``, ``lens_state_missing_frames`` (frames corrected at a table's
first row because its joint has sent no state yet, warned, throttled) and the grid's size
(``lens_grid_states``, ``lens_grid_memory_mb``).

Time: a JointState stamped 0 is placed at its ARRIVAL, rmw's received timestamp (the message
info of :meth:`_on_joint_state` and of a drained take), carried onto the node's clock (sim time
included) as ``now - (system_now - received)``: messages queued under load keep distinct times.
A jump back of the node's clock (``/clock`` reset, a bag loop, a simulator restart) clears the
history (:meth:`~mechdeconv_ros.imaging.lens_state.LensStateHistory.time_jumped_back`), logged
once per jump and counted as ``lens_state_time_jumps``. An error while handling one drained
message is counted (``lens_states_failed``, ``lens_states_last_failure``) and the drain goes on.
Executor thread only.
"""

from __future__ import annotations

from dataclasses import dataclass
import time
from typing import Any, Callable, Mapping

from mechdeconv_ros.imaging.lens_state import LensStateHistory
from mechdeconv_ros.imaging.moving_maps import MovingRectifier, StateCamera
from mechdeconv_ros.node.diagnostics import FrameStats
from mechdeconv_ros.node.image_msgs import fill_camera_info
from mechdeconv_ros.schema.params import MECHANISMS
from rclpy.clock import JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, JointState

#: Seconds between two warnings about a state outside the tables.
CLAMP_WARN_S = 5.0
#: Most lens_state messages a frame takes from the queue before it looks up its state.
DRAIN_LIMIT = 1000


@dataclass(frozen=True)
class _CameraView:
    """What :func:`fill_camera_info` reads of a model, for one lens state."""

    width: int
    height: int
    out_width: int
    out_height: int
    projection: str
    K: Any
    K_new: Any
    D: tuple[float, ...]
    distortion_model: str
    P: Any


def joints_of(values: Mapping[str, Any]) -> dict[str, str]:
    """Return mechanism -> joint name of the mechanisms that move (``lens.m.joint`` set)."""
    return {m: str(values.get(f'lens.{m}.joint', '')) for m in MECHANISMS
            if values.get(f'lens.{m}.joint')}


class LensFollower:
    """The lens_state subscription and the per-frame lens state (module doc)."""

    def __init__(self, node: Node, stats: FrameStats,
                 warn: Callable[[str], None] | None = None) -> None:
        """
        Follow nothing yet; :meth:`configure` subscribes.

        :param node: the node.
        :param stats: the frame counters (``extra`` receives the diagnostics entries).
        :param warn: logs a warning line (default the node's logger).
        """
        self._node = node
        self._stats = stats
        self._warn = warn or node.get_logger().warning
        self._subscription: Any = None
        self.history: LensStateHistory | None = None
        self._infos = (CameraInfo(), CameraInfo())
        self._warned_at = -CLAMP_WARN_S
        self.clamped_frames = 0
        self._missing_warned_at = -CLAMP_WARN_S
        self.missing_frames = 0
        self.failed = 0
        self.last_failure = ''
        # tf2's buffer clears on any jump back of its clock; so does the history.
        self._jump_handle = node.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=False),
            post_callback=self._on_time_jump)

    def configure(self, values: Mapping[str, Any]) -> None:
        """Subscribe while a joint is set; a change of joint names starts a new history."""
        joints = joints_of(values)
        if self.history is not None and self.history.joints == joints:
            return
        if self._subscription is not None:
            self._node.destroy_subscription(self._subscription)
            self._subscription = None
        self.history = LensStateHistory(joints) if joints else None
        if joints:
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                             reliability=ReliabilityPolicy.BEST_EFFORT)
            self._subscription = self._node.create_subscription(
                JointState, 'lens_state', self._on_joint_state, qos)
        self._publish_stats({})

    def drain(self, limit: int = DRAIN_LIMIT) -> int:
        """
        Take every lens_state message waiting in the subscription's queue, now.

        The executor takes one message per entity per wait, so a node busy with frames (each
        a wait of its own) falls behind a 100 Hz JointState stream: measured at 1080p on a
        loaded 2-vCPU VM, frames were corrected with states a second old. Before a frame
        looks up its state, the queue is emptied here, as rclpy's executor takes a message
        (``handle.take_message``).

        :param limit: most messages taken.
        :return: the number taken.
        """
        sub = self._subscription
        taken = 0
        if sub is None:
            return 0
        take = getattr(sub.handle, 'take_message', None)
        if take is None:        # an rclpy without it: the executor delivers them
            return 0
        try:
            with sub.handle:
                while taken < limit:
                    got = take(sub.msg_type, sub.raw)
                    if got is None:
                        break
                    taken += 1
                    try:
                        self._on_joint_state(*got)
                    except Exception as err:    # noqa: B902 - one bad message, not the rest
                        self.failed += 1
                        self.last_failure = repr(err)
                        self._publish_stats(None)
        except InvalidHandle:   # the subscription was destroyed (a reconfigure)
            pass
        return taken

    def _on_joint_state(self, msg: JointState, info: Mapping[str, Any]) -> None:
        # Two parameters: rclpy then passes the message info (its received timestamp).
        history = self.history
        if history is None:
            return
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        now = self._node.get_clock().now().nanoseconds
        received = now
        if not stamp and info and info.get('received_timestamp'):
            # rmw's received time is the system clock's: carry its age onto the node's clock.
            age = max(0, time.time_ns() - int(info['received_timestamp']))
            received = now - age
        jumps = history.time_jumps
        history.add(stamp, list(msg.name), list(msg.position), received_ns=received)
        if history.time_jumps != jumps:
            self._warn_jump(history)
        self._publish_stats(None)

    def _warn_jump(self, history: LensStateHistory) -> None:
        self._warn(f'lens_state: time went back ({history.last_jump}); the lens state history '
                   f'was cleared ({history.time_jumps} jumps so far)')

    def _on_time_jump(self, jump: TimeJump) -> None:
        history = self.history
        if history is None or jump.delta.nanoseconds >= 0:
            return
        if history.time_jumped_back(self._node.get_clock().now().nanoseconds):
            self._warn_jump(history)
            self._publish_stats(None)

    def prepare(self, header: Any, rectifier: MovingRectifier) -> tuple[CameraInfo, CameraInfo]:
        """
        Set the rectifier to the lens state at a frame's stamp; return its two CameraInfos.

        :param header: the frame's header (its stamp).
        :param rectifier: the active model's moving rectifier.
        :return: ``(camera_info, camera_info_rect)`` of that state (headers not set).
        """
        self.drain()
        stamp = header.stamp.sec * 1_000_000_000 + header.stamp.nanosec
        positions: dict[str, float] = {}
        lag_ms = float('nan')
        missing: tuple[str, ...] = ()
        if self.history is not None:
            at = self.history.at(stamp)
            positions, lag_ms, missing = at.positions, at.lag_s * 1e3, at.missing
        state, clamped = rectifier.grid.clamp(positions)
        if missing:
            # No JointState of that joint yet: the table's first row, said out loud.
            self.missing_frames += 1
            now = time.monotonic()
            if now - self._missing_warned_at >= CLAMP_WARN_S:
                self._missing_warned_at = now
                self._warn(', '.join(
                    f'lens.{m}: no lens_state of joint {self.history.joints[m]!r} yet; '
                    f'correcting at lens.{m}.positions[0] = {state[m]:g}' for m in missing
                    if m in state) + f' ({self.missing_frames} frames so far)')
        if clamped:
            self.clamped_frames += 1
            now = time.monotonic()
            if now - self._warned_at >= CLAMP_WARN_S:
                self._warned_at = now
                self._warn(', '.join(
                    f'lens.{m}: joint position {positions[m]:g} is outside lens.{m}.positions; '
                    f'correcting at {state[m]:g}' for m in clamped) +
                    f' ({self.clamped_frames} frames so far)')
        camera = rectifier.prepare(state)
        model = rectifier.model
        view = _CameraView(model.width, model.height, model.out_width, model.out_height,
                           model.projection, camera.K, camera.K_new, camera.D,
                           camera.distortion_model, camera.P)
        fill_camera_info(self._infos[0], view, rectified=False)
        fill_camera_info(self._infos[1], view, rectified=True)
        self._publish_stats({'state': state, 'lag_ms': lag_ms, 'grid': rectifier.grid,
                             'camera': camera})
        return self._infos

    def _publish_stats(self, frame: dict[str, Any] | None) -> None:
        extra = self._stats.extra
        if frame == {}:
            extra.clear()
        history = self.history
        if history is None:
            return
        extra['lens_states_received'] = history.received
        extra['lens_states_ignored'] = history.ignored
        extra['lens_states_last_ignored'] = history.last_ignored
        extra['lens_states_failed'] = self.failed
        extra['lens_states_last_failure'] = self.last_failure
        extra['lens_state_time_jumps'] = history.time_jumps
        for mech, position in history.newest().items():
            extra[f'lens_state_newest.{mech}'] = position
        if frame:
            for mech, position in frame['state'].items():
                extra[f'lens_state.{mech}'] = position
            extra['lens_state_lag_ms'] = frame['lag_ms']
            extra['lens_state_clamped_frames'] = self.clamped_frames
            extra['lens_state_missing_frames'] = self.missing_frames
            grid = frame['grid']
            extra['lens_grid_states'] = len(grid.cameras)
            extra['lens_grid_memory_mb'] = round(
                (grid.memory_bytes + grid.frame_map_bytes) / 1e6, 2)
            camera: StateCamera = frame['camera']
            extra['lens_state_focal_px'] = float(camera.K[0, 0])
