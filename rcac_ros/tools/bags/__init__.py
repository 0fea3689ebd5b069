"""rosbag2 bags: writing, verifying and recovering, recording, inspecting (doc/tools.md)."""
