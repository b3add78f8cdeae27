"""
Limits that bound what the nodes accept from outside, named in one place (no ROS needed).

Each limit says its unit and what it protects. A limit a user may want to tune is a node
parameter instead (etdmp_ros/system.py). Sections are per node or subsystem; keep each one's
constants together under its heading.
"""

# dmp_server, demonstrations and skills ---------------------------------------------------------

#: Largest demonstration file read (bytes), checked before reading: bounds the time and memory
#: of reading a .csv, .npy, .npz or .mcap file (a 200 MB CSV took 83 s and 16 GB before).
MAX_DEMO_FILE_BYTES = 16 * 1024 * 1024

#: Most samples of one demonstration (rows of a file, messages or poses of a recording, poses of
#: a taught Path): bounds learning time and memory. 20 000 samples are 200 s at 100 Hz.
MAX_DEMO_SAMPLES = 20_000

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

#: Largest absolute coordinate of a request's start or goal and of a received goal (m, base_link):
#: anything beyond is no place on the workcell (and 1e308 overflows when projected).
MAX_REQUEST_COORDINATE = 100.0

#: Longest text of a number or reason in a log line (characters).
MAX_REASON_CHARS = 300

#: Largest distance (m) of a goal from the task plane for a 2D skill: a goal further away is
#: refused instead of being projected onto the plane.
MAX_GOAL_PLANE_DISTANCE = 0.2

#: Requests /generalize keeps waiting to be served (the service's request-history depth,
#: KEEP_LAST).
#: rclpy's default of 10 dropped 38 of a burst of 50 silently. A burst beyond this many requests
#: outstanding at once still loses the oldest ones in the middleware, unseen by the node (rclpy
#: offers no notification of a dropped request): the remaining limit.
MAX_QUEUED_REQUESTS = 256

#: Poses of a plan at which the timing check solves the arm's IK (evenly spaced in time); joint
#: velocities and accelerations are finite differences between them, so a peak shorter than
#: the spacing (2 s / 64 = 31 ms at the default) is underestimated. Bounds the check's cost.
TIMING_CHECK_SAMPLES = 64

#: Fraction of each joint's velocity and acceleration limit a plan may need (the limits the
#: controller commands within: UR10Model.velocity_limits, DEFAULT_ACCELERATION_LIMITS).
TIMING_LIMIT_FRACTION = 1.0
