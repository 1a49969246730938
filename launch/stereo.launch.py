# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Launch stereo_node for one stereo camera, as correct.launch.py launches correct_node.

Launch arguments:

* ``namespace`` (default empty): the stereo camera's namespace; the node then subscribes
  ``<namespace>/left/image_raw`` and ``<namespace>/right/image_raw`` (or their
  ``/compressed``) and publishes ``<namespace>/left/image_rect``, ``right/image_rect``,
  ``left/camera_info``, ``right/camera_info``, ``left/camera_info_rect`` and
  ``right/camera_info_rect`` as ``/<namespace>/stereo_node``: what stereo_image_proc's
  disparity node subscribes in the same namespace.
* ``params_file`` (default the installed ``config/stereo.yaml``): both lenses and the rig
  (``stereo_node: ros__parameters:``).
* ``image_transport`` (``raw`` or ``compressed``, default ``raw``): what the node subscribes
  on both sides (``left.image_transport`` and ``right.image_transport``), read at start-up.
* ``use_fastdds_profile`` (default ``true``): run the node with FASTRTPS_DEFAULT_PROFILES_FILE
  set to the installed ``config/fastdds_shm.xml`` (as correct.launch.py).

Example::

    ros2 launch mechdeconv_ros stereo.launch.py namespace:=stereo params_file:=bar.yaml
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from mechdeconv_ros.node.process_env import FASTDDS_PROFILE_NAME, PROFILE_VAR

PACKAGE = 'mechdeconv_ros'


def generate_launch_description() -> LaunchDescription:
    """Return the launch description: the arguments and one stereo_node."""
    share = get_package_share_directory(PACKAGE)
    arguments = [
        DeclareLaunchArgument(
            'namespace', default_value='',
            description='namespace of the stereo camera (topics and node name go under it)'),
        DeclareLaunchArgument(
            'params_file', default_value=os.path.join(share, 'config', 'stereo.yaml'),
            description='parameters YAML of the pair (left.*, right.*, rig.*, output.*)'),
        DeclareLaunchArgument(
            'image_transport', default_value='raw', choices=['raw', 'compressed'],
            description='subscribe */image_raw (raw) or */image_raw/compressed (compressed)'),
        DeclareLaunchArgument(
            'use_fastdds_profile', default_value='true', choices=['true', 'false'],
            description='give the node the installed Fast DDS shared-memory profile'),
    ]
    node = GroupAction(scoped=True, forwarding=True, actions=[
        SetEnvironmentVariable(
            PROFILE_VAR, os.path.join(share, 'config', FASTDDS_PROFILE_NAME),
            condition=IfCondition(LaunchConfiguration('use_fastdds_profile'))),
        Node(
            package=PACKAGE, executable='stereo_node', name='stereo_node',
            namespace=LaunchConfiguration('namespace'),
            parameters=[LaunchConfiguration('params_file'),
                        {'left.image_transport': LaunchConfiguration('image_transport'),
                         'right.image_transport': LaunchConfiguration('image_transport')}],
            output='screen', emulate_tty=True),
    ])
    return LaunchDescription(arguments + [node])
