# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Build the package with colcon as a ROS user would, then run the INSTALLED correct_node.

colcon comes from the Python environment running the tests (``colcon`` next to
``sys.executable``: ``/tmp/v1/bin/colcon`` here, ``.venv/bin/colcon`` in CI). Build, install and
log bases are in the test's temporary directory, so the repository stays clean. Nothing can be
sourced here, so the test sets what ``install/setup.bash`` would: PYTHONPATH to the install's
site-packages (and AMENT_PREFIX_PATH), with the repository itself NOT on the path, so the node
that runs is the installed one.
"""

from __future__ import annotations

import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import sysconfig
import time
import zipfile

from mechdeconv_ros.node.image_msgs import image_to_array
import numpy as np
import pytest
from rclpy.parameter import Parameter
from ros_helpers import (
    BEST_EFFORT, make_image, next_domain_id, node_command, NodeProcess, REPO, ros_env,
    RosClient, stamp_of)
from sensor_msgs.msg import CameraInfo, Image

pytestmark = pytest.mark.ros

PACKAGE = 'mechdeconv_ros'


def find_colcon() -> Path:
    """Return the colcon executable of the Python environment running the tests."""
    candidate = Path(sys.executable).parent / 'colcon'
    if not candidate.exists():
        pytest.fail(f'colcon is not installed next to {sys.executable} '
                    '(requirements-test.txt pins colcon-common-extensions)')
    return candidate


def repo_state() -> set[str]:
    """Return the names at the top of the repository (to check the build leaves none)."""
    return {entry.name for entry in REPO.iterdir()}


@pytest.fixture(scope='module')
def install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Run ``colcon build`` of the repository into a temporary directory; return install/."""
    tmp = tmp_path_factory.mktemp('colcon')
    before = repo_state()
    env = dict(os.environ, COLCON_HOME=str(tmp / 'colcon_home'))
    build = subprocess.run(
        [str(find_colcon()), '--log-base', str(tmp / 'log'), 'build',
         '--base-paths', str(REPO), '--build-base', str(tmp / 'build'),
         '--install-base', str(tmp / 'install'), '--event-handlers', 'console_direct-'],
        cwd=tmp, env=env, capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stdout[-4000:] + build.stderr[-4000:]
    created = repo_state() - before
    assert not created & {'build', 'install', 'log'}, f'colcon wrote into the repo: {created}'
    return tmp / 'install'


def site_packages(install: Path) -> Path:
    """Return the install's site-packages (where colcon's setup would point PYTHONPATH)."""
    version = sysconfig.get_python_version()
    return install / PACKAGE / 'lib' / f'python{version}' / 'site-packages'


def installed_env(install: Path, domain_id: int) -> dict[str, str]:
    """Return the environment ``source install/setup.bash`` would give, repo not on the path."""
    env = ros_env(domain_id, {'PYTHONPATH': str(site_packages(install)),
                              'AMENT_PREFIX_PATH': str(install / PACKAGE)})
    return env


def test_build_installs_the_executable_and_the_config(install: Path) -> None:
    executable = install / PACKAGE / 'lib' / PACKAGE / 'correct_node'
    assert executable.is_file()
    assert os.access(executable, os.X_OK)
    share = install / PACKAGE / 'share' / PACKAGE
    assert (share / 'package.xml').is_file()
    for name in ('case2.yaml', 'fastdds_shm.xml'):
        assert (share / 'config' / name).is_file(), name
    assert (share / 'launch' / 'correct.launch.py').is_file()
    # The stereo node (issue 38): its console script, launch file and example pair.
    assert os.access(install / PACKAGE / 'lib' / PACKAGE / 'stereo_node', os.X_OK)
    assert (share / 'launch' / 'stereo.launch.py').is_file()
    assert (share / 'config' / 'stereo.yaml').is_file()
    assert (install / PACKAGE / 'share' / 'ament_index' / 'resource_index' / 'packages'
            / PACKAGE).is_file()
    # Every layer subpackage is shipped, each with its __init__.py.
    for layer in ('schema', 'optics', 'lenses', 'model', 'imaging', 'node', 'tools'):
        assert (site_packages(install) / PACKAGE / layer / '__init__.py').is_file(), layer
    assert (site_packages(install) / PACKAGE / 'node' / 'correct_node.py').is_file()
    # Package data (the glass catalogs) is installed with the modules.
    assert (site_packages(install) / PACKAGE / 'data' / 'glass_catalogs.csv').is_file()


def test_installed_package_reads_its_glass_catalogs(install: Path, tmp_path: Path) -> None:
    env = installed_env(install, next_domain_id())
    probe = subprocess.run(
        [sys.executable, '-c', 'import mechdeconv_ros.optics.glass as g; '
         'print(g.__file__); print(g.refractive_index("N-BK7", 587.5618))'],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert probe.returncode == 0, probe.stderr
    where, index = probe.stdout.split()
    assert Path(where).is_relative_to(install), where
    assert abs(float(index) - 1.5168) < 1e-5


def test_installed_node_corrects_a_frame_and_exits_cleanly(
        install: Path, tmp_path: Path) -> None:
    executable = install / PACKAGE / 'lib' / PACKAGE / 'correct_node'
    params = install / PACKAGE / 'share' / PACKAGE / 'config' / 'case2.yaml'
    domain = next_domain_id()
    env = installed_env(install, domain)
    # The installed package, not the source tree, is what this environment imports.
    where = subprocess.run([sys.executable, '-c', 'import mechdeconv_ros; '
                            'print(mechdeconv_ros.__file__)'], env=env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=60)
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.strip()).is_relative_to(install), where.stdout
    argv = node_command(params, 'sensor.width_px:=0', 'sensor.height_px:=0',
                        executable=[str(executable)])
    with NodeProcess(argv, env, tmp_path) as proc, RosClient(domain) as client:
        received: dict[tuple[int, int], dict[str, object]] = {}
        for kind, msg_type, topic in (('image', Image, 'image_rect'),
                                      ('info', CameraInfo, 'camera_info')):
            client.node.create_subscription(
                msg_type, topic,
                lambda m, kind=kind: received.setdefault(stamp_of(m), {}).update({kind: m}),
                BEST_EFFORT)
        pub = client.node.create_publisher(Image, 'image_raw', BEST_EFFORT)
        assert client.spin_until(lambda: pub.get_subscription_count() > 0, 15.0), \
            'the installed node did not subscribe:\n' + proc.output()[-3000:]
        src = np.random.default_rng(0).integers(0, 255, (120, 160), dtype=np.uint8)
        frame = make_image(src, 'mono8')
        stamp = client.next_stamp(frame)
        for _ in range(20):
            pub.publish(frame)
            if client.spin_until(lambda: len(received.get(stamp, {})) == 2, 0.5):
                break
        assert len(received.get(stamp, {})) == 2, 'no output:\n' + proc.output()[-3000:]
        got, _ = image_to_array(received[stamp]['image'])       # type: ignore[arg-type]
        assert got.shape == src.shape and not np.array_equal(got, src)
        client.wait_until_answering()
        assert client.get_parameters('lens.r1_mm') == {'lens.r1_mm': 4.0}
        assert client.set_parameters(Parameter('lens.stop_offset_mm', value=0.3))[0].successful
        code = proc.stop(signal.SIGINT)
        log = proc.output()
    assert code == 0, log[-3000:]
    assert 'Traceback' not in log, log[-3000:]


def loaded(pid: int, library: str) -> bool:
    """Return whether a running process has mapped a shared library whose path has ``library``."""
    try:
        return library in Path(f'/proc/{pid}/maps').read_text()
    except OSError:
        return False


def test_installed_node_stopped_while_it_imports_exits_0_without_a_traceback(
        install: Path, tmp_path: Path) -> None:
    """
    Ctrl-C (or ``ros2 launch`` stopping it) in the node's first second, while it imports.

    The signal is sent once numpy's compiled core is mapped: the entry point has installed its
    handlers by then, and rclpy and most of the node's modules are still to come (about 0.5 s).
    Before the entry point caught signals first, this ended with a KeyboardInterrupt traceback
    and exit code -2.
    """
    executable = install / PACKAGE / 'lib' / PACKAGE / 'correct_node'
    params = install / PACKAGE / 'share' / PACKAGE / 'config' / 'case2.yaml'
    env = installed_env(install, next_domain_id())
    argv = node_command(params, executable=[str(executable)])
    with NodeProcess(argv, env, tmp_path) as proc:
        deadline = time.monotonic() + 30.0
        while not loaded(proc.pid, '_multiarray_umath') and time.monotonic() < deadline:
            time.sleep(0.002)
        assert not loaded(proc.pid, '_rclpy_pybind11'), \
            'the node had imported rclpy before the signal: the test proves nothing'
        code = proc.stop(signal.SIGINT)
        log = proc.output()
    assert code == 0, log[-3000:]
    assert 'Traceback' not in log and 'KeyboardInterrupt' not in log, log[-3000:]
    assert 'ready:' not in log, log[-3000:]      # it stopped instead of starting


def test_the_pip_wheel_ships_the_layers_and_the_package_data(tmp_path: Path) -> None:
    """``pip wheel .`` (the other install route) holds every layer, its modules and the data."""
    # A copy of what the build reads, so that setuptools' build/ is not written into the repo.
    src = tmp_path / 'src'
    src.mkdir()
    for name in ('setup.py', 'setup.cfg', 'package.xml', 'resource', PACKAGE, 'config', 'launch'):
        copy = shutil.copytree if (REPO / name).is_dir() else shutil.copy
        copy(REPO / name, src / name, **({'ignore': shutil.ignore_patterns('__pycache__')}
                                         if (REPO / name).is_dir() else {}))
    build = subprocess.run(
        [sys.executable, '-m', 'pip', 'wheel', '--no-deps', '--no-build-isolation', '-q',
         '--disable-pip-version-check', '-w', str(tmp_path), str(src)],
        capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stdout[-2000:] + build.stderr[-2000:]
    (wheel,) = tmp_path.glob('mechdeconv_ros-*.whl')
    names = set(zipfile.ZipFile(wheel).namelist())
    source = {str(p.relative_to(REPO)) for p in (REPO / PACKAGE).rglob('*.py')}
    assert source, 'no modules found in the checkout'
    assert source <= names, f'missing from the wheel: {sorted(source - names)[:5]}'
    assert f'{PACKAGE}/data/glass_catalogs.csv' in names
