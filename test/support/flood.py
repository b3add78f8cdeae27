"""
A flood of junk joint states from another process: the controller's attack test and its benchmark.

:data:`FLOOD` is the program (``python -c FLOOD SECONDS RATE PRIORITY``): joint states naming
other joints at RATE a second (in bursts every millisecond, as serialized bytes), from the
moment a reader is matched, for SECONDS, its sending thread at SCHED_FIFO PRIORITY where the
process may use it. It prints ``flooding`` as it starts and the rate it reached at the end.
"""

import textwrap

#: The flood's SCHED_FIFO priority: above every normal process, so that the machine's other
#: work cannot starve it (a fresh clone's flood at normal priority reached 4 340/s), under the
#: nodes' real-time threads (50, 60) and their reception threads (49). It found the loop's
#: one normal-priority link, ur10_sim's executor thread that takes the commands: starved, the
#: watchdog braked and the letter stopped 'unreachable' (now at 49 too). Only the thread that
#: sends is raised, once matched: raised before rclpy.init, every thread of the flood's
#: middleware (discovery, events, reception) ran at it too, which is no part of the attack;
#: on a slower AMD EPYC the simulation then went 60 ms without a command as the flood began
#: (4 runs of 5 of the module; 0 of 4 with the sending thread alone at it).
FLOOD_PRIORITY = 20
#: The program (see the module's docstring).
FLOOD = textwrap.dedent("""
    import sys, time
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from etdmp_ros.ros.spin import set_realtime_priority
    rclpy.init()
    node = rclpy.create_node('joint_state_flood')
    # Best effort, as the controller reads joint states: matched to the controller alone (not
    # to the test's reliable reader) and without the reliable protocol's bookkeeping, a UDP
    # send per message to the subject. (A reliable flood, sent to both readers, reached only
    # 11.7 of its 13 kHz on an idle AMD EPYC.)
    pub = node.create_publisher(JointState, '/joint_states',
                                QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
    # Published as its serialized bytes: the same message on the wire, without rclpy's
    # conversion each time (which kept a flood next to a busy core at 10.6 of its 13 kHz).
    msg = serialize_message(JointState(name=['a', 'b', 'c'], position=[0.0, 1.0, 2.0]))
    while pub.get_subscription_count() < 1:            # the controller
        time.sleep(0.05)
    # Matched here; the readers' side may match a moment later, which this process cannot see
    # (the test starts the letter only after 'flooding', so nothing depends on this wait).
    time.sleep(0.5)
    set_realtime_priority(int(sys.argv[3]))    # where allowed (FLOOD_PRIORITY)
    print('flooding', flush=True)
    burst = round(float(sys.argv[2]) / 1000)
    start = time.monotonic()
    n, end = 0, start + float(sys.argv[1])
    while time.monotonic() < end:
        for _ in range(burst):
            pub.publish(msg)
        n += burst
        time.sleep(max(0.0, start + n / float(sys.argv[2]) - time.monotonic()))   # the rate
    print(n / (time.monotonic() - start), flush=True)
""")
