"""
What dmp_server refuses beyond the planning's own checks: goals, plans the arm cannot follow.

- :func:`check_goal`: a goal out of the arm's reach, or too far from the task plane (2D skills).
- :class:`ArmChecks`: a plan the arm cannot follow in time (joint velocity and acceleration
  limits along one IK of the plan), or along which a part of the arm would come closer to an
  obstacle than ``arm_clearance``.
- :func:`check_usable`: a taught demonstration whose plans would have fewer than 3 poses.

Each raises ValueError with the reason given to the user (it names the parameters to change).
"""

from typing import NoReturn, Optional

from etdmp_ros import limits
from etdmp_ros.dmp import Demonstration, Skill
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.robot import DEFAULT_ACCELERATION_LIMITS, UR10Model
from etdmp_ros.robot._arm_check import arm_obstacle_violation, ArmGeometry, ArmViolation
from etdmp_ros.robot._timing import joint_timing_violation, plan_joints, TimingViolation
from etdmp_ros.skills.planning import Plan, PlanSettings, Workspace
import numpy as np
from numpy.typing import NDArray


def check_goal(goal: NDArray[np.float64], skill: Skill, workspace: Workspace,
               plane: TaskPlane, skill_name: str) -> None:
    """Refuse a goal (3,) out of the arm's reach, or too far from the task plane (2D skills)."""
    where = f'goal ({goal[0]:.3f}, {goal[1]:.3f}, {goal[2]:.3f})'
    outside = workspace.violation(goal)
    if outside is not None:
        raise ValueError(f"{where} is out of the UR10's reach: {outside[1]}")
    if skill.dim == 2:
        height = float(plane.distance(goal.reshape(1, 3))[0])
        if abs(height) > limits.MAX_GOAL_PLANE_DISTANCE:
            raise ValueError(f'{where} is {height:.3f} m from the task plane, more than '
                             f'MAX_GOAL_PLANE_DISTANCE = {limits.MAX_GOAL_PLANE_DISTANCE:g} '
                             f'm: not a goal for the 2D skill {skill_name!r}')


def check_usable(demo: Demonstration, plan: PlanSettings) -> None:
    """
    Raise ValueError if ``demo`` could not be generalized into a plan with these settings.

    What the Demonstration and learning check already (sample count, duration, extent, finite
    products: etdmp_ros.limits) is not repeated; here: a plan of the demonstration's own
    duration must have at least 3 poses at output_period.
    """
    if plan.duration == 0.0 and demo.duration < 2 * plan.output_period:
        raise ValueError(f'it lasts {demo.duration:.3g} s, less than two output periods '
                         f'({plan.output_period:g} s): a plan of its own duration '
                         'would have fewer than 3 poses')


class ArmChecks:
    """The checks of a plan against the arm (``model``: a UR10Model of its own; not shared)."""

    def __init__(self, model: UR10Model) -> None:
        """Check with ``model`` (its tool offset) and the arm's geometry built from it."""
        self.model = model
        self.arm = ArmGeometry(model)

    def check(self, plan: Plan, skill: Skill, joints_now: NDArray[np.float64],
              obstacles: NDArray[np.float64], radii: NDArray[np.float64],
              settings: PlanSettings, timing: bool = True,
              arm_clearance: Optional[float] = None) -> None:
        """
        Refuse a plan the arm cannot follow in time, or along which it would touch an obstacle.

        One IK along the plan (TIMING_CHECK_SAMPLES poses from ``joints_now`` (6,)) serves both
        checks: ``timing``, and the arm's clearance when ``arm_clearance`` (m) is given;
        ``obstacles`` (m, 3) and ``radii`` (m,) are the obstacles as perceived (top-face centres
        in base_link, not projected onto the plane).
        """
        if not timing and arm_clearance is None:
            return
        rotations = quat.to_matrix(quat.normalized(plan.orientation))
        idx, joints, violation = plan_joints(self.model, plan.positions, rotations, plan.t,
                                             joints_now, limits.TIMING_CHECK_SAMPLES)
        if timing:
            if violation is None:
                fraction = limits.TIMING_LIMIT_FRACTION
                violation = joint_timing_violation(
                    plan.t[idx], joints, self.model.velocity_limits * fraction,
                    np.asarray(DEFAULT_ACCELERATION_LIMITS) * fraction)
            if violation is not None:
                _refuse_timing(violation, plan, skill, settings)
        if arm_clearance is not None and len(joints):
            touch = arm_obstacle_violation(self.arm, joints, plan.t[idx], obstacles, radii,
                                           arm_clearance)
            if touch is not None:
                _refuse_touch(touch, obstacles, radii, arm_clearance)


def _refuse_touch(touch: ArmViolation, obstacles: NDArray[np.float64],
                  radii: NDArray[np.float64], arm_clearance: float) -> NoReturn:
    """Raise the arm check's refusal (an ArmViolation): the part, the obstacle, when."""
    o, r, t = obstacles[touch.obstacle], radii[touch.obstacle], touch.t
    how = (f'{-touch.gap * 1000:.0f} mm into' if touch.gap < 0.0 else
           f'within {touch.gap * 1000:.1f} mm of')
    raise ValueError(
        f'the plan would bring the {touch.part} {how} the obstacle at ({o[0]:.3f}, '
        f'{o[1]:.3f}, {o[2]:.3f}) (radius {r * 1000:.0f} mm) at t = {t:.2f} s, closer than '
        f'arm_clearance {arm_clearance * 1000:g} mm (IK of the plan from the '
        'current joints: the plan keeps the tool clear of obstacles, not the arm); move the '
        'obstacle or the start')


def _refuse_timing(violation: TimingViolation, plan: Plan, skill: Skill,
                   settings: PlanSettings) -> NoReturn:
    """Raise the timing check's refusal; say the shortest feasible duration."""
    tau = settings.duration or skill.tau
    if np.isfinite(violation.slowdown):
        needed = np.ceil(tau * violation.slowdown * 100.0) / 100.0
        hint = (f'; the shortest feasible duration is about {needed:.2f} s (parameter '
                f'duration, now {tau:g} s)')
    elif len(plan.t) < 3:
        hint = (f'; duration {tau:g} s is too short for output_period '
                f'{settings.output_period:g} s: set duration to at least '
                f'{2 * settings.output_period:g} s (more for the arm to follow it)')
    else:
        hint = ''
    raise ValueError(f'{violation.reason}{hint}')
