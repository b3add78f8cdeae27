"""
The whole system in one process (bringup) and the launch file (for installs with ros2launch).

bringup is started from the install layout, as `ros2 run etdmp_ros bringup` would; the test then
does what a user does: waits for the perceived goal, calls /generalize with empty frame ids and
checks that the controller moves the robot, and that Ctrl-C leaves a zero velocity command.
The launch file cannot run here (no ros2launch in this environment): it is executed against
minimal stand-ins of `launch` / `launch_ros` that record what it asks for.
"""

import importlib.util
from pathlib import Path
import signal
import subprocess
import sys
import time
import types

from conftest import REPO, sourced
from etdmp_ros import system
from etdmp_ros.nodes.background import BackgroundNode
from geometry_msgs.msg import PointStamped
from nav_msgs.srv import GetPlan
import numpy as np
import pytest
from std_msgs.msg import Float64MultiArray, String

NODES = system.NODE_NAMES


class Listener(BackgroundNode):
    """rclpy client in this process (own context, spinning in a thread)."""

    def __init__(self):
        super().__init__('bringup_test')
        self.goals, self.commands, self.statuses = [], [], []
        self.node.create_subscription(PointStamped, '/etdmp/goal', self.goals.append, 10)
        self.node.create_subscription(Float64MultiArray, '/forward_velocity_controller/commands',
                                      lambda m: self.commands.append(np.array(m.data)), 100)
        self.node.create_subscription(String, '/etdmp/controller/status',
                                      lambda m: self.statuses.append(m.data), 10)
        self.generalize = self.node.create_client(GetPlan, '/generalize')
        self.start()

    def wait(self, predicate, timeout, what, process):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return
            assert process.poll() is None, f'bringup exited while waiting for {what}'
            time.sleep(0.05)
        pytest.fail(f'timed out after {timeout} s waiting for {what}')


def test_bringup_runs_the_system_in_one_process(colcon_install, ros_env, tmp_path):
    log_path = tmp_path / 'bringup.log'
    env = dict(ros_env, PYTHONUNBUFFERED='1', RCUTILS_COLORIZED_OUTPUT='0', MUJOCO_GL='egl',
               ROS_HOME=str(tmp_path / 'ros_home'))
    with open(log_path, 'w') as log:
        process = subprocess.Popen(
            sourced(colcon_install, f'{colcon_install}/lib/etdmp_ros/bringup'), env=env,
            stdout=log, stderr=log)
    listener = Listener()
    try:
        listener.wait(lambda: set(NODES) <= set(listener.node.get_node_names()), 60,
                      'the four nodes', process)
        listener.wait(lambda: len(listener.goals) > 0, 60, 'a perceived goal', process)
        assert listener.generalize.wait_for_service(timeout_sec=30)
        future = listener.generalize.call_async(GetPlan.Request())   # empty frame ids
        listener.wait(future.done, 30, 'the /generalize response', process)
        plan = future.result().plan
        assert len(plan.poses) > 100, log_path.read_text()
        goal = listener.goals[-1].point
        end = plan.poses[-1].pose.position
        assert np.hypot(end.x - goal.x, end.y - goal.y) < 1e-3
        listener.wait(lambda: any(np.any(np.abs(c) > 1e-3) for c in listener.commands), 30,
                      'a non-zero velocity command', process)
        assert any(s.startswith(('approaching', 'tracking')) for s in listener.statuses)
    finally:
        process.send_signal(signal.SIGINT)
        try:
            code = process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            code = process.wait()
        time.sleep(0.3)
        listener.close()
    text = log_path.read_text()
    assert code == 0, text
    assert 'Traceback' not in text, text
    assert listener.commands and np.all(listener.commands[-1] == 0.0), (
        'the last velocity command after Ctrl-C is not zero')


def _stand_ins(recorded):
    """Minimal `launch`, `launch_ros` and `ament_index_python` modules that record calls."""
    def module(name, **attrs):
        mod = types.ModuleType(name)
        mod.__dict__.update(attrs)
        return mod

    class Recorder:
        """Stand-in for an action: remembers its arguments."""

        def __init__(self, *args, **kwargs):
            self.args, self.kwargs = args, kwargs
            recorded.append(self)

    return {
        'launch': module('launch', LaunchDescription=lambda entities: list(entities)),
        'launch.actions': module('launch.actions', DeclareLaunchArgument=Recorder),
        'launch.substitutions': module('launch.substitutions', LaunchConfiguration=str),
        'launch_ros': module('launch_ros'),
        'launch_ros.actions': module('launch_ros.actions', Node=Recorder),
        'ament_index_python': module('ament_index_python'),
        'ament_index_python.packages': module(
            'ament_index_python.packages', get_package_share_directory=lambda pkg: str(REPO)),
    }


def test_launch_file_starts_every_node_with_its_parameter_files(monkeypatch):
    recorded = []
    for name, mod in _stand_ins(recorded).items():
        monkeypatch.setitem(sys.modules, name, mod)
    path = REPO / 'launch' / 'etdmp.launch.py'
    spec = importlib.util.spec_from_file_location('etdmp_launch', path)
    launch = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(launch)
    entities = launch.generate_launch_description()
    nodes = [r for r in recorded if 'executable' in r.kwargs]
    assert [n.kwargs['executable'] for n in nodes] == list(NODES)
    for node in nodes:
        assert node.kwargs['package'] == 'etdmp_ros'
        files = [p for p in node.kwargs['parameters'] if isinstance(p, str)]
        assert [Path(f).name for f in files] == ['scene.yaml', f'{node.kwargs["executable"]}.yaml']
        assert all(Path(f).is_file() for f in files)
        overrides = {k: v for p in node.kwargs['parameters'] if isinstance(p, dict)
                     for k, v in p.items()}
        assert overrides.get('use_sim_time', False) == (node.kwargs['executable'] == 'dmp_server')
    assert len(entities) == len(recorded)
