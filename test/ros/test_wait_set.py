"""The nodes' publishers carry no event handlers of rclpy's (doc/failsafe.md, "Real-time
options"): the executor's wait set, rebuilt at every spin, holds the subscriptions' handlers
only; an incompatible subscriber is still told, on its side."""

import time

from test_nodes_support import ros_context

from rclpy.event_handler import (EventHandler, PublisherEventCallbacks,  # noqa: E402
                                 SubscriptionEventCallbacks)
from rclpy.node import Node  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from rcac_ros import topics  # noqa: E402
from rcac_ros.nodes.controller.node import ControllerNode  # noqa: E402
from rcac_ros.nodes.simulator.node import SimulatorNode  # noqa: E402


def handlers(node):
    return [w for w in node.waitables if isinstance(w, EventHandler)]


def test_publishers_have_no_default_event_handlers_subscriptions_keep_theirs():
    with ros_context() as (ctx, executor):
        sim = SimulatorNode(context=ctx)
        ctrl = ControllerNode(context=ctx)          # autostart: configured and active
        for node in (sim, ctrl):
            executor.add_node(node)
            subs = list(node.subscriptions)
            assert len(list(node.publishers)) >= 3
            # rclpy gives each subscription two (incompatible QoS, incompatible type)
            assert len(handlers(node)) == 2 * len(subs), node.get_name()
        # the controller's states come on a node of their own, which no executor spins: its
        # reader's thread serves the subscription's two
        state_input = ctrl.states._side
        assert list(sim.subscriptions) and len(list(state_input.node.subscriptions)) == 1
        events = state_input.subscription.event_handlers
        assert len(events) == 2 and state_input._reader._events == events
        # an explicit request is kept
        seen = []
        pub = sim.create_publisher(JointState, "~/probe", 10,
                                   event_callbacks=PublisherEventCallbacks(
                                       incompatible_qos=seen.append,
                                       use_default_callbacks=False))
        assert len(handlers(sim)) == 2 * len(list(sim.subscriptions)) + 1
        sim.destroy_publisher(pub)


def test_an_incompatible_subscriber_is_told_on_its_side():
    """The simulator's joint states are volatile; a subscriber asking for transient-local
    durability is incompatible, and its own default-less callback hears of it."""
    with ros_context() as (ctx, executor):
        sim = SimulatorNode(context=ctx)
        probe = Node("probe", context=ctx)
        told = []
        probe.create_subscription(
            JointState, topics.resolve(topics.JOINT_STATES),
            lambda m: None, QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL),
            event_callbacks=SubscriptionEventCallbacks(incompatible_qos=told.append))
        executor.add_node(sim)
        executor.add_node(probe)
        end = time.monotonic() + 10.0
        while not told and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        assert told and told[-1].total_count >= 1
