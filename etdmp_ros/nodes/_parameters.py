"""
Declare a node's parameters from the system description (:mod:`etdmp_ros.system`).

The one helper every node uses: the descriptor (description with unit, range, choices,
read-only unless runtime-changeable) and the default come from the node's
:class:`~etdmp_ros.system.NodeSpec`; values given in parameter files override the defaults.
"""

from etdmp_ros.system import DOUBLE_ARRAY, STRING_ARRAY
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter

_ARRAY_TYPES = {STRING_ARRAY: Parameter.Type.STRING_ARRAY,
                DOUBLE_ARRAY: Parameter.Type.DOUBLE_ARRAY}


def descriptor(parameter):
    """Return the rcl ParameterDescriptor of a :class:`~etdmp_ros.system.Parameter`."""
    d = ParameterDescriptor(name=parameter.name, description=parameter.full_description,
                            read_only=not parameter.dynamic,
                            dynamic_typing=parameter.dynamic_typing)
    if parameter.choices:
        d.additional_constraints = 'one of ' + ', '.join(parameter.choices)
    if parameter.value_range is not None and not isinstance(parameter.default, list):
        low, high = parameter.value_range
        if isinstance(parameter.default, int) and not isinstance(parameter.default, bool):
            d.integer_range = [IntegerRange(from_value=low, to_value=high, step=1)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(low),
                                                         to_value=float(high), step=0.0)]
    return d


def declare(node, spec):
    """
    Declare every parameter of ``spec`` (a NodeSpec) on ``node``; return their values.

    Raises rclpy's InvalidParameterValueException / InvalidParameterTypeException when a value
    given in a parameter file is out of range or of the wrong type.
    """
    for p in spec.all_parameters:
        # An empty list has no ROS type: declare the type alone (unset means empty).
        default = _ARRAY_TYPES[p.array_type] if p.array_type and not p.default else p.default
        node.declare_parameter(p.name, default, descriptor(p))
    return values(node, spec)


def values(node, spec, changes=()):
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


def plain(value):
    """Return a parameter value as plain Python (arrays as lists)."""
    if value is None or isinstance(value, (str, bytes)) or not hasattr(value, '__len__'):
        return value
    return list(value)
