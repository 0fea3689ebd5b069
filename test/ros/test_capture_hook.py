"""``rcac capture-demo``'s payload requests over real DDS: a request due before the
simulator's parameter service is matched waits for it instead of being lost."""

import time

from test_nodes_support import ros_context

from builtin_interfaces.msg import Time  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402

from rcac_ros import topics  # noqa: E402
from rcac_ros.core.payload import Payload  # noqa: E402
from rcac_ros.tools.demos.capture import capture_hook  # noqa: E402


def test_a_request_due_before_the_service_exists_reaches_it():
    """The clock passes the grasp time while no simulator exists; the simulator's node then
    appears: it receives the grasp (a request sent at the grasp time would have been lost)."""
    lines = []
    hook = capture_hook(0.1, None, Payload(5.0, (0.0, 0.0, 0.5)), lines.append)
    with ros_context() as (ctx, executor):
        clock = Node("clock_source", context=ctx)
        pub = clock.create_publisher(Clock, topics.CLOCK, topics.qos(depth=1))
        close = hook(ctx, executor)
        try:
            def tick(seconds):
                pub.publish(Clock(clock=Time(sec=int(seconds),
                                             nanosec=int(seconds % 1 * 1e9))))

            deadline = time.monotonic() + 30.0      # the clock past the grasp time, until
            while not lines and time.monotonic() < deadline:    # the hook has acted on it
                tick(0.2)
                time.sleep(0.02)
            sim = Node(topics.SIMULATOR_NODE, context=ctx)
            sim.declare_parameter("payload.mass", 0.0)
            sim.declare_parameter("payload.com", [0.0, 0.0, 0.0])
            sim.declare_parameter("payload.inertia", [0.0] * 6)
            executor.add_node(sim)
            deadline = time.monotonic() + 20.0
            while time.monotonic() < deadline and sim.get_parameter("payload.mass").value != 5.0:
                tick(0.3)
                executor.spin_once(timeout_sec=0.02)
            assert sim.get_parameter("payload.mass").value == 5.0, lines
            assert len(hook.futures) == 1 and "waiting for" in lines[0], lines
        finally:
            close()
