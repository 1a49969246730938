# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
stereo_node's messages and topics: the four CameraInfos, its publishers, inputs, diagnostics.

Topics (relative: namespaces and remaps apply): in, ``left/image_raw`` and
``right/image_raw`` (sensor_msgs/Image) or, with ``left.image_transport`` /
``right.image_transport`` ``compressed`` (read at start-up), their RESOLVED names +
``/compressed``; out, ``left/image_rect`` and ``right/image_rect`` (each with its own input's
header and encoding), ``left/camera_info``, ``right/camera_info`` (raw K and the equivalent D,
R the rectifying rotation, P of the pair: the right P's ``Tx = -fx' B``, B in metres),
``left/camera_info_rect`` and ``right/camera_info_rect`` (K = P[:3, :3], D = 0, R = I, the
same P), all with the sensor-data QoS of correct_node (best effort, keep last 1; QoS overrides
allowed), and ``/diagnostics`` (depth 10). The inputs are always subscribed (a pair is two
streams: no lazy subscription).
"""

from __future__ import annotations

import json
import math
import time
from typing import Any, Callable, Mapping

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mechdeconv_ros.model.stereo import stereo_camera_infos, StereoModel
from mechdeconv_ros.node.diagnostics import FrameStats
from mechdeconv_ros.node.frame_input import read_compressed, read_image, sensor_qos
from mechdeconv_ros.runtime.stereo_live import StereoStatus
from mechdeconv_ros.runtime.stereo_sync import StampPairer
from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

#: The stereo check's entry holding when its result was made (time.monotonic): /diagnostics
#: shows ``stereo_check_age_s`` instead.
CHECK_DONE_KEY = 'stereo_check_done_monotonic'
#: The four CameraInfo outputs: key of :func:`stereo_camera_infos` -> topic.
INFO_TOPICS = {'left': 'left/camera_info', 'right': 'right/camera_info',
               'left_rect': 'left/camera_info_rect', 'right_rect': 'right/camera_info_rect'}


def info_messages(stereo: StereoModel) -> dict[str, CameraInfo]:
    """
    Return the four CameraInfo messages of a pair (empty headers), keyed as :data:`INFO_TOPICS`.

    :param stereo: the pair's model.
    :return: ``{'left', 'right', 'left_rect', 'right_rect'}`` -> CameraInfo.
    """
    out = {}
    for key, info in stereo_camera_infos(stereo).items():
        msg = CameraInfo()
        msg.width, msg.height = int(info['width']), int(info['height'])
        msg.distortion_model = str(info['distortion_model'])
        msg.d = [float(x) for x in info['D']]
        msg.k = [float(x) for x in info['K']]
        msg.r = [float(x) for x in info['R']]
        msg.p = [float(x) for x in info['P']]
        out[key] = msg
    return out


def create_stereo_outputs(node: Node) -> tuple[Any, dict[str, Any], dict[str, Any]]:
    """
    Create ``/diagnostics``, both ``image_rect`` and the four CameraInfo publishers.

    :param node: the node.
    :return: ``(diagnostics, {'left', 'right'}: image_rect publishers, INFO_TOPICS keys:
        CameraInfo publishers)``.
    """
    overrides = QoSOverridingOptions.with_default_policies
    diagnostics = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
    images = {side: node.create_publisher(Image, f'{side}/image_rect', sensor_qos(),
                                          qos_overriding_options=overrides())
              for side in ('left', 'right')}
    infos = {key: node.create_publisher(CameraInfo, topic, sensor_qos(),
                                        qos_overriding_options=overrides())
             for key, topic in INFO_TOPICS.items()}
    return diagnostics, images, infos


def subscribe_side(node: Node, side: str, transport: str, group: CallbackGroup,
                   on_frame: Callable[[str, Any, Any], None]) -> tuple[Any, str]:
    """
    Subscribe one camera's raw input (raw or compressed, as correct_node).

    :param node: the node.
    :param side: ``'left'`` or ``'right'``.
    :param transport: the side's ``image_transport``.
    :param group: the frames' callback group (one for both sides: the pairing is serial).
    :param on_frame: ``on_frame(side, msg, read)``.
    :return: ``(subscription, resolved topic)``.
    """
    compressed = transport == 'compressed'
    topic = node.resolve_topic_name(f'{side}/image_raw') + ('/compressed' if compressed else '')
    read = read_compressed if compressed else read_image
    sub = node.create_subscription(
        CompressedImage if compressed else Image, topic, lambda msg: on_frame(side, msg, read),
        sensor_qos(), callback_group=group,
        qos_overriding_options=QoSOverridingOptions.with_default_policies())
    return sub, topic


def _text(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return str(value).lower() if isinstance(value, bool) else 'none'
    if isinstance(value, float):
        return 'nan' if not math.isfinite(value) else f'{value:.6g}'
    if isinstance(value, (list, tuple, dict)):
        return json.dumps(value, default=float)
    return str(value)


def stereo_diagnostics(node: Node, live: StereoStatus, stats: FrameStats, pairer: StampPairer,
                       check: Mapping[str, Any]) -> DiagnosticArray:
    """
    Return stereo_node's diagnostics: one status with the pair's counters and the check.

    :param node: the node (its name and clock).
    :param live: the live pair's status.
    :param stats: the frame counters (``frames_in``: both sides; ``frames_out``: pairs).
    :param pairer: the stamp pairing (pairs, unpaired frames per side).
    :param check: the stereo check's entries (the keys of ``mechdeconv stereo-check``).
    :return: the message, stamped now.
    """
    mean_ms, max_ms, period = stats.take_period()
    entries: dict[str, Any] = {
        'model_generation': live.active_generation, 'values_generation': live.generation,
        'rebuilds': live.rebuilds, 'rebuild_failures': live.rebuild_failures,
        'last_rebuild_ms': live.last_rebuild_ms, 'rebuild_pending': live.rebuild_pending,
        'frames_in': stats.frames_in, 'pairs': pairer.pairs, 'pairs_out': stats.frames_out,
        'unpaired_left': pairer.unpaired['left'], 'unpaired_right': pairer.unpaired['right'],
        'frames_dropped': stats.frames_dropped, 'frames_failed': stats.frames_failed,
        'rejected_encodings': stats.rejected_encodings,
        'pairs_in_last_period': period, 'pair_time_ms_mean': mean_ms,
        'pair_time_ms_max': max_ms, 'pair_time_ms_last': stats.frame_ms_last,
        'last_error': stats.last_error}
    entries.update(stats.extra)
    check = dict(check)
    done = check.pop(CHECK_DONE_KEY, None)
    entries.update(check)
    if done is not None:
        entries['stereo_check_age_s'] = round(time.monotonic() - float(done), 1)
    status = DiagnosticStatus(name=f'{node.get_fully_qualified_name()}: stereo rectification',
                              hardware_id='')
    if live.rebuild_error:
        status.level = DiagnosticStatus.ERROR
        status.message = f'rebuild failed, previous pair in use: {live.rebuild_error}'
    elif check.get('verdict') == 'rig_off':
        status.level = DiagnosticStatus.WARN
        status.message = ('stereo check: rig_off: the rows are '
                          f"{_text(check.get('vertical_disparity_rms_px'))} px rms apart "
                          '(see estimate.*)')
    else:
        status.level = DiagnosticStatus.OK
        status.message = f'rectifying, model generation {live.active_generation}'
    status.values = [KeyValue(key=k, value=_text(v)) for k, v in entries.items()]
    array = DiagnosticArray()
    array.header.stamp = node.get_clock().now().to_msg()
    array.status = [status]
    return array
