# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``check.apply`` against a user's sets, and the node's stop during checks (issue 36 (b), (d), (j)).

The node corrects fisheye frames rendered with the axis 16 px right and 12 px down while its
description says centred, so its check says ``description_off`` and ``check.apply`` sets
the offset. (b), (d): a node in this process (so that the thread of every parameter set can
be seen) spun by its own executor thread, a SEPARATE client node setting the offset through
``/correct_node/set_parameters``: every set, the apply's included, runs on the executor
(validate and commit serialised with the user's), the user's value reaches the model, and
the applies that follow are bounded about the user's value, not the start-up one. (j): a
node process stopped as ``ros2 launch`` stops it (SIGINT, SIGTERM 5 s later) while it
checks and applies exits 0 before the SIGTERM, its child gone.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Iterator

from check_scenes import box_room, grid, Lens, PIXEL_MM
from diagnostic_msgs.msg import DiagnosticArray
from mechdeconv_ros.schema.params import defaults, load_params_file
import numpy as np
import psutil
import pytest
from rclpy.parameter import Parameter
from ros_helpers import (
    BEST_EFFORT, make_image, next_domain_id, node_command, NodeProcess, REPO, ros_env,
    RosClient)
from sensor_msgs.msg import CameraInfo, Image

pytestmark = pytest.mark.ros

OFFSET_PX = (16.0, 12.0)
PARAMS = REPO / 'config' / 'fisheye.yaml'
X = 'sensor.axis_offset_x_mm'
#: ``ros2 launch``'s default wait between SIGINT and SIGTERM (launch's ``sigterm_timeout``).
LAUNCH_SIGTERM_TIMEOUT_S = 5.0


@pytest.fixture(scope='module')
def frames() -> list[np.ndarray]:
    """Return three fisheye frames rendered with the axis off."""
    lens = Lens('fisheye')
    return [grid(lens, OFFSET_PX, 0.0, 0.0, 10.0), grid(lens, OFFSET_PX, 35.0, -10.0, -25.0),
            box_room(lens, OFFSET_PX)]


@pytest.fixture(scope='module')
def node_here() -> Iterator[tuple[Any, int, threading.Thread]]:
    """Run a correct_node in this process, spun by its own executor thread."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from mechdeconv_ros.node.correct_node import CorrectNode

    class Recording(CorrectNode):
        """correct_node, recording the thread of every parameter set it validates."""

        def _on_set_parameters(self, parameters: list[Any]) -> Any:
            self.set_threads.append((threading.get_ident(), threading.current_thread().name,
                                     [p.name for p in parameters]))
            return super()._on_set_parameters(parameters)

    Recording.set_threads = []
    domain = next_domain_id()
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = Recording(context=context, cli_args=[
        '--ros-args', '--params-file', str(PARAMS), '-p', 'check.rate_hz:=10.0',
        '-p', 'check.window:=3', '-p', 'check.max_load:=1.0', '-p', 'check.apply:=true',
        # The parameter path is under test, not when checks run (test_check_cost.py): every
        # frame is fed back to back here, so a child held per frame would barely run.
        '-p', 'check.stable_period_s:=0.0', '-p', 'check.pause_during_frames:=false',
        '-p', 'lazy_subscription:=false'])
    node.set_threads.clear()     # the input's QoS overrides, declared by the constructor
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)

    spinner = threading.Thread(target=spin, name='executor', daemon=True)
    spinner.start()
    try:
        yield node, domain, spinner
    finally:
        stop.set()
        spinner.join(10.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_a_user_set_reaches_the_model_and_bounds_the_applies(
        node_here: tuple[Any, int, threading.Thread], frames: list[np.ndarray]) -> None:
    """
    Issue 36 (b), (d): check.apply beside a user's ``ros2 param set``.

    Caught: the apply's ``set_parameters_atomically`` ran in the check's thread, outside the
    executor that validates and commits the user's sets (its on-set callback is recorded on
    that thread here), and the applies were bounded about the start-up value: after the
    user set the offset to 7 tolerances, the next apply dragged it back to 3.
    """
    node, domain, spinner = node_here
    tol = float(defaults()['sensor.tolerance.axis_offset_x_mm'])
    start = float(load_params_file(PARAMS).get(X, 0.0))
    with RosClient(domain, name='user') as client:     # a separate node, its own context
        client.wait_until_answering()
        pub = client.node.create_publisher(Image, 'image_raw', BEST_EFFORT)
        infos: list[CameraInfo] = []
        client.node.create_subscription(CameraInfo, 'camera_info', infos.append, BEST_EFFORT)
        diagnostics: list[DiagnosticArray] = []
        client.node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
        count = [0]

        def applied() -> int:
            """Return ``check_applied`` of the last /diagnostics (sets made by check.apply)."""
            if not diagnostics:
                return 0
            values = {kv.key: kv.value for kv in diagnostics[-1].status[0].values}
            return int(values.get('check_applied', '0'))

        def feed_until(predicate: Any, timeout: float) -> bool:
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                msg = make_image(frames[count[0] % len(frames)], 'mono8')
                client.next_stamp(msg)
                pub.publish(msg)
                count[0] += 1
                if client.spin_until(predicate, 0.2):
                    return True
            return False

        assert feed_until(lambda: applied() >= 1, 180.0), 'no apply'
        user = start + 7.0 * tol
        assert all(r.successful for r in client.set_parameters(
            Parameter(X, Parameter.Type.DOUBLE, user)))
        # The user's value reaches the model: a camera_info with its principal point.
        cx = (Lens('fisheye').width - 1) / 2.0 + user / PIXEL_MM
        assert feed_until(lambda: infos and abs(infos[-1].k[2] - cx) < 1e-6, 60.0)
        before = applied()
        assert feed_until(lambda: applied() > before, 180.0), 'no apply after'
        got = client.get_parameters(X)[X]
        # Every set (the user's, the applies) validated on the executor's thread, and the
        # apply after the user's set bounded about the user's value (px: got, user).
        elsewhere = [entry for entry in node.set_threads if entry[0] != spinner.ident]
        assert not elsewhere and got >= user - 3.0 * tol - 1e-12, \
            (elsewhere, got / PIXEL_MM, user / PIXEL_MM)
        # What `ros2 param get` shows is what the frames are corrected with.
        cx = (Lens('fisheye').width - 1) / 2.0 + client.get_parameters(X)[X] / PIXEL_MM
        assert feed_until(lambda: infos and abs(infos[-1].k[2] - cx) < 1e-6, 60.0)


def test_stopped_as_launch_stops_it_while_checking_it_exits_cleanly(
        tmp_path: Any, frames: list[np.ndarray]) -> None:
    """
    Issue 36 (j): SIGINT during checks and applies; launch's SIGTERM 5 s later.

    A guard more than a catch: today's code passed it in two runs here (its stop could wait
    2 s after SIGTERM and 2 s after SIGKILL for the child, up to 10 s for the check's
    thread and, in an apply, for a model build in that thread: more than launch's 5 s only
    when those waits run out, which these runs did not reach). Now the apply's build runs
    on the executor (before the stop, as a user's set's does), the child is moved off
    SCHED_IDLE before SIGTERM (the CPUs are kept busy here) and every wait is bounded
    (1.5 s for the child, 1 s for the thread).
    """
    domain = next_domain_id()
    argv = node_command(PARAMS, 'check.rate_hz:=10.0', 'check.window:=3',
                        'check.max_load:=1.0', 'check.apply:=true', 'lazy_subscription:=false')
    with NodeProcess(argv, ros_env(domain), tmp_path) as proc, RosClient(domain) as client:
        client.wait_until_answering(timeout=30.0)
        pub = client.node.create_publisher(Image, 'image_raw', BEST_EFFORT)
        deadline = time.monotonic() + 180.0
        k = 0
        # Until an apply, then a few frames more: a check (and maybe an apply) in progress.
        while not re.search('check.apply: set', proc.output()) or k % 7:
            assert time.monotonic() < deadline, proc.output()[-3000:]
            pub.publish(make_image(frames[k % len(frames)], 'mono8'))
            k += 1
            client.spin_for(0.1)
        children = [c for c in psutil.Process(proc.pid).children()
                    if 'check_worker' in ' '.join(c.cmdline())]
        assert len(children) == 1, children
        # A robot's CPUs busy with other work (one spinning process per core, nice 0): the
        # child at SCHED_IDLE gets almost no CPU to run its exit.
        hogs = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
                for _ in range(os.cpu_count() or 2)]
        try:
            began = time.monotonic()
            code = proc.stop(signal.SIGINT, timeout=LAUNCH_SIGTERM_TIMEOUT_S)
            print(f'\nstopped in {time.monotonic() - began:.2f} s (CPUs kept busy)')
        finally:
            for hog in hogs:
                hog.kill()
                hog.wait()
        log = proc.output()
    assert code == 0, f'exit {code} (a SIGTERM was needed: {code == -signal.SIGTERM}):\n' \
        + log[-3000:]
    assert 'Traceback' not in log, log[-3000:]
    gone, alive = psutil.wait_procs(children, timeout=5.0)
    assert not alive, alive
