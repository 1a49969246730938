# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Helpers for the tests that run real ROS 2 processes (no mocks).

* :func:`next_domain_id` gives every node launch of a test run its own ``ROS_DOMAIN_ID``
  (the tests' range of :data:`mechdeconv_ros.node.process_env.DOMAIN_RANGES`, pid-derived, so
  parallel runs on one machine do not see each other; under pytest-xdist each worker takes
  the ids of its own residue class, so two workers of one run never share a domain), and
  :func:`ros_env` the environment for it (:func:`mechdeconv_ros.node.process_env.graph_env`:
  discovery limited to localhost and the package's Fast DDS profile, whose big shared-memory
  segment lets large best-effort frames arrive).
* :class:`NodeProcess` is :class:`mechdeconv_ros.node.process_env.Child` with ``<name>.out`` and
  ``<name>.err`` logs: a node in its own process group, stopped with SIGINT to the group
  (escalating to SIGTERM, SIGKILL), returning the exit code; its context manager kills the
  group if anything goes wrong, so no process outlives a test.
* :class:`RosClient` is a client node in the test process, in its own rclpy Context on the
  same domain: it publishes frames, collects the node's outputs by stamp and calls the
  parameter services exactly as ``ros2 param set`` does.
"""

from __future__ import annotations

import array
import contextlib
import itertools
import os
from pathlib import Path
import signal
import sys
import tempfile
import time
from typing import Any, Callable, Iterator, Sequence

from mechdeconv_ros.node import process_env
from mechdeconv_ros.node.process_env import Child
import numpy as np
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.srv import GetParameters, SetParameters, SetParametersAtomically
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

REPO = Path(__file__).resolve().parents[1]
FASTDDS_PROFILE = process_env.fastdds_profile()
NODE_NAME = 'correct_node'

#: Best effort, keep last: what the node publishes and subscribes with by default.
BEST_EFFORT = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                         reliability=ReliabilityPolicy.BEST_EFFORT)

_domain_counter = itertools.count()


def next_domain_id() -> int:
    """
    Return a ROS_DOMAIN_ID for one node launch: distinct within this run, pid-derived.

    :return: the domain id, in the tests' range (1-100).
    """
    # pytest-xdist names its workers gw0, gw1, ... and says how many there are: each worker
    # is a lane of the tests' range, so two workers never share a domain.
    worker = int(os.environ.get('PYTEST_XDIST_WORKER', 'gw0')[2:])
    workers = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1'))
    return process_env.pick_domain_id('tests', next(_domain_counter), worker, workers)


def ros_env(domain_id: int, extra: dict[str, str] | None = None) -> dict[str, str]:
    """
    Return the environment of a ROS process of a test.

    :param domain_id: the ROS_DOMAIN_ID.
    :param extra: more variables (override the rest).
    :return: a copy of ``os.environ`` with the graph's settings and the repo on PYTHONPATH.
    """
    return process_env.graph_env(domain_id, extra=extra)


#: The test process's Fast DDS profile (configure_test_process), written once per process.
_ANNOUNCING: Path | None = None


def configure_test_process() -> None:
    """
    Set the ROS environment of the test process itself (before its first participant).

    Fast DDS reads its profile file once per process, at the first participant, so this must
    run before any ``rclpy.init`` of the session. The test process's participants announce
    themselves every 0.5 s (:func:`~mechdeconv_ros.node.process_env.announcing_profile`):
    a client made before the node it tests discovered the node only at its own announcements,
    every 3 s by default. The nodes under test keep the package's profile.
    """
    global _ANNOUNCING
    if _ANNOUNCING is None:
        _ANNOUNCING = process_env.announcing_profile(Path(tempfile.mkdtemp(prefix='ros_test_')))
    process_env.configure_this_process(
        process_env.graph_env(0, extra={process_env.PROFILE_VAR: str(_ANNOUNCING)}))


class NodeProcess(Child):
    """A ROS node process in its own process group, stopped by SIGINT to the group."""

    def __init__(self, argv: Sequence[str], env: dict[str, str], log_dir: Path,
                 name: str = 'node') -> None:
        """
        Start the process.

        :param argv: the command.
        :param env: its environment.
        :param log_dir: where ``<name>.out`` and ``<name>.err`` go.
        :param name: file name stem of the logs.
        """
        super().__init__(argv, env, log_dir / f'{name}.out', log_dir / f'{name}.err', name)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0, **kwargs: Any) -> int:
        """
        Send ``sig`` to the group and wait for the exit; escalate after ``timeout``.

        :param sig: the signal (SIGINT, as Ctrl-C in ``ros2 run``).
        :param timeout: seconds to wait.
        :param kwargs: see :meth:`mechdeconv_ros.node.process_env.Child.stop`.
        :return: the exit code (negative: killed by a signal).
        """
        return super().stop(sig, timeout, **kwargs)


@contextlib.contextmanager
def running_node(argv: Sequence[str], domain: int, log_dir: Path,
                 answer_timeout: float = 15.0, node_name: str = NODE_NAME
                 ) -> Iterator[tuple[NodeProcess, RosClient]]:
    """
    Run a node until the block ends, then stop it by SIGINT and assert a clean exit.

    :param argv: the node's command (:func:`node_command`).
    :param domain: its ``ROS_DOMAIN_ID``.
    :param log_dir: where its logs go.
    :param answer_timeout: seconds the node may take to answer its first service call.
    :param node_name: the node's name (its parameter services).
    :return: the process and a client already talking to it.
    """
    with NodeProcess(argv, ros_env(domain), log_dir) as proc:
        client = RosClient(domain, node_name=node_name)
        try:
            client.wait_until_answering(timeout=answer_timeout)
            yield proc, client
        finally:
            client.close()
            code = proc.stop(signal.SIGINT)
            log = proc.output()
        assert code == 0, f'correct_node exited with {code} after SIGINT:\n{log[-3000:]}'
        assert 'Traceback' not in log, log[-3000:]


def node_command(params_file: Path | None, *overrides: str,
                 executable: Sequence[str] | None = None) -> list[str]:
    """
    Return the command that runs correct_node with a params file and ``-p`` overrides.

    :param params_file: the ``--params-file`` (None: none).
    :param overrides: ``name:=value`` strings.
    :param executable: the program (default: ``python -m mechdeconv_ros.node.correct_node``).
    :return: argv.
    """
    argv = list(executable or [sys.executable, '-m', 'mechdeconv_ros.node.entry'])
    argv.append('--ros-args')
    if params_file is not None:
        argv += ['--params-file', str(params_file)]
    for item in overrides:
        argv += ['-p', item]
    return argv


def stamp_of(msg: Any) -> tuple[int, int]:
    """Return ``(sec, nanosec)`` of a message's header."""
    return int(msg.header.stamp.sec), int(msg.header.stamp.nanosec)


def make_image(pixels: np.ndarray, encoding: str, *, pad: int = 0, bigendian: bool = False,
               frame_id: str = 'test_optical_frame') -> Any:
    """
    Build a sensor_msgs/Image holding ``pixels``, optionally row-padded or big-endian.

    :param pixels: ``(H, W)`` or ``(H, W, C)``, native byte order.
    :param encoding: the encoding name.
    :param pad: extra bytes at the end of every row.
    :param bigendian: store multi-byte values big-endian and set ``is_bigendian``.
    :param frame_id: the header's frame_id.
    :return: the message (stamp unset).
    """
    from sensor_msgs.msg import Image
    height, width = pixels.shape[:2]
    stored = pixels.astype(pixels.dtype.newbyteorder('>' if bigendian else '<'))
    rows = np.ascontiguousarray(stored).reshape(height, -1).view(np.uint8)
    padded = np.full((height, rows.shape[1] + pad), 0xAB, np.uint8)
    padded[:, :rows.shape[1]] = rows
    msg = Image()
    msg.header.frame_id = frame_id
    msg.width, msg.height, msg.encoding = width, height, encoding
    msg.step = padded.shape[1]
    msg.is_bigendian = int(bigendian)
    msg.data = array.array('B', padded.tobytes())
    return msg


class RosClient:
    """A client node in the test process: publishes frames, collects outputs, sets params."""

    def __init__(self, domain_id: int, name: str = 'test_client',
                 node_name: str = NODE_NAME) -> None:
        """
        Create the context, the node and the parameter clients of ``node_name``.

        :param domain_id: the ROS_DOMAIN_ID of the node under test.
        :param name: this client's node name.
        :param node_name: the node under test.
        """
        configure_test_process()
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._set = self.node.create_client(SetParameters, f'/{node_name}/set_parameters')
        self._set_atomic = self.node.create_client(
            SetParametersAtomically, f'/{node_name}/set_parameters_atomically')
        self._get = self.node.create_client(GetParameters, f'/{node_name}/get_parameters')
        self._stamps = itertools.count(1)

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> RosClient:
        """Return self."""
        return self

    def __exit__(self, *exc: Any) -> None:
        """Close."""
        self.close()

    def next_diagnostics(self, diagnostics: list[Any], timeout: float = 3.0) -> dict[str, str]:
        """
        Spin until a new message lands in ``diagnostics``; return its first status's values.

        :param diagnostics: the list a /diagnostics subscription appends to.
        :param timeout: seconds to wait.
        :return: key -> value of the node's status.
        """
        start = len(diagnostics)
        assert self.spin_until(lambda: len(diagnostics) > start, timeout), 'no /diagnostics'
        return {kv.key: kv.value for kv in diagnostics[-1].status[0].values}

    def spin_until(self, predicate: Callable[[], bool], timeout: float,
                   poll: float = 0.02) -> bool:
        """
        Spin until ``predicate()`` is true or ``timeout`` seconds pass.

        :return: the last value of the predicate.
        """
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return predicate()
            self.executor.spin_once(timeout_sec=poll)
        return True

    def spin_for(self, seconds: float) -> None:
        """Spin for a while (to let messages arrive)."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, deadline - time.monotonic())))

    def next_stamp(self, msg: Any) -> tuple[int, int]:
        """Give ``msg`` a fresh, unique header stamp and return it."""
        sec = next(self._stamps)
        msg.header.stamp.sec = sec
        msg.header.stamp.nanosec = 1000 * sec
        return stamp_of(msg)

    def answered(self, client: Any, request: Any, timeout: float = 30.0,
                 attempt: float = 1.0) -> Any:
        """
        Send ``request`` until the service answers it; return the response.

        Only for requests that may be served twice (reads, empty sets). It exists for the
        first call after discovery: Fast DDS sends a reply only once the service's reply
        writer has matched this client's reply reader, waits 100 ms for that and then drops
        the reply (ros2/rmw_fastrtps#842), so on a loaded machine the first request can go
        unanswered although ``wait_for_service`` returned True.

        :param client: the rclpy service client.
        :param request: the request to (re)send.
        :param timeout: seconds before the test fails.
        :param attempt: seconds to wait for each reply before resending.
        :return: the response.
        """
        deadline = time.monotonic() + timeout
        assert client.wait_for_service(timeout_sec=timeout), f'{client.srv_name} not available'
        while True:
            future = client.call_async(request)
            if self.spin_until(future.done, attempt):
                return future.result()
            client.remove_pending_request(future)
            assert time.monotonic() < deadline, f'{client.srv_name} never answered'

    def wait_until_answering(self, timeout: float = 30.0) -> None:
        """
        Return once each parameter service of the node has answered this client.

        Empty requests (they change nothing) are resent until answered (see
        :meth:`answered`); after that every reply of these services reaches this client, so
        the calls of the test itself are sent once and must be answered.

        :param timeout: seconds before the test fails.
        """
        for client, request in ((self._get, GetParameters.Request()),
                                (self._set, SetParameters.Request()),
                                (self._set_atomic, SetParametersAtomically.Request())):
            self.answered(client, request, timeout)

    def call(self, client: Any, request: Any, timeout: float = 10.0) -> Any:
        """Call a service and return its response (fails the test on a timeout)."""
        assert client.wait_for_service(timeout_sec=timeout), f'{client.srv_name} not available'
        future = client.call_async(request)
        assert self.spin_until(future.done, timeout), f'{client.srv_name} did not answer'
        return future.result()

    def set_parameters(self, *params: Parameter) -> list[Any]:
        """
        Set parameters one by one through ``set_parameters``, as ``ros2 param set`` does.

        :return: one SetParametersResult per parameter.
        """
        request = SetParameters.Request(parameters=[p.to_parameter_msg() for p in params])
        return list(self.call(self._set, request).results)

    def set_parameters_async(self, *params: Parameter) -> Any:
        """Start a ``set_parameters`` call and return its future (spin to complete it)."""
        assert self._set.wait_for_service(timeout_sec=10.0)
        return self._set.call_async(
            SetParameters.Request(parameters=[p.to_parameter_msg() for p in params]))

    def set_parameters_atomically(self, *params: Parameter) -> Any:
        """Set parameters together through ``set_parameters_atomically``; return the result."""
        request = SetParametersAtomically.Request(
            parameters=[p.to_parameter_msg() for p in params])
        return self.call(self._set_atomic, request).result

    def get_parameters(self, *names: str) -> dict[str, Any]:
        """Return the current values of parameters of the node under test."""
        response = self.call(self._get, GetParameters.Request(names=list(names)))
        return {name: Parameter.from_parameter_msg(ParameterMsg(name=name, value=value)).value
                for name, value in zip(names, response.values)}
