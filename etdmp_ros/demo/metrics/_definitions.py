"""
What each figure of a run means: written once, here, and repeated in ``metrics.json``.

:data:`DEFINITIONS` applies to every run, :data:`MOVE_DEFINITIONS` is added when the goal marker
(stir: the bottle) moved while the pen wrote, :data:`SYSTEM_DEFINITIONS` describes ``system``.
The package's docstring and the functions that compute a figure refer to these entries by key.
"""

#: The end of the window of the switch speed check after the switch (s of path time).
SWITCH_WINDOW = 0.5
#: Plan speeds below this fraction of the plan's speed at the switch are the plan slowing down
#: itself: left out of the switch speed check.
SLOW_PLAN = 0.2

DEFINITIONS = {
    'nrmse': 'the conventional nRMSE (etdmp_ros.dmp.nrmse) against the demonstration, over the '
             "plan's tau only (its duration without the margin a plan with obstacles has: 1.5 "
             'tau; its tail would be squeezed into the phase resampling, as in etdmp '
             'reproduce); 2D skills in the task plane (base_link points projected onto it), 3D '
             'in base_link. trace: the true pen tip from the moment the controller started '
             'tracking (its stamped reference fitted to the plan, to 0.1 ms) to that + tau; the '
             'approach before it is left out. A 3D skill planned in mode 2 (the taught stir) is '
             "first taken back to the demonstration's situation by mode 2's own transform (its "
             "turn about the independent axis and its per-block scales, from the path's start "
             "and end): the measure's alignment of the start direction alone would count that "
             'turn as a difference of shape',
    'tracking_error': "true pen tip minus the controller's reference at the same simulated "
                      'stamps, while the plan is tracked',
    'goal_error': 'pen tip at the end (after the hold) to the true goal marker projected onto '
                  'the task plane (2D) or to the requested goal (3D)',
    'min_clearance': "smallest distance from the pen tip's surface (radius PEN_TIP_RADIUS, 3 "
                     "mm) to an obstacle cylinder's surface (true positions; cylinders of their "
                     'radii standing on the table up to their top point), over the whole '
                     'executed motion; > 0: the tip touched none (the pen body and the arm: '
                     'contacts)',
    'command_ratios': 'the largest |qd_j| / limit_j (UR10Model.velocity_limits times the '
                      "controller's velocity_scale) and |qd_j[k] - qd_j[k-1]| * control_rate / "
                      "a_j (the controller's joint_acceleration_limits) over every command "
                      'received',
    'contacts': "the simulation's contacts (/ur10_sim/ground_truth/contacts, published at every "
                'tick while a link or the tool touches an obstacle, the bottle, the table or '
                'the floor; the tool tip writing on the table is none): ticks with one over the '
                'whole recording (None: not recorded), the pairs part/item, the deepest (mm)',
    'orientation_tracking': 'angle between the true tool orientation (forward kinematics of the '
                            "simulation's /joint_states on the UR10 model with the scene's "
                            'tool_offset; orientation_fk_vs_tip_max_mm: its tip vs the '
                            "simulation's) and the plan's at the same path time (geodesic "
                            "between poses), or the controller's reference at the same stamps "
                            "(_vs_reference_), while tracking; plan_vs_demo_turned: the plan's "
                            "orientations vs the demonstration's at the same phase turned by "
                            "the Euclidean transform's rotation (about the task plane's normal "
                            'in 2D; R^T in 3D, mode 1), computed from start and goal',
    'quadrant': 'quadrant of start - goal in the task plane (I: +x +y, II: -x +y, ...); for '
                'the demonstration in its own coordinates',
    'moving_commands_per_s': 'non-zero joint-velocity commands per simulated second from the '
                             'first to the last of them (approach, plan, hold); the time from '
                             'the /generalize call to the first is '
                             'first_moving_command_after_call_s',
}

#: Added to ``definitions`` when the goal marker (stir: the bottle) moved during the run.
MOVE_DEFINITIONS = {
    'executed_plan': 'the /generalize plan with each later /etdmp/path of the same stamp laid '
                     "over it from that path's first pose on (path time = pose stamp - plan "
                     'stamp); nrmse_plan, nrmse_trace, tracking, clearance are taken on it, '
                     'nrmse_original_plan on the plan as /generalize returned it',
    'nrmse_trace_moved': "nrmse_trace: the trace over tau with the marker's final position "
                         '(projected) appended as its last point, i.e. against the '
                         'demonstration placed at the new goal; nrmse_trace_own_end: without',
    'goal_error_moved': "goal_error_mm: pen tip after the hold to the marker's final position "
                        'projected onto the task plane; goal_error_vs_first_marker_mm: to '
                        'where it was when the plan was requested',
    'goal_moved_by_mm': 'distance between the marker before and after the move (true positions)',
    'nrmse_move_reference': "the nRMSE (as nrmse_trace) of the core's online ET-DMP "
                            '(etdmp_ros.skills.following.FollowedPlan, no ROS, no obstacles) '
                            "from the run's start to the first goal with the goal moved to the "
                            'final one at switch_path_time_s: what the move itself costs (the '
                            'part written before the switch was written for the old goal)',
    'switch': 'switch_path_time_s: first path time at which the executed plan departs from the '
              'original plan (> 1 nm): where dmp_server re-planned from; switch_time_s: that, '
              'simulated s after the /generalize call',
    'switch_speed': f'over [min(new path published, switch), switch + {SWITCH_WINDOW:g} s] in '
                    'path time: switch_speed_ratio_min = min true tip speed (finite differences '
                    'of its samples) / executed plan speed at the same path time; '
                    'switch_tool_speed_min_fraction = min tip speed / plan speed at the switch; '
                    f'samples where the plan is slower than {SLOW_PLAN:g} of its speed at the '
                    'switch left out. No stop-and-go: both >= 0.2',
    'goal_follow': 'latencies of the first update: marker moved (simulated time of the '
                   'parameter change) -> first /etdmp/goal showing it (more than follow_'
                   'threshold from where it was; received here, simulated s) -> the '
                   'confirming one (FOLLOW_CONFIRMATIONS-th); dmp_server_ms: its own figure '
                   "(its 'followed' event: confirming message -> remainder published); "
                   "controller: path published (dmp_server's clock, its 'followed' event's "
                   "published_wall_ns) -> its 'path_accepted' event -> first command after "
                   'it received here; end_to_end_ms: the confirming message '
                   'received here (dmp_server receives it at about the same time), or '
                   "dmp_server's own time of it (its event less dmp_server_ms) if earlier -> "
                   "that first command received here (wall clock: the events' and the "
                   'receipt times)',
}

#: What ``metrics.json``'s ``system`` holds (etdmp_ros.demo.metrics.system_figures).
SYSTEM_DEFINITIONS = {
    'cpu': 'CPU-s per simulated s of each process from the call to the end (/proc), the '
           'real-time factor (CpuMonitor)',
    'commands': 'moving commands per simulated second, the wall-clock period between '
                'commands as the recorder received them',
    'controller': "the controller's own figures of the last path it tracked (its "
                  "'path_tracked' event): tracking error (reference minus its forward "
                  'kinematics), control steps, joint states and their largest gap',
    'simulation': "ur10_sim's 'stalled' events from the call to the end (simulated s, ms "
                  "between two ticks) and its 'stopped' event (late ticks, frames, command "
                  "waits), with the camera process's 'stopped' event (frames rendered, "
                  'skipped)',
}
