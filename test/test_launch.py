# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
launch/correct.launch.py starts the node in its namespace and Ctrl-C ends it cleanly.

Runs only where ``launch_ros`` is importable (a ROS install, or the ros2 venv of the
development machine); the PyPI route of requirements.txt has no launch packages, so there the
tests skip and say so. The file's content (arguments, node, parameters) is checked everywhere,
without launch_ros, by test_launch_file.py.

The launch file is run by ``launch.LaunchService`` (what ``ros2 launch`` calls) in a child
process of its own process group, from an ament prefix made in the test's temporary directory:
the ament index marker, ``share/mechdeconv_ros/{config,launch,package.xml}`` linked to the
source tree and ``lib/mechdeconv_ros/correct_node`` running this interpreter, which is the
layout a colcon install has (test_colcon_build.py checks that the real install holds the
launch file). Ctrl-C in a terminal sends SIGINT to the whole process group, and launch then
forwards SIGINT to the node once more: the test does the same with ``killpg`` and expects
launch and the node to exit with code 0 within 5 s.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

import pytest
from ros_helpers import BEST_EFFORT, next_domain_id, NodeProcess, REPO, ros_env, RosClient
from sensor_msgs.msg import Image

try:
    import launch_ros
except ImportError:     # the PyPI route: rclpy wheels without the launch packages
    launch_ros = None

pytestmark = [
    pytest.mark.ros,
    pytest.mark.skipif(
        launch_ros is None,
        reason='launch_ros is not importable (the PyPI route has no launch packages): run '
               'this test in a ROS 2 install to exercise launch/correct.launch.py'),
]

PACKAGE = 'mechdeconv_ros'
STOP_BUDGET_S = 5.0

#: Runs a launch file with ``name:=value`` arguments, as ``ros2 launch [--noninteractive]``
#: does. Interactive, launch leaves the SIGINT to the terminal (it reached the whole group);
#: non-interactive, it also sends SIGINT to the node itself, so the node gets two.
LAUNCHER = """
import sys
from launch import LaunchService
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource
noninteractive = '--noninteractive' in sys.argv
arguments = [tuple(item.split(':=', 1)) for item in sys.argv[2:] if ':=' in item]
service = LaunchService(noninteractive=noninteractive)
service.include_launch_description(IncludeLaunchDescription(
    PythonLaunchDescriptionSource(sys.argv[1]), launch_arguments=arguments))
sys.exit(service.run())
"""


@pytest.fixture(scope='module')
def prefix(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return an ament prefix holding this package as a colcon install lays it out."""
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
    executable = lib / 'correct_node'
    executable.write_text(f'#!{sys.executable}\nimport sys\n'
                          'from mechdeconv_ros.node.entry import correct_node\n'
                          'sys.exit(correct_node())\n')
    executable.chmod(0o755)
    return root


def start_launch(prefix: Path, domain: int, log_dir: Path, *arguments: str,
                 drop: tuple[str, ...] = ()) -> NodeProcess:
    """
    Start correct.launch.py; return the launch process.

    :param arguments: ``name:=value`` launch arguments, and ``--noninteractive``.
    :param drop: environment variables the launch process must not have.
    """
    env = ros_env(domain, {
        'AMENT_PREFIX_PATH': os.pathsep.join(
            [str(prefix)] + [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
                             if p]),
        'ROS_LOG_DIR': str(log_dir / 'ros_log')})
    for name in drop:
        env.pop(name, None)
    launch_file = prefix / 'share' / PACKAGE / 'launch' / 'correct.launch.py'
    return NodeProcess([sys.executable, '-c', LAUNCHER, str(launch_file), *arguments], env,
                       log_dir, name='launch')


def node_pid(proc: NodeProcess, timeout: float = 30.0) -> int:
    """Return the pid launch reports for correct_node ('process started with pid [N]')."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = re.search(r'\[correct_node-\d+\]: process started with pid \[(\d+)\]',
                          proc.output())
        if found:
            return int(found.group(1))
        assert proc.running(), 'launch exited:\n' + proc.output()[-3000:]
        time.sleep(0.1)
    pytest.fail('launch did not start correct_node:\n' + proc.output()[-3000:])


def environ_of(pid: int) -> dict[str, str]:
    """Return the environment of a running process (Linux /proc)."""
    raw = Path(f'/proc/{pid}/environ').read_bytes()
    return dict(item.split('=', 1) for item in raw.decode(errors='replace').split('\0')
                if '=' in item)


def ctrl_c(proc: NodeProcess, pid: int) -> tuple[int, float]:
    """
    Send SIGINT to the launch process group, as Ctrl-C in its terminal does.

    :return: launch's exit code and the seconds until launch and the node had both exited.
    """
    start = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    try:
        code = proc.proc.wait(timeout=STOP_BUDGET_S + 10.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail('launch did not exit after SIGINT:\n' + proc.output()[-3000:])
    while Path(f'/proc/{pid}').exists() and time.monotonic() - start < STOP_BUDGET_S + 10.0:
        time.sleep(0.05)
    return code, time.monotonic() - start


def test_launch_starts_the_node_in_its_namespace_and_ctrl_c_ends_it_cleanly(
        prefix: Path, tmp_path: Path) -> None:
    domain = next_domain_id()
    with start_launch(prefix, domain, tmp_path, 'namespace:=left') as proc:
        pid = node_pid(proc)
        share = prefix / 'share' / PACKAGE
        assert environ_of(pid).get('FASTRTPS_DEFAULT_PROFILES_FILE') == str(
            share / 'config' / 'fastdds_shm.xml')
        with RosClient(domain, node_name='left/correct_node') as client:
            client.wait_until_answering()
            # case2.yaml, the default params_file, was loaded by /left/correct_node.
            assert client.get_parameters('lens.r1_mm', 'image_transport') == {
                'lens.r1_mm': 4.0, 'image_transport': 'raw'}
            assert client.spin_until(
                lambda: ('correct_node', '/left') in
                client.node.get_node_names_and_namespaces(), 10.0)
            topics = dict(client.node.get_topic_names_and_types())
            for topic in ('/left/image_rect', '/left/camera_info', '/left/camera_info_rect'):
                assert topic in topics, sorted(topics)
            # An output subscriber makes the (lazy) node subscribe its input.
            client.node.create_subscription(Image, '/left/image_rect', lambda m: None,
                                            BEST_EFFORT)
            assert client.spin_until(
                lambda: client.node.count_subscribers('/left/image_raw') > 0, 10.0)
        code, seconds = ctrl_c(proc, pid)
        log = proc.output()
    assert code == 0, log[-3000:]
    assert seconds < STOP_BUDGET_S, f'{seconds:.1f} s to stop:\n{log[-3000:]}'
    assert not Path(f'/proc/{pid}').exists()
    assert re.search(rf'process has finished cleanly \[pid {pid}\]', log), log[-3000:]
    assert 'Traceback' not in log, log[-3000:]


def test_launch_arguments_reach_the_node_and_a_second_sigint_is_harmless(
        prefix: Path, tmp_path: Path) -> None:
    domain = next_domain_id()
    triplet = REPO / 'config' / 'cooke_triplet.yaml'
    # --noninteractive: launch forwards SIGINT to the node after the group's own SIGINT.
    with start_launch(prefix, domain, tmp_path, '--noninteractive', 'namespace:=right',
                      f'params_file:={triplet}', 'use_fastdds_profile:=false',
                      'image_transport:=compressed',
                      drop=('FASTRTPS_DEFAULT_PROFILES_FILE',)) as proc:
        pid = node_pid(proc)
        assert 'FASTRTPS_DEFAULT_PROFILES_FILE' not in environ_of(pid)
        with RosClient(domain, node_name='right/correct_node') as client:
            client.wait_until_answering()
            values = client.get_parameters('lens.surfaces.radius_mm', 'image_transport')
            assert len(values['lens.surfaces.radius_mm']) > 2    # the triplet's prescription
            assert values['image_transport'] == 'compressed'
            client.node.create_subscription(Image, '/right/image_rect', lambda m: None,
                                            BEST_EFFORT)
            assert client.spin_until(lambda: client.node.count_subscribers(
                '/right/image_raw/compressed') > 0, 10.0)
            assert client.node.count_subscribers('/right/image_raw') == 0
        code, seconds = ctrl_c(proc, pid)
        log = proc.output()
    assert code == 0, log[-3000:]
    assert seconds < STOP_BUDGET_S, f'{seconds:.1f} s to stop:\n{log[-3000:]}'
    assert re.search(rf'process has finished cleanly \[pid {pid}\]', log), log[-3000:]
    assert 'Traceback' not in log, log[-3000:]


def test_the_real_launch_description_declares_what_the_content_test_checks(
        prefix: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The launch package reads the arguments that test_launch_file.py checks by parsing."""
    import importlib.util

    from mechdeconv_ros.schema.params import IMAGE_TRANSPORTS

    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    path = prefix / 'share' / PACKAGE / 'launch' / 'correct.launch.py'
    spec = importlib.util.spec_from_file_location('correct_launch', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    arguments = {a.name: a for a in module.generate_launch_description().get_launch_arguments()}
    assert sorted(arguments) == ['image_transport', 'namespace', 'params_file',
                                 'use_fastdds_profile']
    assert list(arguments['image_transport'].choices) == list(IMAGE_TRANSPORTS)
    assert list(arguments['use_fastdds_profile'].choices) == ['true', 'false']
