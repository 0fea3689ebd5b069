"""The ROS interface helpers of rcac_ros/topics.py against rclpy itself.

``topics.resolve`` (used offline, on a bag's topic names) must expand a name as a node
does (``Node.resolve_topic_name`` with ``only_expand``); ``topics.is_watchdog_effort``
(read on raw bytes, without deserialising) must agree with the label of the message rclpy
serialises.
"""

import pytest

rclpy = pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from std_msgs.msg import Float64MultiArray, MultiArrayDimension  # noqa: E402

from rcac_ros import topics  # noqa: E402

NAMES = [topics.JOINT_STATES, topics.EFFORT_COMMANDS, topics.JOINT_TRAJECTORY,
         topics.PARAMETER_ESTIMATES, topics.PREDICTION_ERRORS, topics.TRACKING_ERROR,
         topics.DESIRED_STATE, topics.DIAGNOSTICS, topics.CLOCK]


@pytest.mark.parametrize("namespace", ["", "/arm", "/robot/left"])
def test_resolve_expands_every_topic_as_a_node_does(namespace):
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        node = rclpy.create_node(topics.CONTROLLER_NODE, namespace=namespace or None,
                                 context=ctx, start_parameter_services=False)
        for name in NAMES:
            assert topics.resolve(name, topics.CONTROLLER_NODE, namespace) \
                == node.resolve_topic_name(name, only_expand=True), name
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def effort(label, n=7):
    msg = Float64MultiArray(data=[0.5] * n)
    msg.layout.dim = [MultiArrayDimension(label=label, size=n, stride=n)]
    return serialize_message(msg)


@pytest.mark.parametrize("n", [1, 7, 224])
def test_the_watchdog_tag_is_read_from_the_raw_bytes(n):
    assert topics.is_watchdog_effort(effort(topics.effort_label(watchdog=True), n))
    stamped = topics.effort_label(Time(sec=12, nanosec=345))
    assert not topics.is_watchdog_effort(effort(stamped, n))
    assert not topics.is_watchdog_effort(effort(topics.effort_label(), n))
    # and the deserialised reading agrees
    assert topics.effort_tag(topics.effort_label(watchdog=True)) == ("watchdog", None)
