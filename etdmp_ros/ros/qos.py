"""
The QoS profiles the nodes share, written once.

A *latched* topic keeps its last messages for subscribers that join later (transient local
durability, reliable), as ``/robot_description``, ``/tf_static`` and the controller's status
are: a late subscriber gets the state at once instead of waiting for the next change.
"""

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy


def latched(depth: int = 1) -> QoSProfile:
    """Return a reliable, transient-local QoS profile keeping the last ``depth`` messages."""
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


#: The last message of a topic kept for late subscribers (/etdmp/path, statuses, URDF).
LATCHED = latched()
