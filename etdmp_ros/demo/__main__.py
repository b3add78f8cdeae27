"""``python -m etdmp_ros.demo``: the closed-loop demo (``make demo``)."""

import sys

from etdmp_ros.demo.cli import main

sys.exit(main())
