"""
The nodes' events (etdmp_ros.ros.events) and the metrics read from them in a recording.

A node's facts travel as DiagnosticArray values, not as log text: they survive serialization,
a recording (MCAP) and reading back; the metrics computed from them are the figures the nodes
published, and rewording the human message changes none of them.
"""

import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from etdmp_ros.demo.metrics import system_figures
from etdmp_ros.demo.recording import EVENT_TOPICS, read_streams
from etdmp_ros.ros import events
from etdmp_ros.skills import recordings as bag
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message


class _Clock:

    def now(self):
        return self

    def to_msg(self):
        return Time(sec=12, nanosec=345)


class _Publisher:

    def __init__(self):
        self.sent = []

    def publish(self, msg):
        self.sent.append(serialize_message(msg))


class _Node:
    """What EventPublisher needs of a node: its name, its clock, a publisher (kept here)."""

    def __init__(self, name):
        self.name = name
        self.publisher = _Publisher()
        self.qos = None

    def get_name(self):
        return self.name

    def get_clock(self):
        return _Clock()

    def create_publisher(self, msg_type, topic, qos):
        assert msg_type is DiagnosticArray and topic == '~/events'
        self.qos = qos
        return self.publisher


def test_an_event_round_trips_through_its_message():
    node = _Node('controller')
    publisher = events.EventPublisher(node)
    assert node.qos.depth == events.HISTORY
    publisher.publish('path_tracked', 'path tracked: error RMS 0.123 mm', events.WARN,
                      error_rms_mm=0.12345678901234, steps=np.int64(500), continued=True,
                      goal=np.array([0.85, 0.14, 0.002]), reason='a, b: c', nothing=[])
    (found,) = events.from_message(deserialize_message(node.publisher.sent[0], DiagnosticArray))
    assert (found.node, found.kind, found.level) == ('controller', 'path_tracked', events.WARN)
    assert found.message == 'path tracked: error RMS 0.123 mm'
    assert found.stamp_ns == 12 * 10**9 + 345
    assert found.number('error_rms_mm') == 0.12345678901234      # exactly: shortest repr
    assert found.integer('steps') == 500 and found.flag('continued')
    np.testing.assert_array_equal(found.numbers('goal'), [0.85, 0.14, 0.002])
    assert found.values['reason'] == 'a, b: c' and len(found.numbers('nothing')) == 0
    assert found.number('missing') is None and not found.flag('missing')
    assert abs(found.wall_ns - time.time_ns()) < 60 * 10**9
    assert events.of_kind([found], 'controller', 'path_tracked') == [found]
    assert events.of_kind([found], 'ur10_sim', 'path_tracked') == []


CALL_NS, END_NS = 2_000_000_000, 9_000_000_000


def _recording(path, wording):
    """Write and read back the events of a run's nodes, their messages worded by ``wording``."""
    nodes = {name: _Node(name) for name in EVENT_TOPICS.values()}
    publishers = {name: events.EventPublisher(node) for name, node in nodes.items()}
    publishers['ur10_sim'].publish('stalled', wording('stall 1'), events.WARN, gap_ms=40.5,
                                   t_s=1.0, late_ticks=1)       # before the call: not counted
    publishers['ur10_sim'].publish('stalled', wording('stall 2'), events.WARN, gap_ms=75.25,
                                   t_s=3.5, late_ticks=4)
    publishers['controller'].publish('path_tracked', wording('tracked'), error_rms_mm=0.0421,
                                     error_max_mm=0.3999, steps=500, periods=501,
                                     joint_states=503, largest_gap_ms=17.5,
                                     largest_gap_at_s=4.25, delay_ms=1.6)
    publishers['ur10_sim_camera'].publish('stopped', wording('camera'), frames=280, skipped=7,
                                          early=3)
    publishers['ur10_sim'].publish('stopped', wording('stopped'), t_s=10.0, ticks=1250,
                                   late_ticks=6, late_after_periods=3, largest_tick_gap_ms=75.25,
                                   frames=300, frames_dropped=2, command_waits=9,
                                   command_wait_ms=12.5, command_waits_in_vain=1,
                                   largest_command_age_ms=24.0, contact_ticks=0,
                                   contact_pairs='')
    with bag.BagWriter(path) as writer:
        receipt = 1_700_000_000_000_000_000
        for topic, name in EVENT_TOPICS.items():
            writer.add_topic(topic, events.TYPE_NAME, [bag.qos_profile(True, True, 100)])
            for data in nodes[name].publisher.sent:
                receipt += 1000
                writer.write(topic, receipt, data)
    return read_streams(path)


class _NoMonitor:

    def window(self, start, end):
        return None


def test_the_system_figures_are_the_events_of_the_recording(tmp_path):
    rec = _recording(tmp_path / 'run.mcap', lambda text: text)
    assert len(rec['events']) == 5
    figures = system_figures(_NoMonitor(), rec, CALL_NS, END_NS)
    assert figures['controller'] == {
        'tracking_rms_mm': 0.0421, 'tracking_max_mm': 0.3999, 'steps': 500, 'periods': 501,
        'joint_states_received': 503, 'largest_joint_state_gap_ms': 17.5,
        'largest_joint_state_gap_at_s': 4.25}
    assert figures['simulation_stalls'] == [(3.5, 75.25)]
    assert figures['simulation'] == {
        'late_ticks': 6, 'largest_tick_gap_ms': 75.25, 'frames': 300, 'frames_dropped': 2 + 7,
        'command_waits': 9, 'command_wait_ms': 12.5, 'command_waits_in_vain': 1,
        'largest_command_age_ms': 24.0, 'frames_rendered': 280}


def test_rewording_a_log_line_changes_no_figure(tmp_path):
    plain = _recording(tmp_path / 'a.mcap', lambda text: text)
    reworded = _recording(tmp_path / 'b.mcap', lambda text: f'SOMETHING ELSE ({text[::-1]})')
    assert [e.message for e in plain['events']] != [e.message for e in reworded['events']]
    assert system_figures(_NoMonitor(), plain, CALL_NS, END_NS) == \
        system_figures(_NoMonitor(), reworded, CALL_NS, END_NS)


def test_no_events_recorded_gives_no_node_figures(tmp_path):
    with bag.BagWriter(tmp_path / 'empty.mcap') as writer:
        writer.add_topic('/ur10_sim/events', events.TYPE_NAME)
    rec = read_streams(tmp_path / 'empty.mcap')
    figures = system_figures(_NoMonitor(), rec, CALL_NS, END_NS)
    assert figures == {'simulation_stalls': []}


@pytest.mark.parametrize('level', [events.OK, events.WARN, events.ERROR])
def test_the_levels_are_diagnostic_status_levels(level):
    node = _Node('dmp_server')
    events.EventPublisher(node).publish('refused', 'x', level, reason='r')
    msg = deserialize_message(node.publisher.sent[0], DiagnosticArray)
    assert msg.status[0].level == bytes([level]) and msg.status[0].name == 'dmp_server: refused'
