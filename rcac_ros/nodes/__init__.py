"""ROS 2 nodes: ``controller`` and ``simulator`` (they never import each other)."""
