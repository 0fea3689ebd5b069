"""doc/failsafe.md, "stamps" and "watchdog": stamps and the watchdog, against a controller process
over DDS."""

import threading
import time

import numpy as np

from failsafe_harness import (controller, feed, first_answer, H_NS, NS, PAPER_Q0, session,
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
        n = len(probe.watchdog_efforts())       # (the safe effort before the first state)
        feed(probe, [t0 + k * H_NS for k in range(1, 20)])
        feed(probe, [k * H_NS for k in range(100)])
        assert wait(lambda: probe.answered(99 * H_NS), timeout=20.0)
        # the watchdog did not trip (a trip takes the next old stamp as a restart at once:
        # a stall of a process for 1 s, the parameter's maximum, would)
        assert len(probe.watchdog_efforts()) == n
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
        # /clock frozen at 1 s, no more states: the safe effort must follow (state_timeout
        # after the last state; the timeout only bounds a loaded machine's wait)
        assert wait(lambda: len(probe.watchdog_efforts()) > n, timeout=30.0)


def test_timer_mode_with_frozen_sim_clock_still_commands_safely():
    """Timer mode ticks on /clock with use_sim_time; a frozen /clock must not silence it."""
    with session() as probe, controller(probe, "use_sim_time:=true", "mode:=timer"):
        for k in range(50):
            probe.clock(NS + k * H_NS)
            probe.state(NS + k * H_NS)
            time.sleep(H_NS / NS)
        # /clock and states stop: safe efforts keep coming, on the steady clock
        n = len(probe.watchdog_efforts())
        assert wait(lambda: len(probe.watchdog_efforts()) > n + 5, timeout=30.0)


class SimClock:
    """Publish /clock and a state every 2 ms of the steady clock, from a thread.

    Like a simulator behind a clock relay: the sim time runs on; ``frozen`` stops /clock
    (not the states); ``q`` is the position sent (the arm is not simulated).
    """

    def __init__(self, probe):
        self.probe, self.q, self.frozen, self.t_ns = probe, PAPER_Q0.copy(), False, NS
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        nxt = time.monotonic()
        while not self._stop.is_set():
            self.t_ns += H_NS
            if not self.frozen:
                self.probe.clock(self.t_ns)
            self.probe.state(self.t_ns, self.q)
            nxt += H_NS / NS
            time.sleep(max(0.0, nxt - time.monotonic()))

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(5.0)


def test_control_resumes_from_the_measured_state_after_a_frozen_clock():
    """/clock frozen for 1.5 s (safe effort; the unactuated arm drifts 0.5 rad), then resumed:
    efforts come back and the motion goes on from where the arm is, not from where the time
    -indexed motion would have been (which would ask the gains for the whole drift at once)."""
    with session() as probe, controller(probe, "use_sim_time:=true", "mode:=timer",
                                        "K_D:=1000.0"), SimClock(probe) as sim:
        def efforts_since(k, watchdog):
            with probe.lock:
                return [e for e in probe.efforts[k:] if e[2].endswith("watchdog") == watchdog]

        def desired_after(t_ns):
            with probe.lock:
                return [p for s, p in probe.desired if s > t_ns]
        t_ns = sim.t_ns
        assert wait(lambda: desired_after(t_ns), timeout=30.0)         # tracking, on /clock
        sim.frozen = True
        k = len(probe.efforts)
        assert wait(lambda: len(efforts_since(k, True)) > 10)          # the safe effort
        sim.q = PAPER_Q0 + 0.5                  # the arm, unactuated, drifted
        # held for more than watchdog.replan_after (0.5 s) of the controller's steady clock:
        # its watchdog timer sends the safe effort every 10 ms and skips the periods a stall
        # misses, so 150 of them after the drift are at least 1.5 s
        k = len(probe.efforts)
        assert wait(lambda: len(efforts_since(k, True)) >= 150, timeout=60.0)
        k, clock_ns = len(probe.efforts), sim.t_ns
        sim.frozen = False
        assert wait(lambda: efforts_since(k, False), timeout=20.0)     # control back
        assert wait(lambda: desired_after(clock_ns), timeout=20.0)
        # the motion restarted from the measured state (the paper's: at rest, then slow)
        np.testing.assert_allclose(desired_after(clock_ns)[0], sim.q, atol=0.02)
        assert wait(lambda: probe.logged("the motion restarts from the measured state"))
        assert wait(lambda: int(probe.diagnostics.get("rcac_controller: control loop", {})
                                .get("watchdog_replans", 0)) >= 1, timeout=10.0)


def test_use_sim_time_cannot_be_switched_at_run_time():
    with session() as probe, controller(probe):
        first_answer(probe, 0)
        ok, reason = set_parameter(probe, "use_sim_time", True)
        assert not ok and "use_sim_time" in reason
        # still on the steady clock: silence trips the watchdog
        n = len(probe.watchdog_efforts())
        assert wait(lambda: len(probe.watchdog_efforts()) > n, timeout=30.0)


def test_state_timeout_is_bounded():
    with session() as probe, controller(probe):
        ok, reason = set_parameter(probe, "state_timeout", 1e9)
        assert not ok
        ok, _ = set_parameter(probe, "state_timeout", 0.5)
        assert ok
    proc = start("controller_node", "state_timeout:=1000.0")
    out, _ = proc.communicate(timeout=120.0)
    assert proc.returncode == 2, out
    lines = [ln for ln in out.splitlines() if "error" in ln]
    assert len(lines) == 1 and "state_timeout" in lines[0], out
