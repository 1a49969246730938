# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Tests of :mod:`~mechdeconv_ros.node.process_env`, without ROS: environment, ids, children.

The child processes are ``python -c`` scripts: one that exits with a chosen code on SIGINT,
one that ignores SIGINT (so the stop must escalate to SIGTERM), and one that starts a
grandchild in the same process group (so the stop must reach it too).
"""

from __future__ import annotations

import itertools
import os
from pathlib import Path
import signal
import sys
import time
import xml.etree.ElementTree as ET

from mechdeconv_ros.node import process_env
from mechdeconv_ros.node.process_env import (
    Child, config_file, DOMAIN_RANGES, fastdds_profile, graph_env as make_env, MALLOC_ENV,
    pick_domain_id)
import pytest

#: Prints 'ready', then waits; SIGINT makes it exit with status 3.
ON_SIGINT_EXIT_3 = (
    'import signal, sys, time\n'
    'signal.signal(signal.SIGINT, lambda *_: sys.exit(3))\n'
    "print('ready', flush=True)\n"
    'time.sleep(60)\n')
#: Prints 'ready', ignores SIGINT; SIGTERM ends it (default action: status -15).
IGNORES_SIGINT = (
    'import signal, time\n'
    'signal.signal(signal.SIGINT, signal.SIG_IGN)\n'
    "print('ready', flush=True)\n"
    'time.sleep(60)\n')
#: Starts a grandchild that sleeps, prints its pid, waits.
WITH_GRANDCHILD = (
    'import subprocess, sys, time\n'
    "p = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
    'print(p.pid, flush=True)\n'
    'time.sleep(60)\n')


def wait_for_output(child: Child, timeout: float = 20.0) -> str:
    """Return the child's first line of output once it is there."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = child.stdout()
        if text.endswith('\n'):
            return text.splitlines()[0]
        assert child.running(), child.output()
        time.sleep(0.02)
    raise AssertionError(f'no output from {child.argv}')


def gone(pid: int) -> bool:
    """Return True when ``pid`` no longer runs (or is a zombie)."""
    try:
        return Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0] == 'Z'
    except OSError:
        return True


def test_domain_ranges_are_disjoint_and_valid():
    ids = {user: set(range(first, last + 1)) for user, (first, last) in DOMAIN_RANGES.items()}
    assert {'tests', 'demo', 'benchmarks', 'soak'} <= set(ids)
    for (a, set_a), (b, set_b) in itertools.combinations(ids.items(), 2):
        assert not set_a & set_b, (a, b)
    assert min(min(s) for s in ids.values()) >= 1
    assert max(max(s) for s in ids.values()) <= 232     # Fast DDS port mapping limit


@pytest.mark.parametrize('user', sorted(DOMAIN_RANGES))
def test_picked_domains_stay_in_the_users_range_and_vary_with_the_salt(user, monkeypatch):
    monkeypatch.delenv('ROS_DOMAIN_ID', raising=False)
    first, last = DOMAIN_RANGES[user]
    picked = [pick_domain_id(user, salt) for salt in range(last - first + 1)]
    assert all(first <= d <= last for d in picked)
    assert len(set(picked)) == last - first + 1      # a run's launches get distinct ids


def test_picked_domain_skips_the_exported_one(monkeypatch):
    monkeypatch.delenv('ROS_DOMAIN_ID', raising=False)
    usual = pick_domain_id('demo')
    monkeypatch.setenv('ROS_DOMAIN_ID', str(usual))
    assert pick_domain_id('demo') != usual
    with pytest.raises(KeyError):
        pick_domain_id('nobody')


def test_env_has_the_graph_settings_and_the_package_first_on_the_path(monkeypatch):
    monkeypatch.setenv('ROS_LOCALHOST_ONLY', '1')
    monkeypatch.setenv('PYTHONPATH', '/elsewhere')
    monkeypatch.setenv('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')
    monkeypatch.setenv('MALLOC_TRIM_THRESHOLD_', '5')
    env = make_env(42)
    assert env['ROS_DOMAIN_ID'] == '42'
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert 'ROS_LOCALHOST_ONLY' not in env and 'FASTDDS_BUILTIN_TRANSPORTS' not in env
    assert Path(env['FASTRTPS_DEFAULT_PROFILES_FILE']) == fastdds_profile()
    assert fastdds_profile().name == 'fastdds_shm.xml' and fastdds_profile().is_file()
    for name, value in MALLOC_ENV.items():
        assert env[name] == value            # the package's own, not the exported 5
    assert env['PYTHONPATH'].split(os.pathsep) == [str(process_env.PACKAGE_PARENT), '/elsewhere']
    assert env['PYTHONUNBUFFERED'] == '1'
    assert os.environ['ROS_LOCALHOST_ONLY'] == '1'   # the caller's environment is untouched


def test_env_keeps_what_the_caller_exported_when_asked(monkeypatch, tmp_path):
    monkeypatch.setenv('FASTRTPS_DEFAULT_PROFILES_FILE', str(tmp_path / 'mine.xml'))
    monkeypatch.setenv('MALLOC_TRIM_THRESHOLD_', '5')
    monkeypatch.delenv('MALLOC_MMAP_THRESHOLD_', raising=False)
    env = make_env(7, keep_exported=True, extra={'X_EXTRA': 'y'})
    assert env['FASTRTPS_DEFAULT_PROFILES_FILE'] == str(tmp_path / 'mine.xml')
    assert env['MALLOC_TRIM_THRESHOLD_'] == '5'
    assert env['MALLOC_MMAP_THRESHOLD_'] == MALLOC_ENV['MALLOC_MMAP_THRESHOLD_']
    assert env['X_EXTRA'] == 'y'


def test_env_without_the_profile_uses_the_builtin_transports(monkeypatch):
    monkeypatch.setenv('FASTRTPS_DEFAULT_PROFILES_FILE', '/some/profile.xml')
    env = make_env(3, shm_profile=False)
    assert 'FASTRTPS_DEFAULT_PROFILES_FILE' not in env
    assert env['ROS_DOMAIN_ID'] == '3'


def test_config_file_is_found_and_a_missing_one_named():
    assert config_file('case2.yaml').is_file()
    with pytest.raises(FileNotFoundError, match='no_such.yaml'):
        config_file('no_such.yaml')


def test_child_is_stopped_by_sigint_to_its_group_with_its_exit_code(tmp_path):
    with Child([sys.executable, '-c', ON_SIGINT_EXIT_3], make_env(9), tmp_path / 'a.out',
               tmp_path / 'a.err') as child:
        assert wait_for_output(child) == 'ready'
        assert os.getpgid(child.pid) == child.pid != os.getpgid(0)    # its own group
        assert child.stop() == 3
        assert not child.killed and not child.running()
    assert child.stop() == 3        # stopping again returns the same code


def test_child_that_ignores_sigint_gets_sigterm(tmp_path):
    lines: list[str] = []
    child = Child([sys.executable, '-c', IGNORES_SIGINT], make_env(9), tmp_path / 'b.log',
                  name='stubborn')
    assert wait_for_output(child) == 'ready'
    start = time.monotonic()
    code = child.stop(timeout=0.5, escalate_s=(5.0, 5.0), log=lines.append)
    assert code == -signal.SIGTERM
    assert child.killed and child.ignored == ['SIGINT']
    assert lines == ['stubborn did not exit within 0.5 s of SIGINT']
    assert time.monotonic() - start < 5.0


def test_stopping_the_group_stops_the_grandchild_too(tmp_path):
    child = Child([sys.executable, '-c', WITH_GRANDCHILD], make_env(9), tmp_path / 'c.log')
    grandchild = int(wait_for_output(child))
    assert os.getpgid(grandchild) == child.pid
    assert child.stop(timeout=5.0) == -signal.SIGINT    # no handler: killed by SIGINT
    deadline = time.monotonic() + 5.0
    while not gone(grandchild) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert gone(grandchild)


def test_context_manager_kills_a_child_left_running(tmp_path):
    with Child([sys.executable, '-c', IGNORES_SIGINT], make_env(9), tmp_path / 'd.log') as c:
        assert wait_for_output(c) == 'ready'
    assert c.returncode == -signal.SIGKILL and gone(c.pid)
    assert 'ready' in c.tail()


def test_announcing_profile_keeps_the_transports_and_announces_every_period(
        tmp_path: Path) -> None:
    path = process_env.announcing_profile(tmp_path, period_s=0.5)
    assert path.parent == tmp_path and path != process_env.fastdds_profile()
    ns = {'f': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    ours, package = ET.parse(path).getroot(), ET.parse(process_env.fastdds_profile()).getroot()
    rtps = ours.find('.//f:participant/f:rtps', ns)
    lease = rtps.find('f:builtin/f:discovery_config/f:leaseAnnouncement', ns)
    assert (lease.find('f:sec', ns).text, lease.find('f:nanosec', ns).text) == ('0', '500000000')
    # Everything else is the package's: the same transports, segment and message sizes.
    for tag in ('userTransports', 'useBuiltinTransports'):
        assert ET.tostring(rtps.find(f'f:{tag}', ns)) == ET.tostring(
            package.find(f'.//f:participant/f:rtps/f:{tag}', ns))
    assert ET.tostring(ours.find('.//f:transport_descriptors', ns)) == ET.tostring(
        package.find('.//f:transport_descriptors', ns))
    # A profile that already sets builtin discovery is used as it is.
    assert process_env.announcing_profile(tmp_path / 'x', source=path) == path
