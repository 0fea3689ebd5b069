"""Issue 9.1-9.2: stamps and the watchdog, against a controller process over DDS."""

from failsafe_harness import (controller, feed, first_answer, H_NS, NS, session,
                              set_parameter, start, wait)


def test_simulator_restart_is_followed_after_the_watchdog():
    """Stamps start again at 0 after a pause: the controller answers them (no lockout)."""
    with session() as probe, controller(probe):
        t0 = 10 * NS
        first_answer(probe, t0)
        feed(probe, [t0 + k * H_NS for k in range(1, 50)])
        assert wait(lambda: probe.answered(t0 + 49 * H_NS))
        n = len(probe.watchdog_efforts())
        assert wait(lambda: len(probe.watchdog_efforts()) > n, timeout=20.0)   # tripped
        # the simulator restarted: stamps from 0
        feed(probe, [k * H_NS for k in range(50)])
        assert wait(lambda: probe.answered(49 * H_NS), timeout=20.0)
        assert probe.answered(0)            # the first after the silence: a restart
        assert wait(lambda: probe.logged("restart"))


def test_one_future_stamp_does_not_lock_out():
    with session() as probe, controller(probe):
        first_answer(probe, 0)
        feed(probe, [k * H_NS for k in range(1, 20)])
        probe.state(10 ** 6 * NS)           # one stray state, 11 days ahead
        feed(probe, [k * H_NS for k in range(20, 60)])
        assert wait(lambda: probe.answered(59 * H_NS), timeout=20.0)
        assert not probe.answered(10 ** 6 * NS)
        assert wait(lambda: probe.warned("rejected (stamp future)"))


def test_restart_without_silence_is_accepted_after_a_consistent_run():
    """A long state_timeout: no watchdog trip; a consistent run of old stamps takes over."""
    with session() as probe, controller(probe, "state_timeout:=1.0"):
        t0 = 100 * NS
        first_answer(probe, t0)
        feed(probe, [t0 + k * H_NS for k in range(1, 20)])
        feed(probe, [k * H_NS for k in range(100)])
        assert wait(lambda: probe.answered(99 * H_NS), timeout=20.0)
        # the first few are refused (a single old state is not a restart)
        assert not probe.answered(0)


def test_watchdog_trips_with_a_frozen_sim_clock():
    """use_sim_time and a /clock that stops: state silence is still measured (steady clock)."""
    with session() as probe, controller(probe, "use_sim_time:=true"):
        probe.clock(NS)
        first_answer(probe, NS)
        feed(probe, [NS + k * H_NS for k in range(1, 20)])
        assert wait(lambda: probe.answered(NS + 19 * H_NS))
        n = len(probe.watchdog_efforts())
        # /clock frozen at 1 s, no more states: the safe effort must follow
        assert wait(lambda: len(probe.watchdog_efforts()) > n, timeout=2.0)


def test_timer_mode_with_frozen_sim_clock_still_commands_safely():
    """Timer mode ticks on /clock with use_sim_time; a frozen /clock must not silence it."""
    with session() as probe, controller(probe, "use_sim_time:=true", "mode:=timer"):
        for k in range(50):
            probe.clock(NS + k * H_NS)
            probe.state(NS + k * H_NS)
            wait(lambda: False, timeout=0.002)
        # /clock and states stop: safe efforts keep coming, on the steady clock
        n = len(probe.watchdog_efforts())
        assert wait(lambda: len(probe.watchdog_efforts()) > n + 5, timeout=2.0)


def test_use_sim_time_cannot_be_switched_at_run_time():
    with session() as probe, controller(probe):
        first_answer(probe, 0)
        ok, reason = set_parameter(probe, "use_sim_time", True)
        assert not ok and "use_sim_time" in reason
        # still on the steady clock: silence trips the watchdog
        n = len(probe.watchdog_efforts())
        assert wait(lambda: len(probe.watchdog_efforts()) > n, timeout=2.0)


def test_state_timeout_is_bounded():
    with session() as probe, controller(probe):
        ok, reason = set_parameter(probe, "state_timeout", 1e9)
        assert not ok
        ok, _ = set_parameter(probe, "state_timeout", 0.5)
        assert ok
    proc = start("controller_node", "state_timeout:=1000.0")
    out, _ = proc.communicate(timeout=60.0)
    assert proc.returncode == 2, out
    lines = [ln for ln in out.splitlines() if "error" in ln]
    assert len(lines) == 1 and "state_timeout" in lines[0], out
