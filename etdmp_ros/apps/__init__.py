"""The offline command line ``etdmp`` (no ROS): generalize, reproduce the paper, plot."""
