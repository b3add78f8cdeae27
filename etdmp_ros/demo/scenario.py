"""
The demo's scenario for one skill: the parameter files read, the skill's layout, the overrides.

The letter G uses config/scene.yaml's ``goal_position`` and ``obstacle_positions`` as shipped
(they are G's layout: the pen starts in another quadrant of the goal than the demonstration, two
obstacles sit 20 mm beside the obstacle-free path). The other 2D skills get their own layout
(:data:`LAYOUTS`, given to ``ur10_sim`` like ``ros2 param set`` would): the goal 90 degrees round
from the demonstration's start direction, so that each is drawn upright as the camera sees it,
about 0.2 m tall, with two obstacles 20-35 mm beside its obstacle-free path (chosen offline with
the planning core; layout ``scene`` keeps the scene file's). ``stir`` (3D, base_link): the
simulation starts with the stirrer above the bottle, its start direction turned 30 degrees about
the vertical from the demonstration's (:data:`STIR_START_TURN_DEG`); the goal is explicit: the
bottle's mouth centre plus the demonstration's goal offset (the built-in stir demo's origin is
the mouth), near the bottom, because the marker on the table cannot be seen inside a bottle.
With ``perceived_bottle`` (the demo's ``--move-goal`` for stir) the goal is the perceived
bottle instead: dmp_server's ``goal_object: bottle`` and ``goal_offset`` the demonstration's
goal offset, the request's goal frame empty, so that a plan in execution follows the bottle.
The request's start stays empty (the tool's current position). Letters are written in 4 s,
wiping in 5 s (:data:`DURATIONS`, dmp_server's ``duration``).

A stir taught by moving the arm (``demo_file``: a rosbag2 ``.mcap`` of ``/joint_states``, what
:mod:`etdmp_ros.demo.kinesthetic` records; the demo's ``--demo-file``) replaces the built-in one:
dmp_server learns it from the file (``demo_files``) and plans it, and the demonstration the run
is measured against is the recorded tool path (by the same forward kinematics), taken relative
to the bottle's mouth. The stirrer then starts :data:`TAUGHT_STIR_TURN_DEG` round the bottle's
axis from where the recording started, in another quadrant, with dmp_server's 3D ``mode`` 2
(the vertical follows the 1D rule, the horizontal plane the 2D one): the movement turns about
the bottle's axis and stays in the bottle, where mode 1's Rodrigues rotation would tilt a turn
this large out of it; and with ``orientation_mode`` ``tool``: the scripted hand held the tool's
orientation, which the repeat keeps rather than turning it by 150 degrees with the movement.

Each node gets the system's parameter files (:func:`etdmp_ros.ros.system.parameter_files`), then an
overrides file of its own: the system's wiring (:func:`etdmp_ros.ros.system.wiring_overrides`), the
skill's layout and the caller's parameters.
"""

from dataclasses import dataclass, field

import math
from pathlib import Path


from etdmp_ros.dmp import builtin_demo, Demonstration, euclidean_transform

from etdmp_ros.geometry import quaternion as quat

from etdmp_ros.geometry.task_plane import TaskPlane

from etdmp_ros.robot import UR10Model

from etdmp_ros.ros import system

from etdmp_ros.ros.config_files import read_node_parameters, read_parameter_file

import numpy as np
import yaml

SKILLS = ('G', 'P', 'R', 'W', 'wipe', 'stir')
#: Layouts of the 2D skills other than G on the shipped scene (default start pose and task
#: plane): ur10_sim's goal_position and obstacle_positions (base_link, m). G uses scene.yaml.
LAYOUTS = {
    'P': ([0.898, 0.111, 0.002], [0.826, 0.127, 0.08, 0.828, 0.233, 0.08]),
    'R': ([0.993, 0.256, 0.002], [0.83, 0.126, 0.08, 0.843, 0.222, 0.08]),
    'W': ([0.827, 0.329, 0.002], [0.909, 0.164, 0.08, 0.974, 0.257, 0.08]),
    # A wiping motion covers an area with no room for a 5 cm cylinder: beside its turns.
    'wipe': ([0.83, 0.256, 0.002], [0.746, 0.248, 0.08, 0.908, 0.296, 0.08]),
}
#: Plan duration (dmp_server ``duration``, s) per skill; stir: its demonstration's own 5 s.
#: The letters are demonstrated in 2 s (wipe in 4 s): written 0.2 m tall, with the detours
#: around the obstacles, in that time they ask the elbow for more than its acceleration limit
#: (35 rad/s^2) at their sharpest turns and the tracking error grows to millimetres there.
DURATIONS = {'G': 4.0, 'P': 4.0, 'R': 4.0, 'W': 4.0, 'wipe': 5.0}
#: Stir: the stirrer starts at the demonstration's start offset from the goal turned by this
#: angle about the vertical and scaled (the default Rodrigues ET-DMP then tilts the movement
#: by 9 degrees, which keeps it inside the bottle; the plain DMP squeezes its circles).
STIR_START_TURN_DEG = 30.0
STIR_START_SCALE = 0.9
#: A taught stir (``demo_file``) is repeated from its recorded start turned by this angle about
#: the bottle's axis (another quadrant), not scaled.
TAUGHT_STIR_TURN_DEG = 150.0


#: ``--move-goal``: the goal marker moves by this much (base_link, m) per skill, at
#: MOVE_GOAL_AT of the movement: 4 cm along the task plane, away from the skill's obstacles.
MOVE_GOAL_BY = {'G': [0.0, 0.04, 0.0], 'P': [0.0, 0.04, 0.0], 'R': [0.04, 0.0, 0.0],
                'W': [0.0, 0.04, 0.0], 'wipe': [0.0, -0.04, 0.0]}
#: When the goal moves (``--move-goal``): this fraction of the letter's duration (dmp_server's
#: ``duration``, the plan's without its obstacle margin) after tracking began; for G about 35 %
#: of the letter's length is written by then.
MOVE_GOAL_AT = 0.4
#: Stir with ``--move-goal``: the bottle moves by this (base_link, m; ur10_sim's
#: ``bottle.position``) at MOVE_BOTTLE_AT of the stir's duration, while the stirrer comes down
#: towards the mouth (at 5 % it is 9 cm above it and enters it at about 22 %; the re-plan takes
#: effect some 0.2 s after the move). Not later: a bottle put 2 cm away in an instant while the
#: stirrer circles 25 mm from its axis inside it would push its wall through the stirrer before
#: any plan could follow, and a move at 10 % (since plans end at rest in tau, the stir's 5 s)
#: left the re-planned stirrer grazing the rim (3-5 ticks of contact, 7.3 mm between the tip and
#: the wall; at 5 %: none, 9.0 mm).
MOVE_BOTTLE_BY = [0.0, 0.02, 0.0]
MOVE_BOTTLE_AT = 0.05


class ScenarioError(ValueError):
    """The scenario cannot be set up (an unknown node, a start pose out of reach)."""


@dataclass
class Scenario:
    """
    What the demo needs from the parameter files (config folder + the skill's layout).

    ``config_dir``: the folder of the parameter files (None: the package's); ``parameters``:
    extra node parameters, ``{node: {name: value}}``, after the skill's layout;
    ``demo_file``: a recorded stir to use instead of the built-in one (see the module docstring).
    """

    config_dir: Path
    skill: str
    layout: str = 'skill'
    parameters: dict = field(default_factory=dict)
    demo_file: Path = None
    perceived_bottle: bool = False
    scene: dict = field(init=False)
    server: dict = field(init=False)
    controller: dict = field(init=False)
    plane: TaskPlane = field(init=False)
    demo: object = field(init=False)
    overrides: dict = field(init=False)
    explicit_goal: np.ndarray = field(init=False, default=None)

    def __post_init__(self):
        """Read the files; work out the per-node overrides of this skill's scene."""
        if self.config_dir is not None:
            self.config_dir = Path(self.config_dir)
        # Every node's files start with the scene file.
        self.scene = read_parameter_file(system.parameter_files('ur10_sim', self.config_dir)[0])
        self.server = read_node_parameters('dmp_server', self.config_dir)
        self.controller = read_node_parameters('controller', self.config_dir)
        self.plane = TaskPlane.create(self.scene['task_plane.origin'],
                                      self.scene['task_plane.x_axis'],
                                      self.scene['task_plane.y_axis'],
                                      self.server['task_plane.scale'])
        self.demo = builtin_demo(self.skill)
        self.start_turn_deg, self.start_scale = STIR_START_TURN_DEG, STIR_START_SCALE
        self.overrides = {name: dict(system.wiring_overrides(name)) for name in system.NODE_NAMES}
        self.overrides['dmp_server']['skill'] = self.skill
        if self.demo_file is not None:
            self._use_taught_stir()
        self.overrides['ur10_sim'].update(self._simulation_layout())
        if self.skill in DURATIONS:
            self.overrides['dmp_server']['duration'] = DURATIONS[self.skill]
            self.server['duration'] = DURATIONS[self.skill]
        for name, values in self.parameters.items():
            if name not in self.overrides:
                raise ScenarioError(f'no node {name!r} (nodes: {", ".join(system.NODE_NAMES)})')
            self.overrides[name].update(values)
        if 'control_rate' in self.parameters.get('controller', {}):
            self.controller['control_rate'] = self.parameters['controller']['control_rate']
        # What the run is measured with (its duration, its tau) is what dmp_server is given.
        self.server.update(self.parameters.get('dmp_server', {}))

    def _use_taught_stir(self):
        """Replace the built-in stir by the recorded one of ``demo_file``."""
        from etdmp_ros.skills.library import load_demonstration
        if self.skill != 'stir':
            raise ScenarioError(f'a demonstration file replaces the built-in stir (a 3D skill '
                                f'taught in the bottle); the skill is {self.skill!r}')
        self.demo_file = Path(self.demo_file).expanduser().resolve()
        model = UR10Model(tool_offset=self.scene['tool_offset'])
        try:
            recorded = load_demonstration(self.demo_file, self.plane, recorded_dim='3d',
                                          kinematics=model)
        except ValueError as err:
            raise ScenarioError(str(err)) from None
        self.demo = Demonstration(recorded.name, recorded.positions - self.bottle_mouth,
                                  recorded.t, recorded.orientations)
        self.start_turn_deg, self.start_scale = TAUGHT_STIR_TURN_DEG, 1.0
        # The scripted hand holds the tool's orientation: the recording's is constant, and mode
        # 'demo' would turn it by the 150 degrees with the movement (a 10 s turn of the wrist
        # during the approach, for a stirrer that looks the same either way).
        self.overrides['dmp_server'].update(skill=recorded.name, mode=2, orientation_mode='tool',
                                            demo_files=[str(self.demo_file)])
        self.server.update(mode=2, orientation_mode='tool')

    def _simulation_layout(self):
        """Return ur10_sim's overrides: the skill's goal and obstacles, the stir start pose."""
        sim = {}
        if self.layout == 'skill' and self.skill in LAYOUTS:
            goal, obstacles = LAYOUTS[self.skill]
            sim.update(goal_position=[float(v) for v in goal],
                       obstacle_positions=[float(v) for v in obstacles])
        if self.skill == 'stir':
            self.explicit_goal = self.bottle_mouth + self.demo.positions[-1]
            sim['initial_joint_positions'] = stir_start_joints(self).tolist()
            if self.perceived_bottle:
                self.overrides['dmp_server'].update(
                    goal_object='bottle', goal_offset=[float(v) for v in self.goal_offset])
        elif self.perceived_bottle:
            raise ScenarioError(f'only stir targets the bottle, not {self.skill!r}')
        return sim

    @property
    def goal_offset(self):
        """Stir: the goal relative to the bottle's mouth (the demonstration's own goal)."""
        return np.asarray(self.demo.positions[-1], dtype=float)

    @property
    def request_goal(self):
        """Return the goal of the demo's /generalize requests: explicit, or None (perceived)."""
        return None if self.perceived_bottle else self.explicit_goal

    @property
    def goal_move(self):
        """How the goal marker (stir: the bottle) moves with ``--move-goal`` (base_link, m)."""
        if self.skill == 'stir':
            return np.array(MOVE_BOTTLE_BY, dtype=float)
        if self.skill not in MOVE_GOAL_BY:
            raise ScenarioError(f'--move-goal moves the perceived goal marker; the goal of '
                                f'{self.skill!r} is explicit (skills: {", ".join(MOVE_GOAL_BY)})')
        return np.array(MOVE_GOAL_BY[self.skill], dtype=float)

    @property
    def move_at(self):
        """Fraction of the movement's duration at which ``--move-goal`` moves the goal."""
        return MOVE_BOTTLE_AT if self.skill == 'stir' else MOVE_GOAL_AT

    @property
    def planar(self):
        """Whether the skill is a 2D one (drawn in the task plane)."""
        return self.demo.positions.shape[1] == 2

    @property
    def bottle_mouth(self):
        """Centre of the bottle's mouth (base_link)."""
        return np.array([*self.scene['bottle.position'], self.scene['bottle.height']], float)

    @property
    def tool_rotation(self):
        """Tool orientation of every planned pose (dmp_server's ``tool_orientation``)."""
        return quat.to_matrix(quat.normalized(self.server['tool_orientation']))

    @property
    def start_rotation(self):
        """
        Stir: the tool's orientation at the start, the plan's first (no turn before tracking).

        The demonstration's first orientation turned by the plan's transform (orientation_mode
        ``demo``, docs/orientation.md), else the tool orientation of every pose.
        """
        demo = self.demo
        if demo.orientations is None or self.server.get('orientation_mode', 'demo') == 'tool':
            return self.tool_rotation
        transform = euclidean_transform(demo.positions[0] - demo.positions[-1],
                                        stir_start(self) - self.explicit_goal,
                                        self.server.get('mode', 1),
                                        self.server.get('independent_axis', 2))
        turned = quat.multiply(quat.from_matrix(transform.R.T), demo.orientations[0])
        return quat.to_matrix(quat.normalized(turned))

    @property
    def obstacle_radii(self):
        """Return each obstacle's radius (m) in the simulation: obstacle_radii, obstacle.radius."""
        from etdmp_ros.robot import obstacle_radii_for
        sim = {**self.scene, **self.overrides['ur10_sim']}
        return obstacle_radii_for(self.obstacle_count, sim.get('obstacle_radii') or [],
                                  sim['obstacle.radius'])

    @property
    def obstacle_count(self):
        """Return how many obstacles the simulation shows (the layout's or the scene's)."""
        positions = self.overrides['ur10_sim'].get('obstacle_positions',
                                                   self.scene['obstacle_positions'])
        return len(np.asarray(positions).reshape(-1, 3))

    def param_files(self, name, directory):
        """Write node ``name``'s overrides file into ``directory``; return its parameter files."""
        path = Path(directory) / f'{name}_overrides.yaml'
        path.write_text(yaml.safe_dump({name: {'ros__parameters': self.overrides[name]}}))
        return [*system.parameter_files(name, self.config_dir), path]


def stir_start(scenario):
    """Return where the stirrer starts (base_link): see :data:`STIR_START_TURN_DEG`."""
    a = math.radians(scenario.start_turn_deg)
    turn = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                     [0.0, 0.0, 1.0]])
    offset = scenario.demo.positions[0] - scenario.demo.positions[-1]
    return scenario.explicit_goal + scenario.start_scale * turn @ offset


def stir_start_joints(scenario, rotation=None):
    """
    Return the simulation's initial joints for stir: the stirrer at :func:`stir_start`.

    ``rotation``: the tool's (3, 3), default the plan's first (:attr:`Scenario.start_rotation`).
    """
    model = UR10Model(tool_offset=scenario.scene['tool_offset'])
    q0 = np.array(scenario.scene['initial_joint_positions'], dtype=float)
    target = stir_start(scenario)
    # Turn the base towards the bottle first, so Newton starts from the same elbow-up posture.
    p0 = model.tool_position(q0)
    q0[0] += math.atan2(target[1], target[0]) - math.atan2(p0[1], p0[0])
    rotation = scenario.start_rotation if rotation is None else rotation
    q, error = model.solve_pose(target, rotation, q0, iterations=200,
                                tolerance=1e-9)
    if np.linalg.norm(error[:3]) > 1e-5 or np.any(q < model.lower) or np.any(q > model.upper):
        raise ScenarioError(f'cannot put the tool at {np.round(target, 3).tolist()}')
    return q
