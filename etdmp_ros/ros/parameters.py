"""
Declare a node's parameters from the system description (:mod:`etdmp_ros.ros.system`).

The one helper every node uses: the descriptor (description with unit, range, choices,
read-only unless runtime-changeable) and the default come from the node's
:class:`~etdmp_ros.ros.system.NodeSpec`; values given in parameter files override the defaults.

List parameters take a list however the command line types it: ``ros2 param set`` types ``[]``
as ``bool[]`` and ``[1, 0, 0]`` as ``integer[]``. :func:`declare` registers :func:`as_declared`
as the node's pre-set callback, which turns such a value into the list type the parameter is
declared with before rclpy checks the type; any other type is refused by rclpy with its reason
(``Wrong parameter type, expected 'Type.DOUBLE_ARRAY' got 'Type.STRING'``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
import math
from typing import Any, TypeVar

from etdmp_ros.ros.specs import DOUBLE_ARRAY, NodeSpec, Parameter as ParameterSpec, STRING_ARRAY
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterUninitializedException)
from rclpy.node import Node
from rclpy.parameter import Parameter

T = TypeVar('T')

_ARRAY_TYPES = {STRING_ARRAY: Parameter.Type.STRING_ARRAY,
                DOUBLE_ARRAY: Parameter.Type.DOUBLE_ARRAY}
_ELEMENT_TYPES = ((bool, Parameter.Type.BOOL_ARRAY), (int, Parameter.Type.INTEGER_ARRAY),
                  (float, Parameter.Type.DOUBLE_ARRAY), (str, Parameter.Type.STRING_ARRAY))
_LISTS = (Parameter.Type.BOOL_ARRAY, Parameter.Type.BYTE_ARRAY, Parameter.Type.INTEGER_ARRAY,
          Parameter.Type.DOUBLE_ARRAY, Parameter.Type.STRING_ARRAY)


def descriptor(parameter: ParameterSpec) -> ParameterDescriptor:
    """Return the rcl ParameterDescriptor of a :class:`~etdmp_ros.ros.system.Parameter`."""
    d = ParameterDescriptor(name=parameter.name, description=parameter.full_description,
                            read_only=not parameter.dynamic,
                            dynamic_typing=parameter.dynamic_typing)
    if parameter.choices:
        d.additional_constraints = 'one of ' + ', '.join(parameter.choices)
    elif parameter.count:
        d.additional_constraints = f'{parameter.count} values'
    if parameter.value_range is not None and not isinstance(parameter.default, list):
        low, high = parameter.value_range
        if isinstance(parameter.default, int) and not isinstance(parameter.default, bool):
            d.integer_range = [IntegerRange(from_value=low, to_value=high, step=1)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(low),
                                                         to_value=float(high), step=0.0)]
    return d


def list_type(parameter: ParameterSpec) -> Parameter.Type | None:
    """Return the rclpy list type of a :class:`~etdmp_ros.ros.system.Parameter` (None: scalar)."""
    if parameter.array_type:
        return _ARRAY_TYPES[parameter.array_type]
    if not isinstance(parameter.default, list):
        return None
    for kind, ros_type in _ELEMENT_TYPES:
        if isinstance(parameter.default[0], kind):
            return ros_type
    return None


def as_declared(spec: NodeSpec, parameters: Iterable[Parameter]) -> list[Parameter]:
    """
    Return rclpy ``parameters`` with list values in the list type ``spec`` declares for them.

    An empty list of any type becomes the declared type's empty list, integers become floats
    for a list of floats, and whole floats integers for a list of integers. Anything else is
    returned as it is (rclpy refuses a wrong type; a node with ``dynamic_typing`` checks it).
    """
    declared = {p.name: list_type(p) for p in spec.all_parameters}
    return [_converted(parameter, declared.get(parameter.name)) for parameter in parameters]


def _converted(parameter: Parameter, target: Parameter.Type | None) -> Parameter:
    given = parameter.type_
    if target is None or given == target or given not in _LISTS:
        return parameter
    value = list(parameter.value)
    if not value:
        return Parameter(parameter.name, target, [])
    if target == Parameter.Type.DOUBLE_ARRAY and given == Parameter.Type.INTEGER_ARRAY:
        return Parameter(parameter.name, target, [float(v) for v in value])
    if target == Parameter.Type.INTEGER_ARRAY and given == Parameter.Type.DOUBLE_ARRAY and \
            all(math.isfinite(v) and v == int(v) for v in value):
        return Parameter(parameter.name, target, [int(v) for v in value])
    return parameter


def declare(node: Node, spec: NodeSpec) -> dict[str, Any]:
    """
    Declare every parameter of ``spec`` (a NodeSpec) on ``node``; return their values.

    Lists given as parameter overrides are converted as :func:`as_declared` does, which is
    registered as the node's pre-set callback (the only one: rclpy joins the lists that several
    return). Raises rclpy's InvalidParameterValueException / InvalidParameterTypeException when
    a value given in a parameter file is out of range or of the wrong type, and ValueError when
    a list's element is out of its range (:meth:`etdmp_ros.ros.system.Parameter.check`);
    :func:`in_range` checks every later change the same way.
    """
    # Values given with --ros-args -p (typed by rcl as the command line is): the same
    # conversion. rclpy keeps them in this dict and offers no public way to change them.
    overrides = getattr(node, '_parameter_overrides', {})
    for p in spec.all_parameters:
        if p.name in overrides:
            overrides[p.name] = _converted(overrides[p.name], list_type(p))
        # An empty list has no ROS type: declare the type alone (unset means empty).
        default = _ARRAY_TYPES[p.array_type] if p.array_type and not p.default else p.default
        node.declare_parameter(p.name, default, descriptor(p))
    node.add_pre_set_parameters_callback(lambda parameters: as_declared(spec, parameters))
    declared = values(node, spec)
    for p in spec.all_parameters:
        p.check(declared[p.name])   # ValueError: the node program's FATAL start-up error
    node.add_on_set_parameters_callback(lambda parameters: in_range(spec, parameters))
    return declared


def in_range(spec: NodeSpec, parameters: Iterable[Parameter]) -> SetParametersResult:
    """
    Return the SetParametersResult of checking rclpy ``parameters`` against ``spec``'s ranges.

    rclpy checks a scalar's range (its descriptor); a list's elements only this does
    (:meth:`etdmp_ros.ros.system.Parameter.check`), e.g. static_obstacles [1e308, 0, 0].
    """
    described = {p.name: p for p in spec.all_parameters}
    for parameter in parameters:
        if parameter.name in described and parameter.type_ != Parameter.Type.NOT_SET:
            try:
                described[parameter.name].check(plain(parameter.value))
            except ValueError as err:
                return SetParametersResult(successful=False, reason=str(err))
    return SetParametersResult(successful=True)


def values(node: Node, spec: NodeSpec, changes: Iterable[Parameter] = ()
           ) -> dict[str, Any]:
    """
    Return ``{name: value}`` of the node's parameters, arrays as lists, unset lists empty.

    ``changes`` (rclpy Parameters about to be set) replace the current values.
    """
    result = {}
    for p in spec.all_parameters:
        try:
            result[p.name] = plain(node.get_parameter(p.name).value)
        except ParameterUninitializedException:
            result[p.name] = []
    for parameter in changes:
        unset = parameter.type_ == Parameter.Type.NOT_SET
        result[parameter.name] = [] if unset else plain(parameter.value)
    return result


def plain(value: Any) -> Any:
    """Return a parameter value as plain Python (arrays as lists)."""
    if value is None or isinstance(value, (str, bytes)) or not hasattr(value, '__len__'):
        return value
    return list(value)


class InvalidConfiguration(Exception):
    """A node's start-up configuration is unusable (the reason has been logged as FATAL)."""


def declared_settings(node: Node, spec: NodeSpec, build: Callable[[dict[str, Any]], T]) -> T:
    """
    Declare ``spec``'s parameters on ``node`` and return ``build({name: value})``.

    A value out of range or of the wrong type, or one ``build`` refuses with ValueError, is
    logged as FATAL and raised as InvalidConfiguration (the node program exits with 1).
    """
    try:
        return build(declare(node, spec))
    except (InvalidParameterValueException, InvalidParameterTypeException, ValueError) as err:
        node.get_logger().fatal(f'invalid parameter: {err}')
        raise InvalidConfiguration(str(err)) from None
