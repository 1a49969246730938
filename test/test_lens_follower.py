# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The lens_state drain of correct_node (issue 29, item 1), with real rclpy and real topics.

The follower's node is not spun while the client publishes: its subscription queue fills as it
does under load, and :meth:`LensFollower.drain` empties it as a frame would. Unstamped
JointStates must keep their own arrival times (rmw's received timestamp, carried onto the
node's sim-time clock), and an error while handling one message must be counted without
losing the rest of the queue. The whole node (sim time, ``/clock`` jumps, frames) is in
test_zoom_node.py.
"""

from __future__ import annotations

import time
from typing import Any, Iterator

from builtin_interfaces.msg import Time
from mechdeconv_ros.node.diagnostics import FrameStats
from mechdeconv_ros.node.lens_follower import LensFollower
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import configure_test_process, next_domain_id
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

pytestmark = pytest.mark.ros

S = 1_000_000_000


def _node(domain: int, name: str, **kwargs: Any) -> tuple[Context, Node, SingleThreadedExecutor]:
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = Node(name, context=context, **kwargs)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    return context, node, executor


@pytest.fixture()
def pair() -> Iterator[tuple[Node, SingleThreadedExecutor, LensFollower, FrameStats, Node]]:
    configure_test_process()
    domain = next_domain_id()
    made = [_node(domain, 'follower', parameter_overrides=[Parameter('use_sim_time',
                                                                     value=True)]),
            _node(domain, 'driver')]
    (_, node, executor), (_, driver, driver_exec) = made
    stats = FrameStats()
    follower = LensFollower(node, stats, warn=lambda line: None)
    follower.configure({'lens.zoom.joint': 'zoom_joint'})
    try:
        yield node, executor, follower, stats, driver
    finally:
        for context, each, each_exec in made:
            each_exec.shutdown()
            each.destroy_node()
            rclpy.try_shutdown(context=context)


def _wait_matched(publisher: Any, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while publisher.get_subscription_count() == 0:
        assert time.monotonic() < deadline, 'no subscriber matched'
        time.sleep(0.02)


def _state(position: float, stamp_ns: int = 0) -> JointState:
    msg = JointState(name=['zoom_joint'], position=[position])
    msg.header.stamp = Time(sec=stamp_ns // S, nanosec=stamp_ns % S)
    return msg


def test_queued_unstamped_states_keep_their_arrival_times(pair) -> None:
    node, executor, follower, stats, driver = pair
    clock = driver.create_publisher(Clock, '/clock', 10)
    states = driver.create_publisher(JointState, 'lens_state', 10)
    _wait_matched(clock)
    _wait_matched(states)
    deadline = time.monotonic() + 10.0
    while node.get_clock().now().nanoseconds != 80 * S:
        assert time.monotonic() < deadline, 'the follower never saw /clock'
        clock.publish(Clock(clock=Time(sec=80)))
        executor.spin_once(timeout_sec=0.05)
    # The node is busy (not spinning): two unstamped states 0.3 s apart queue up.
    states.publish(_state(0.0))
    time.sleep(0.3)
    states.publish(_state(0.125))
    time.sleep(0.2)
    assert follower.drain() == 2
    joint = follower.history._by_joint['zoom_joint']
    # Both kept, at their arrival (sim clock 80 s at the drain, less each one's age).
    assert joint.positions == [0.0, 0.125], joint.stamps
    assert joint.stamps[1] - joint.stamps[0] == pytest.approx(0.3 * S, abs=0.1 * S)
    assert 80 * S - joint.stamps[1] == pytest.approx(0.2 * S, abs=0.1 * S)
    assert stats.extra['lens_states_received'] == 2


def test_an_error_on_one_drained_message_is_counted_and_the_rest_taken(pair) -> None:
    node, executor, follower, stats, driver = pair
    states = driver.create_publisher(JointState, 'lens_state', 10)
    _wait_matched(states)
    history = follower.history
    add = history.add

    def add_failing_on_half(stamp_ns, names, positions, received_ns=0):
        if positions == [0.5]:
            raise RuntimeError('a bug while handling one message')
        return add(stamp_ns, names, positions, received_ns)

    history.add = add_failing_on_half
    for k, position in enumerate((0.25, 0.5, 0.75)):
        states.publish(_state(position, (90 + k) * S))
    time.sleep(0.3)
    assert follower.drain() == 3
    assert history._by_joint['zoom_joint'].positions == [0.25, 0.75]
    assert follower.failed == 1 and 'a bug while handling' in follower.last_failure
    assert stats.extra['lens_states_failed'] == 1
