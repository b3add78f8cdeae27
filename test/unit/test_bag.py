"""
The demo's recording: rosbag2 MCAP files, read back by mcap-ros2-support.

Files written by etdmp_ros.skills.recordings decode with mcap-ros2-support's own decoder for
every type the system publishes; CompressedImage bytes are what rclpy would serialize; the measured
streams come back in the order the recorder received them.
"""

import cv2
from etdmp_ros.demo.recording import (COMMAND_TOPIC, read_streams, REFERENCE_TOPIC, STATUS_TOPIC,
                                      TIP_TOPIC)
from etdmp_ros.ros.conversions import (compress_image_cdr, compressed_image_cdr,
                                       compressed_image_from_cdr, image_msg, message_class,
                                       ns_to_stamp, tf_available)
from etdmp_ros.skills import recordings as bag
from geometry_msgs.msg import PointStamped, PoseStamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CompressedImage, JointState
from std_msgs.msg import Float64MultiArray, String
import yaml

#: Types the system publishes, nested ones among them (TFMessage when tf2_msgs is installed:
#: it is not on PyPI, make ros-tools builds it).
TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage', 'sensor_msgs/msg/JointState',
         'sensor_msgs/msg/CameraInfo', 'nav_msgs/msg/Path',
         'visualization_msgs/msg/MarkerArray', 'rcl_interfaces/msg/Log',
         'rcl_interfaces/msg/ParameterEvent', 'rosgraph_msgs/msg/Clock',
         'geometry_msgs/msg/PoseArray', 'std_msgs/msg/Float64MultiArray',
         'std_msgs/msg/String') + (('tf2_msgs/msg/TFMessage',) if tf_available() else ())


def test_message_definitions_are_embedded_the_rosbag2_way():
    text = bag.message_definition('geometry_msgs/msg/PoseStamped')
    assert text.startswith(open(bag._msg_file('geometry_msgs', 'PoseStamped')).read().rstrip())
    for dependency in ('std_msgs/Header', 'builtin_interfaces/Time', 'geometry_msgs/Pose',
                       'geometry_msgs/Point', 'geometry_msgs/Quaternion'):
        assert f'{"=" * 80}\nMSG: {dependency}\n' in text
        assert text.count(f'MSG: {dependency}\n') == 1
    with pytest.raises(bag.BagError):
        bag.message_definition('no_such_msgs/msg/Thing')


def _messages(path):
    with open(path, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        return header, list(reader.iter_decoded_messages(log_time_order=True))


def test_a_bag_of_every_type_reads_back_with_mcap_ros2(tmp_path):
    path = tmp_path / 'run.mcap'
    joint = JointState(name=['a', 'b'], position=[0.5, -1.0])
    joint.header.stamp = ns_to_stamp(1_500_000_000)
    with bag.BagWriter(path) as writer:
        for i, type_name in enumerate(TYPES):     # mcap-ros2 decodes each with its definition
            writer.add_topic('/' + type_name.replace('/msg/', '_'), type_name)
            writer.write('/' + type_name.replace('/msg/', '_'), 100 + i,
                         serialize_message(message_class(type_name)()))
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState',
                         [bag.qos_profile(reliable=True, transient_local=True, depth=1)])
        writer.write('/joint_states', 20, serialize_message(joint))
        writer.write('/joint_states', 10, serialize_message(joint))
    header, messages = _messages(path)
    assert header.profile == 'ros2'
    assert [m.message.log_time for m in messages] == [10, 20] + [100 + i
                                                                 for i in range(len(TYPES))]
    assert [m.schema.name for m in messages[2:]] == list(TYPES)
    decoded = messages[0].decoded_message
    assert list(decoded.name) == ['a', 'b'] and list(decoded.position) == [0.5, -1.0]
    assert decoded.header.stamp.sec == 1 and decoded.header.stamp.nanosec == 500_000_000
    assert all(m.schema.encoding == 'ros2msg' and m.channel.message_encoding == 'cdr'
               for m in messages)
    qos = yaml.safe_load(messages[0].channel.metadata['offered_qos_profiles'])
    assert qos[0]['durability'] == 'transient_local' and qos[0]['reliability'] == 'reliable'
    assert bag.topics(path)['/joint_states'] == ('sensor_msgs/msg/JointState', 2)
    meta = yaml.safe_load((tmp_path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['storage_identifier'] == 'mcap' and meta['relative_file_paths'] == ['run.mcap']
    assert meta['message_count'] == 2 + len(TYPES) and meta['starting_time'] == {
        'nanoseconds_since_epoch': 10}
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in meta['topics_with_message_count']}
    assert counts['/joint_states'] == 2 and len(counts) == len(TYPES) + 1


def test_compressed_images_are_what_rclpy_would_serialize():
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:48, 0:64]
    rgb = np.stack([x * 4, y * 5, np.full_like(x, 200)], axis=2).astype(np.uint8)  # smooth
    depth = rng.integers(0, 3000, (48, 64), dtype=np.uint16)
    stamp = ns_to_stamp(12_345_000_001)
    colour = compress_image_cdr(serialize_message(image_msg(rgb, 'rgb8', stamp, 'cam')))
    deep = compress_image_cdr(serialize_message(image_msg(depth, '16UC1', stamp, 'optical')))
    ns, fmt, pixels = compressed_image_from_cdr(deep)
    assert (ns, fmt) == (12_345_000_001, '16UC1; png compressed ')
    np.testing.assert_array_equal(pixels, depth)                # PNG: lossless
    ns, fmt, pixels = compressed_image_from_cdr(colour)
    assert fmt == 'rgb8; jpeg compressed bgr8' and pixels.shape == rgb.shape
    assert np.abs(pixels.astype(int) - rgb).mean() < 2.0        # JPEG: lossy, channels kept
    payload = cv2.imencode('.png', depth)[1].tobytes()
    msg = CompressedImage(format='16UC1; png compressed ', data=payload)
    msg.header.stamp, msg.header.frame_id = stamp, 'optical'
    ours = compressed_image_cdr(12, 345_000_001, 'optical', '16UC1; png compressed ', payload)
    # Byte for byte but the alignment padding (which Fast CDR leaves as it finds it).
    assert len(ours) == len(serialize_message(msg))
    assert deserialize_message(ours, CompressedImage) == msg
    with pytest.raises(ValueError):
        compress_image_cdr(serialize_message(image_msg(np.zeros((2, 2), np.float32), '32FC1')))


def test_measured_streams_come_back_in_the_order_they_arrived(tmp_path):
    def tip(ns):
        msg = PointStamped()
        msg.header.stamp = ns_to_stamp(ns)
        msg.point.x = ns * 1e-9
        return serialize_message(msg)

    def reference(ns):
        msg = PoseStamped()
        msg.header.stamp = ns_to_stamp(ns)
        msg.pose.position.y = 2.0
        return serialize_message(msg)

    path = tmp_path / 'run.mcap'
    with bag.BagWriter(path, metadata_yaml=False) as writer:
        for topic, type_name in ((TIP_TOPIC, 'geometry_msgs/msg/PointStamped'),
                                 (REFERENCE_TOPIC, 'geometry_msgs/msg/PoseStamped'),
                                 (COMMAND_TOPIC, 'std_msgs/msg/Float64MultiArray'),
                                 (STATUS_TOPIC, 'std_msgs/msg/String')):
            writer.add_topic(topic, type_name)
        writer.write(STATUS_TOPIC, 1, serialize_message(String(data='idle')))
        writer.write(TIP_TOPIC, 2, tip(8_000_000))
        writer.write(COMMAND_TOPIC, 3, serialize_message(Float64MultiArray(data=[0.1] * 6)))
        writer.write(TIP_TOPIC, 4, tip(16_000_000))
        writer.write(REFERENCE_TOPIC, 5, reference(16_000_000))
        writer.write(COMMAND_TOPIC, 6, serialize_message(Float64MultiArray(data=[0.2] * 6)))
        writer.write(STATUS_TOPIC, 7, serialize_message(String(data='tracking')))
    assert not (tmp_path / 'metadata.yaml').exists()
    rec = read_streams(path)
    np.testing.assert_array_equal(rec['tip'][:, 0], [8e6, 16e6])
    np.testing.assert_allclose(rec['tip'][:, 1], [0.008, 0.016])
    np.testing.assert_array_equal(rec['reference'], [[16e6, 0.0, 2.0, 0.0]])
    # A command gets the simulated time of the latest pen tip received before it.
    np.testing.assert_array_equal(rec['command_time'], [8e6, 16e6])
    np.testing.assert_allclose(rec['command_wall_time'], [3e-9, 6e-9])
    np.testing.assert_array_equal(rec['commands'], [[0.1] * 6, [0.2] * 6])
    assert rec['status'] == [(0, 'idle'), (16_000_000, 'tracking')]
