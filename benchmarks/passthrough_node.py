# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A pass-through node: the transport-only baseline of the node benchmarks, and its ablations.

It does what ``correct_node`` does minus the correction: subscribes ``image_raw`` and
publishes every frame it receives on ``image_rect``, with the same QoS (best effort, keep
last 1, volatile: :func:`mechdeconv_ros.node.frame_input.sensor_qos`) and the same transport (the
process environment decides it). The received message is republished as it is, so the
Python side adds no copy: what remains is rclpy's receive conversion, the executor and the
publish, the cost every Python relay pays per frame.

``--upto`` adds correct_node's per-frame work one stage at a time, with the node's own code
(the stage benchmark, :mod:`benchmarks.stages`, runs each rung):

* ``relay`` (default): republish the received message;
* ``copy``: read the pixels (:func:`~mechdeconv_ros.node.frame_input.read_image`), copy them into a
  pooled output message (:class:`~mechdeconv_ros.node.image_msgs.OutputImagePool`) and publish
  that: the conversion and the message fill, without the remap;
* ``remap``: the same with ``Rectifier.correct`` (Case 2 model of the frame's size, built at
  the first frame) instead of the copy;
* ``info``: and publish ``camera_info`` (the model's prebuilt message, restamped);
* ``info_rect``: and ``camera_info_rect``;
* ``remap_fixed``: a side variant of ``remap``, the maps converted to CV_16SC2 + CV_16UC1
  (correct_node keeps them as two CV_32FC1: which is faster in a running relay, with the
  caches shared between frames, is measured, not assumed).

What remains between the last rung and ``correct_node`` is the node itself: the live model's
reference read, counters, diagnostics timer, parameter callbacks, matched-event waitables and
the rebuild and summary threads. With ``MECHDECONV_STAGE_TIMES`` set the relay times its
stages as correct_node does (:mod:`mechdeconv_ros.node.stage_clock`).

Run::

    python -m benchmarks.passthrough_node [--executor single|multi] [--upto RUNG] [--stereo]
        [--ros-args ...]

``--stereo`` relays two streams instead (``left/image_raw`` -> ``left/image_rect`` and
``right/image_raw`` -> ``right/image_rect``, each message republished as it is, one callback
group): the baseline of stereo_node (:mod:`benchmarks.stereo_latency`).

``--executor multi`` uses a two-thread MultiThreadedExecutor (default: single, the cheapest
relay, as correct_node). SIGINT stops it with exit code 0.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
from typing import Any

from mechdeconv_ros.node.diagnostics import FrameStats
from mechdeconv_ros.node.frame_input import read_image, sensor_qos
from mechdeconv_ros.node.image_msgs import camera_infos_from_model, OutputImagePool
from mechdeconv_ros.node.node_main import STOP_POLL_S
from mechdeconv_ros.node.stage_clock import stage_clock_from_env
from mechdeconv_ros.node.stop_signals import StopSignals
import numpy as np
import rclpy
from rclpy.executors import (
    ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor)
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import CameraInfo, Image

#: The rungs of ``--upto``, each adding one stage to the one before.
RUNGS = ('relay', 'copy', 'remap', 'info', 'info_rect', 'remap_fixed')
CASE2_YAML = Path(__file__).resolve().parents[1] / 'config' / 'case2.yaml'


class PassthroughNode(Node):
    """Republish ``image_raw`` on ``image_rect``, doing correct_node's work up to a rung."""

    def __init__(self, upto: str = 'relay') -> None:
        """
        Create the publishers and the subscription.

        :param upto: one of :data:`RUNGS`.
        """
        super().__init__('passthrough_node')
        self.frames = 0
        self._fixed_point = upto == 'remap_fixed'
        self._rung = RUNGS.index('remap' if self._fixed_point else upto)
        self._stage_clock = stage_clock_from_env()
        self._stats = FrameStats()
        self._pool = OutputImagePool()
        self._model: Any = None         # (size, Rectifier, (camera_info, camera_info_rect))
        self._pub = self.create_publisher(Image, 'image_rect', sensor_qos())
        self._pub_info = self.create_publisher(CameraInfo, 'camera_info', sensor_qos())
        self._pub_info_rect = self.create_publisher(CameraInfo, 'camera_info_rect',
                                                    sensor_qos())
        self._sub = self.create_subscription(Image, 'image_raw', self._on_image, sensor_qos())

    def _model_for(self, width: int, height: int) -> Any:
        if self._model is None or self._model[0] != (width, height):
            from mechdeconv_ros.imaging.remap import Rectifier
            from mechdeconv_ros.model.model import build_model
            from mechdeconv_ros.schema.params import load_params_file
            values = load_params_file(CASE2_YAML)
            values.update({'sensor.width_px': 0, 'sensor.height_px': 0})
            model = build_model(values, width, height)
            self._model = ((width, height), Rectifier(model, fixed_point=self._fixed_point),
                           camera_infos_from_model(model))
        return self._model

    def _on_image(self, msg: Image) -> None:
        clock = self._stage_clock
        if clock is not None:
            clock.start(msg.header.stamp)
        self.frames += 1
        if self._rung == 0:
            self._pub.publish(msg)
            if clock is not None:
                clock.mark('publish_image')
                clock.end()
            return
        pixels, encoding = read_image(msg, self._stats)
        if clock is not None:
            clock.mark('read')
        height, width = pixels.shape[:2]
        _, rectifier, (info, info_rect) = self._model_for(width, height)
        out = self._pool.get(width, height, encoding.name)
        if clock is not None:
            clock.mark('model')
        if self._rung == 1:
            np.copyto(out.pixels, pixels)
        else:
            rectifier.correct(pixels, out.pixels)
        if clock is not None:
            clock.mark('copy' if self._rung == 1 else 'remap')
        out.msg.header = msg.header
        self._pub.publish(out.msg)
        if clock is not None:
            clock.mark('publish_image')
        if self._rung >= 3:
            info.header = msg.header
            self._pub_info.publish(info)
            if clock is not None:
                clock.mark('publish_info')
        if self._rung >= 4:
            info_rect.header = msg.header
            self._pub_info_rect.publish(info_rect)
            if clock is not None:
                clock.mark('publish_info_rect')
        if clock is not None:
            clock.end()

    def destroy_node(self) -> None:
        """Write the stage times (when on), then destroy the node."""
        if self._stage_clock is not None:
            self._stage_clock.dump()
        super().destroy_node()


class StereoRelay(Node):
    """Republish ``left/image_raw`` and ``right/image_raw`` on their ``image_rect``."""

    def __init__(self) -> None:
        """Create both publishers and subscriptions."""
        super().__init__('passthrough_node')
        self.frames = 0
        for side in ('left', 'right'):
            pub = self.create_publisher(Image, f'{side}/image_rect', sensor_qos())
            self.create_subscription(Image, f'{side}/image_raw',
                                     lambda msg, pub=pub: self._relay(pub, msg), sensor_qos())

    def _relay(self, pub: Any, msg: Image) -> None:
        self.frames += 1
        pub.publish(msg)


def main(argv: list[str] | None = None) -> None:
    """Run until SIGINT (exit code 0)."""
    argv = list(sys.argv if argv is None else argv)
    parser = argparse.ArgumentParser(description='pass-through image relay')
    parser.add_argument('--executor', choices=('single', 'multi'), default='single')
    parser.add_argument('--upto', choices=RUNGS, default='relay')
    parser.add_argument('--stereo', action='store_true', help='relay left/ and right/')
    args, ros_args = parser.parse_known_args(rclpy.utilities.remove_ros_args(argv)[1:])
    if ros_args:
        parser.error(f'unknown arguments {ros_args}')
    # Stopped as correct_node is: SIGINT only sets a flag. Under rclpy's own handler a SIGINT
    # during a take became a RuntimeError in the conversion and exit code 1 (seen once in
    # the stage smoke test).
    signals = StopSignals().install()
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = StereoRelay() if args.stereo else PassthroughNode(args.upto)
        executor = (MultiThreadedExecutor(num_threads=2) if args.executor == 'multi'
                    else SingleThreadedExecutor())
        executor.add_node(node)
        while not signals.event.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=STOP_POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        signals.restore()


if __name__ == '__main__':
    main()
