"""The hand-over of the controller's state input between its side thread and the control
thread (module docstring of ``nodes/controller/state_input.py``): the side thread hands over
one snapshot and never touches the watchdog or the node; a reset waits for a state being
read."""

import threading

import numpy as np

from test_nodes_support import ros_context

from rclpy.node import Node  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from rcac_ros.nodes.controller.state_input import StateInput  # noqa: E402
from rcac_ros.nodes.safety.state_guards import StampGate  # noqa: E402

JOINTS = ["a", "b"]
H = 0.002


def state(stamp_ns, q):
    msg = JointState(name=JOINTS, position=list(q), velocity=[0.0, 0.0])
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    return msg


class Watchdog:
    """Records the threads that tell it of a valid state."""

    def __init__(self):
        self.tripped = True
        self.calls = []

    def valid_state(self, unbroken):
        self.calls.append(threading.get_ident())
        self.tripped = False


class PausingGate(StampGate):
    """A stamp gate that, once armed, stops inside ``check`` until released."""

    def __init__(self):
        super().__init__()
        self.armed = False
        self.inside, self.release = threading.Event(), threading.Event()

    def check(self, stamp, now, stale=False):
        if self.armed:
            self.inside.set()
            assert self.release.wait(10.0)
        return super().check(stamp, now, stale)


def state_input(ctx, gate, watchdog, restarted):
    node = Node("state_input_threads", context=ctx)
    warnings = []
    states = StateInput(node, joint_names=JOINTS, lockstep=False, h=H, velocity_cutoff=20.0,
                        gate=gate, max_bytes=65_536, watchdog=watchdog, outputs=None,
                        log=node.get_logger(),
                        warn=lambda kind, text: warnings.append((kind, text)),
                        is_running=lambda: True, steps=lambda: 1, restarted=restarted,
                        control=None)
    return node, states, warnings


def in_thread(fn, *args):
    thread = threading.Thread(target=fn, args=args)
    thread.start()
    return thread


def test_the_side_thread_hands_over_a_snapshot_and_the_control_thread_tells_the_watchdog():
    with ros_context() as (ctx, _):
        watchdog, restarts = Watchdog(), []
        node, states, warnings = state_input(
            ctx, StampGate(), watchdog, lambda: restarts.append(threading.get_ident()))
        try:
            # the side thread: a state, then one that goes back in time while the watchdog
            # has tripped (a restart of the stream, accepted at once)
            in_thread(states._on_state, state(5_000_000_000, [0.1, 0.2])).join()
            assert watchdog.calls == [] and restarts == []
            first = states.take()           # the control thread
            assert watchdog.calls == [threading.get_ident()] and restarts == []
            np.testing.assert_array_equal(first.q, [0.1, 0.2])
            assert first.stamp == 5_000_000_000 and first.received == states.received
            watchdog.tripped = True
            in_thread(states._on_state, state(1_000_000, [0.3, 0.4])).join()
            assert len(watchdog.calls) == 1 and restarts == []  # nothing from the side thread
            second = states.take()
            assert restarts == [threading.get_ident()]      # once, in the control thread
            assert watchdog.calls == [threading.get_ident()] * 2
            np.testing.assert_array_equal(second.q, [0.3, 0.4])
            assert second.stamp == 1_000_000
            assert states.take() is second and len(watchdog.calls) == 2     # told once
            assert len(restarts) == 1 and warnings == []
        finally:
            states.close()
            node.destroy_node()


def test_after_a_trip_only_the_first_state_may_go_back_in_time_until_the_control_thread_takes():
    """The watchdog hears of a state when the control thread takes it: until then, a second
    state going back in time is a stale message, not a second restart."""
    with ros_context() as (ctx, _):
        watchdog, restarts = Watchdog(), []
        node, states, warnings = state_input(ctx, StampGate(), watchdog,
                                             lambda: restarts.append(1))
        try:
            in_thread(states._on_state, state(5_000_000_000, [0.1, 0.2])).join()
            states.take()
            watchdog.tripped = True                 # no valid state for a while
            in_thread(states._on_state, state(1_000_000_000, [0.3, 0.4])).join()  # restart
            in_thread(states._on_state, state(2_000_000, [0.5, 0.6])).join()      # stale
            assert [kind for kind, _ in warnings] == [StampGate.BACKWARDS]
            taken = states.take()
            assert taken.stamp == 1_000_000_000 and restarts == [1]
            np.testing.assert_array_equal(taken.q, [0.3, 0.4])
        finally:
            states.close()
            node.destroy_node()


def test_a_reset_waits_for_a_state_being_read_and_none_from_before_survives_it():
    with ros_context() as (ctx, _):
        gate = PausingGate()
        node, states, _ = state_input(ctx, gate, Watchdog(), lambda: None)
        try:
            gate.armed = True
            reader = in_thread(states._on_state, state(5_000_000_000, [0.1, 0.2]))
            assert gate.inside.wait(10.0)           # the side thread is inside the gate
            resetter = in_thread(states.reset)
            resetter.join(0.2)
            assert resetter.is_alive()              # the reset waits for it ...
            gate.release.set()
            reader.join(10.0)
            resetter.join(10.0)
            assert not reader.is_alive() and not resetter.is_alive()
            assert states.latest is None            # ... and nothing from before it is left
            assert gate.last is None
        finally:
            gate.release.set()
            states.close()
            node.destroy_node()
