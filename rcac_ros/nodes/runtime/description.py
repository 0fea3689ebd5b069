"""The robot description from the stack: a transient-local std_msgs/String topic.

robot_state_publisher publishes the URDF on ``/robot_description`` with a reliable,
transient-local, keep-last-1 profile: a node that subscribes late still receives it. With
the parameter ``description_topic`` set, the controller waits in ``unconfigured`` until the
text arrives (then configures from it); the simulator waits before it starts.
"""

import time

from rclpy.exceptions import InvalidTopicNameException
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from rcac_ros.errors import ConfigError, first_line
from rcac_ros.nodes.runtime import interrupt

#: robot_state_publisher's profile for /robot_description
DESCRIPTION_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)


def subscribe_description(node, topic, callback):
    """Subscribe ``callback(xml: str)`` to the description ``topic`` (empty texts ignored)."""
    def on_message(msg):
        if msg.data.strip():
            callback(msg.data)
        else:
            node.get_logger().warning(f"{topic}: empty robot description ignored")
    try:
        return node.create_subscription(String, topic, on_message, DESCRIPTION_QOS)
    except InvalidTopicNameException as err:    # e.g. '{ns}/x' in the root namespace: '//x'
        why = first_line(err).removeprefix("Invalid topic name: ").rstrip(":")
        raise ConfigError(f"description_topic: {topic!r} is not a valid topic name in "
                          f"{node.get_namespace()} ({why})") from None


def wait_for_description(node, topic, executor_factory, log_every=5.0):
    """Block until the description arrives on ``topic``; return its text.

    The node is spun on its own executor (``executor_factory(context)``) meanwhile; an
    interrupt (KeyboardInterrupt) ends the wait. Logs "waiting" every ``log_every`` s.
    """
    received = []
    sub = subscribe_description(node, topic, received.append)
    executor = executor_factory(context=node.context)
    executor.add_node(node)
    try:
        last = -float("inf")
        while not received:
            now = time.monotonic()
            if now - last >= log_every:
                node.get_logger().info(f"waiting for the robot description on {topic}")
                last = now
            executor.spin_once(timeout_sec=0.1)
            interrupt.check()               # one Python dropped in a callback still counts
    finally:
        executor.remove_node(node)
        executor.shutdown()
        node.destroy_subscription(sub)
    return received[-1]
