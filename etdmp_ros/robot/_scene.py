"""
The workcell every node shares, validated: :class:`SceneConfig`.

Its values are flat parameter names (``camera.position``), as the nodes declare them; the
defaults and the file ``config/scene.yaml`` are the system description's
(:data:`etdmp_ros.ros.system.SCENE`, :func:`etdmp_ros.ros.system.scene_config`). The simulation
builds from a SceneConfig, and the nodes build it from their parameters with
:meth:`SceneConfig.from_parameters`.

Objects and the point that stands for each (all in base_link, metres; table top is z = 0):

- goal marker: a flat disc of radius ``goal_marker.radius``, 2 mm thick; ``goal_position`` is the
  centre of its TOP face (default z = 0.002: the disc lies on the table).
- obstacles: upright cylinders of height ``obstacle.height``; each position in
  ``obstacle_positions`` is the centre of a cylinder's TOP face (z equal to the height: it
  stands on the table). The top face is what a camera above sees. Obstacle ``i`` has radius
  ``obstacle_radii[i]``; those beyond that list (all, when it is empty) ``obstacle.radius``.
- bottle: an open cylindrical container standing on the table at ``bottle.position`` [x, y];
  its mouth is at z = ``bottle.height`` (the built-in "stir" demo's origin is on the bottle axis
  at the mouth).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from etdmp_ros import limits
from etdmp_ros.geometry.arrays import Array, Points3
from etdmp_ros.geometry.camera import CameraPose
import numpy as np

# Scene keys (flat ROS parameter names) that SceneConfig.from_parameters reads.
SCENE_PARAMETERS = (
    'tool_offset', 'initial_joint_positions', 'task_plane.origin',
    'camera.position', 'camera.orientation',
    'table.center', 'table.size', 'table.height', 'table.color',
    'whiteboard.size', 'whiteboard.color',
    'bottle.position', 'bottle.radius', 'bottle.height', 'bottle.color',
    'goal_position', 'goal_marker.radius', 'goal_marker.color',
    'obstacle_positions', 'obstacle_radii', 'obstacle.radius', 'obstacle.height',
    'obstacle.color',
)
#: Scene keys that may be missing (a YAML file cannot type an empty list: it leaves it unset).
OPTIONAL_SCENE_PARAMETERS = ('obstacle_radii',)
GOAL_MARKER_THICKNESS = 0.002
#: The tool held along the flange axis from tool0 to the tool tip (pen, stirrer): a cylinder of
#: PEN_RADIUS (m) whose last PEN_TIP_LENGTH (m) is its tip, of PEN_TIP_RADIUS (m; its clearance
#: to an obstacle counts from that surface). The simulation builds it, the arm check and
#: dmp_server's ``tool_radius`` take its sizes from here.
PEN_RADIUS = 0.009
PEN_TIP_RADIUS = 0.003
PEN_TIP_LENGTH = 0.02


def _vector(name: str, value: object, size: int | None = None,
            multiple_of: int | None = None) -> Array:
    try:
        array = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be a list of numbers, got {value!r}') from None
    if size is not None and array.size != size:
        raise ValueError(f'{name} must have {size} values, got {array.size}')
    if multiple_of is not None and array.size % multiple_of:
        raise ValueError(f'{name} must have a multiple of {multiple_of} values '
                         f'(x1, y1, z1, x2, ...), got {array.size}')
    if not np.all(np.isfinite(array)):
        raise ValueError(f'{name} must be finite, got {array.tolist()}')
    return array


def _array(value: object) -> Array:
    """Return a list parameter's value (checked by its description) as a float array."""
    return np.asarray(value, dtype=float).reshape(-1)


def _rgba(value: object) -> Array:
    """Return a colour parameter's value, rgb or rgba (checked by its description), as rgba."""
    rgb = _array(value)
    return np.append(rgb[:3], rgb[3] if rgb.size == 4 else 1.0)


def _in_workcell(name: str, array: Array) -> Array:
    big = np.flatnonzero(np.abs(array) > limits.MAX_REQUEST_COORDINATE)
    if big.size:
        raise ValueError(f'{name} has a coordinate of {array[big[0]]:.3g} m, beyond '
                         f'{limits.MAX_REQUEST_COORDINATE:g} m (MAX_REQUEST_COORDINATE): no place '
                         'of the workcell')
    return array


def parse_goal_position(value: object) -> Points3:
    """Return ``goal_position`` as a float array (3,); ValueError if not 3 bounded numbers."""
    return _in_workcell('goal_position', _vector('goal_position', value, size=3))


def parse_bottle_position(value: object) -> Array:
    """Return ``bottle.position`` as a float array (2,) [x, y]; ValueError if not 2 bounded."""
    return _in_workcell('bottle.position', _vector('bottle.position', value, size=2))


def parse_obstacle_radii(value: object) -> Array:
    """
    Return ``obstacle_radii`` (flat [r1, r2, ...], m) as an array (N,); [] means none given.

    ValueError unless every value is a finite positive number.
    """
    radii = _vector('obstacle_radii', value)
    if np.any(radii <= 0.0):
        raise ValueError(f'obstacle_radii must be positive (m), got {radii.tolist()}')
    return radii


def obstacle_radii_for(count: int, radii: Array, default: float) -> Array:
    """Return the radius (count,) of each of ``count`` obstacles: ``radii``, then ``default``."""
    radii = np.asarray(radii, dtype=float).reshape(-1)[:count]
    return np.concatenate([radii, np.full(count - len(radii), float(default))])


def parse_obstacle_positions(value: object) -> Points3:
    """
    Return ``obstacle_positions`` (flat [x1, y1, z1, x2, ...]) as an array (N, 3).

    An empty list means no obstacles. ValueError if the length is not a multiple of 3 or a value
    is not finite or beyond MAX_REQUEST_COORDINATE.
    """
    return _in_workcell('obstacle_positions',
                        _vector('obstacle_positions', value, multiple_of=3)).reshape(-1, 3)


#: The scene's objects that stand on the table and may be moved at runtime: their parameter,
#: its parser, the SceneConfig field of their radius, and what they are called.
MOVABLE = {
    'goal_position': (parse_goal_position, 'goal_radius', 'the goal marker'),
    'obstacle_positions': (parse_obstacle_positions, 'obstacle_radius', 'obstacle'),
    'bottle.position': (parse_bottle_position, 'bottle_radius', 'the bottle'),
}


@dataclass(frozen=True, eq=False)
class SceneConfig:
    """
    The validated workcell: robot start, tool, table, objects and camera pose (base_link, m).

    Build it with :meth:`from_parameters` (from a node's parameters, or
    :func:`etdmp_ros.ros.system.scene_config` for the defaults); the constructor takes the values
    as they are. Colours are rgba in 0..1.
    """

    tool_offset: np.ndarray
    initial_joint_positions: np.ndarray
    task_plane_origin: np.ndarray
    camera_pose: CameraPose
    table_center: np.ndarray
    table_size: np.ndarray
    table_height: float
    table_color: np.ndarray
    whiteboard_size: np.ndarray
    whiteboard_color: np.ndarray
    bottle_position: np.ndarray
    bottle_radius: float
    bottle_height: float
    bottle_color: np.ndarray
    goal_position: np.ndarray
    goal_radius: float
    goal_color: np.ndarray
    obstacle_positions: np.ndarray
    obstacle_radii: np.ndarray
    obstacle_radius: float
    obstacle_height: float
    obstacle_color: np.ndarray

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> SceneConfig:
        """
        Return the scene of flat parameter values (those of :data:`SCENE_PARAMETERS`).

        Each value must be one its description accepts (:data:`etdmp_ros.ros.system.SCENE`:
        its number of values and its range), as the values that reach here are: checked where
        they are typed (a node's parameters, :func:`etdmp_ros.ros.system.scene_config`). Checked
        here is what one value cannot say: the camera's orientation is a rotation, and each
        object that may move stands on the table clear of the robot's base (:meth:`placed`).
        Raises ValueError naming a missing parameter or what is wrong.
        """
        missing = [name for name in SCENE_PARAMETERS
                   if name not in params and name not in OPTIONAL_SCENE_PARAMETERS]
        if missing:
            raise ValueError(f'scene parameters missing: {", ".join(missing)}')
        p = params
        try:
            camera_pose = CameraPose(p['camera.position'], p['camera.orientation'])
        except ValueError as exc:
            raise ValueError(f'camera pose: {exc}') from None
        scene = cls(
            tool_offset=_array(p['tool_offset']),
            initial_joint_positions=_array(p['initial_joint_positions']),
            task_plane_origin=_array(p['task_plane.origin']), camera_pose=camera_pose,
            table_center=_array(p['table.center']), table_size=_array(p['table.size']),
            table_height=float(p['table.height']), table_color=_rgba(p['table.color']),
            whiteboard_size=_array(p['whiteboard.size']),
            whiteboard_color=_rgba(p['whiteboard.color']),
            bottle_position=parse_bottle_position(p['bottle.position']),
            bottle_radius=float(p['bottle.radius']), bottle_height=float(p['bottle.height']),
            bottle_color=_rgba(p['bottle.color']),
            goal_position=parse_goal_position(p['goal_position']),
            goal_radius=float(p['goal_marker.radius']), goal_color=_rgba(p['goal_marker.color']),
            obstacle_positions=parse_obstacle_positions(p['obstacle_positions']),
            obstacle_radii=parse_obstacle_radii(p.get('obstacle_radii') or []),
            obstacle_radius=float(p['obstacle.radius']),
            obstacle_height=float(p['obstacle.height']),
            obstacle_color=_rgba(p['obstacle.color']),
        )
        for name in MOVABLE:
            scene.placed(name, p[name])
        return scene

    def placed(self, name: str, value: object) -> Array:
        """
        Return the position of movable object ``name`` (a key of MOVABLE) parsed and checked.

        Each object stands on the table: its footprint (a disc of its radius about the point's
        x, y) lies on the table top, and clear of the robot's base (ROBOT_BASE_RADIUS about
        base_link's z axis). Heights are free within MAX_REQUEST_COORDINATE (a goal marker below
        the table top is hidden from the camera, as a test does). Raises ValueError saying
        where the object would be and why not (before, 1e308 or a bottle inside the robot's
        base were accepted).
        """
        parse, radius_field, what = MOVABLE[name]
        points = np.atleast_2d(parse(value))
        radius = getattr(self, radius_field)
        low = self.table_center - self.table_size / 2.0 + radius
        high = self.table_center + self.table_size / 2.0 - radius
        for k, point in enumerate(points):
            where = f'{what} {k + 1} ' if len(points) > 1 else f'{what} '
            where += f'at ({", ".join(f"{c:.3f}" for c in point)})'
            if np.any(point[:2] < low) or np.any(point[:2] > high):
                raise ValueError(
                    f'{name}: {where} is off the table: with its radius {radius:g} m it must '
                    f'stand within x {low[0]:.3f} to {high[0]:.3f} m, y {low[1]:.3f} to '
                    f'{high[1]:.3f} m (table.center, table.size)')
            axis = float(np.hypot(point[0], point[1]))
            if axis < limits.ROBOT_BASE_RADIUS + radius:
                raise ValueError(
                    f"{name}: {where} is inside the robot's base: {axis:.3f} m from its axis, "
                    f'less than ROBOT_BASE_RADIUS {limits.ROBOT_BASE_RADIUS:g} m + its radius '
                    f'{radius:g} m')
        return parse(value)
