"""An operator's freeze is the operator's (doc/failsafe.md, "Freeze causes"), in a controller
process over real DDS: ``~/set_adaptation`` and the starvation guard are two causes, the
adaptation of eq 24 runs only when neither holds, in both orders.

The machine is starved by stopping the controller process 40 ms in every 50 ms: its
smoothed delay then reaches about 25 ms on an idle machine. The guard's delay margin is set
to 30 ms, so it acts past 15 ms (margin / ``SAFETY``): above the 5-7 ms that three busy
processes beside the test gave (with the derived margin, 7.7 ms on this arm, the guard acts
past 3.9 ms, which such a load reaches, and then never recovers). ``state_timeout`` is
0.1 s so that the watchdog does not add its own spells to the stops.
``starvation.recover_after`` is 5 s so that the operator's call lands inside the starved
spell on a loaded machine too. Each cause is read from the diagnostics (``adaptation``,
``adaptation_frozen_by``) and from the service's answer.
"""

import os
import signal
import time

from std_srvs.srv import SetBool

from failsafe_harness import controller, session, state_driver, wait

DIAG = "rcac_controller: control loop"
#: s to wait for the guard's recovery: recover_after (5 s) once the delay is back within the
#: margin, which other jobs on a loaded machine can postpone
RECOVERY = 90.0


def status(probe):
    return probe.diagnostics.get(DIAG, {})


def frozen_by(probe):
    return set(filter(None, status(probe).get("adaptation_frozen_by", "").split(","))) \
        - {"none"}


def set_adaptation(client, on):
    future = client.call_async(SetBool.Request(data=on))
    assert wait(future.done, timeout=20.0)
    response = future.result()
    assert response.success
    return response.message


def starve(proc, seconds=1.5):
    """Stop the process 40 ms in every 50 ms for ``seconds``."""
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            os.kill(proc.pid, signal.SIGSTOP)
            time.sleep(0.040)
            os.kill(proc.pid, signal.SIGCONT)
            time.sleep(0.010)
    finally:
        os.kill(proc.pid, signal.SIGCONT)


def overs(probe):
    """The guard's recovery lines so far."""
    with probe.lock:
        return [m.msg for m in probe.logs if m.msg.startswith("starvation over")]


def fresh(probe, key, value, timeout=30.0):
    """Wait for a diagnostics message published after now with ``key`` == ``value``."""
    probe.diagnostics.pop(DIAG, None)
    return wait(lambda: status(probe).get(key) == value, timeout=timeout)


def test_the_operators_freeze_and_the_guards_are_two_causes_in_both_orders():
    with session() as probe, controller(probe, "mode:=timer", "starvation.recover_after:=5.0",
                                        "starvation.delay_margin:=0.03",
                                        "state_timeout:=0.1") as proc, \
            state_driver(probe):
        client = probe.create_client(SetBool, "/rcac_controller/set_adaptation")
        assert client.wait_for_service(timeout_sec=30.0)
        assert wait(lambda: len(probe.efforts) > 1000, timeout=30.0)
        # a machine loaded by other jobs may starve it already: start from nominal
        assert fresh(probe, "adaptation_frozen_by", "none", timeout=60.0)
        assert status(probe)["adaptation"] == "on"

        # guard, then operator: the operator's freeze outlasts the guard's recovery
        spells, recovered = int(status(probe)["starved_spells"]), len(overs(probe))
        starve(proc)
        assert wait(lambda: "starved" in frozen_by(probe)
                    and int(status(probe)["starved_spells"]) > spells, timeout=10.0)
        assert set_adaptation(client, False).startswith("adaptation frozen")
        assert wait(lambda: len(overs(probe)) > recovered, timeout=RECOVERY)
        assert "adaptation still frozen (by set_adaptation)" in overs(probe)[-1]
        # the operator's cause outlasts the guard's recovery (a loaded machine may starve
        # the process again meanwhile: "starved" beside it)
        probe.diagnostics.pop(DIAG, None)
        assert wait(lambda: "user" in frozen_by(probe), timeout=30.0)
        assert status(probe)["adaptation"] == "frozen"

        # operator (still frozen), then guard, then the operator's resume during starvation:
        # the guard's freeze holds until its recovery
        recovered = len(overs(probe))
        starve(proc)
        probe.diagnostics.pop(DIAG, None)  # (a loaded machine may have starved it already)
        assert wait(lambda: {"starved", "user"} <= frozen_by(probe), timeout=10.0)
        # within recover_after (5 s) of the starving's end: the guard still holds its cause
        # (a spell of safe effort during the starving may hold "recovering" beside it)
        message = set_adaptation(client, True)
        assert "still frozen by" in message and "the starvation guard" in message, message
        assert wait(lambda: len(overs(probe)) > recovered, timeout=RECOVERY)
        assert "adaptation again" in overs(probe)[-1], overs(probe)
        assert fresh(probe, "adaptation_frozen_by", "none", timeout=60.0)
        assert status(probe)["adaptation"] == "on"
        assert proc.poll() is None
