"""
Reference plans and plants shared by the controller tests and benchmark (not a test module).

- :func:`g_plan`: the ET-DMP plan of letter G on the task plane of config/scene.yaml, 0.02 m per
  demo unit, over the demonstration's nominal duration (2 s), pen pointing down
  (:func:`letter_plan`: another letter so).
- :func:`stir_plan`: the 3D stirring skill generalized into the bottle of the scene.
- :func:`run_kinematic`: a pure kinematic plant ``q += qd_cmd * T`` whose commands act one
  control period late (what a ros2_control velocity interface does).
"""

from dataclasses import dataclass, field

from etdmp_ros.dmp import builtin_demo, learn
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.robot import PoseTrajectory, UR10Model
from etdmp_ros.ros import system
import numpy as np

SCENE = system.scene_defaults()
TOOL_OFFSET = tuple(SCENE['tool_offset'])
Q_INITIAL = np.array(SCENE['initial_joint_positions'], dtype=float)
PLANE = TaskPlane.create(SCENE['task_plane.origin'], SCENE['task_plane.x_axis'],
                         SCENE['task_plane.y_axis'], scale=0.02)
#: Where the stirrer ends: the demonstration's own goal relative to the scene's bottle mouth
#: (the built-in "stir" demo has its origin on the bottle axis at the mouth).
STIR_GOAL = (np.array([*SCENE['bottle.position'], SCENE['bottle.height']])
             + builtin_demo('stir').positions[-1])


def tool_down():
    """Return the tool rotation at the scene's initial joints (pointing down at the table)."""
    return UR10Model(TOOL_OFFSET).frame_pose(Q_INITIAL)[1]


def g_plan(dt=0.004, goal_uv=(0.0, 0.0), rotate_deg=90.0):
    """
    Return (PoseTrajectory, t, positions) of the ET-DMP letter G on the task plane.

    The start is the demonstration's own start offset rotated by ``rotate_deg`` about the goal,
    so ET-DMP draws a rotated G (its point); duration: the demonstration's 2 s.
    """
    return letter_plan('G', dt, goal_uv, rotate_deg)


def letter_plan(name, dt=0.004, goal_uv=(0.0, 0.0), rotate_deg=90.0):
    """Return (PoseTrajectory, t, positions) of a built-in 2D skill as :func:`g_plan` does G."""
    demo = builtin_demo(name)
    skill = learn(demo)
    a = np.radians(rotate_deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    goal = np.asarray(goal_uv, dtype=float)
    start = goal + rot @ (demo.positions[0] - demo.positions[-1])
    traj = skill.generalize(start, goal, method='etdmp', dt=dt)
    positions = PLANE.from_plane(traj.x)
    rotations = np.repeat(tool_down()[None], len(positions), axis=0)
    return PoseTrajectory(traj.t, positions, rotations), traj.t, positions


def stir_plan(dt=0.01, goal=STIR_GOAL, rotate_deg=90.0):
    """Return (PoseTrajectory, t, positions) of the stirring skill ending in the bottle."""
    demo = builtin_demo('stir')
    skill = learn(demo)
    a = np.radians(rotate_deg)
    rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0, 0, 1.0]])
    goal = np.asarray(goal, dtype=float)
    start = goal + rot @ (demo.positions[0] - demo.positions[-1])
    traj = skill.generalize(start, goal, method='etdmp', mode=1, dt=dt)
    rotations = np.repeat(tool_down()[None], len(traj.x), axis=0)
    return PoseTrajectory(traj.t, traj.x, rotations), traj.t, traj.x


def turning_plan(name, rotate_deg=90.0, goal_orientation=None, start=None, goal=None):
    """
    Return (PoseTrajectory, Plan) of ``stir`` or ``wipe`` with their own orientations.

    dmp_server's plan (``plan_path``, default settings): ``stir`` into the scene's bottle,
    ``wipe`` on the task plane, from the demonstration's start offset turned by ``rotate_deg``
    about the goal (or from ``start`` to ``goal``, base_link); every pose has the tool
    orientation the skill gives it (the stirrer's tilt, the sponge's yaw, turned with the
    motion), or converges to ``goal_orientation``.
    """
    from etdmp_ros.skills.planning import plan_path
    from etdmp_ros.geometry import quaternion as quat
    given = None if start is None else (start, goal)
    demo = builtin_demo(name)
    skill = learn(demo)
    a = np.radians(rotate_deg)
    rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0, 0, 1.0]])
    if name == 'stir':
        goal, plane = STIR_GOAL, None
        start = goal + rot @ (demo.positions[0] - demo.positions[-1])
    else:
        plane = PLANE
        goal = PLANE.from_plane(np.array([0.0, 0.0]))
        offset = PLANE.from_plane(demo.positions[0] - demo.positions[-1]) - PLANE.origin
        start = goal + rot @ offset
    if given is not None:
        start, goal = given
    plan = plan_path(skill, start, goal, plane=plane, goal_orientation=goal_orientation)
    rotations = quat.to_matrix(quat.normalized(plan.orientations))
    return PoseTrajectory(plan.t, plan.positions, rotations), plan


@dataclass
class Log:
    """What a closed-loop run recorded, one row per control step."""

    t: list = field(default_factory=list)
    q: list = field(default_factory=list)
    qd: list = field(default_factory=list)
    status: list = field(default_factory=list)
    error: list = field(default_factory=list)
    tool: list = field(default_factory=list)
    condition: list = field(default_factory=list)
    reason: list = field(default_factory=list)

    def arrays(self):
        """Return the numeric fields as a dict of numpy arrays."""
        return {name: np.array(getattr(self, name)) for name in
                ('t', 'q', 'qd', 'error', 'tool', 'condition')}

    def errors(self, status='tracking'):
        """Return the tracking errors in metres of the steps in ``status``."""
        return np.array([e for e, s in zip(self.error, self.status) if s == status])


def run_kinematic(controller, q0, duration, delay_periods=1, events=(), stop_when_idle=True):
    """
    Close the loop around a kinematic plant; return (Log, final q).

    Commands act ``delay_periods`` control periods after they are computed. ``events``: pairs
    (time in s, callable(controller)) run before the step at that time.
    """
    T = controller.period
    q = np.array(q0, dtype=float)
    queue = [np.zeros(6)] * delay_periods
    events = sorted(events, key=lambda e: e[0])
    log = Log()
    for k in range(int(round(duration / T))):
        t = k * T
        while events and events[0][0] <= t + 1e-9:
            events.pop(0)[1](controller)
        command = controller.step(q, t)
        log.t.append(t)
        log.q.append(q.copy())
        log.qd.append(command.qd.copy())
        log.status.append(command.status)
        log.error.append(command.tracking_error)
        log.tool.append(command.tool_position)
        log.condition.append(command.condition)
        log.reason.append(command.reason)
        queue.append(command.qd)
        q = q + queue.pop(0) * T
        if stop_when_idle and command.status == 'idle' and k > 2 and not events \
                and not np.any(command.qd):
            break
    return log, q


def path_time_offset(path, t, reference):
    """
    Return ``t0`` such that ``reference[k] = path.pose(t[k] - t0)`` (positions), or raise.

    Found from the sample where the path moves fastest (a point there has one path time),
    by a dense search then bisection-free refinement; the caller checks every other sample.
    """
    t = np.asarray(t, dtype=float)
    reference = np.asarray(reference, dtype=float)
    speed = np.array([np.linalg.norm(path.velocity(s)) for s in path.t])
    tau_fast = path.t[int(np.argmax(speed))]
    grid = np.linspace(0.0, path.duration, int(path.duration / 1e-4) + 1)
    points = np.array([path.pose(s)[0] for s in grid])
    # The reference sample closest in time to the fastest part: search its path time.
    k = int(np.argmin(np.min(np.linalg.norm(reference[:, None] - path.pose(tau_fast)[0],
                                            axis=2), axis=1)))
    tau = grid[int(np.argmin(np.linalg.norm(points - reference[k], axis=1)))]
    for step in (1e-5, 1e-6, 1e-7):
        local = tau + step * np.arange(-20, 21)
        tau = local[int(np.argmin([np.linalg.norm(path.pose(s)[0] - reference[k])
                                   for s in local]))]
    return t[k] - tau
