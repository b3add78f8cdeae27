"""
numpy <-> ROS message helpers, written once for every node (no cv_bridge or tf2 here).

Importing this package imports rclpy message modules; the ROS-free core never does.
"""

from ._cdr import header_stamp_ns, message_class  # noqa: F401
from ._compressed import (compress_image_cdr, compressed_image_cdr,  # noqa: F401
                          compressed_image_from_cdr, COMPRESSED_IMAGE_TYPE, COMPRESSED_SUFFIX)
from ._geometry import (ns_to_stamp, path_from_numpy, path_to_numpy,  # noqa: F401
                        point_to_numpy, points_from_numpy, pose_array_from_numpy,
                        pose_array_to_numpy, serialize_path, stamp_to_ns)
from ._image import (camera_image_from_msg, camera_info_msg, ENCODINGS,  # noqa: F401
                     image_from_cdr, image_from_msg, image_msg, intrinsics_from_camera_info)
from ._joint_state import (joint_state_arrays, joint_state_from_cdr,  # noqa: F401
                           joint_state_msg, velocity_command_array, velocity_command_msg)
from ._markers import (contact_markers, contacts_from_markers,  # noqa: F401
                       cylinder_markers, cylinders_from_markers)
from ._path_cdr import path_from_cdr  # noqa: F401
from ._tf import MovingTransforms, tf_available, tf_message  # noqa: F401
