"""
Limits that bound what the nodes accept from outside, named in one place (no ROS needed).

Each limit says its unit and what it protects. A limit a user may want to tune is a node
parameter instead (etdmp_ros/ros/system.py). Sections are per node or subsystem; keep each one's
constants together under its heading.
"""

# dmp_server, demonstrations and skills ---------------------------------------------------------

#: Largest demonstration file read (bytes), checked before reading: bounds the time and memory
#: of reading a .csv, .npy, .npz or .mcap file (a 200 MB CSV took 83 s and 16 GB before).
MAX_DEMO_FILE_BYTES = 16 * 1024 * 1024

#: Most samples of one demonstration (rows of a file, messages or poses of a recording, poses of
#: a taught Path): bounds learning time and memory. 20 000 samples are 200 s at 100 Hz.
MAX_DEMO_SAMPLES = 20_000

#: Most joint states read from one ``.mcap`` recording (kinesthetic teaching): a UR driver
#: publishes them at 500 Hz, so this is 200 s of teaching; the motion, once trimmed, is
#: decimated to at most MAX_DEMO_SAMPLES samples.
MAX_RECORDED_JOINT_STATES = 100_000

#: Most coordinates per sample of a demonstration file (skills use 2 or 3).
MAX_DEMO_COORDINATES = 16

#: Largest uncompressed array in an .npz archive or .npy file (bytes), from its header, checked
#: before anything is allocated: a 289-byte .npy may claim 14.6 TiB, a 1.5 MB .npz 800 MB.
MAX_DEMO_ARRAY_BYTES = MAX_DEMO_SAMPLES * MAX_DEMO_COORDINATES * 8

#: Most rows a CSV reader looks at, blank ones included (bounds the time spent on a file of
#: empty lines; data rows are bounded by MAX_DEMO_SAMPLES).
MAX_CSV_ROWS = 2 * MAX_DEMO_SAMPLES + 1

#: Longest demonstration (s, last minus first sample time): a plan samples it every
#: output_period, so the duration bounds the plan's size (stamps spanning 1.975e9 s asked for
#: 2e11 samples). The same bound as the dmp_server parameter duration.
MAX_DEMO_DURATION = 600.0

#: Shortest time between two samples of a demonstration (s): closer stamps make the fitted
#: accelerations meaningless (and huge).
MIN_DEMO_SAMPLE_INTERVAL = 1e-6

#: Largest absolute coordinate of a demonstration (demo units for 2D skills, metres for 3D):
#: keeps every product of learning and generalizing finite (coordinates x 1e300 overflowed).
MAX_DEMO_COORDINATE = 1e4

#: Smallest extent of a demonstration (its largest distance from its goal, in its units): below
#: this it does not move, and scaling it to a request divides by ~0.
MIN_DEMO_EXTENT = 1e-6

#: Largest serialized nav_msgs/Path accepted on /etdmp/demonstrations (bytes), checked before
#: it is decoded: a pose takes about 90 bytes with frame id base_link. Bounds the time the
#: node spends on one taught path (10^5 poses blocked /generalize for 4.7 s).
MAX_TAUGHT_PATH_BYTES = MAX_DEMO_SAMPLES * 128 + 4096

#: Largest absolute coordinate (m, base_link) of a point given from outside: a request's start
#: or goal; a received goal, obstacle or tool position; dmp_server's static_obstacles; the scene's
#: positions (task plane origin, camera, table, goal marker, obstacles, bottle). Anything beyond
#: is no place on the workcell, and 1e308 overflows: when projected, and in every later plan
#: when it is an obstacle or the plane's origin (they were accepted, then every /generalize was
#: refused with "overflow encountered in divide").
MAX_REQUEST_COORDINATE = 100.0

#: Longest text of a number or reason in a log line (characters).
MAX_REASON_CHARS = 300

#: Largest distance (m) of a goal from the task plane for a 2D skill: a goal further away is
#: refused instead of being projected onto the plane.
MAX_GOAL_PLANE_DISTANCE = 0.2

#: Requests /generalize holds waiting to be served: the depth of the middleware's request history
#: (KEEP_LAST) and of the node's own queue, into which its service thread takes them with their
#: receipt times. rclpy's default of 10 dropped 38 of a burst of 50 silently, and a history of
#: 256 lost 31 of a burst of 356 on a loaded machine, before the thread could take them. A
#: request whose turn comes after more than ``max_request_wait`` is answered at once with an
#: empty plan (refused as busy), so the queues stay short under overload; a burst of more than
#: this many at once can still lose the oldest in the middleware, unseen by the node.
MAX_QUEUED_REQUESTS = 1024

#: Poses of a plan at which the timing check solves the arm's IK (evenly spaced in time); joint
#: velocities and accelerations are finite differences between them, so a peak shorter than
#: the spacing (2 s / 32 = 62 ms at the default) is underestimated: the check is for plans far
#: beyond the arm (a 2 s letter asked in 0.5 s needs 6 times the elbow's acceleration). Bounds
#: the check's cost: 32 poses about 1.8 ms per plan, 64 poses 3.7 ms, which took /generalize
#: past 1.5 x the bare-rclpy floor (bench_dmp_server.py).
TIMING_CHECK_SAMPLES = 32

#: Fraction of each joint's velocity and acceleration limit a plan may need (the limits the
#: controller commands within: UR10Model.velocity_limits, DEFAULT_ACCELERATION_LIMITS).
TIMING_LIMIT_FRACTION = 1.0

# perception and camera input -------------------------------------------------------------------
# What a RealSense D435 colour camera (with depth aligned to it) can deliver in this workcell.
# A camera_info, image or detection outside these is refused with the reason (docs/perception.md).

#: Image width (px) of camera_info and the images: the D435 colour stream's modes, 320x180 up
#: to 1920x1080.
CAMERA_WIDTH_RANGE = (320, 1920)

#: Image height (px) of camera_info and the images (D435 colour modes).
CAMERA_HEIGHT_RANGE = (180, 1080)

#: Horizontal field of view (deg) that fx of camera_info must give, 2 atan(width / 2 fx). A
#: D435's colour lens sees about 69 x 42 deg (16:9 modes; 55 x 43 deg in the 4:3 modes such as
#: 640x480, fx = fy = 617 px there). fx = 1e-300 px (180 deg) put a goal at 1e301 m.
CAMERA_HFOV_RANGE = (40.0, 90.0)

#: Vertical field of view (deg) that fy of camera_info must give, 2 atan(height / 2 fy).
CAMERA_VFOV_RANGE = (30.0, 65.0)

#: Largest difference of fx and fy, relative to fx (the D435's pixels are square).
MAX_FOCAL_ASPECT_ERROR = 0.05

#: Largest distance of the principal point (cx, cy) from the image centre, as a fraction of the
#: image width and height (a D435's is within 2 %).
MAX_PRINCIPAL_POINT_OFFSET = 0.1

#: Depth (z in the optical frame, m) a D435 can measure: its minimum distance at 640x480 is about
#: 0.1 m, its range at most 10 m. An object whose median depth is outside is refused (a depth
#: image in metres or with swapped bytes reads as centimetres or 20 m).
DEPTH_RANGE = (0.1, 10.0)

#: A blob may cover at most this many times the image area of the sphere around its object,
#: seen at the blob's depth and stretched as perspective stretches it in the image corners (the
#: goal marker's disc covers about 0.8 of the unstretched sphere at 1.1 m depth, an obstacle
#: 0.55; the margin is for the pixels along the edge of a small blob): an all-green frame
#: (307 200 px) is no goal marker (700 px; at most 2 300 px at its 1.1 m).
MAX_BLOB_AREA_FACTOR = 1.5

#: Obstacles of one colour that touch are one blob, reported once (Detection.single False): a
#: blob may be this many obstacles large, in image area and in metres.
MAX_MERGED_OBSTACLES = 3

#: How much farther (m, horizontally in base_link) than its radius a located object's points
#: may lie from its axis (depth noise; see MAX_OUTSIDE_FRACTION).
OBJECT_EXTENT_MARGIN = 0.015

#: Fraction of a located object's points that may lie farther from its axis than its radius +
#: OBJECT_EXTENT_MARGIN (flying pixels at its edges, up to the object's depth extent behind
#: it). A green strip of 160 x 12 px on the table (1 900 px, below the area bound) spreads over
#: 0.3 m: refused.
MAX_OUTSIDE_FRACTION = 0.05

# controller and its inputs ---------------------------------------------------------------------
# The tunable ones are controller parameters: max_path_poses (20 000), joint_state_timeout,
# simulation_stall_timeout (docs/controller.md).

#: Joint states the controller's subscription holds (KEEP_LAST): a flood from another publisher,
#: delivered in bursts when the machine is busy, must not push the robot's own out before they
#: are read (13 000 junk joint states a second through a 10-deep queue lost the robot's for
#: 0.1 s). All that queued is taken in one go, microseconds each, and the controller steps once.
JOINT_STATE_QUEUE = 1000

#: Most joints one JointState may name (a whole robot with grippers and sensors: generous);
#: bounds reading a forged message.
MAX_JOINT_STATE_JOINTS = 256

# ur10_sim, the simulated workcell --------------------------------------------------------------
# The scene's sizes are ranges in etdmp_ros/ros/system.py (docs/ur10_sim.md); where its objects may
# stand is checked by etdmp_ros.robot.SceneConfig, at start-up and when they are moved.

#: Radius (m) about base_link's z axis of what the UR10 occupies at its foot: its base (0.095 m,
#: up to 0.04 m high) and the shoulder turning above it (0.114 m, up to 0.22 m), from the
#: collision meshes. The goal marker, an obstacle or the bottle standing nearer (their own
#: radius included) would stand inside the robot: refused.
ROBOT_BASE_RADIUS = 0.115

# teach, the teaching page ----------------------------------------------------------------------

#: Largest request body the teaching page's server reads (bytes): a bigger one is refused with
#: HTTP 413 before it is parsed. A drawing of MAX_DRAWN_POINTS points sent as JSON [x, y, t]
#: rows takes at most about 0.8 MB; 10^6 points take 8-30 MB.
MAX_TEACH_REQUEST_BYTES = 2 * 1024 * 1024

#: Most points of one drawing: its strokes' points and those joining them, as many as a
#: demonstration may have (MAX_DEMO_SAMPLES).
MAX_DRAWN_POINTS = MAX_DEMO_SAMPLES

#: Most strokes of one drawing (each pen-up starts a new one; they are joined in order).
MAX_STROKES = 100
