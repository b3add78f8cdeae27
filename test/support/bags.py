"""rosbag2 .mcap recordings written for the tests, as ``ros2 bag record`` stores them."""

from mcap_ros2.writer import Writer

# Message definitions as rosbag2 stores them in .mcap schemas (ros2msg, dependencies appended).
_SEP = '=' * 80 + '\n'
_HEADER_DEPS = (_SEP + 'MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n' +
                _SEP + 'MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n')
_POSE_DEPS = (_SEP + 'MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n' +
              _SEP + 'MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n' +
              _SEP + 'MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\n'
              'float64 w 1\n')
POSE_STAMPED_MSGDEF = 'std_msgs/Header header\ngeometry_msgs/Pose pose\n' + _HEADER_DEPS + \
    _POSE_DEPS
PATH_MSGDEF = ('std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n' + _HEADER_DEPS +
               _SEP + 'MSG: geometry_msgs/PoseStamped\nstd_msgs/Header header\n'
               'geometry_msgs/Pose pose\n' + _POSE_DEPS)


def pose_message(p, stamp_ns, frame='base_link'):
    """Return a geometry_msgs/PoseStamped as a dict (identity orientation) at ``stamp_ns``."""
    return {'header': {'stamp': {'sec': stamp_ns // 10**9, 'nanosec': stamp_ns % 10**9},
                       'frame_id': frame},
            'pose': {'position': dict(zip('xyz', (float(c) for c in p))),
                     'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}}}


def write_mcap(path, topics):
    """Write {topic: (kind, [(log_time_ns, message dict), ...])} as a rosbag2 .mcap."""
    with open(path, 'wb') as stream:
        writer = Writer(stream)
        schemas = {'pose': writer.register_msgdef('geometry_msgs/msg/PoseStamped',
                                                  POSE_STAMPED_MSGDEF),
                   'path': writer.register_msgdef('nav_msgs/msg/Path', PATH_MSGDEF)}
        for topic, (kind, messages) in topics.items():
            for k, (log_time, msg) in enumerate(messages):
                writer.write_message(topic, schemas[kind], msg, log_time=log_time, sequence=k)
        writer.finish()
