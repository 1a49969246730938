# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
A pass-through node: the transport-only baseline of the node benchmark.

It does what ``correct_node`` does minus the correction: subscribes ``image_raw`` and
publishes every frame it receives on ``image_rect``, with the same QoS (best effort, keep
last 1, volatile: :func:`mechdeconv_ros.frame_io.sensor_qos`) and the same transport (the
process environment decides it). The received message is republished as it is, so the
Python side adds no copy: what remains is rclpy's receive conversion, the executor and the
publish, the cost every Python relay pays per frame.

Run::

    python -m benchmarks.passthrough_node [--executor single|multi] [--ros-args ...]

``--executor multi`` uses a two-thread MultiThreadedExecutor as correct_node does (default:
single, the cheapest relay). SIGINT stops it with exit code 0.
"""

from __future__ import annotations

import argparse
import sys

from mechdeconv_ros.frame_io import sensor_qos
import rclpy
from rclpy.executors import (
    ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor)
from rclpy.node import Node
from sensor_msgs.msg import Image


class PassthroughNode(Node):
    """Republish ``image_raw`` on ``image_rect`` unchanged."""

    def __init__(self) -> None:
        """Create the publisher and the subscription."""
        super().__init__('passthrough_node')
        self.frames = 0
        self._pub = self.create_publisher(Image, 'image_rect', sensor_qos())
        self._sub = self.create_subscription(Image, 'image_raw', self._on_image, sensor_qos())

    def _on_image(self, msg: Image) -> None:
        self._pub.publish(msg)
        self.frames += 1


def main(argv: list[str] | None = None) -> None:
    """Run until SIGINT (exit code 0)."""
    argv = list(sys.argv if argv is None else argv)
    parser = argparse.ArgumentParser(description='pass-through image relay')
    parser.add_argument('--executor', choices=('single', 'multi'), default='single')
    args, ros_args = parser.parse_known_args(rclpy.utilities.remove_ros_args(argv)[1:])
    if ros_args:
        parser.error(f'unknown arguments {ros_args}')
    rclpy.init(args=argv)
    node = None
    try:
        node = PassthroughNode()
        executor = (MultiThreadedExecutor(num_threads=2) if args.executor == 'multi'
                    else SingleThreadedExecutor())
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
