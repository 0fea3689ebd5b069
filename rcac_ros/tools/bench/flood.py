"""A separate process that floods the controller's inputs with huge messages.

``python -m rcac_ros.tools.bench.flood SECONDS`` publishes, alternately and as fast as it can, a
JointState of 1e6 positions (8 MB) and a JointTrajectory of 1e5 points (5.6 MB), until
SECONDS have passed; it prints how many it sent.
"""

import sys
import time

import rclpy
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint


def main():
    seconds = float(sys.argv[1])
    rclpy.init()
    node = rclpy.create_node("failsafe_flood")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE)
    pub_state = node.create_publisher(JointState, "/joint_states", qos)
    pub_traj = node.create_publisher(JointTrajectory, "/rcac_controller/joint_trajectory", qos)
    names = [f"joint{i}" for i in range(1, 8)]
    big_state = JointState(name=names, position=[0.0] * 1_000_000)
    big_traj = JointTrajectory(joint_names=names, points=[
        JointTrajectoryPoint(positions=[0.0] * 7) for _ in range(100_000)])
    end = time.monotonic() + 30.0
    while time.monotonic() < end and (pub_state.get_subscription_count() == 0
                                      or pub_traj.get_subscription_count() == 0):
        time.sleep(0.01)
    print("flood: start", flush=True)
    sent = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pub_state.publish(big_state)
        pub_traj.publish(big_traj)
        sent += 2
        time.sleep(0.01)
    print(f"flood: sent {sent}", flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
