"""The starvation guard in the node (doc/failsafe.md, "Starved machine"): a controller process
stopped for 15 ms every 30 ms (SIGSTOP/SIGCONT: what a starved machine does to it) says once
that it is starved, scales K_D down, keeps controlling, and returns to nominal afterwards."""

import os
import signal
import time

from failsafe_harness import controller, session, state_driver, wait

DIAG = "rcac_controller: control loop"


def over_lines(probe):
    with probe.lock:
        return [m for m in probe.logs if m.msg.startswith("starvation over")]


def test_a_starved_controller_degrades_once_and_recovers():
    with session() as probe, controller(probe, "mode:=timer") as proc, state_driver(probe):
        try:
            assert wait(lambda: len(probe.efforts) > 1000)
            # a machine loaded by other jobs may starve it already: start from nominal
            assert wait(lambda: probe.diagnostics.get(DIAG, {}).get("starved") == "no",
                        timeout=30.0)
            before = int(probe.diagnostics[DIAG]["starved_spells"])
            overs = len(over_lines(probe))
            end = time.monotonic() + 1.5
            while time.monotonic() < end:   # starve it
                os.kill(proc.pid, signal.SIGSTOP)
                time.sleep(0.015)
                os.kill(proc.pid, signal.SIGCONT)
                time.sleep(0.015)
            assert wait(lambda: int(probe.diagnostics[DIAG]["starved_spells"]) > before,
                        timeout=5.0)
            n = len(probe.efforts)
            assert wait(lambda: len(over_lines(probe)) > overs, timeout=20.0)
            assert len(probe.efforts) > n + 500         # it kept controlling
        finally:
            os.kill(proc.pid, signal.SIGCONT)
        spells = int(probe.diagnostics[DIAG]["starved_spells"])
        with probe.lock:
            starved = [m for m in probe.logs if m.msg.startswith("starved:")]
        assert len(starved) == spells and len(over_lines(probe)) >= spells - 1  # once a spell


def test_a_stalled_loop_is_a_spell_from_the_laws_last_effort():
    """The controller's process stopped 1 s while the states go on: when it runs again the
    arm has held its last effort for the whole second. The spell is measured from the law's
    last effort (not from the watchdog's first safe effort, which comes only after the
    stall), so it is longer than ``watchdog.replan_after`` (0.5 s): the motion restarts from
    the measured state and the adaptation holds (cause ``recovering``) until the law's
    effort is within its limits."""
    with session() as probe, controller(probe, "mode:=timer") as proc, state_driver(probe):
        assert wait(lambda: len(probe.efforts) > 1000)
        replans = int(probe.diagnostics.get(DIAG, {}).get("watchdog_replans", 0))
        os.kill(proc.pid, signal.SIGSTOP)
        try:
            time.sleep(1.0)
        finally:
            os.kill(proc.pid, signal.SIGCONT)

        def resumed():
            with probe.lock:
                return [m.msg for m in probe.logs if m.msg.startswith("watchdog: ")
                        and "restarts from the measured state" in m.msg]
        assert wait(lambda: resumed(), timeout=10.0)
        held = float(resumed()[0].split(" s without")[0].split()[-1])
        assert held >= 1.0, resumed()
        assert wait(lambda: int(probe.diagnostics[DIAG]["watchdog_replans"]) > replans,
                    timeout=5.0)
        assert wait(lambda: probe.logged("adaptation again: the law's effort is within")
                    or "recovering" in probe.diagnostics[DIAG]["adaptation_frozen_by"],
                    timeout=5.0)
