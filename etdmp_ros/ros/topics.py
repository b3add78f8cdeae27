"""
The system's topic and service names, as the nodes use them: written once.

Relative names (``etdmp/path``), so that a namespace (``__ns``) moves them all; ``~/`` names are
private to the node that publishes them (``~/ground_truth/tool_tip`` of ``ur10_sim`` is
``/ur10_sim/ground_truth/tool_tip``). ``/clock`` is absolute: rclpy's simulated time listens
to it. A tool in the root namespace (the demo's recorder, the tests) takes the absolute names
from :func:`absolute`. docs/ros.md lists them all with their types.
"""

# ur10_sim (and its camera process) -> perception, controller, dmp_server
JOINT_STATES = 'joint_states'
CLOCK = '/clock'
COLOR = 'camera/camera/color/image_raw'
COLOR_INFO = 'camera/camera/color/camera_info'
DEPTH = 'camera/camera/aligned_depth_to_color/image_raw'
DEPTH_INFO = 'camera/camera/aligned_depth_to_color/camera_info'
#: The camera's topics by the names its publishers use (``_sim_camera.CameraPublishers``).
CAMERA = {'color': COLOR, 'depth': DEPTH, 'color_info': COLOR_INFO, 'depth_info': DEPTH_INFO}
ROBOT_DESCRIPTION = 'robot_description'
TF = 'tf'
TF_STATIC = 'tf_static'
GROUND_TRUTH_GOAL = '~/ground_truth/goal'
GROUND_TRUTH_OBSTACLES = '~/ground_truth/obstacles'
GROUND_TRUTH_BOTTLE = '~/ground_truth/bottle'
GROUND_TRUTH_TOOL_TIP = '~/ground_truth/tool_tip'
GROUND_TRUTH_CONTACTS = '~/ground_truth/contacts'
TEACHING = '~/teaching'

# perception -> dmp_server
GOAL = 'etdmp/goal'
OBSTACLES = 'etdmp/obstacles'
OBSTACLE_VOLUMES = 'etdmp/obstacle_volumes'
BOTTLE = 'etdmp/bottle'
DETECTIONS_IMAGE = 'etdmp/detections/image'

# dmp_server -> controller, and teaching
GENERALIZE = 'generalize'
TEACH = '~/teach'
GENERALIZE_WITH = '~/generalize_with'
PATH = 'etdmp/path'
MARKERS = 'etdmp/markers'
DEMONSTRATIONS = 'etdmp/demonstrations'

# controller -> ur10_sim, and what it reports
COMMANDS = 'forward_velocity_controller/commands'
TOOL_POSE = 'etdmp/tool_pose'
CONTROLLER_STATUS = 'etdmp/controller/status'
TRACKING_ERROR = 'etdmp/controller/tracking_error'
REFERENCE = 'etdmp/controller/reference'
PAUSE = '~/pause'

#: What a node reports happened (diagnostic_msgs/DiagnosticArray; etdmp_ros.ros.events).
EVENTS = '~/events'


def of_node(name: str, node: str) -> str:
    """
    Return node ``node``'s private ``~/`` name as another node subscribes it (relative).

    >>> of_node(GROUND_TRUTH_TOOL_TIP, 'ur10_sim')
    'ur10_sim/ground_truth/tool_tip'
    """
    if not name.startswith('~/'):
        raise ValueError(f'{name!r} is not a private name')
    return f'{node}/{name[2:]}'


def absolute(name: str, node: str = '') -> str:
    """
    Return ``name`` as seen from the root namespace: ``/<name>``, ``/<node>/...`` for ``~/``.

    >>> absolute(PATH), absolute(GROUND_TRUTH_TOOL_TIP, 'ur10_sim')
    ('/etdmp/path', '/ur10_sim/ground_truth/tool_tip')
    """
    if name.startswith('/'):
        return name
    if name.startswith('~/'):
        if not node:
            raise ValueError(f'{name!r} is private to a node: name the node')
        return f'/{node}/{name[2:]}'
    return '/' + name
