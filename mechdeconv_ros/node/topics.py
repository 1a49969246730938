# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
correct_node's topics: its publishers and the input it subscribes only while it is needed.

:func:`create_outputs` creates ``/diagnostics`` (depth 10) and the four outputs
(``image_rect``, ``camera_info``, ``camera_info_rect``, ``image_rect/compressed``, sensor
data QoS, QoS overrides allowed). It probes for publisher matched events on ``/diagnostics``
first: that topic has no QoS override parameters, which a second try at creating an output
would declare twice. With matched events (the shipped Fast DDS profile: within 1 ms of a
remote subscription's creation or removal) the outputs call back on every match; an rmw
without them is polled by the node.

:class:`LazyInput` holds the input subscription (``image_raw``, or its ``/compressed``
topic) while an output has a subscriber, or always when ``lazy_subscription`` is false.
Executor thread only.
"""

from __future__ import annotations

from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticArray
from mechdeconv_ros.node.diagnostics import FrameStats
from mechdeconv_ros.node.frame_input import read_compressed, read_image, sensor_qos
from rclpy.callback_groups import CallbackGroup
from rclpy.event_handler import PublisherEventCallbacks, UnsupportedEventTypeError
from rclpy.node import Node
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.subscription import Subscription
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

#: ``read(msg, stats) -> (pixels, encoding)``: a frame message's pixels.
Reader = Callable[[Any, FrameStats], Any]


def create_outputs(node: Node, on_matched: Callable[[], None]) -> tuple[Any, tuple[Any, ...],
                                                                        bool]:
    """
    Create ``/diagnostics`` and the four outputs of correct_node.

    :param node: the node.
    :param on_matched: called when an output gains or loses a subscriber (matched events).
    :return: ``(diagnostics publisher, (image_rect, camera_info, camera_info_rect,
        image_rect/compressed) publishers, whether the rmw has matched events)``.
    """
    try:
        diagnostics = node.create_publisher(
            DiagnosticArray, '/diagnostics', 10,
            event_callbacks=PublisherEventCallbacks(matched=lambda info: None))
        events = PublisherEventCallbacks(matched=lambda info: on_matched())
    except UnsupportedEventTypeError:
        diagnostics = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        events = None
    outputs = tuple(
        node.create_publisher(msg_type, topic, sensor_qos(), event_callbacks=events,
                              qos_overriding_options=QoSOverridingOptions.
                              with_default_policies())
        for msg_type, topic in ((Image, 'image_rect'), (CameraInfo, 'camera_info'),
                                (CameraInfo, 'camera_info_rect'),
                                (CompressedImage,
                                 node.resolve_topic_name('image_rect') + '/compressed')))
    return diagnostics, outputs, events is not None


class LazyInput:
    """The input subscription, held while it is needed (module doc)."""

    def __init__(self, node: Node, transport: str, on_frame: Callable[[Any, Reader], None],
                 group: CallbackGroup, on_error: Callable[[str, str], None]) -> None:
        """
        Subscribe to nothing yet; :meth:`update` does.

        :param node: the node.
        :param transport: ``image_transport``: ``'compressed'`` subscribes the RESOLVED
            ``image_raw`` + ``/compressed`` (sensor_msgs/CompressedImage), else ``image_raw``.
        :param on_frame: ``on_frame(msg, read)`` runs the frame path of a message, ``read``
            its reader (:func:`~mechdeconv_ros.node.frame_input.read_image` or
            :func:`~mechdeconv_ros.node.frame_input.read_compressed`, a decode).
        :param group: the frames' callback group.
        :param on_error: ``on_error(kind, message)`` records a failed subscription.
        """
        self._node = node
        self._compressed = transport == 'compressed'
        #: The resolved input topic.
        self.topic = node.resolve_topic_name('image_raw') + (
            '/compressed' if self._compressed else '')
        self._topic = self.topic
        read = read_compressed if self._compressed else read_image
        self._callback = lambda msg: on_frame(msg, read)
        self._group = group
        self._on_error = on_error
        self.subscription: Subscription | None = None

    def update(self, lazy: bool, outputs: tuple[Any, ...]) -> None:
        """
        Subscribe while it is needed (lazy: an output has a subscriber), unsubscribe when not.

        :param lazy: ``lazy_subscription``.
        :param outputs: the publishers whose subscribers need the input.
        """
        node = self._node
        wanted = not lazy or any(pub.get_subscription_count() > 0 for pub in outputs)
        if wanted and self.subscription is None:
            try:
                self.subscription = node.create_subscription(
                    CompressedImage if self._compressed else Image, self._topic,
                    self._callback, sensor_qos(), callback_group=self._group,
                    qos_overriding_options=QoSOverridingOptions.with_default_policies())
            except Exception as err:    # noqa: B902 - e.g. a bad qos_overrides value
                return self._on_error('subscribe', f'cannot subscribe to {self._topic}: {err}')
            node.get_logger().debug(f'subscribed to {self._topic}')
        elif not wanted and self.subscription is not None:
            node.destroy_subscription(self.subscription)
            self.subscription = None
            node.get_logger().debug('no subscriber on the outputs: unsubscribed from image_raw')
