"""
The system, described once: its nodes, their parameters and how they are started.

Everything else is made from this module. The nodes declare their parameters from it
(:func:`etdmp_ros.ros.parameters.declare`); ``config/*.yaml`` and the parameter tables in
``docs/<node>.md`` are written from it (``make config``, checked by ``test/unit/test_system.py``);
the launch file, ``bringup``, the demo and the test fixtures start the nodes as
:data:`NODES` and :func:`parameter_files` say. To change a default, a range or a description,
change it here and run ``make config``.

A parameter is a :class:`Parameter`: name, default (its type is the ROS type), description,
unit, range, whether it may change at runtime, and an optional longer note (the comment above it
in the YAML file); the machinery is :mod:`etdmp_ros.ros.specs`. The workcell that every node
shares is :data:`SCENE` (``config/scene.yaml``, section ``/**``); each node declares the scene
parameters it needs (:attr:`NodeSpec.scene`) and its own (:attr:`NodeSpec.parameters`,
``config/<node>.yaml``). The tables: the workcell, ur10_sim, perception and teach in
``_workcell_parameters.py``; dmp_server (with its services) and the controller in
``_motion_parameters.py``; this module gathers them into the nodes.

Wiring: every node gets ``config/scene.yaml``, then its own ``config/<node>.yaml``, then
:func:`wiring_overrides` (``use_sim_time`` for the nodes that stamp with the ROS clock), then
the user's files. The module needs no ROS.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
import os
from pathlib import Path
from typing import Any

from etdmp_ros.robot import SceneConfig
from etdmp_ros.ros._motion_parameters import (CONTROLLER, CONTROLLER_SCENE, DMP_SERVER,
                                              DMP_SERVER_SCENE, DMP_SERVER_SERVICES,
                                              GOAL_OBJECTS)
from etdmp_ros.ros._workcell_parameters import (PERCEPTION, PERCEPTION_SCENE, SCENE, TEACH,
                                                TEACH_SCENE, UR10_SIM, UR10_SIM_SCENE)
from etdmp_ros.ros.paths import config_path
from etdmp_ros.ros.specs import (ARGUMENTS_SERVICE_TYPE, DOUBLE_ARRAY, NodeSpec, Parameter,
                                 ServiceSpec, STRING_ARRAY)

__all__ = [
    'ALL_NODES', 'ARGUMENTS_SERVICE_TYPE', 'CONTROLLER', 'CONTROLLER_SCENE', 'DMP_SERVER',
    'DMP_SERVER_SCENE', 'DMP_SERVER_SERVICES', 'DOUBLE_ARRAY', 'GOAL_OBJECTS', 'HOST_CHOICES',
    'HOSTS', 'NODE_NAMES', 'NODES', 'NodeSpec', 'PERCEPTION', 'PERCEPTION_SCENE', 'Parameter',
    'SCENE', 'SCENE_FILE', 'STRING_ARRAY', 'ServiceSpec', 'TEACH', 'TEACH_NODE', 'TEACH_SCENE',
    'UR10_SIM', 'UR10_SIM_SCENE', 'defaults', 'node', 'parameter_files', 'scene_config',
    'scene_defaults', 'select_nodes', 'wiring_overrides']

#: The nodes in start order (the simulation first: the others wait for its topics).
NODES = (
    NodeSpec('ur10_sim', 'MuJoCo UR10 workcell: joint states, /clock, camera, ground truth',
             UR10_SIM_SCENE, UR10_SIM, 'etdmp_ros.nodes.ur10_sim:UR10SimNode',
             config_header='Without parameter files the node uses these values too (they '
             'are its built-in defaults).'),
    NodeSpec('perception', 'goal and obstacles in base_link from the colour + depth camera',
             PERCEPTION_SCENE, PERCEPTION, 'etdmp_ros.nodes.perception:PerceptionNode',
             shared_memory=True,
             config_header='Everything here except reliable_images can be changed at runtime '
             '(ros2 param set /perception <name> <value>).'),
    NodeSpec('dmp_server', 'learns skills from demonstrations and serves /generalize',
             DMP_SERVER_SCENE, DMP_SERVER, 'etdmp_ros.nodes.dmp_server:DmpServer',
             sim_time=True, services=DMP_SERVER_SERVICES),
    NodeSpec('controller', 'follows /etdmp/path with the UR10 tool tip (closed-loop IK)',
             CONTROLLER_SCENE, CONTROLLER, 'etdmp_ros.nodes.controller:ControllerNode',
             sim_time=True),
)
NODE_NAMES = tuple(n.name for n in NODES)
#: The teaching page (docs/teach.md): started beside the system on demand (``make teach``, the
#: launch file's ``teach:=true``), not by ``make demo``, ``bringup`` or the launch file's default.
TEACH_NODE = NodeSpec('teach', 'the teaching page: draw a movement in a browser, teach it to '
                      'dmp_server, watch the UR10 write it', TEACH_SCENE, TEACH,
                      'etdmp_ros.nodes.teach:TeachNode', shared_memory=True,
                      config_header='The page is served to this machine only unless address '
                      'says otherwise.')
#: Every node of the package: the system's, then the teaching page's.
ALL_NODES = NODES + (TEACH_NODE,)
SCENE_FILE = 'scene.yaml'
#: Where the nodes run in a lab of two computers (docs/two_hosts.md): the robot's PC beside the
#: arm runs the UR driver (here ur10_sim) and the controller, which closes the 125 Hz loop with
#: it (a real UR's velocity interface holds its last command: that loop must not cross a link
#: that can fail); the workstation runs the camera processing and the skills. The launch file's
#: ``host:=robot|workstation``, bringup's ``--host``; ``all`` (the default) is every node.
HOSTS = {'robot': ('ur10_sim', 'controller'), 'workstation': ('perception', 'dmp_server')}
HOST_CHOICES = ('all', *HOSTS)


def select_nodes(host: str = 'all', nodes: str | Iterable[str] = '') -> tuple[str, ...]:
    """
    Return the names of the nodes to start on this computer, in start order (:data:`NODES`).

    ``host``: ``all`` or a key of :data:`HOSTS`; ``nodes``: node names (a list, or one string
    separated by commas or spaces) instead of a host's. ValueError, naming the choices, for an
    unknown host or node, or both given.
    """
    if isinstance(nodes, str):
        nodes = nodes.replace(',', ' ').split()
    nodes = list(nodes)
    if host not in HOST_CHOICES:
        raise ValueError(f'host must be one of {", ".join(HOST_CHOICES)}, got {host!r}')
    if nodes and host != 'all':
        raise ValueError(f'give host ({host!r}) or nodes ({",".join(nodes)}), not both')
    unknown = [n for n in nodes if n not in NODE_NAMES]
    if unknown:
        raise ValueError(f'no node {unknown[0]!r} (nodes: {", ".join(NODE_NAMES)})')
    chosen = set(nodes) if nodes else set(NODE_NAMES if host == 'all' else HOSTS[host])
    return tuple(n for n in NODE_NAMES if n in chosen)


def node(name: str) -> NodeSpec:
    """Return the :class:`NodeSpec` called ``name``; KeyError naming the nodes if none."""
    for spec in ALL_NODES:
        if spec.name == name:
            return spec
    raise KeyError(f'no node {name!r} (nodes: {", ".join(n.name for n in ALL_NODES)})')


def defaults(name: str) -> dict[str, Any]:
    """Return ``{parameter: default}`` of node ``name`` (scene parameters it declares + own)."""
    return node(name).defaults()


def scene_defaults() -> dict[str, Any]:
    """Return ``{parameter: default}`` of the whole workcell (config/scene.yaml)."""
    return {p.name: p.default for p in SCENE}


def scene_config(overrides: Mapping[str, Any] | None = None) -> SceneConfig:
    """
    Return the default workcell as a validated SceneConfig.

    ``overrides``: optional ``{flat name: value}`` replacing defaults, e.g.
    ``{'goal_position': [0.7, 0.2, 0.002]}``; ValueError names a bad value. Each value is
    typed and checked by its description (:data:`SCENE`), as a node's parameters are, before
    :meth:`SceneConfig.from_parameters` checks what no single value can say.
    """
    values = scene_defaults()
    values.update(overrides or {})
    return SceneConfig.from_parameters({p.name: p.typed(values[p.name]) for p in SCENE})


def parameter_files(name: str, config_dir: str | os.PathLike[str] | None = None) -> list[Path]:
    """
    Return the parameter files of node ``name`` in order: scene.yaml, then ``<name>.yaml``.

    From ``config_dir`` if given, else from the package's config folder (share/etdmp_ros).
    """
    node(name)
    if config_dir is not None:
        return [Path(config_dir) / SCENE_FILE, Path(config_dir) / f'{name}.yaml']
    return [config_path(SCENE_FILE), config_path(f'{name}.yaml')]


def wiring_overrides(name: str) -> dict[str, Any]:
    """Return the parameters the system sets on node ``name`` after its files (sim time)."""
    return {'use_sim_time': True} if node(name).sim_time else {}


def _check_names() -> None:
    placed = sorted(n for names in HOSTS.values() for n in names)
    if placed != sorted(NODE_NAMES):
        raise ValueError(f'HOSTS must place every node once, got {placed}')
    for spec in ALL_NODES:
        names = [p.name for p in spec.all_parameters]
        if len(names) != len(set(names)):
            raise ValueError(f'{spec.name}: a parameter is declared twice')


_check_names()
