"""
The system with its nodes killed and restarted one at a time (test_faults, bench_faults).

:class:`System`: the four installed nodes as ``ros2 run`` runs them
(:mod:`etdmp_ros.ros.processes`, the letter G's scene, a 4 s letter), each one killable
(SIGKILL, as a crash) and restartable alone in the same domain. :class:`Watch`: rclpy in the
calling process (joint states with their simulated stamps, the commands, the controller's
status, perceived and true goal, /rosout; /generalize and dmp_server's parameters). The
functions below run one fault each and return what happened as figures (the tests assert on
them, the benchmark prints them):

- :func:`kill_while_writing`: a node killed KILL_AT into the letter; whether the letter was
  completed, the largest stall of the simulation (its own ``simulation loop stalled``
  warnings, which name the largest of each second), stale input;
- :func:`kill_controller`: robot time from the kill to the brake (the arm's speed halved) and
  to standstill (under 1e-3 rad/s);
- :func:`kill_simulation`: wall time until the controller says why it stopped, and its last
  command;
- :func:`restart`: the node started again, waited for until it serves.
"""

import os
from pathlib import Path
import re
import signal
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from etdmp_ros.demo.recording import Recorder
from etdmp_ros.demo.scenario import Scenario
from etdmp_ros.ros import events, fastdds_files, qos, system
from etdmp_ros.ros.background import BackgroundNode
from etdmp_ros.ros.conversions import joint_state_from_cdr
from etdmp_ros.ros.processes import installed_command, NodeProcess, SystemProcesses
from geometry_msgs.msg import PointStamped
from nav_msgs.srv import GetPlan
import numpy as np
from rcl_interfaces.msg import Log, Parameter as ParameterMsg, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from support import waiting

#: Start-up of the four nodes on a loaded 2-core machine (numba caches, DDS discovery).
STARTUP = 180.0
#: A node restarted alone.
RESTART = 90.0
#: Plan duration (s): the G written faster than the demo's 6 s (as the README examples) keeps
#: the module short.
DURATION = 4.0
#: Path time (s) into the tracking at which a node is killed.
KILL_AT = 0.8
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STALL = re.compile(r'simulation loop stalled: (\d+) ms between two ticks at t = ([\d.]+) s')
#: Joint speed (rad/s) under which the arm counts as standing still.
STILL = 1e-3


class Watch(BackgroundNode):
    """Joint states, commands, status, goals, /rosout; /generalize and dmp_server's parameters."""

    def __init__(self, domain):
        super().__init__('fault_watch', domain)
        self.lock = threading.Lock()
        self.joints = []        # (receipt wall ns, sim ns, qd)
        self.commands = []      # (receipt monotonic, qd)
        self.status = []        # (receipt monotonic, text)
        self.goals = []         # perceived goals, (receipt monotonic, xyz)
        self.truth = None       # the goal marker's true position
        self.home = None        # the true tool tip when this node first heard of it
        self.logs = []          # (receipt monotonic, node name, text) from /rosout
        self.refusals = []      # dmp_server's plan_refused events' reasons, in order
        self.brakes = []        # ur10_sim's braked events: (last command, braked) in sim s
        n = self.node
        n.create_subscription(JointState, '/joint_states', self._on_joints,
                              QoSProfile(depth=2000), raw=True)
        n.create_subscription(Float64MultiArray, '/forward_velocity_controller/commands',
                              self._on_command, QoSProfile(depth=2000))
        n.create_subscription(String, '/etdmp/controller/status', self._on_status, LATCHED)
        n.create_subscription(PointStamped, '/etdmp/goal', self._on_goal, 10)
        n.create_subscription(PointStamped, '/ur10_sim/ground_truth/goal', self._on_truth, 10)
        n.create_subscription(PointStamped, '/ur10_sim/ground_truth/tool_tip', self._on_tip, 10)
        # /rosout keeps a node's recent lines for late joiners (transient local).
        n.create_subscription(Log, '/rosout', self._on_log,
                              QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        n.create_subscription(DiagnosticArray, '/dmp_server/events', self._on_events,
                              qos.latched(events.HISTORY))
        n.create_subscription(DiagnosticArray, '/ur10_sim/events', self._on_sim_events,
                              qos.latched(events.HISTORY))
        self.generalize_client = n.create_client(GetPlan, '/generalize')
        self.parameters = n.create_client(SetParameters, '/dmp_server/set_parameters')
        self.start()

    def _on_events(self, msg):
        with self.lock:
            self.refusals += [e.values.get('reason', e.message) for e in events.from_message(msg)
                              if e.kind == 'plan_refused']

    def _on_sim_events(self, msg):
        with self.lock:
            self.brakes += [(float(e.values['last_command_s']), float(e.values['braked_s']))
                            for e in events.from_message(msg) if e.kind == 'braked']

    def _on_joints(self, data):
        try:
            stamp, _, qd = joint_state_from_cdr(data)
        except ValueError:
            return
        with self.lock:
            self.joints.append((time.time_ns(), stamp, qd))

    def _on_command(self, msg):
        with self.lock:
            self.commands.append((time.monotonic(), np.array(msg.data)))

    def _on_status(self, msg):
        with self.lock:
            self.status.append((time.monotonic(), msg.data))

    def _on_goal(self, msg):
        with self.lock:
            self.goals.append((time.monotonic(), np.array([msg.point.x, msg.point.y,
                                                           msg.point.z])))

    def _on_truth(self, msg):
        self.truth = np.array([msg.point.x, msg.point.y, msg.point.z])

    def _on_tip(self, msg):
        if self.home is None:
            self.home = np.array([msg.point.x, msg.point.y, msg.point.z])

    def _on_log(self, msg):
        with self.lock:
            self.logs.append((time.monotonic(), msg.name, msg.msg))

    def logged(self, node, text, since):
        """Return whether ``node`` logged ``text`` (to /rosout) after ``since`` (monotonic)."""
        with self.lock:
            return any(t > since and name == node and text in line
                       for t, name, line in self.logs)

    def state(self):
        """Return the controller's latest status word."""
        with self.lock:
            return self.status[-1][1].split(':')[0] if self.status else None

    def mark(self):
        """Return the current lengths of the records (to read what came after)."""
        with self.lock:
            return len(self.joints), len(self.commands), len(self.status), time.monotonic()

    def since(self, mark):
        """Return joints, commands and status texts received after ``mark``."""
        with self.lock:
            return (self.joints[mark[0]:], self.commands[mark[1]:],
                    [s for _, s in self.status[mark[2]:]])

    def generalize(self):
        """
        Call /generalize from where the tool started to the perceived goal; return the plan.

        The start is given (the tool is at the goal after a letter): the controller approaches it.
        """
        request = GetPlan.Request()
        request.start.header.frame_id = 'base_link'
        p = request.start.pose.position
        p.x, p.y, p.z = map(float, self.home)
        assert self.generalize_client.wait_for_service(timeout_sec=RESTART)
        future = self.generalize_client.call_async(request)
        wait(future.done, 60, 'the /generalize response')
        return future.result().plan

    def set_dmp_server(self, **values):
        """Set boolean parameters of dmp_server (as ros2 param set)."""
        assert self.parameters.wait_for_service(timeout_sec=RESTART)
        request = SetParameters.Request(parameters=[
            ParameterMsg(name=k, value=ParameterValue(type=ParameterType.PARAMETER_BOOL,
                                                      bool_value=v))
            for k, v in values.items()])
        future = self.parameters.call_async(request)
        wait(future.done, 30, 'set_parameters')
        assert all(r.successful for r in future.result().results)


def wait(predicate, timeout, what, processes=(), details=None):
    """Wait until ``predicate()``; fail naming ``what`` (and the logs of dead processes)."""
    return waiting.wait_for(predicate, timeout, what, processes, period=0.01, details=details)


def shared_memory_state(log=''):
    """
    Return what a blind restarted reader's failure needs to be explained.

    The start of its log ``log`` and, of every Fast DDS port in /dev/shm, its age, who locks
    it and who maps it (process names).
    """
    owners, maps = fastdds_files.lock_owners(), fastdds_files.mappers()
    now = time.time()

    def who(pids):
        names = []
        for pid in sorted(pids):
            try:
                command = Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ')
                names.append(f'{pid} ({command[-60:].decode(errors="replace").strip()})')
            except OSError:
                names.append(f'{pid} (gone)')
        return ', '.join(names) or '-'
    lines = ['start of the log:', *log.splitlines()[:3], '/dev/shm ports:']
    for name, st in sorted(fastdds_files.listing().items()):
        if 'port' in name:
            lines.append(f'  {name}: {now - st.st_mtime:.1f} s old, locked by '
                         f'{who(owners.get(st.st_ino, ()))}, mapped by {who(maps.get(name, ()))}')
    return '\n'.join(lines)


class System:
    """The four installed nodes (:class:`SystemProcesses`), each restartable alone."""

    def __init__(self, install, env, tmp):
        # A faster approach (default 0.1 m/s) to the plan's start keeps the module short.
        self.scenario = Scenario(install / 'share' / 'etdmp_ros' / 'config', 'G',
                                 parameters={'dmp_server': {'duration': DURATION},
                                             'controller': {'approach_speed': 0.25}})
        self.logs = tmp / 'logs'
        self.command = installed_command(install)
        self.env = env
        self.nodes = SystemProcesses(self.scenario.param_files, self.logs, env, self.command)
        self.restarts = 0
        self.down = set()       # killed, not restarted yet

    @property
    def processes(self):
        """Return ``{name: NodeProcess}`` of the nodes."""
        return self.nodes.processes

    def running(self):
        """Return the processes of the nodes not killed (or killed and started again)."""
        return [p for name, p in self.processes.items() if name not in self.down]

    def kill(self, name):
        """SIGKILL node ``name`` (as a crash); return when it is gone."""
        process = self.processes[name]
        self.down.add(name)
        os.kill(process.pid, signal.SIGKILL)
        process.wait()

    def interrupt(self, name):
        """Stop node ``name`` with Ctrl-C (SIGINT), as a user does; return its exit code."""
        self.down.add(name)
        return self.processes[name].stop()

    def restart(self, name):
        """Start node ``name`` again, alone, in the same domain (its log: <name>_<n>.log)."""
        self.restarts += 1
        argv = self.command(name, self.scenario.param_files(name, self.logs))
        self.processes[name] = NodeProcess(argv, self.logs / f'{name}_{self.restarts}.log',
                                           self.env)
        self.down.discard(name)

    def stop(self):
        """Ctrl-C to every node; return the exit codes of those not killed last."""
        codes = self.nodes.stop()
        return {name: code for name, code in codes.items() if name not in self.down}


def ready(sys_, watch, timeout):
    """Wait until every node is running: idle controller, a perceived goal, /generalize."""
    running = sys_.running()
    wait(lambda: watch.state() == 'idle', timeout, 'the controller idle', running)
    wait(lambda: watch.goals, timeout, 'a perceived goal', running)
    wait(lambda: watch.generalize_client.service_is_ready(), timeout, '/generalize', running)
    wait(lambda: watch.home is not None, timeout, 'the tool tip', running)


def tracking_started(watch, mark):
    """Return a predicate: the controller reports tracking after ``mark``."""
    return lambda: any(s.startswith('tracking') for s in watch.since(mark)[2])


def write(watch, sys_, during=None):
    """
    Plan and execute the G; run ``during(watch)`` once it tracks; wait for the end.

    Returns (joints, commands, statuses) received meanwhile.
    """
    mark = watch.mark()
    reason = ''
    for _ in range(20):
        # Right after a (re)start dmp_server may not have heard the goal or the obstacles'
        # volumes yet, though this process has: its plan_refused event says 'yet'; asked again.
        seen = len(watch.refusals)
        plan = watch.generalize()
        if len(plan.poses):
            break
        wait(lambda: len(watch.refusals) > seen, 2.0, "dmp_server's plan_refused event")
        reason = watch.refusals[-1]
        if ' yet' not in reason:
            break
        time.sleep(0.2)
    assert len(plan.poses) > 100, f'no plan: {reason}'
    wait(tracking_started(watch, mark), 30, 'tracking', sys_.running())
    if during is not None:
        during(watch)
    wait(lambda: watch.state() == 'idle', 30, 'the end of the path', sys_.running())
    return watch.since(mark)


def largest_tick_gap(sim, joints):
    """
    Return the largest wall-clock gap (s) between two ticks of the simulation while ``joints``.

    As the simulation measured it: its log names the largest stall of each second (ur10_sim's
    ``simulation loop stalled`` warnings, LATE_TICKS periods or more), at its simulated time.
    """
    time.sleep(1.2)         # a stall is warned about at most a second after it
    start, end = joints[0][1] * 1e-9, joints[-1][1] * 1e-9
    stalls = [float(ms) * 1e-3 for ms, t in STALL.findall(sim.log())
              if start <= float(t) <= end]
    return max(stalls, default=0.0)


def motion_figures(sys_, joints, status):
    """Return the figures of a motion: largest stall (s), stale input, completed."""
    return {'largest_gap_s': largest_tick_gap(sys_.processes['ur10_sim'], joints),
            'stale_input': any(s.startswith('stale-input') for s in status),
            'completed': bool(status) and status[-1] == 'idle'
            and any(s.startswith('tracking') for s in status), 'status': status}


def write_with_tools(sys_, watch, cli=None):
    """
    Write the letter while tools join and leave; return :func:`motion_figures`.

    ``cli``: a :class:`ros2_cli.Ros2` on the system's domain, or None (then only the
    subscriber of every topic, the demo's recorder, as ``ros2 bag record``).
    """
    domain = int(sys_.env['ROS_DOMAIN_ID'])
    echo = ['ros2', 'topic', 'echo', '/joint_states', 'sensor_msgs/msg/JointState']
    tools = {}
    if cli is not None:
        tools['leaving'] = cli.start(echo, 'echo_leaving')
        wait(lambda: 'position:' in tools['leaving'].log(), RESTART, 'ros2 topic echo')

    def during(_):
        if cli is not None:     # they start now: they join while the arm moves
            tools['joining'] = cli.start(echo, 'echo_joining')
            tools['call'] = cli.start(['ros2', 'service', 'call', '/dmp_server/get_parameters',
                                       'rcl_interfaces/srv/GetParameters', '{names: [skill]}'],
                                      'service_call')
        recorder = Recorder(domain, animation=False)      # subscribes every topic
        time.sleep(0.5)         # the subject: tools joining for 0.5 s of the motion ...
        if cli is not None:
            tools['leaving'].stop()
        time.sleep(0.5)         # ... and one leaving for the next 0.5 s
        recorder.close()
    try:
        joints, _, status = write(watch, sys_, during=during)
    finally:
        if 'call' in tools:     # it ends by itself once it has its answer, maybe after the letter
            tools['call'].wait(RESTART)
        for tool in tools.values():
            tool.stop()
    figures = motion_figures(sys_, joints, status)
    figures['service_call'] = tools['call'].log() if cli is not None else None
    return figures


def kill_while_writing(sys_, watch, name):
    """Kill node ``name`` KILL_AT into the letter; return :func:`motion_figures`."""
    during, _ = after_the_kill(watch, sys_, name)
    joints, _, status = write(watch, sys_, during=during)
    return motion_figures(sys_, joints, status)


def kill_controller(sys_, watch):
    """
    Kill the controller KILL_AT into the letter; return robot-time figures of the arm's stop.

    ``braking_s``: from the kill (the last command's simulated time when ur10_sim reported
    the brake, else that of the last joint state received before it) to the first joint
    state at half the speed the arm had then; ``standstill_s``: to the first under
    :data:`STILL`; ``moved_again``: the arm moved after
    that; ``plan_end``: the plan's last position (the goal it went to). From ur10_sim's
    ``braked`` event, exact in simulated time (the kill's is known only to a joint state's
    latency): ``last_command_s`` and ``braked_s``, and ``halved_s`` (the first joint state at
    half speed), None without the event.
    """
    during, killed = after_the_kill(watch, sys_, 'controller')
    mark = watch.mark()
    n_brakes = len(watch.brakes)
    plan = watch.generalize()
    wait(tracking_started(watch, mark), 30, 'tracking', sys_.running())
    during(watch)
    time.sleep(1.0)             # the subject: the arm's stop watched for 1 s after the kill
    joints, _, _ = watch.since(mark)
    wall = np.array([j[0] for j in joints])
    sim = np.array([j[1] for j in joints]) * 1e-9
    speed = np.array([np.abs(j[2]).max() for j in joints])
    at_kill = np.searchsorted(wall, killed['wall_ns']) - 1
    t_kill = sim[at_kill]
    brake = next((b for b in watch.brakes[n_brakes:] if b[1] > t_kill - 1.0), (None, None))
    if brake[0] is not None:
        # The last command, in simulated time, is the kill's exact lower bound; this process
        # may have received the joint states around the kill late (its thread not scheduled).
        t_kill = brake[0]
        at_kill = max(int(np.searchsorted(sim, t_kill, side='right')) - 1, 0)
    moving = speed[at_kill]
    after = sim > t_kill
    halved = np.flatnonzero(after & (speed < 0.5 * moving))
    still = np.flatnonzero(after & (speed < STILL))
    end = plan.poses[-1].pose.position
    return {'last_command_s': brake[0], 'braked_s': brake[1],
            'halved_s': float(sim[halved[0]]) if halved.size else None,
            'speed_at_kill': float(moving),
            'braking_s': float(sim[halved[0]] - t_kill) if halved.size else None,
            'standstill_s': float(sim[still[0]] - t_kill) if still.size else None,
            'moved_again': bool(still.size and np.any(speed[still[0]:] >= STILL)),
            'largest_gap_s': largest_tick_gap(sys_.processes['ur10_sim'], joints),
            'plan_end': np.array([end.x, end.y, end.z])}


def kill_simulation(sys_, watch):
    """
    Kill the simulation KILL_AT into the letter; return what the controller did.

    ``said_after_s``: wall time from the kill to its next status; ``status``: that status;
    ``last_command``: the last command it sent after the kill (None if none).
    """
    during, _ = after_the_kill(watch, sys_, 'ur10_sim')
    mark = watch.mark()
    watch.generalize()
    wait(tracking_started(watch, mark), 30, 'tracking', sys_.running())
    during(watch)
    killed_at = time.monotonic()
    stall = system.node('controller').parameter('simulation_stall_timeout').default
    n = len(watch.status)
    wait(lambda: len(watch.status) > n, stall + 5.0, 'the controller to report')
    said_at, text = watch.status[n]
    commands = [c for t, c in watch.commands if t > killed_at]
    return {'said_after_s': said_at - killed_at, 'status': text,
            'last_command': commands[-1] if commands else None}


def restart(sys_, watch, name):
    """
    Start node ``name`` again, alone, if it was stopped; return when it serves.

    Returns the seconds from the start until it served (None if it was running).
    """
    if name not in sys_.down:
        return None
    since = time.monotonic()
    sys_.restart(name)
    if name == 'dmp_server':
        # Until the dead server's lease expires (20 s) its service still looks ready: wait
        # for the new one to say it serves (this node has then discovered it), then give
        # discovery a moment to match the service's endpoints too.
        wait(lambda: watch.logged('dmp_server', 'serving /generalize', since), RESTART,
             'the restarted dmp_server', sys_.running())
        # The new server has no perceived goal until perception's next one reaches it.
        serving = time.monotonic()
        wait(lambda: watch.goals[-1][0] > serving, RESTART, 'a goal perceived since',
             sys_.running())
        time.sleep(1.0)     # nothing says the service's endpoints matched: no condition
    elif name == 'perception':
        wait(lambda: watch.goals[-1][0] > since, RESTART, 'a goal perceived again',
             sys_.running(),
             details=lambda: shared_memory_state(sys_.processes['perception'].log()))
    else:   # the controller, or the simulation: the controller idle again, with joint states
        wait(lambda: watch.status[-1][0] > since and watch.state() == 'idle', RESTART,
             f'the controller idle after the restart of {name}', sys_.running())
    return time.monotonic() - since


def after_the_kill(watch, sys_, name):
    """Return a ``during`` that kills node ``name`` KILL_AT into the path; keeps the time."""
    killed = {}

    def during(_):
        time.sleep(KILL_AT)     # the subject: the kill KILL_AT into the path
        killed['wall_ns'] = time.time_ns()
        sys_.kill(name)
    return during, killed
