"""Messages to arrays: sensor_msgs/JointState and trajectory_msgs/JointTrajectory."""
