# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The parameter schema declared on an rclpy node: descriptors, declaration, start-up values.

Shared by ``correct_node`` (every spec of :data:`mechdeconv_ros.schema.params.SCHEMA`) and
``demo_camera`` (the ``lens.*``, ``sensor.*`` and ``scene.*`` specs, with defaults from its
params file). Scalar bounds become a ``FloatingPointRange`` / ``IntegerRange``, which rclpy
enforces (inclusive); array bounds and string choices go to ``additional_constraints``, which
rclpy does not enforce (the on-set callback does).
"""

from __future__ import annotations

import sys
from typing import Any, Iterable, Mapping

from mechdeconv_ros.runtime.live_model import check_length, plain
from mechdeconv_ros.schema.params import coerce, ParamSpec, ParamValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import (
    InvalidParameterTypeException, InvalidParameterValueException,
    ParameterUninitializedException)
from rclpy.node import Node
from rclpy.parameter import Parameter


#: The ROS type of each array type of the schema (declared statically typed).
_ARRAY_TYPES = {'double_array': Parameter.Type.DOUBLE_ARRAY,
                'integer_array': Parameter.Type.INTEGER_ARRAY,
                'string_array': Parameter.Type.STRING_ARRAY}


def descriptor_for(spec: ParamSpec) -> ParameterDescriptor:
    """
    Turn a schema entry into the ParameterDescriptor that ``ros2 param describe`` shows.

    :param spec: the parameter's spec.
    :return: the descriptor (its ``type`` is set by the declaration).
    """
    if spec.unit == '1':
        unit = ' Unit: 1 (dimensionless).'
    elif spec.unit:
        unit = f' Unit: {spec.unit}.'
    else:
        unit = ''
    descriptor = ParameterDescriptor(description=spec.description + unit,
                                     read_only=spec.read_only)
    low, high = spec.minimum, spec.maximum
    if spec.type == 'double' and (low is not None or high is not None):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(low) if low is not None else -sys.float_info.max,
            to_value=float(high) if high is not None else sys.float_info.max, step=0.0)]
    elif spec.type == 'integer' and (low is not None or high is not None):
        descriptor.integer_range = [IntegerRange(
            from_value=int(low) if low is not None else -(2 ** 63),
            to_value=int(high) if high is not None else 2 ** 63 - 1, step=1)]
    constraints = []
    if spec.choices:
        constraints.append('One of: ' + ', '.join(spec.choices) + '.')
    if spec.type in ('double_array', 'integer_array') and (low is not None or high is not None):
        constraints.append(f'Every element in [{low:g}, {high:g}] {spec.unit}.'.replace(
            ' 1.', '.'))
    descriptor.additional_constraints = ' '.join(constraints)
    return descriptor


def type_hint(spec: ParamSpec) -> str:
    """Return how to write a value of this type when an integer was given for a double."""
    if spec.type == 'double':
        return ' (write doubles with a decimal point, e.g. 4.0 not 4)'
    if spec.type == 'double_array':
        return ' (write every element with a decimal point, e.g. [4.0, -4.0])'
    return ''


def declare_schema(node: Node, specs: Iterable[ParamSpec],
                   defaults: Mapping[str, Any] | None = None) -> dict[str, ParamValue]:
    """
    Declare schema parameters with their descriptors and return their checked start-up values.

    Double, integer and string arrays are declared statically typed, since rclpy cannot infer
    a type from ``[]`` (it would make a BYTE_ARRAY), and set to ``[]`` when no override gave
    them a value.

    :param node: the node to declare on.
    :param specs: the specs to declare.
    :param defaults: name -> default replacing the spec's default (e.g. from a params file).
    :return: name -> value (overrides applied, coerced with the schema).
    :raises ValueError: listing every parameter whose start-up value is refused.
    """
    specs = list(specs)
    defaults = defaults or {}
    errors = []
    for spec in specs:
        default = defaults.get(spec.name, spec.default)
        if spec.type in _ARRAY_TYPES and not default:
            default = _ARRAY_TYPES[spec.type]
        try:
            node.declare_parameter(spec.name, default, descriptor_for(spec))
        except InvalidParameterTypeException as err:
            errors.append(f'{spec.name}: {err}{type_hint(spec)}')
        except InvalidParameterValueException as err:
            errors.append(f'{spec.name}: {err}')
    if errors:
        raise ValueError('invalid start-up parameters:\n  ' + '\n  '.join(errors))
    unset = [Parameter(spec.name, _ARRAY_TYPES[spec.type], [])
             for spec in specs if spec.type in _ARRAY_TYPES
             and node.get_parameter_or(spec.name).type_ == Parameter.Type.NOT_SET]
    if unset:
        node.set_parameters(unset)
    values: dict[str, ParamValue] = {}
    for spec in specs:
        try:
            value = node.get_parameter(spec.name).value
            check_length(spec, value)
            values[spec.name] = coerce(spec, plain(value))
        except ParameterUninitializedException:
            values[spec.name] = coerce(spec, spec.default)
        except ValueError as err:
            errors.append(str(err))
    if errors:
        raise ValueError('invalid start-up parameters:\n  ' + '\n  '.join(errors))
    return values
