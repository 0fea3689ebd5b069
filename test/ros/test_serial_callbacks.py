"""The controller's lockstep answer, its watchdog and its executor's callbacks run one at a
time (``rcac_ros/nodes/runtime/serial.py``, doc/failsafe.md, "Watchdog clock"): the answer
runs in the state input's thread and the watchdog in its own, each holding the node's lock,
which every callback of the node's executor holds too."""

import os
import threading
import time

import numpy as np
from test_nodes_support import H_NS, PAPER_Q0, Probe, ros_context, spin_until

from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from rcac_ros.nodes.controller.node import ControllerNode  # noqa: E402
from rcac_ros.nodes.runtime.serial import (SerialCallbackGroup, SerialCallbacks,  # noqa: E402
                                           SerialTimer)


class Serial(SerialCallbacks, Node):
    pass


def label(k):
    return f"stamp={k * H_NS // 1_000_000_000}.{k * H_NS % 1_000_000_000:09d}"


def test_every_entity_of_the_controller_is_in_its_serial_group():
    """The services rclpy makes in the node's constructor (parameters, lifecycle) too."""
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx)
        group = node.default_callback_group
        assert isinstance(group, SerialCallbackGroup)
        entities = [*node.services, *node.timers, *node.subscriptions, *node.guards,
                    *node.waitables, *node.clients]
        assert len(list(node.services)) >= 10
        assert all(e.callback_group is group for e in entities), \
            [type(e).__name__ for e in entities if e.callback_group is not group]


def test_an_executor_callback_never_runs_while_another_thread_holds_the_lock():
    with ros_context() as (ctx, executor):
        node = Serial("serial", context=ctx)
        calls = []
        node.create_timer(0.002, lambda: calls.append(time.monotonic()))
        executor.add_node(node)
        spin_until(executor, lambda: len(calls) >= 5)
        held = []

        def hold():
            with node.callback_lock:
                held.append(time.monotonic())
                time.sleep(0.2)
                held.append(time.monotonic())
        holder = threading.Thread(target=hold)
        holder.start()
        spin_until(executor, lambda: len(held) == 2 and calls[-1] > held[1], timeout=5.0)
        holder.join()
        inside = [t for t in calls if held[0] <= t <= held[1]]
        assert not inside and calls[-1] > held[1]


def test_a_serial_timer_runs_under_the_lock_and_reports_a_fault_once():
    lock = threading.RLock()
    owned, faults = [], []

    def tick():
        # the lock is ours: another thread cannot take it now
        other = []
        t = threading.Thread(target=lambda: other.append(lock.acquire(blocking=False)))
        t.start()
        t.join()
        owned.append(not other[0])
        if len(owned) == 5:
            raise KeyError("injected")
    timer = SerialTimer(0.005, tick, lock, "test timer", faults.append)
    end = time.monotonic() + 5.0
    while not faults and time.monotonic() < end:
        time.sleep(0.01)
    time.sleep(0.05)
    timer.close()
    assert owned == [True] * 5
    assert len(faults) == 1 and "KeyError: 'injected'" in faults[0]
    assert lock.acquire(blocking=False)     # released after the fault


def test_a_lockstep_answer_waits_for_the_lock():
    """A state that comes while an executor callback runs is answered once it ends."""
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("state_timeout", value=1.0)])
        probe = Probe(ctx)
        executor.add_node(node)
        executor.add_node(probe)
        assert spin_until(executor, lambda: probe.pub_state.get_subscription_count() > 0)
        for _ in range(40):                 # (until active: its kernels may still compile)
            probe.state(H_NS, PAPER_Q0, np.full(7, 0.5))
            if spin_until(executor, lambda: any(label(1) in lab for lab, _ in probe.efforts),
                          timeout=0.5):
                break
        assert node.counts.steps == 1
        with node.callback_lock:            # as a callback of the executor would
            probe.state(2 * H_NS, PAPER_Q0, np.full(7, 0.5))
            spin_until(executor, lambda: False, timeout=0.3)
            assert not any(label(2) in lab for lab, _ in probe.efforts)
            assert node.counts.steps == 1
        assert spin_until(executor, lambda: any(label(2) in lab for lab, _ in probe.efforts))
        assert node.counts.steps == 2


def test_closing_while_a_state_waits_for_the_lock_does_not_wait_for_it():
    """The cleanup runs in an executor callback, holding the lock that a state being
    answered waits for: the state input's thread gives up the state and ends."""
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("state_timeout", value=1.0)])
        probe = Probe(ctx)
        executor.add_node(node)
        executor.add_node(probe)
        assert spin_until(executor, lambda: probe.pub_state.get_subscription_count() > 0)
        for _ in range(40):
            probe.state(H_NS, PAPER_Q0, np.full(7, 0.5))
            if spin_until(executor, lambda: any(label(1) in lab for lab, _ in probe.efforts),
                          timeout=0.5):
                break
        with node.callback_lock:
            probe.state(2 * H_NS, PAPER_Q0, np.full(7, 0.5))
            spin_until(executor, lambda: False, timeout=0.3)    # taken, waiting for the lock
            start = time.monotonic()
            node.states.close()
            assert time.monotonic() - start < 1.0           # (a joined thread: 2 s at most)
        spin_until(executor, lambda: False, timeout=0.3)
        assert not any(label(2) in lab for lab, _ in probe.efforts)
        assert node.counts.steps == 1


def test_a_state_read_before_a_deactivation_is_not_answered_after_the_activation():
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("state_timeout", value=1.0)])
        probe = Probe(ctx)
        executor.add_node(node)
        executor.add_node(probe)
        assert spin_until(executor, lambda: probe.pub_state.get_subscription_count() > 0)
        for _ in range(40):
            probe.state(H_NS, PAPER_Q0, np.full(7, 0.5))
            if spin_until(executor, lambda: any(label(1) in lab for lab, _ in probe.efforts),
                          timeout=0.5):
                break
        with node.callback_lock:
            probe.state(2 * H_NS, PAPER_Q0, np.full(7, 0.5))
            spin_until(executor, lambda: False, timeout=0.3)    # read, waiting for the lock
            node.trigger_deactivate()
            node.trigger_activate()
        spin_until(executor, lambda: False, timeout=0.3)
        assert not any(label(2) in lab for lab, _ in probe.efforts)
        assert node.running and node.counts.steps == 1


def test_an_interrupt_waits_for_the_answer_being_computed():
    """SIGINT's zero effort goes out after the answer in flight (here: a thread holding the
    lock as an answer does), so no effort of the law follows it."""
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("state_timeout", value=1.0)])
        executor.add_node(node)
        held, released = threading.Event(), []

        def answer():
            with node.callback_lock:
                held.set()
                time.sleep(0.3)
                released.append(time.monotonic())
        other = threading.Thread(target=answer)
        other.start()
        held.wait()
        node.on_interrupt()
        stopped = time.monotonic()
        other.join()
        assert not node.running and stopped >= released[0]


def test_the_state_input_follows_the_controllers_remappings():
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, cli_args=[
            "--ros-args", "-r", "joint_states:=/robot2/joint_states"])
        assert node.states._side.topic == "/robot2/joint_states"
        assert node.states._side.subscription.topic_name == "/robot2/joint_states"


def test_an_incompatible_state_publisher_is_reported_by_the_state_input(tmp_path):
    """The state input's subscription lives on a node no executor spins; its QoS events are
    served by the input's reader thread (rclpy's default handler logs them, on fd 2). The
    log is read from a file fd 2 is pointed at, not by polling pytest's capture, which
    truncates its file on each read and loses a line written meanwhile."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    path = tmp_path / "stderr.log"
    saved = os.dup(2)
    try:
        with open(path, "wb") as log:
            os.dup2(log.fileno(), 2)
        with ros_context() as (ctx, executor):
            node = ControllerNode(context=ctx)
            other = Node("best_effort_driver", context=ctx)
            other.create_publisher(JointState, "/joint_states",
                                   QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
            executor.add_node(node)
            executor.add_node(other)
            told = spin_until(executor, lambda: b"offering incompatible QoS" in path.read_bytes(),
                              timeout=30.0)
    finally:
        os.dup2(saved, 2)
        os.close(saved)
    assert told, path.read_text(errors="replace")[-3000:]


def test_the_watchdog_checks_under_the_lock():
    """No state for ``state_timeout``: the watchdog's safe effort, but not while the lock is
    held (an answer, a callback), and at once after."""
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("state_timeout", value=0.2)])
        probe = Probe(ctx)
        executor.add_node(node)
        executor.add_node(probe)
        assert spin_until(executor, lambda: probe.pub_state.get_subscription_count() > 0)
        for _ in range(40):
            probe.state(H_NS, PAPER_Q0, np.full(7, 0.5))
            if spin_until(executor, lambda: any(label(1) in lab for lab, _ in probe.efforts),
                          timeout=0.5):
                break
        with node.callback_lock:
            spin_until(executor, lambda: False, timeout=0.6)     # beyond state_timeout
            held = len(probe.efforts)
            assert node.watchdog.trips == 0
        assert spin_until(executor, lambda: node.watchdog.trips == 1, timeout=5.0)
        assert spin_until(executor, lambda: any(lab.endswith("watchdog")
                                                for lab, _ in probe.efforts[held:]))


def test_a_state_that_came_while_inactive_is_answered_at_the_activation():
    """A lockstep simulator started as the controller is configured sends its first state
    before the controller is active: the activation answers it."""
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("state_timeout", value=1.0)])
        probe = Probe(ctx)
        executor.add_node(node)
        executor.add_node(probe)
        assert spin_until(executor, lambda: probe.pub_state.get_subscription_count() > 0)
        assert spin_until(executor, lambda: node.running)
        node.trigger_deactivate()
        for _ in range(10):                 # taken by the input thread while inactive
            probe.state(H_NS, PAPER_Q0, np.full(7, 0.5))
            spin_until(executor, lambda: False, timeout=0.05)
        assert node.states._parked is not None
        assert not any(label(1) in lab for lab, _ in probe.efforts)
        node.trigger_activate()
        assert spin_until(executor, lambda: any(label(1) in lab for lab, _ in probe.efforts))
        assert node.counts.steps == 1


def test_a_shutdown_under_the_watchdog_thread_ends_the_run_without_a_fault(capfd):
    """rclpy shut down while the watchdog's thread runs (Ctrl-C, a launch's end): its next
    safe effort fails on the invalid context. That is the run's end, not a fault: no fatal
    report, the exit code not 1; the thread has ended."""
    import rclpy
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("state_timeout", value=0.02)])
        executor.add_node(node)
        assert spin_until(executor, lambda: node.running)
        spin_until(executor, lambda: False, timeout=0.2)   # safe efforts: no state yet
        rclpy.try_shutdown(context=ctx)
        time.sleep(0.5)                       # many periods of the watchdog's thread
        err = capfd.readouterr().err
        assert "fatal" not in err and "stop failed" not in err, err
        assert node.exit_code != 1
