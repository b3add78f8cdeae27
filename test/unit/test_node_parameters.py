"""Each node's typed parameters, generated from its description (etdmp_ros.ros.node_parameters)."""

import dataclasses

from etdmp_ros.ros import config_files, node_parameters, system
import pytest


def _classes():
    return [(spec, getattr(node_parameters, config_files.parameters_class_name(spec)))
            for spec in system.ALL_NODES]


@pytest.mark.parametrize('spec, cls', _classes(), ids=lambda v: getattr(v, 'name', ''))
def test_every_parameter_is_a_typed_field_holding_its_default(spec, cls):
    fields = {f.name: f for f in dataclasses.fields(cls)}
    assert list(fields) == [p.name.replace('.', '_') for p in spec.all_parameters]
    params = cls.from_values(spec.defaults())
    for p in spec.all_parameters:
        value = getattr(params, p.field_name)
        if isinstance(p.default, list):
            assert value == tuple(p.default)
        else:
            assert value == p.default and type(value) is type(p.default)
    with pytest.raises(dataclasses.FrozenInstanceError):
        params.port = 1


def test_values_are_checked_by_their_description():
    spec = system.node('perception')
    values = spec.defaults()
    params = node_parameters.PerceptionParameters
    assert params.from_values({**values, 'max_rate': 5}).max_rate == 5.0     # int for a double
    assert isinstance(params.from_values({**values, 'max_rate': 5}).max_rate, float)
    for name, bad, reason in (
            ('max_rate', -1.0, 'max_rate = -1 Hz is outside its range 0 to 1000 Hz'),
            ('max_rate', '5', "max_rate must be of type double, got '5'"),
            ('min_blob_area', 40.0, 'min_blob_area must be of type integer, got 40.0'),
            ('min_blob_area', True, 'min_blob_area must be of type integer, got True'),
            ('detect_bottle', 1, 'detect_bottle must be of type bool, got 1'),
            ('obstacle_radius_range', [0.01, 5.0],
             'obstacle_radius_range[1] = 5 m is outside its range 0.0001 to 1 m'),
            ('camera.position', [1.0, 'a', 0.5],
             "camera.position must be of type double[], got 'a'"),
            ('camera.position', 1.0, 'camera.position must be of type double[], got 1.0')):
        with pytest.raises(ValueError) as err:
            params.from_values({**values, name: bad})
        assert str(err.value) == reason
    with pytest.raises(KeyError):
        params.from_values({k: v for k, v in values.items() if k != 'warn_period'})
    # A list with dynamic typing may come as a YAML string, or whole floats: the node parses it.
    assert params.from_values({**values, 'goal_hsv_low': '[45, 100, 50]'}).goal_hsv_low == \
        '[45, 100, 50]'
    assert params.from_values({**values, 'goal_hsv_low': [45.0, 100, 50]}).goal_hsv_low == \
        (45.0, 100, 50)
    teach = node_parameters.TeachParameters
    with pytest.raises(ValueError, match='trace_source must be one of ground_truth, tool_pose'):
        teach.from_values({**system.defaults('teach'), 'trace_source': 'magic'})
