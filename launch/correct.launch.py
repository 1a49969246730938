# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Launch correct_node for one camera, the way image_proc.launch.py launches its nodes.

Launch arguments:

* ``namespace`` (default empty): the camera's namespace; the node then subscribes
  ``<namespace>/image_raw`` (or ``<namespace>/image_raw/compressed``) and publishes
  ``<namespace>/image_rect``, ``camera_info`` and ``camera_info_rect`` as
  ``/<namespace>/correct_node``.
* ``params_file`` (default the installed ``config/case2.yaml``): the lens of this camera. The
  package's files are keyed ``/**:``, so one file serves any namespace.
* ``image_transport`` (``raw`` or ``compressed``, default ``raw``): what the node subscribes;
  read once at start-up, as image_proc's ``image_transport`` parameter.
* ``use_fastdds_profile`` (default ``true``): run the node with FASTRTPS_DEFAULT_PROFILES_FILE
  set to the installed ``config/fastdds_shm.xml`` (large shared-memory segment, so big
  best-effort frames arrive). Only this node gets it: the other processes of the graph need
  the same profile too (export it in their shell), else they fall back to the builtin
  transports for the frames they exchange with it.

Example (two cameras)::

    ros2 launch mechdeconv_ros correct.launch.py namespace:=left params_file:=left.yaml
    ros2 launch mechdeconv_ros correct.launch.py namespace:=right params_file:=right.yaml

There is no ``container`` argument: correct_node is a Python node, not a composable component.
Ctrl-C stops the node cleanly (exit code 0) even though it receives SIGINT twice (from the
terminal and from launch).
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
    """Return the launch description: the arguments and one correct_node."""
    share = get_package_share_directory(PACKAGE)
    arguments = [
        DeclareLaunchArgument(
            'namespace', default_value='',
            description='namespace of the camera (topics and node name go under it)'),
        DeclareLaunchArgument(
            'params_file', default_value=os.path.join(share, 'config', 'case2.yaml'),
            description='parameters YAML of this camera (lens, sensor, scene, output)'),
        DeclareLaunchArgument(
            'image_transport', default_value='raw', choices=['raw', 'compressed'],
            description='subscribe image_raw (raw) or image_raw/compressed (compressed)'),
        DeclareLaunchArgument(
            'use_fastdds_profile', default_value='true', choices=['true', 'false'],
            description='give the node the installed Fast DDS shared-memory profile'),
    ]
    node = GroupAction(scoped=True, forwarding=True, actions=[
        # Scoped: the variable is set for the node started in this group only.
        SetEnvironmentVariable(
            PROFILE_VAR, os.path.join(share, 'config', FASTDDS_PROFILE_NAME),
            condition=IfCondition(LaunchConfiguration('use_fastdds_profile'))),
        Node(
            package=PACKAGE, executable='correct_node', name='correct_node',
            namespace=LaunchConfiguration('namespace'),
            parameters=[LaunchConfiguration('params_file'),
                        {'image_transport': LaunchConfiguration('image_transport')}],
            output='screen', emulate_tty=True),
    ])
    return LaunchDescription(arguments + [node])
