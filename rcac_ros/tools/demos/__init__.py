"""The experiments and demos: the paper's experiment, the ROS demo, the payload demo, the
comparison of laws (doc/tools.md)."""
