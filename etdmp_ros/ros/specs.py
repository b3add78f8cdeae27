"""
How the system description is written: a node's parameters, its services' arguments, the node.

:class:`Parameter` is one ROS parameter as declared and documented (type from its default,
range, choices, whether it may change at runtime); :class:`ServiceSpec` a service whose request
is named, typed arguments; :class:`NodeSpec` a node with its parameters and services. The
tables of every node are in :mod:`etdmp_ros.ros.system`. The module needs no ROS.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

#: ROS types of parameters whose default is an empty list (ROS cannot type ``[]``).
STRING_ARRAY, DOUBLE_ARRAY = 'string_array', 'double_array'


@dataclass(frozen=True)
class Parameter:
    """
    One ROS parameter of a node, as declared and as documented.

    ``value_range`` is ``(low, high)`` (ints for an integer parameter; of each value of a list),
    ``choices`` the allowed strings; ``lengths`` the numbers of values a list parameter may have
    (empty: any), ``multiple_of`` a number its count of values must be a multiple of (points
    given flat, x1, y1, z1, x2, ...). ``dynamic``: may change at runtime (``ros2 param set``);
    otherwise read-only. ``dynamic_typing``: values of another type are accepted and converted
    by the node (a list as a YAML string). Every list parameter takes ``[]`` (which ``ros2 param
    set`` types as ``bool[]``), integers for floats and whole floats for integers without it:
    they are turned into its declared list type before rclpy checks the type
    (:func:`etdmp_ros.ros.parameters.as_declared`). ``array_type`` types an empty-list
    default. ``section`` starts a new group of parameters in the YAML file; ``note`` is the
    comment above the parameter there (the description when empty); ``example``, for an empty
    default, is shown commented out.
    """

    name: str
    default: Any
    description: str
    unit: str = ''
    value_range: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    lengths: tuple[int, ...] = ()
    multiple_of: int = 0
    dynamic: bool = False
    dynamic_typing: bool = False
    array_type: str = ''
    section: str = ''
    note: str = ''
    example: Any = None

    def __post_init__(self) -> None:
        """Check that the default fits the declared range and choices."""
        if self.value_range is not None:
            low, high = self.value_range
            values = self.default if isinstance(self.default, list) else [self.default]
            if any(not low <= v <= high for v in values):
                raise ValueError(f'{self.name}: default {self.default!r} outside '
                                 f'{self.value_range}')
        if self.choices and self.default not in self.choices:
            raise ValueError(f'{self.name}: default {self.default!r} not in {self.choices}')
        if isinstance(self.default, list):
            self.check(self.default)
        if isinstance(self.default, list) and not self.default and not self.array_type:
            raise ValueError(f'{self.name}: an empty default needs array_type')

    def check(self, value: Any) -> None:
        """
        Raise ValueError saying why ``value`` is no value of this parameter, by its description.

        Checks ``choices``, a list's ``lengths`` and ``multiple_of``, and ``value_range`` (each
        element of a list, NaN included: a list parameter's range is checked here, rclpy checks
        only a scalar's). A value of another type (a string for a list with ``dynamic_typing``)
        is the node's to check.
        """
        if self.choices and isinstance(value, str) and value not in self.choices:
            raise ValueError(f'{self.name} must be one of {", ".join(self.choices)}, got '
                             f'{value!r}')
        many = isinstance(value, (list, tuple))
        if many and self.lengths and len(value) not in self.lengths:
            raise ValueError(f'{self.name} must have {self.count} values, got {len(value)}')
        if many and self.multiple_of and len(value) % self.multiple_of:
            raise ValueError(f'{self.name} must have {self.count} values, got {len(value)}')
        if self.value_range is None:
            return
        low, high = self.value_range
        for i, v in enumerate(value if many else [value]):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                continue
            if not low <= v <= high:
                where = f'{self.name}[{i}]' if many else self.name
                unit = f' {self.unit}' if self.unit else ''
                raise ValueError(f'{where} = {v:.6g}{unit} is outside its range {low:g} to '
                                 f'{high:g}{unit}')

    @property
    def count(self) -> str:
        """Return how many values the parameter has (``3``, ``3 or 4``, ...; '' for any)."""
        if self.lengths:
            return ' or '.join(str(n) for n in self.lengths)
        if self.multiple_of:
            return f'a multiple of {self.multiple_of} (x1, y1, z1, x2, ...)' \
                if self.multiple_of == 3 else f'a multiple of {self.multiple_of}'
        return ''

    @property
    def type_name(self) -> str:
        """Return the ROS type name (``double``, ``integer[]`` ...) of the parameter."""
        if self.array_type:
            return {STRING_ARRAY: 'string[]', DOUBLE_ARRAY: 'double[]'}[self.array_type]
        value = self.default
        suffix = ''
        if isinstance(value, list):
            value, suffix = value[0], '[]'
        for kind, name in ((bool, 'bool'), (int, 'integer'), (float, 'double'), (str, 'string')):
            if isinstance(value, kind):
                return name + suffix
        raise TypeError(f'{self.name}: no ROS type for {value!r}')

    @property
    def field_name(self) -> str:
        """Return the name of the parameter's field in its node's typed parameters."""
        return self.name.replace('.', '_')

    @property
    def python_type(self) -> str:
        """Return the Python type of the parameter's typed value (``Any``: dynamic typing)."""
        if self.dynamic_typing:
            return 'Any'
        element = _PYTHON_TYPES[self.type_name.removesuffix('[]')]
        return f'tuple[{element}, ...]' if self.type_name.endswith('[]') else element

    def typed(self, value: Any) -> Any:
        """
        Return ``value`` as this parameter's Python type, checked against its description.

        A list becomes a tuple; an integer is a float where a float is declared. Raises
        ValueError naming the parameter for a value of another type, or outside its range or
        choices (:meth:`check`). A parameter with ``dynamic_typing`` takes a value of any type
        as it is, a list as a tuple (its node parses it: a list as a YAML string, whole floats
        for integers); only its range and choices are checked.
        """
        element = _PYTHON_TYPES[self.type_name.removesuffix('[]')]
        result: Any
        if self.dynamic_typing:
            result = tuple(value) if isinstance(value, list) else value
        elif self.type_name.endswith('[]'):
            if not isinstance(value, (list, tuple)):
                raise ValueError(f'{self.name} must be of type {self.type_name}, got {value!r}')
            result = tuple(_as_element(element, v, self) for v in value)
        else:
            result = _as_element(element, value, self)
        self.check(result)
        return result

    @property
    def full_description(self) -> str:
        """Return the description with its unit, as ``ros2 param describe`` shows it."""
        return f'{self.description} [{self.unit}]' if self.unit else self.description


#: Python types of the ROS parameter types.
_PYTHON_TYPES = {'bool': 'bool', 'integer': 'int', 'double': 'float', 'string': 'str'}


def _as_element(element: str, value: Any, parameter: Parameter) -> Any:
    """Return one value (a list's element) as the Python type named ``element``."""
    if element == 'float' and isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if element == 'int' and isinstance(value, int) and not isinstance(value, bool):
        return value
    if element in ('bool', 'str') and type(value).__name__ == element:
        return value
    raise ValueError(f'{parameter.name} must be of type {parameter.type_name}, got {value!r}')


def typed_values(spec: NodeSpec, values: Mapping[str, Any]) -> dict[str, Any]:
    """
    Return ``{field name: typed value}`` of a node's parameter ``values`` (``{name: value}``).

    Every parameter ``spec`` declares, typed and checked by :meth:`Parameter.typed`: what the
    generated classes of :mod:`etdmp_ros.ros.node_parameters` are made from. KeyError names a
    parameter missing from ``values``.
    """
    return {p.field_name: p.typed(values[p.name]) for p in spec.all_parameters}


def parameter(name: str, default: Any, description: str, **kwargs: Any) -> Parameter:
    """Return a :class:`Parameter`; a tuple default becomes a list (the ROS array value)."""
    if isinstance(default, tuple):
        default = list(default)
    return Parameter(name, default, description, **kwargs)


#: The type of dmp_server's services whose request carries what it needs, so that concurrent
#: clients cannot mix (docs/dmp_server.md, "Requests that carry their settings"): named, typed
#: arguments (rcl_interfaces/Parameter) answered with successful and a reason. Standard types
#: only: the package builds no message package of its own.
ARGUMENTS_SERVICE_TYPE = 'rcl_interfaces/srv/SetParametersAtomically'


@dataclass(frozen=True)
class ServiceSpec:
    """
    A service whose request is named, typed arguments (:data:`ARGUMENTS_SERVICE_TYPE`).

    ``name`` is relative to the node (``~/<name>``). Each argument is a :class:`Parameter`: its
    default gives its type (and is its value when not given, unless it is ``required``); an
    argument named like one of the node's parameters is that parameter's value for this one
    request, with its range and choices.
    """

    name: str
    summary: str
    arguments: tuple[Parameter, ...]
    required: tuple[str, ...] = ()

    def argument(self, name: str) -> Parameter:
        """Return the argument :class:`Parameter` called ``name``; KeyError if none."""
        for a in self.arguments:
            if a.name == name:
                return a
        raise KeyError(f'~/{self.name} has no argument {name!r}')

    def values(self, given: Mapping[str, Any]) -> dict[str, Any]:
        """
        Return ``{argument: value}`` of a request's ``given`` arguments ({name: plain value}).

        Arguments not given are absent (the caller's defaults apply). Raises ValueError naming
        an unknown argument, a missing required one, a value of the wrong type, or one outside
        its range or choices (:meth:`Parameter.check`).
        """
        known = {a.name: a for a in self.arguments}
        unknown = sorted(set(given) - set(known))
        if unknown:
            raise ValueError(f'~/{self.name} has no argument {unknown[0]!r}; its arguments are '
                             f'{", ".join(known)}')
        missing = [name for name in self.required if name not in given]
        if missing:
            raise ValueError(f'~/{self.name} needs the argument {missing[0]!r}')
        values = {}
        for name, value in given.items():
            values[name] = _typed(known[name], value, self.name)
            known[name].check(values[name])
        return values


def _typed(argument: Parameter, value: Any, service: str) -> Any:
    """Return ``value`` as the type of ``argument``'s default; ValueError if it is not one."""
    default = [] if argument.array_type == DOUBLE_ARRAY else argument.default
    number = (int, float)
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, number) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif isinstance(default, str):
        ok = isinstance(value, str)
    else:   # a list of floats
        ok = isinstance(value, (list, tuple)) and all(
            isinstance(v, number) and not isinstance(v, bool) for v in value)
        value = [float(v) for v in value] if ok else value
    if not ok:
        raise ValueError(f'~/{service} argument {argument.name!r} must be a {argument.type_name}, '
                         f'got {type(value).__name__}')
    return value


@dataclass(frozen=True)
class NodeSpec:
    """
    One node of the system: what it is, how it starts, which parameters it declares.

    ``sim_time``: the node follows the simulation's /clock (``use_sim_time``): dmp_server,
    which stamps plans with the ROS clock, and the controller, which judges its joint states
    stale on the simulation's time (a stalled simulation is late, not lost). The others stamp
    with their inputs' stamps and need no clock.

    ``shared_memory``: the node receives camera images, which Fast DDS's shared-memory
    transport carries (config/fastdds.xml). The others talk UDP only (config/fastdds_udp.xml):
    a shared-memory send can wait seconds for another process (docs/reliability.md), and the
    simulation, the controller and dmp_server close the control loop.
    """

    name: str
    summary: str
    scene: tuple[Parameter, ...]
    parameters: tuple[Parameter, ...]
    node_class: str
    sim_time: bool = False
    shared_memory: bool = False
    config_header: str = field(default='', repr=False)
    services: tuple[ServiceSpec, ...] = ()

    @property
    def executable(self) -> str:
        """Return the executable's name (``ros2 run etdmp_ros <executable>``)."""
        return self.name

    @property
    def module(self) -> str:
        """Return the module that runs the node (``python -m <module>``)."""
        return f'etdmp_ros.nodes.{self.name}'

    @property
    def all_parameters(self) -> tuple[Parameter, ...]:
        """Return every parameter the node declares: its scene ones, then its own."""
        return self.scene + self.parameters

    def parameter(self, name: str) -> Parameter:
        """Return the :class:`Parameter` called ``name``; KeyError if the node has none."""
        for p in self.all_parameters:
            if p.name == name:
                return p
        raise KeyError(f'{self.name} has no parameter {name!r}')

    def defaults(self) -> dict[str, Any]:
        """Return ``{name: default}`` of every parameter the node declares."""
        return {p.name: p.default for p in self.all_parameters}

    def service(self, name: str) -> ServiceSpec:
        """Return the :class:`ServiceSpec` called ``name``; KeyError if the node has none."""
        for spec in self.services:
            if spec.name == name:
                return spec
        raise KeyError(f'{self.name} has no service {name!r}')
