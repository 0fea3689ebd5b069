"""The simulator node in-process: the lockstep protocol, bad efforts, timeouts, parameters."""

import math
import time

import numpy as np
import pytest

from test_nodes_support import distinct, JOINTS, NS, PAPER_Q0, Probe, ros_context, spin_until

from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout  # noqa: E402

from rcac_ros.errors import ConfigError  # noqa: E402
from rcac_ros.core.model import css_arm  # noqa: E402
from rcac_ros.core.simulator import Simulator  # noqa: E402
from rcac_ros.nodes.simulator.node import SimulatorNode  # noqa: E402

DT_NS = 2_000_000


def make(ctx, executor, **params):
    params.setdefault("lockstep_timeout", 0.3)
    node = SimulatorNode(context=ctx, parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])
    probe = Probe(ctx)
    clocks = []
    probe.create_subscription(Clock, "/clock", clocks.append, 100)
    executor.add_node(node)
    executor.add_node(probe)
    # the node starts once the probe subscribes to joint_states and publishes efforts
    assert spin_until(executor, lambda: len(probe.states) >= 1)
    return node, probe, clocks


def effort(data, label="joint"):
    return Float64MultiArray(layout=MultiArrayLayout(dim=[
        MultiArrayDimension(label=label, size=len(data), stride=len(data))]),
        data=[float(x) for x in data])


def tag(k):
    ns = k * DT_NS
    return f"joint stamp={ns // NS}.{ns % NS:09d}"


def stamp_of(msg):
    return msg.header.stamp.sec * NS + msg.header.stamp.nanosec


def test_lockstep_protocol_matches_core_simulator():
    """State k at stamp k dt; one step per answer; the same trajectory as the core Simulator."""
    rng = np.random.default_rng(3)
    taus = rng.normal(0.0, 50.0, (5, 7))
    ref = Simulator(css_arm(), dt=0.002, q0=PAPER_Q0)
    with ros_context() as (ctx, ex):
        node, probe, clocks = make(ctx, ex)
        for k, tau in enumerate(taus):
            assert spin_until(ex, lambda: len(distinct(probe.states)) == k + 1)
            state = distinct(probe.states)[-1]
            assert stamp_of(state) == k * DT_NS
            assert list(state.name) == JOINTS
            np.testing.assert_allclose(state.position, ref.q, rtol=0, atol=1e-12)
            np.testing.assert_allclose(state.velocity, ref.qd, rtol=0, atol=1e-12)
            probe.pub_effort.publish(effort(tau, tag(k)))
            ref.step(tau)
        assert spin_until(ex, lambda: len(distinct(probe.states)) == len(taus) + 1)
        np.testing.assert_allclose(probe.states[-1].position, ref.q, atol=1e-12)
        assert spin_until(ex, lambda: any(c.clock.sec * NS + c.clock.nanosec ==
                                          len(taus) * DT_NS for c in clocks))
        assert node.misses == 0


def test_bad_efforts_rejected_timeout_holds_previous_and_late_answer_ignored():
    ref = Simulator(css_arm(), dt=0.002, q0=PAPER_Q0)
    tau0 = np.linspace(-20.0, 20.0, 7)
    with ros_context() as (ctx, ex):
        node, probe, _ = make(ctx, ex)
        probe.pub_effort.publish(effort(tau0, tag(0)))
        ref.step(tau0)
        assert spin_until(ex, lambda: len(probe.states) == 2)
        bad = [[math.nan] * 7, [1.0] * 6, [], [0.0, math.inf, 0, 0, 0, 0, 0]]
        for data in bad:
            probe.pub_effort.publish(effort(data, tag(1)))
        probe.pub_effort.publish(effort([5.0] * 7, "joint watchdog"))    # ignored in lockstep
        assert spin_until(ex, lambda: node._throttle.total >= len(bad))
        assert spin_until(ex, lambda: node.ignored_watchdog == 1)
        for kind in ("nan", "length", "empty"):
            assert spin_until(ex, lambda: probe.warned(f"rejected ({kind})", "rcac_simulator"))
        # no valid answer to state 1: after the timeout the previous effort is held
        assert spin_until(ex, lambda: len(probe.states) == 3, timeout=30.0)
        assert node.misses == 1
        ref.step(tau0)
        np.testing.assert_allclose(probe.states[-1].position, ref.q, atol=1e-12)
        np.testing.assert_allclose(probe.states[-1].effort, tau0, atol=1e-12)
        # a late answer to state 1 must not be taken as the answer to state 2
        probe.pub_effort.publish(effort([100.0] * 7, tag(1)))
        assert spin_until(ex, lambda: node.late == 1)
        tau2 = -tau0
        probe.pub_effort.publish(effort(tau2, tag(2)))
        ref.step(tau2)
        assert spin_until(ex, lambda: len(probe.states) == 4)
        np.testing.assert_allclose(probe.states[-1].position, ref.q, atol=1e-12)
        # an untagged effort (another controller) answers the pending state
        probe.pub_effort.publish(effort(tau0))
        ref.step(tau0)
        assert spin_until(ex, lambda: len(probe.states) == 5)
        np.testing.assert_allclose(probe.states[-1].position, ref.q, atol=1e-12)


def test_a_second_answer_to_the_resent_first_state_is_not_late():
    """State 0 unanswered for 50 ms is sent again; both copies answered: one step, not late."""
    tau0 = np.linspace(-20.0, 20.0, 7)
    ref = Simulator(css_arm(), dt=0.002, q0=PAPER_Q0)
    with ros_context() as (ctx, ex):
        node, probe, _ = make(ctx, ex)
        assert spin_until(ex, lambda: len(probe.states) >= 2)      # the copy of state 0
        assert all(stamp_of(m) == 0 for m in probe.states)
        for _ in range(2):                  # a controller answers each copy
            probe.pub_effort.publish(effort(tau0, tag(0)))
        ref.step(tau0)
        assert spin_until(ex, lambda: node.repeated == 1)
        assert spin_until(ex, lambda: stamp_of(probe.states[-1]) == DT_NS)
        assert [stamp_of(m) for m in probe.states].count(DT_NS) == 1
        np.testing.assert_allclose(probe.states[-1].position, ref.q, rtol=0, atol=1e-12)
        assert node.k == 1 and node.late == 0 and node.misses == 0
        probe.pub_effort.publish(effort(tau0, tag(1)))
        assert spin_until(ex, lambda: stamp_of(probe.states[-1]) == 2 * DT_NS)
        probe.pub_effort.publish(effort(tau0, tag(1)))     # state 1 was sent once: late
        assert spin_until(ex, lambda: node.late == 1)
        assert node.repeated == 1 and node.k == 2


def test_duration_finishes_and_noise_is_added():
    with ros_context() as (ctx, ex):
        node, probe, _ = make(ctx, ex, duration=0.01, position_noise=0.01, noise_seed=7)
        for k in range(5):
            assert spin_until(ex, lambda: len(distinct(probe.states)) == k + 1)
            probe.pub_effort.publish(effort(np.zeros(7), tag(k)))
        assert spin_until(ex, lambda: node.finished)
        assert node.k == 5 and node.exit_code == 0
        q = np.array([m.position for m in probe.states])
        dev = q - PAPER_Q0                  # zero effort, g = 0: the arm does not move
        assert 0.003 < np.std(dev) < 0.03


def test_lockstep_max_speed_holds_the_next_state_until_its_wall_time():
    """With lockstep_max_speed s, state k goes out no earlier than k dt / s after the start,
    however fast the answers come (the demo uses 1.0 so that its recorder keeps up)."""
    speed, steps = 0.2, 10                 # state k at >= k x 10 ms
    with ros_context() as (ctx, ex):
        node, probe, _ = make(ctx, ex, lockstep_max_speed=speed)
        for k in range(steps):
            assert spin_until(ex, lambda: len(distinct(probe.states)) == k + 1)
            probe.pub_effort.publish(effort(np.zeros(7), tag(k)))
        assert spin_until(ex, lambda: len(distinct(probe.states)) == steps + 1)
        elapsed = time.monotonic() - node._wall_start
        assert elapsed >= steps * 0.002 / speed
        assert node.misses == 0 and node.late == 0


def test_effort_limit_clips():
    ref = Simulator(css_arm(), dt=0.002, q0=PAPER_Q0)
    with ros_context() as (ctx, ex):
        _, probe, _ = make(ctx, ex, effort_limit=[10.0])
        tau = np.array([100.0, -100.0, 5.0, 0.0, 50.0, -3.0, 1000.0])
        probe.pub_effort.publish(effort(tau, tag(0)))
        ref.step(np.clip(tau, -10.0, 10.0))
        assert spin_until(ex, lambda: len(probe.states) == 2)
        np.testing.assert_allclose(probe.states[-1].position, ref.q, atol=1e-12)


@pytest.mark.parametrize("name, value", [
    ("dt", 0.0), ("q0", [0.0, 1.0]), ("qd0", [0.0] * 8), ("effort_limit", [0.0]),
    ("model", "unknown_arm"), ("joints", ["a"] * 7), ("mode", "turbo"),
    ("position_noise", -0.1), ("lockstep_timeout", 0.0), ("duration", -1.0),
    ("robot_description", "<robot name='x'><link name='a'/></robot"),
])
def test_invalid_parameter_is_refused_naming_it(name, value):
    with ros_context() as (ctx, _):
        with pytest.raises(ConfigError) as err:
            SimulatorNode(context=ctx, parameter_overrides=[Parameter(name, value=value)])
        assert str(err.value).startswith(name + ":"), str(err.value)
        assert "\n" not in str(err.value)


def test_default_q0_follows_the_joint_names_when_joints_are_reordered():
    """joints [joint2, joint1, ...]: the published state still gives each joint its own q0."""
    order = ["joint2", "joint1"] + [f"joint{i}" for i in range(3, 8)]
    with ros_context() as (ctx, ex):
        node, probe, _ = make(ctx, ex, joints=order)
        state = probe.states[0]
        by_name = dict(zip(state.name, state.position))
        for i, name in enumerate(JOINTS):
            assert by_name[name] == pytest.approx(PAPER_Q0[i], abs=1e-12)
        node.destroy_node()
