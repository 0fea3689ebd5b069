"""rcac_ros: recursive composite adaptive control for serial manipulators (ROS 2 Jazzy)."""

__version__ = "0.1.0"
