"""Pacing of the free-running modes: the absolute-deadline loop, and sim time in timer mode."""

import numpy as np
import pytest

from test_nodes_support import PAPER_Q0, Probe, ros_context, spin_until, stamp

from rclpy.parameter import Parameter  # noqa: E402  (after the importorskip in support)
from rosgraph_msgs.msg import Clock as ClockMsg  # noqa: E402

from rcac_ros import topics  # noqa: E402
from rcac_ros.errors import ConfigError  # noqa: E402
from rcac_ros.nodes.runtime.pacing import DeadlineLoop  # noqa: E402
from rcac_ros.nodes.controller.node import ControllerNode  # noqa: E402
from rcac_ros.nodes.simulator.node import SimulatorNode  # noqa: E402

H = 0.002
H_NS = 2_000_000


class FakeClock:
    """A steady clock the test moves by hand (integer ns)."""

    def __init__(self):
        self.t = 1_000_000_000

    def __call__(self):
        return self.t


class FakeExecutor:
    """Records the timeouts it is asked to wait, and lets that much time pass."""

    def __init__(self, clock):
        self.clock = clock
        self.timeouts = []

    def spin_once(self, timeout_sec=None):
        self.timeouts.append(timeout_sec)
        self.clock.t += round(timeout_sec * 1e9)


def test_deadline_loop_waits_exactly_until_each_deadline():
    clock = FakeClock()
    ticks = []
    loop = DeadlineLoop(H, lambda: ticks.append(clock()), clock=clock)
    ex = FakeExecutor(clock)
    start = clock()
    loop.start()
    while len(ticks) < 10:
        loop.spin_once(ex)
    # ticks exactly on start + k h: the executor was asked to wait the time left
    assert ticks == [start + k * H_NS for k in range(1, 11)]
    assert loop.late == 0 and loop.skipped == 0


def test_late_ticks_are_caught_up_not_skipped():
    """A tick 1.7 periods late is followed by the missed one at once: no tick is lost."""
    clock = FakeClock()
    ticks = []
    loop = DeadlineLoop(H, lambda: ticks.append(clock()), resync=4, clock=clock)
    start = clock()
    loop.start()
    clock.t = start + H_NS + round(1.7 * H_NS)      # the process slept past two deadlines
    assert loop.due() <= 0 and loop.due() > 0        # two ticks back to back, then a wait
    assert len(ticks) == 2 and loop.late == 2 and loop.skipped == 0
    # the next deadline is still on the grid start + k h
    assert loop.next_ns == start + 3 * H_NS


def test_far_behind_the_loop_resynchronises_and_counts_the_skipped_ticks():
    clock = FakeClock()
    ticks = []
    loop = DeadlineLoop(H, lambda: ticks.append(clock()), resync=4, clock=clock)
    start = clock()
    loop.start()
    clock.t = start + H_NS + 10 * H_NS + H_NS // 4   # 10.25 periods late: beyond resync
    loop.due()
    assert ticks == [clock.t] and loop.skipped == 10
    assert (loop.next_ns - start) % H_NS == 0 and loop.next_ns > clock.t
    # ticks run (1) + skipped (10) = deadlines passed (11): the count is exact
    assert len(ticks) + loop.skipped == (clock.t - start) // H_NS


def test_phase_lock_brings_the_ticks_to_the_states_plus_the_offset():
    """Events (states) every period at a fixed phase: the ticks converge to event + offset
    at the rate (1 - gain)^k, no period changes by more than an eighth, the average rate
    stays the period's."""
    clock = FakeClock()
    ticks = []
    loop = DeadlineLoop(H, lambda: ticks.append(clock.t), clock=clock)
    loop.start()
    phase, offset, gain = 1_300_000, 300_000, 0.25          # ns
    t0 = clock.t
    errors = []
    for k in range(60):
        clock.t = loop.next_ns              # each tick exactly on time
        loop.due()
        event = t0 + phase + (ticks[-1] - t0) // H_NS * H_NS - H_NS   # the newest state
        errors.append(loop.lock_phase(event, offset, gain))
    # the first error: the deadline 1 period after the start against the state + offset
    want = (H_NS - phase - offset + H_NS // 2) % H_NS - H_NS // 2
    assert errors[0] == want
    for k in range(1, 60):                  # the closed form, within the clamp and rounding
        bound = max(abs(errors[k - 1]) - H_NS // 8, (1 - gain) * abs(errors[k - 1])) + 1
        assert abs(errors[k]) <= bound
    assert abs(errors[-1]) <= 2              # rounding: a move of gain * 2 ns rounds to 0
    assert (ticks[-1] - t0 - phase - offset + 2) % H_NS <= 4
    periods = np.diff(ticks)
    assert periods.min() >= H_NS - H_NS // 8 and periods.max() <= H_NS + H_NS // 8


def test_phase_lock_follows_a_drifting_driver():
    """States from a clock 100 ppm fast: the ticks follow them (bounded phase error)."""
    clock = FakeClock()
    ticks = []
    loop = DeadlineLoop(H, lambda: ticks.append(clock.t), clock=clock)
    loop.start()
    t0 = clock.t
    period = H_NS * (1 - 1e-4)              # the driver's period on our clock
    errors = []
    for k in range(5000):
        clock.t = loop.next_ns
        loop.due()
        event = t0 + int(np.floor((clock.t - t0) / period) * period)
        errors.append(loop.lock_phase(event, 200_000))
    assert max(abs(e) for e in errors[100:]) < 2_000    # ns: locked, 0.1 % of a period
    # without the lock the phase would have slipped by 5000 * 200 ns = one half period


def test_stopped_loop_only_serves_the_executor():
    clock = FakeClock()
    loop = DeadlineLoop(H, lambda: pytest.fail("ticked while stopped"), clock=clock)
    ex = FakeExecutor(clock)
    loop.spin_once(ex, idle=0.05)
    assert ex.timeouts == [0.05] and not loop.running
    with pytest.raises(ConfigError, match="period"):
        DeadlineLoop(0.0, lambda: None)


def test_controller_timer_mode_with_sim_time_ticks_on_clock():
    """With use_sim_time the timer follows /clock, not the steady clock."""
    with ros_context() as (ctx, ex):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("mode", value="timer"), Parameter("use_sim_time", value=True),
            Parameter("state_timeout", value=1.0)])
        probe = Probe(ctx)
        pub_clock = probe.create_publisher(ClockMsg, topics.CLOCK, topics.qos())
        ex.add_node(node)
        ex.add_node(probe)
        assert node.loop is None
        assert spin_until(ex, lambda: probe.pub_state.get_subscription_count() > 0
                          and pub_clock.get_subscription_count() > 0)
        probe.state(0, PAPER_Q0, np.zeros(7))
        # no /clock yet: ROS time stands still, so no tick (a steady timer would give ~100);
        # only the watchdog's safe effort (steady clock: an absent /clock is no excuse)
        spin_until(ex, lambda: False, timeout=0.2)
        assert [lab for lab, _ in probe.efforts if lab != "joint watchdog"] == []
        steps = 30
        for k in range(1, steps + 1):
            pub_clock.publish(ClockMsg(clock=stamp(k * H_NS)))
            probe.state(k * H_NS, PAPER_Q0, np.zeros(7))
            assert spin_until(ex, lambda: node.get_clock().now().nanoseconds == k * H_NS)
        spin_until(ex, lambda: False, timeout=0.1)
        control = [d for lab, d in probe.efforts if lab == "joint"]
        assert 1 <= len(control) <= steps
        assert node.counts.steps == len(control)


def test_simulator_realtime_mode_steps_on_the_deadline_loop():
    with ros_context() as (ctx, ex):
        sim = SimulatorNode(context=ctx, parameter_overrides=[
            Parameter("mode", value="realtime"), Parameter("wait_for_controller", value=False),
            Parameter("duration", value=0.2), Parameter("use_sim_time", value=True)])
        probe = Probe(ctx)
        ex.add_node(sim)
        ex.add_node(probe)
        assert sim.loop is not None and not sim.loop.running
        assert spin_until(ex, lambda: sim.finished, timeout=60.0)
        assert sim.k == 100 and not sim.loop.running
        assert sim.loop.ticks == 100
        status = {kv.key: kv.value for kv in sim.diagnostics().values}
        assert int(status["skipped_ticks"]) == sim.loop.skipped
