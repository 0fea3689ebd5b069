"""The fault bench's cases (:mod:`.faults`, the table of its docstring): what each injects,
when, the figures it adds and its verdicts."""

import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from rcac_ros import topics
from rcac_ros.tools.launch import spawn

GOALS = {"tracking_ratio": 3.0, "restart_recovery_s": 1.0, "gap_periods": 2.0,
         "memory_growth": 0.05, "settle_s": 5.0, "starved_ratio": 10.0}
#: the hostile flood (doc/failsafe.md): 1e6 joint names, a pair of messages every 100 ms
HOSTILE = ["--names", "1000000", "--period", "0.1"]
#: a busy process, at the default scheduler whatever the bench's own
BUSY = "import os\nos.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))\n" \
    "while True:\n    pass\n"
FLOOD = os.path.join(os.path.dirname(os.path.abspath(__file__)), "flood.py")


def _freeze_clock(run):
    run.relay.freeze_clock = True


def _thaw_clock(run):
    run.relay.freeze_clock = False


def start_busy(count):
    """``count`` busy processes (:data:`BUSY`): a starved machine."""
    return [spawn([sys.executable, "-c", BUSY]) for _ in range(count)]


def stop_busy(processes):
    for p in processes:
        p.kill()
        p.wait()


def _starve(run):
    run.busy = start_busy(2 * (os.cpu_count() or 1))


def _stop_busy(run):
    stop_busy(run.busy)
    run.busy = []


#: s the flood process may take to build its messages and match the controller's inputs
FLOOD_START_TIMEOUT = 60.0


def _flood(run, extra=(), prefix=()):
    """Start the flood process and serve this process's node until it publishes: the
    faulty third begins with its first message, not with its start-up (building 1e6 names
    in a niced process took seconds)."""
    from rcac_ros.tools.launch import NodeFailed
    cmd = list(prefix) + [sys.executable, FLOOD, str(run.third)] + list(extra)
    err_path = os.path.join(run.log_dir, "flood.log")
    with open(err_path, "w", encoding="utf-8") as err_file:    # never a pipe left unread
        run.flood = spawn(cmd, env=run.env, stdout=subprocess.PIPE, stderr=err_file,
                          text=True)
    started = threading.Event()

    def read():
        for line in run.flood.stdout:
            if line.startswith("flood: start"):
                started.set()
    threading.Thread(target=read, daemon=True).start()
    run.spin_for(FLOOD_START_TIMEOUT, lambda: started.is_set() or run.flood.poll() is not None,
                 "while the flood started")
    if not started.is_set():
        run.flood.kill()
        run.flood.wait()
        with open(err_path, encoding="utf-8") as f:
            err = f.read().strip().splitlines()
        raise NodeFailed("the flood process did not start publishing: "
                         + (err[-1] if err else f"nothing within {FLOOD_START_TIMEOUT:g} s"))


def _hostile_flood(run):
    _flood(run, HOSTILE, ("nice", "-n", "10"))


#: a process that starts a short-lived node with a JointState publisher every ``period`` s,
#: ``count`` times (each node joins the graph, stays 1.5 s and leaves)
JOINERS = """
import subprocess, sys, time
period, count = float(sys.argv[1]), int(sys.argv[2])
node = ("import sys, time, rclpy; from sensor_msgs.msg import JointState; rclpy.init(); "
        "n = rclpy.create_node('rcac_bench_joiner'); "
        "n.create_publisher(JointState, sys.argv[1], 10); time.sleep(1.5)")
procs = []
for _ in range(count):
    procs.append(subprocess.Popen([sys.executable, "-c", node, sys.argv[3]]))
    time.sleep(period)
for p in procs:
    p.wait()
"""
#: s between two joiners
JOIN_PERIOD = 2.0


#: s a joiner's participant takes to appear after its process starts (1.9-2.9 s measured):
#: the last joiner starts this long before the third ends
JOIN_LEAD = 3.0


def _joiners(run):
    count = max(1, int((run.third - JOIN_LEAD) / JOIN_PERIOD) + 1)
    run.joiners = spawn(
        [sys.executable, "-c", JOINERS, str(JOIN_PERIOD), str(count),
         topics.resolve(topics.JOINT_STATES)], env=run.env, start_new_session=True)


#: s the controller's process is stopped in the ``stall`` case
STALL_S = 5.0


def _stall(run):
    """Stop the controller's process for :data:`STALL_S` (SIGSTOP/SIGCONT: a process the
    machine does not schedule) while the simulator goes on in real time."""
    os.kill(run.ctrl.proc.pid, signal.SIGSTOP)
    try:
        run.spin_for(STALL_S)
    finally:
        os.kill(run.ctrl.proc.pid, signal.SIGCONT)
    run.t_stall_end = time.monotonic_ns()


def _stall_figures(run, out):
    run.t_resume = run.t_stall_end          # recovery counts from the end of the stall
    _resume_figures(run, out)


def _restart_figures(run, out):
    first = run.relay.first_state_after[1]
    resumed = [e[1] for e in run.probe.efforts if not e[2] and first is not None
               and e[1] > first]
    out["restart_recovery_s"] = (resumed[0] - first) * 1e-9 if resumed else None
    out["restart_at_s"] = (run.t_restart - run.t0) * 1e-9


def _resume_figures(run, out):
    resumed = [e[1] for e in run.probe.efforts if not e[2] and e[1] > run.t_resume]
    out["control_back_s"] = (resumed[0] - run.t_resume) * 1e-9 if resumed else None
    out["resume_at_s"] = (run.t_resume - run.t0) * 1e-9


def _window_and_machine_figures(run, out):
    out.update(window_figures(run.probe, run.track, run.window, run.h))
    ticks = run.plain.communicate(timeout=60.0)[0].split() if run.plain is not None else []
    machine = np.diff(np.array(ticks, dtype=np.int64)) * 1e-6
    out["plain_loop_gap_ms"] = float(machine.max()) if machine.size else None


def _judge_restart(r, ref):
    rec = r.get("restart_recovery_s")
    r["recovered"] &= rec is not None and rec <= GOALS["restart_recovery_s"]


def _judge_resume(r, ref):
    if not ref:
        return
    r["settle_s"] = settle_time(r["tracking_t_s"], r["tracking"], r["resume_at_s"],
                                GOALS["tracking_ratio"] * ref)
    back = r.get("control_back_s")
    r["recovered"] = back is not None and back <= GOALS["restart_recovery_s"] \
        and r["settle_s"] is not None and r["settle_s"] <= GOALS["settle_s"]


def _judge_hostile(r, ref):
    if r.get("plain_loop_gap_ms") is not None:
        # no safe effort, and no gap beyond the machine's own plus two periods
        r["window_ok"] = r["window_safe"] == 0 and r["window_gap_ms"] <= \
            r["plain_loop_gap_ms"] + GOALS["gap_periods"] * 1e3 / r["rate"]


def _judge_starved(r, ref):
    if ref and r.get("window_tracking_rms") is not None:
        r["window_ratio"] = r["window_tracking_rms"] / ref
        r["window_ok"] = r["window_ratio"] <= GOALS["starved_ratio"] and r["theta_bounded"]


@dataclass(frozen=True)
class Case:
    """One fault case (the table in the module docstring): what to inject, when, what to check.

    ``window`` is ``"run"`` (the fault, if any, for the whole run: the relay's ``drop`` and
    ``jitter``, the nodes' overrides), ``"restart"`` (the simulator restarted at mid-run) or
    ``"third"`` (``inject`` called after a third of the run, ``clear`` after two thirds).
    ``figures(run, out)`` adds the case's own figures, ``check(result, nominal RMS)`` its
    verdicts (:func:`judge`).
    """

    controller: dict = field(default_factory=dict)
    simulator: dict = field(default_factory=dict)
    drop: float = 0.0
    jitter: float = 0.0
    window: str = "run"
    inject: Callable = None
    clear: Callable = None
    plain_loop: bool = False        # measure the machine's own stalls in the window
    relay: bool = True              # False: the simulator publishes to the controller directly
    figures: Callable = None
    check: Callable = None


#: the floods' controller: its trajectory input subscribed, as an integrator's would be
TOPIC = {"trajectory": "topic"}

CASES = {
    "nominal": Case(),
    "direct": Case(relay=False),
    "drops": Case(drop=0.1),
    "jitter": Case(jitter=0.002),
    "noise": Case(simulator={"position_noise": 1e-4, "velocity_noise": 1e-3}),
    "restart": Case(window="restart", figures=_restart_figures, check=_judge_restart),
    "frozen_clock": Case(controller={"use_sim_time": True}, window="third",
                         inject=_freeze_clock, clear=_thaw_clock, figures=_resume_figures,
                         check=_judge_resume),
    "flood": Case(controller=TOPIC, window="third", inject=_flood, relay=False),
    "hostile_flood": Case(controller=TOPIC, window="third", inject=_hostile_flood,
                          plain_loop=True, relay=False, figures=_window_and_machine_figures,
                          check=_judge_hostile),
    "starved": Case(window="third", inject=_starve, clear=_stop_busy, plain_loop=True,
                    relay=False, figures=_window_and_machine_figures, check=_judge_starved),
    "stall": Case(window="third", inject=_stall, relay=False, figures=_stall_figures,
                  check=_judge_resume),
    "joiners": Case(window="third", inject=_joiners, plain_loop=True, relay=False,
                    figures=_window_and_machine_figures, check=_judge_hostile),
}


def window_figures(probe, track, window, h):
    """Efforts and tracking in the faulty third (``window``: wall and steady ns, start/end)."""
    wall0, steady0, wall1, steady1 = window
    inside = [e for e in probe.efforts if wall0 <= e[0] <= wall1]
    src = np.array([e[0] for e in inside], dtype=np.int64)
    gaps = np.diff(src) * 1e-6 if src.size > 1 else np.array([np.inf])
    during = track[(track[:, 0] >= steady0) & (track[:, 0] <= steady1)] if track.size \
        else track
    return {"window_efforts": len(inside), "window_safe": int(sum(e[2] for e in inside)),
            "window_gap_ms": float(gaps.max()),
            # where the longest gap ends: s after the faulty third began, and wall time (s)
            # to set it beside the machine's own logs
            "window_gap_at_s": float((src[int(np.argmax(gaps)) + 1] - wall0) * 1e-9)
            if src.size > 1 else None,
            "window_gap_end_wall_s": float(src[int(np.argmax(gaps)) + 1] * 1e-9)
            if src.size > 1 else None,
            "window_gaps_over_2h": int(np.sum(gaps > 2e3 * h)),
            "window_tracking_rms": float(np.sqrt(np.mean(during[:, 1] ** 2)))
            if during.size else None}


def settle_time(t_s, error, after_s, bound):
    """Seconds from ``after_s`` until ``error`` stays within ``bound`` (``None``: never)."""
    t, e = np.asarray(t_s), np.asarray(error)
    keep = t >= after_s
    t, e = t[keep], e[keep]
    if not t.size or e[-1] > bound:
        return None
    above = np.flatnonzero(e > bound)
    return 0.0 if not above.size else float(t[above[-1] + 1] - after_s)
