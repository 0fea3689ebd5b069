"""``rcac record`` and the simulator's ``~/payload`` (transient local, depth 10): a recorder
that matches the publisher after its messages were sent still records them, as a late
subscriber of a transient-local topic gets the writer's history (doc/tools.md, "rcac
record")."""

from bagtest_support import read_rosbags, Recorder, wait_for
from bagtest_support import ros_env  # noqa: F401 - a fixture

from rcac_ros import topics

PAYLOAD = topics.resolve(topics.PAYLOAD, topics.SIMULATOR_NODE)


def test_payload_sent_before_the_recorder_is_recorded(tmp_path, ros_env):  # noqa: F811
    import rclpy
    from geometry_msgs.msg import InertiaStamped

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(ros_env["_DOMAIN"]))
    node = rclpy.create_node("payload_test_publisher", context=ctx)
    pub = node.create_publisher(InertiaStamped, PAYLOAD, topics.qos(10, transient_local=True))
    masses = (0.0, 1000.0)
    for mass in masses:                 # the payload at start, then a grasp: before the recorder
        msg = InertiaStamped()
        msg.inertia.m = mass
        pub.publish(msg)
    bag = tmp_path / "bag"
    rec = Recorder(tmp_path, ros_env, "--out", str(bag), "--duration", "3")
    try:
        wait_for(lambda: pub.get_subscription_count() > 0, 90, "the recorder subscribes", rec)
        assert rec.proc.wait(90) == 0, rec.output()
    finally:
        rec.stop()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    data = read_rosbags(str(bag))
    assert [m.inertia.m for _, m in data.get(PAYLOAD, [])] == list(masses), rec.output()
