"""A separate process that floods the controller's inputs with huge messages.

``python -m rcac_ros.tools.bench.flood SECONDS`` builds a JointState of 1e6 positions (8 MB)
and a JointTrajectory of 1e5 points (5.6 MB), waits for a subscriber on both topics (the
controller with ``trajectory: topic``; none within ``--match-timeout`` s, default
:data:`MATCH_TIMEOUT`: one line on stderr, exit code 1),
prints ``flood: start`` and publishes them alternately, every 10 ms, for SECONDS; it prints
how many it sent. ``--names N`` gives the JointState N joint names (and N positions)
instead: 1e6 names are about 20 MB, and a names list is costly to build; ``--period S``
sets the pause between two pairs (the hostile flood of doc/failsafe.md: ``--names 1000000
--period 0.1``).
"""

import argparse
import sys
import time

import rclpy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from rcac_ros import topics

#: s to wait for a subscriber on both topics before giving up (exit code 1)
MATCH_TIMEOUT = 30.0


def messages(names, points):
    """The JointState (``names`` joint names, or 7 and 1e6 positions) and trajectory."""
    joints = [f"joint{i}" for i in range(1, 8)]
    if names:
        state = JointState(name=[f"joint{i}" for i in range(names)], position=[0.0] * names)
    else:
        state = JointState(name=joints, position=[0.0] * 1_000_000)
    traj = JointTrajectory(joint_names=joints, points=[
        JointTrajectoryPoint(positions=[0.0] * 7) for _ in range(points)])
    return state, traj


def main(argv=None):
    parser = argparse.ArgumentParser(prog="flood", description=__doc__.splitlines()[0])
    parser.add_argument("seconds", type=float)
    parser.add_argument("--names", type=int, default=0)
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--period", type=float, default=0.01)
    parser.add_argument("--match-timeout", type=float, default=MATCH_TIMEOUT)
    args = parser.parse_args(argv)
    rclpy.init()
    node = rclpy.create_node("failsafe_flood")
    qos = topics.qos()
    pub_state = node.create_publisher(JointState, topics.resolve(topics.JOINT_STATES), qos)
    pub_traj = node.create_publisher(JointTrajectory, topics.resolve(topics.JOINT_TRAJECTORY),
                                     qos)
    big_state, big_traj = messages(args.names, args.points)
    end = time.monotonic() + args.match_timeout
    while pub_state.get_subscription_count() == 0 or pub_traj.get_subscription_count() == 0:
        if time.monotonic() > end:
            print(f"flood: error: no subscriber on {pub_state.topic_name} and "
                  f"{pub_traj.topic_name} within {args.match_timeout:g} s (the controller needs "
                  "trajectory: topic)", file=sys.stderr, flush=True)
            node.destroy_node()
            rclpy.shutdown()
            return 1
        time.sleep(0.01)
    print("flood: start", flush=True)
    sent = 0
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        pub_state.publish(big_state)
        pub_traj.publish(big_traj)
        sent += 2
        time.sleep(args.period)
    print(f"flood: sent {sent}", flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
