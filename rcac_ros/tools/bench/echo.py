"""A plain DDS echo: the baseline of the ROS benchmark's latency (``rcac bench ros``).

One rclpy node, nothing of this package's control code: it republishes every
``sensor_msgs/JointState`` it receives on :data:`PING` to :data:`PONG`, from the
subscription's callback in a ``SingleThreadedExecutor``, as the controller answers a state
in ``on_state`` mode. The benchmark's probe sends a 7-joint ping every 20 ms and halves the
round trip: one hop of the same message over the same DDS, in the same run as the loop it
measures, with the wake-up of a Python executor at the far end
(``python -m rcac_ros.tools.bench.echo``, started by
:func:`rcac_ros.tools.bench.ros.run_ros_bench`).
"""

import sys

PING = "/rcac_bench/ping"
PONG = "/rcac_bench/pong"


def main(argv=None):
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    from rcac_ros import topics

    rclpy.init(args=argv)
    node = rclpy.create_node("rcac_bench_echo")
    pub = node.create_publisher(JointState, PONG, topics.qos(10))
    node.create_subscription(JointState, PING, pub.publish, topics.qos(10))
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
