# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Hardening of rclpy's set_parameters and set_parameters_atomically services.

The rclpy behaviours worked around (rclpy 7.1.x, Jazzy: ``rclpy/parameter_service.py`` and
``Node.set_parameters_atomically``):

* a request with a type code outside rcl_interfaces/msg/ParameterType raises in the executor
  (``Parameter.from_parameter_msg``), which ends ``spin``: one bad request stops the node;
* the names of undeclared parameters are lost: the reason is built from a generator already
  consumed by ``any()``, so it lists ``[]``; a parameter named ``''`` is even declared;
* a wrong type, a read-only parameter or an undeclare is refused without saying which
  parameter of the request it was.

:func:`guard_parameter_services` wraps both services' callbacks: it refuses the first two with
a reason naming the parameter, puts the name in front of the others, and turns any other
exception into a refusal (a request can fail, the node cannot). After each request it calls
``after_request``, which the node uses to start one rebuild per request: rclpy applies a
multi-parameter ``set_parameters`` (what ``ros2 param load`` sends) one parameter at a time.
"""

from __future__ import annotations

from typing import Any, Callable, Iterable

from mechdeconv_ros.node.ros_params import type_hint
from mechdeconv_ros.schema.params import SPECS
from rcl_interfaces.msg import Parameter as ParameterMsg, SetParametersResult
from rcl_interfaces.srv import SetParameters, SetParametersAtomically
from rclpy.exceptions import ParameterNotDeclaredException
from rclpy.node import Node
from rclpy.parameter import Parameter

#: The type codes of rcl_interfaces/msg/ParameterType that rclpy can parse.
PARAMETER_TYPES = frozenset(t.value for t in Parameter.Type)


def validation_result(validate: Callable[[dict[str, Any]], Any],
                      changes: dict[str, Any]) -> SetParametersResult:
    """
    Return a set's answer from a validator that raises ValueError naming what it refuses.

    An on-set-parameters callback must never raise: any other exception is an internal error.

    :param validate: builds the candidate model of ``changes`` (raises ValueError to refuse).
    :param changes: parameter name -> new value.
    :return: successful, or refused with the validator's reason.
    """
    try:
        validate(changes)
    except Exception as err:        # noqa: B902 - a callback must never raise
        return SetParametersResult(successful=False, reason=str(err) if isinstance(
            err, ValueError) else f'internal error while validating: {err!r}')
    return SetParametersResult(successful=True)


def guard_parameter_services(node: Node, after_request: Callable[[], Any],
                             allow_undeclared: bool = False) -> None:
    """
    Wrap the node's set_parameters and set_parameters_atomically service callbacks.

    :param node: the node (its parameter services exist: ``start_parameter_services``).
    :param after_request: called after every request, before the reply goes out.
    :param allow_undeclared: the node's ``allow_undeclared_parameters``.
    """
    guard = _Guard(node, after_request, allow_undeclared)
    for service in node.services:
        if service.srv_type is SetParameters:
            service.callback = guard.set_parameters(service.callback)
        elif service.srv_type is SetParametersAtomically:
            service.callback = guard.set_parameters_atomically(service.callback)


class _Guard:
    def __init__(self, node: Node, after_request: Callable[[], Any],
                 allow_undeclared: bool) -> None:
        self._node = node
        self._after_request = after_request
        self._allow_undeclared = allow_undeclared

    def set_parameters(self, handler: Any) -> Any:
        def callback(request: Any, response: Any) -> Any:
            for msg in request.parameters:
                reason = self._refusal_before_rclpy(msg)
                if reason is None:
                    single = SetParameters.Response()
                    try:
                        handler(SetParameters.Request(parameters=[msg]), single)
                        result = single.results[0]
                    except Exception as err:    # noqa: B902 - a request fails, not the node
                        result = SetParametersResult(successful=False,
                                                     reason=f'{msg.name}: {err}')
                    result = self._name_in_reason(result, [msg])
                else:
                    result = SetParametersResult(successful=False, reason=reason)
                response.results.append(result)
            self._after_request()
            return response
        return callback

    def set_parameters_atomically(self, handler: Any) -> Any:
        def callback(request: Any, response: Any) -> Any:
            reasons = [reason for reason in map(self._refusal_before_rclpy, request.parameters)
                       if reason is not None]
            if reasons:
                response.result = SetParametersResult(successful=False,
                                                      reason='; '.join(reasons))
                return response
            try:
                handler(request, response)
            except Exception as err:    # noqa: B902 - a request fails, not the node
                response.result = SetParametersResult(
                    successful=False, reason=f'{", ".join(p.name for p in request.parameters)}'
                                             f': {err}')
            response.result = self._name_in_reason(response.result, request.parameters)
            self._after_request()
            return response
        return callback

    def _refusal_before_rclpy(self, msg: ParameterMsg) -> str | None:
        """Return why rclpy must not see this parameter message, or None."""
        if msg.value.type not in PARAMETER_TYPES:
            return (f'{msg.name}: unknown parameter type {msg.value.type} (rcl_interfaces/msg/'
                    f'ParameterType has {min(PARAMETER_TYPES)} to {max(PARAMETER_TYPES)})')
        if not self._allow_undeclared and not self._node.has_parameter(msg.name):
            return (f'{msg.name!r}: {self._node.get_name()} has no such parameter '
                    '(see ros2 param list)')
        return None

    def _name_in_reason(self, result: SetParametersResult,
                        messages: Iterable[ParameterMsg]) -> SetParametersResult:
        """Put the parameter at fault in front of a refusal that does not name it."""
        messages = list(messages)
        if result.successful or any(m.name and m.name in result.reason for m in messages):
            return result
        culprit = messages[0].name if messages else ''
        hint = ''
        for msg in messages:
            try:
                descriptor = self._node.describe_parameter(msg.name)
            except ParameterNotDeclaredException:
                continue
            if descriptor.read_only or (not descriptor.dynamic_typing and msg.value.type not in (
                    descriptor.type, Parameter.Type.NOT_SET.value)):
                culprit = msg.name
                spec = SPECS.get(msg.name)
                if spec is not None and msg.value.type == Parameter.Type.INTEGER.value:
                    hint = type_hint(spec)
                break
            if msg.value.type == Parameter.Type.NOT_SET.value:
                culprit = msg.name
                break
        return SetParametersResult(successful=False, reason=f'{culprit}: {result.reason}{hint}')
