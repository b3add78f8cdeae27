"""
ROS-free ET-DMP core: learn a movement from one demonstration, generalize it from any start.

Notation (the paper's symbols, used in every module here):

- ``x``, ``v = tau dx/dt``: position and scaled velocity of the transformation system;
  ``x0``, ``g``: start and goal; ``K``, ``D``: stiffness and damping (Table 1: 156.25, 25).
- ``tau``: duration scale; ``s``: phase, ``tau ds/dt = -alpha s``, ``s(0) = 1``.
- ``f(s) = s G(s) sum_i psi_i(s) w_i / sum_i psi_i(s)``: forcing term, with
  ``tau dv/dt = K (g - x) - D v + (g - x0) f(s)`` (Ijspeert; docs/design.md#dmp-formulations) or
  ``tau dv/dt = K (g - x) - D v - K (g - x0) s + K f(s)`` (Hoffmann); ``G`` the gate that ends
  the forcing at tau, and Hoffmann's ``K s`` made to end there too (docs/design.md#coming-to-rest).
- ``I_D = x0_D - g_D``, ``I_C = x0_C - g_C``: demonstrated and current start relative to the goal;
  ``R``: the Euclidean transform turning ``I_C`` onto the direction of ``I_D``;
  ``theta``: its angle;
  ``x0' = R I_C + g``: the virtual start (Eq. 12).
- ``lambda``: obstacle coupling added to ``tau dv/dt`` (Eq. 22-27), gains ``gamma``, ``beta``,
  ``gamma2``, ``k`` (the paper's point obstacles, ``avoidance='paper'``).
- Obstacles with a size (``obstacle_radii``, docs/design.md#obstacles-with-a-size): ``c_j``,
  ``r_j`` centre and radius (the clearance to keep); the default ``avoidance='detour'`` adds to
  the obstacle-free plan a displacement ``delta(t) = sum_e A_e b_e(t) n_e``: per encounter an
  amplitude, a C2 bump in time and a direction.
- Online (``Skill.online``, docs/design.md#online-goal): ``g_f`` the filtered goal,
  ``tau dg_f/dt = alpha_goal (g - g_f)``; the transform is taken between ``x0`` and ``g_f``.
- Orientation (docs/orientation.md): ``q`` unit quaternions (x, y, z, w), ``omega`` angular
  velocity; ``e = 2 log(q q_g^-1)`` the rotation vector of the quaternion DMP; ``Q`` the rotation
  part of ``R^T`` that turns the orientation with the motion.

Typical use::

    from etdmp_ros.dmp import builtin_demo, learn, nrmse
    skill = learn(builtin_demo("G"))
    traj = skill.generalize(start=[-4.0, 3.0], goal=[0.0, 0.0], method="etdmp")
    print(nrmse(traj.x, skill.demo))
"""

from ._demos import (builtin_demo, builtin_demo_names, check_file_size, Demonstration, load_demo,
                     save_demo, unit_quaternions)
from ._errors import DemonstrationError, GeneralizationError
from ._goal_jump import compare_goal_jump, goal_jump_case, GOAL_JUMP_WAYS, GoalJump
from ._obstacles import obstacle_coupling, ObstacleGains
from ._online import OnlineRun, RunRows
from ._online_gains import OnlineGains
from ._orientation import ORIENTATION_MODES
from ._similarity import clearance, nrmse, Similarity, similarity
from ._skill import (AVOIDANCES, FORMULATIONS, learn, METHOD_LABELS, METHODS, OBSTACLE_MARGIN,
                     Skill, Trajectory)
from ._transform import euclidean_transform, EuclideanTransform

__all__ = [
    'AVOIDANCES', 'Demonstration', 'DemonstrationError', 'EuclideanTransform', 'FORMULATIONS',
    'GOAL_JUMP_WAYS', 'GeneralizationError', 'GoalJump', 'METHOD_LABELS', 'METHODS',
    'OBSTACLE_MARGIN', 'ORIENTATION_MODES', 'ObstacleGains', 'OnlineGains', 'OnlineRun',
    'RunRows', 'Similarity', 'Skill', 'Trajectory', 'builtin_demo', 'builtin_demo_names',
    'check_file_size', 'clearance', 'compare_goal_jump', 'euclidean_transform',
    'goal_jump_case', 'learn', 'load_demo', 'nrmse', 'obstacle_coupling', 'save_demo',
    'similarity', 'unit_quaternions',
]
