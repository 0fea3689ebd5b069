"""The lock-free take of the side inputs (``nodes/runtime/rawtake.py``, doc/failsafe.md "Where the
time of a flood goes"): what ``rcl`` hands over is the message as published, a sample above
the cap never reaches the callback, and the thread stops cleanly."""

import threading
import time

from rclpy.node import Node
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from test_nodes_support import QOS, ros_context
from rcac_ros.nodes.runtime.inputs import SideInput


def test_side_input_delivers_within_the_cap_and_refuses_above_it():
    with ros_context() as (ctx, _):
        owner = Node("rawtake_owner", context=ctx)
        got, refused, lock = [], [], threading.Lock()

        def on_msg(msg):
            with lock:
                got.append(msg)

        def reject(kind, text):
            with lock:
                refused.append((kind, text))
        small = JointState(name=["a", "b"], position=[1.5, -2.0])
        cap = len(serialize_message(small)) + 16
        big = JointState(name=[f"j{i}" for i in range(1000)], position=[0.0] * 1000)
        side = SideInput(owner, JointState, "/rawtake_test", QOS, on_msg, cap, "state", reject)
        pub = owner.create_publisher(JointState, "/rawtake_test", QOS)
        try:
            end = time.monotonic() + 20.0
            while pub.get_subscription_count() == 0 and time.monotonic() < end:
                time.sleep(0.01)
            for msg in (small, big, small, big, small):
                pub.publish(msg)
                time.sleep(0.02)
            end = time.monotonic() + 10.0
            while time.monotonic() < end:
                with lock:
                    if len(got) == 3 and len(refused) == 2:
                        break
                time.sleep(0.01)
        finally:
            side.close()
            owner.destroy_node()
        assert [(list(m.name), list(m.position)) for m in got] == [(["a", "b"], [1.5, -2.0])] * 3
        size = len(serialize_message(big)) - 4      # rclpy's serialize adds 4 bytes of padding
        assert [k for k, _ in refused] == ["size", "size"]
        assert all(f"above the cap of {cap}" in t for _, t in refused)
        assert all(abs(int(t.split(": ")[1].split()[0]) - size) <= 8 for _, t in refused), \
            (refused, size)
        assert not side._reader._thread.is_alive()
