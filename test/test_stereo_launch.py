# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
launch/stereo.launch.py starts stereo_node in a namespace with its params file; Ctrl-C ends it.

Runs only where ``launch_ros`` is importable, as test_launch.py (whose launcher, process-group
Ctrl-C and ``/proc`` helpers it uses); elsewhere it skips and says so. The default params file
(config/stereo.yaml) must reach the node in ``namespace:=stereo``: a file keyed
``stereo_node:`` reaches only ``/stereo_node``, and the node then exits on an empty sensor.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import sys
import time

import pytest
from ros_helpers import next_domain_id, NodeProcess, REPO, ros_env, RosClient
from test_launch import ctrl_c, environ_of, LAUNCHER, PACKAGE, STOP_BUDGET_S

try:
    import launch_ros
except ImportError:     # the PyPI route: rclpy wheels without the launch packages
    launch_ros = None

pytestmark = [
    pytest.mark.ros,
    pytest.mark.skipif(
        launch_ros is None,
        reason='launch_ros is not importable (the PyPI route has no launch packages): run '
               'this test in a ROS 2 install to exercise launch/stereo.launch.py'),
]


@pytest.fixture(scope='module')
def prefix(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return an ament prefix holding this package (stereo_node) as colcon lays it out."""
    root = tmp_path_factory.mktemp('prefix')
    index = root / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / PACKAGE).touch()
    share = root / 'share' / PACKAGE
    share.mkdir()
    for name in ('config', 'launch', 'package.xml'):
        (share / name).symlink_to(REPO / name)
    lib = root / 'lib' / PACKAGE
    lib.mkdir(parents=True)
    executable = lib / 'stereo_node'
    executable.write_text(f'#!{sys.executable}\nimport sys\n'
                          'from mechdeconv_ros.node.entry import stereo_node\n'
                          'sys.exit(stereo_node())\n')
    executable.chmod(0o755)
    return root


def test_stereo_launch_in_a_namespace_loads_the_default_params_and_ctrl_c_ends_it(
        prefix: Path, tmp_path: Path) -> None:
    domain = next_domain_id()
    env = ros_env(domain, {
        'AMENT_PREFIX_PATH': os.pathsep.join(
            [str(prefix)] + [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
                             if p]),
        'ROS_LOG_DIR': str(tmp_path / 'ros_log')})
    launch_file = prefix / 'share' / PACKAGE / 'launch' / 'stereo.launch.py'
    with NodeProcess([sys.executable, '-c', LAUNCHER, str(launch_file), 'namespace:=stereo'],
                     env, tmp_path, name='launch') as proc:
        deadline = time.monotonic() + 60.0
        found = None
        while found is None and time.monotonic() < deadline:
            found = re.search(r'\[stereo_node-\d+\]: process started with pid \[(\d+)\]',
                              proc.output())
            time.sleep(0.1)
        assert found, proc.output()[-3000:]
        pid = int(found.group(1))
        assert environ_of(pid).get('FASTRTPS_DEFAULT_PROFILES_FILE') == str(
            prefix / 'share' / PACKAGE / 'config' / 'fastdds_shm.xml')
        with RosClient(domain, node_name='stereo/stereo_node') as client:
            client.wait_until_answering(timeout=90.0)
            assert client.get_parameters('left.sensor.width_px', 'rig.baseline_mm') == {
                'left.sensor.width_px': 1280, 'rig.baseline_mm': 120.0}
            topics = dict(client.node.get_topic_names_and_types())
            for topic in ('/stereo/left/camera_info', '/stereo/right/camera_info_rect',
                          '/stereo/right/image_rect'):
                assert topic in topics, sorted(topics)
        code, seconds = ctrl_c(proc, pid)
        log = proc.output()
    assert code == 0, log[-3000:]
    assert seconds < STOP_BUDGET_S, f'{seconds:.1f} s to stop:\n{log[-3000:]}'
    assert re.search(rf'process has finished cleanly \[pid {pid}\]', log), log[-3000:]
    assert 'Traceback' not in log, log[-3000:]
