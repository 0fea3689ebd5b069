"""The fault benchmark behind ``rcac bench faults`` (doc/failsafe.md, "How to check a machine").

The simulator (``mode: realtime``) and the controller (``mode: timer``) run as two
processes over DDS, as on a real arm. The simulator's joint states and ``/clock`` go
through a relay in this process (``/sim/joint_states`` -> ``/joint_states``), which
injects the faults of the wires; the others come from outside:

============  ===================================================================
nominal       no fault (the reference: the relay in the loop, as in the wire faults)
direct        no fault, the simulator publishing to the controller (the soak's case)
drops         10 % of the joint states dropped at random
jitter        each state delayed by 0-2 ms (+-1 ms around the mean), order kept
noise         the simulator's measurement noise (1e-4 rad, 1e-3 rad/s)
restart       the simulator process killed at mid-run and started again (stamps
              and state from 0: the arm back at q0)
frozen_clock  the controller on ``use_sim_time``; ``/clock`` stops for a third of
              the run while the states go on
flood         a third process publishes 8 MB JointStates and 5.6 MB trajectories
              for a third of the run
hostile_flood a third process (niced) publishes every 100 ms a JointState of 1e6 joint
              names (24 MB) and a trajectory of 1e5 points (8 MB) for a third of the
              run, while a plain 500 Hz loop in a fourth process measures the
              machine's own stalls in the same window
starved       busy processes (two per core) beside the nodes for a third of the run
joiners       every 2 s of a third of the run a new process (a node with a publisher on
              ``/joint_states``) joins the graph and leaves after 1.5 s, while a plain
              500 Hz loop measures the machine's own stalls
============  ===================================================================

The flood, starved and joiners cases leave the relay out: the simulator (real time with
``--rt``, as an arm's driver) publishes to the controller directly, so that a stall of this
process (Python, not real time) is not counted as one of the controller's input.

Each case is one entry of :data:`CASES` (a :class:`Case`: the fault, its window, its
figures and its checks).

Per case it reports the tracking RMS (the controller's ``~/tracking_error``, norm over
the joints) against nominal, the longest gap between efforts (sender's stamps), whether
the estimates stayed finite and bounded, and whether control recovered: the last fifth
of the run tracks within 3x nominal; after the restart, also the first non-watchdog
effort within 1 s of the first new state; after the frozen ``/clock``, instead: the first
non-watchdog effort within 1 s of ``/clock`` resuming, and the tracking error back within
3x the nominal RMS (and staying there) within 5 s of it (doc/failsafe.md).
``rcac bench soak MINUTES`` runs the direct case that long and reports the controller's memory
growth (RSS) and late ticks.
"""

import json
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from rcac_ros import topics
from rcac_ros.errors import ConfigError
from rcac_ros.tools.warm import warm_once

GOALS = {"tracking_ratio": 3.0, "restart_recovery_s": 1.0, "gap_periods": 2.0,
         "memory_growth": 0.05, "settle_s": 5.0, "starved_ratio": 10.0}
#: the hostile flood (doc/failsafe.md): 1e6 joint names, a pair of messages every 100 ms
HOSTILE = ["--names", "1000000", "--period", "0.1"]
#: a process that only wakes every period (``h``, ``seconds``) and prints its wake-up times
PLAIN_LOOP = """
import sys, time
h, secs = float(sys.argv[1]), float(sys.argv[2])
t, nxt = [], time.monotonic()
end = nxt + secs
while nxt < end:
    nxt += h
    time.sleep(max(0.0, nxt - time.monotonic()))
    t.append(time.monotonic_ns())
print(" ".join(str(x) for x in t))
"""
#: a busy process, at the default scheduler whatever the bench's own
BUSY = "import os\nos.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))\n" \
    "while True:\n    pass\n"
FLOOD = os.path.join(os.path.dirname(os.path.abspath(__file__)), "flood.py")
BOUND = 1e6                 # |theta_hat| above this: not bounded
#: the namespace the simulator's states and clock are remapped into, ahead of the relay
SIM = "/sim"


class Relay:
    """Forward the simulator's states and clock, with drops, jitter and a clock freeze."""

    def __init__(self, node, h, seed=0):
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState
        qos = topics.qos()
        self.drop = 0.0
        self.jitter = 0.0           # s: each message delayed by U(0, jitter)
        self.freeze_clock = False
        self.first_state_after = None    # (steady ns threshold, first state ns after it)
        self.forwarded = 0
        self.dropped = 0
        self._rng = np.random.default_rng(seed)
        self._queue = queue.Queue()
        states = topics.resolve(topics.JOINT_STATES)
        self._pub_state = node.create_publisher(JointState, states, qos)
        self._pub_clock = node.create_publisher(Clock, topics.CLOCK, qos)
        self._subs = [node.create_subscription(JointState, SIM + states, self._on_state, qos,
                                               raw=True),
                      node.create_subscription(Clock, SIM + topics.CLOCK, self._on_clock, qos,
                                               raw=True)]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        self._release = 0

    def _on_state(self, data):
        now = time.monotonic_ns()
        if self.first_state_after is not None and self.first_state_after[1] is None \
                and now > self.first_state_after[0]:
            self.first_state_after = (self.first_state_after[0], now)
        if self.drop and self._rng.random() < self.drop:
            self.dropped += 1
            return
        delay = round(self._rng.uniform(0.0, self.jitter) * 1e9) if self.jitter else 0
        self._release = max(self._release, now + delay)     # order kept
        self._queue.put((self._release, data))

    def _on_clock(self, data):
        if not self.freeze_clock:
            self._pub_clock.publish(bytes(data))

    def _run(self):
        while not self._stop.is_set():
            try:
                release, data = self._queue.get(timeout=0.05)
            except queue.Empty:
                continue
            wait = release - time.monotonic_ns()
            if wait > 0:
                time.sleep(wait * 1e-9)
            self._pub_state.publish(bytes(data))
            self.forwarded += 1

    def close(self):
        self._stop.set()
        self._thread.join(2.0)


class Probe:
    """Efforts (sender's stamps), tracking errors, estimates and diagnostics."""

    def __init__(self, node):
        from std_msgs.msg import Float64MultiArray

        from rcac_ros.tools.bench.ros import subscribe_diagnostics
        qos = topics.qos(topics.MONITOR_DEPTH)
        self.recording = False
        self.efforts = []           # (source ns, receive steady ns, watchdog)
        self.tracking = []          # (receive steady ns, |q - q_d|)
        self.theta_max = 0.0
        self.theta_finite = True
        self.diagnostics = {}
        self.subs = [
            node.create_subscription(Float64MultiArray, topics.resolve(topics.EFFORT_COMMANDS),
                                     self._on_effort, qos, raw=True),
            node.create_subscription(Float64MultiArray, topics.resolve(topics.TRACKING_ERROR),
                                     self._on_tracking, qos),
            node.create_subscription(Float64MultiArray,
                                     topics.resolve(topics.PARAMETER_ESTIMATES),
                                     self._on_theta, qos),
            subscribe_diagnostics(node, self.diagnostics, qos)]

    def _on_effort(self, data, info):
        if self.recording:
            self.efforts.append((info["source_timestamp"], time.monotonic_ns(),
                                 topics.is_watchdog_effort(data)))

    def _on_tracking(self, msg):
        if self.recording:
            self.tracking.append((time.monotonic_ns(), float(np.linalg.norm(msg.data))))

    def _on_theta(self, msg):
        if self.recording:
            theta = np.asarray(msg.data)
            self.theta_finite &= bool(np.all(np.isfinite(theta)))
            if theta.size and np.all(np.isfinite(theta)):
                self.theta_max = max(self.theta_max, float(np.max(np.abs(theta))))


def rss_kb(pid):
    """Resident set size of a process, kB (``/proc``), or ``None``."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _freeze_clock(run):
    run.relay.freeze_clock = True


def _thaw_clock(run):
    run.relay.freeze_clock = False


def _starve(run):
    run.busy = [subprocess.Popen([sys.executable, "-c", BUSY])
                for _ in range(2 * (os.cpu_count() or 1))]


def _stop_busy(run):
    for p in run.busy:
        p.kill()
        p.wait()
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
        run.flood = subprocess.Popen(cmd, env=run.env, stdout=subprocess.PIPE,
                                     stderr=err_file, text=True)
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
    run.joiners = subprocess.Popen(
        [sys.executable, "-c", JOINERS, str(JOIN_PERIOD), str(count),
         topics.resolve(topics.JOINT_STATES)], env=run.env, start_new_session=True)


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
    "joiners": Case(window="third", inject=_joiners, plain_loop=True, relay=False,
                    figures=_window_and_machine_figures, check=_judge_hostile),
}


class _Run:
    """What a case's functions reach: the relay, the probe, the processes and the times."""

    def __init__(self, h, env):
        self.h, self.env = h, env
        self.relay = self.probe = self.flood = self.joiners = self.plain = self.window = None
        self.busy = []
        self.third = self.t0 = self.t_restart = self.t_resume = self.track = None
        self.children, self.ctx, self.executor = [], None, None
        self.ctrl = self.sim_child = None

    def spin_for(self, seconds, cond=None, what="running"):
        """Spin this process's node for ``seconds`` (or until ``cond()``); the controller
        exiting meanwhile raises :class:`NodeFailed`."""
        from rcac_ros.tools.launch import NodeFailed
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if cond is not None and cond():
                return True
            if not self.ctrl.alive():
                raise NodeFailed(f"the controller exited ({self.ctrl.returncode}) {what}:"
                                 f"\n{self.ctrl.tail()}")
            self.executor.spin_once(timeout_sec=0.005)
        return cond is None


def run_case(case, duration, controller, rate=500.0, warmup=3.0, log_dir=None, soak=False,
             verbose=True, simulator=None, discovery_range="LOCALHOST"):
    """Run one case; return its figures (see the module docstring)."""
    import domain_coordinator

    from rcac_ros.tools.launch import child_env

    spec = CASES[case]
    h = 1.0 / rate
    log_dir = log_dir or tempfile.mkdtemp(prefix="rcac_faults_")
    os.makedirs(log_dir, exist_ok=True)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = discovery_range
    out = {"case": case, "rate": float(rate), "discovery_range": discovery_range}
    with domain_coordinator.domain_id() as domain:
        env = child_env(domain)
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = discovery_range
        run = _Run(h, env)
        run.log_dir = log_dir
        try:
            _start_nodes(run, case, spec, controller, simulator or {}, rate, domain, log_dir)
            run.spin_for(warmup)
            run.probe.recording = True
            rss = _run_windows(run, spec, duration, soak, verbose)
            run.probe.recording = False
            t1 = time.monotonic_ns()
            run.spin_for(1.2)       # one more diagnostics message
        finally:
            _stop_all(run)
    _collect_figures(run, spec, out, rss, t1, soak)
    return out


def _start_nodes(run, case, spec, controller, simulator, rate, domain, log_dir):
    """This process's node (the relay and the probe), the controller and the simulator;
    returns once they are connected."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from rcac_ros.tools.launch import init_context
    from rcac_ros.tools.launch import Child, node_command, NodeFailed

    h, env = run.h, run.env
    ctrl_over = dict(controller, mode="timer", rate=float(rate), monitor_decimation=10)
    ctrl_over.update(spec.controller)
    sim_over = dict(simulator, mode="realtime", dt=h, duration=0.0)
    sim_over.update(spec.simulator)
    remap = ["-r", f"{topics.JOINT_STATES}:={SIM}{topics.resolve(topics.JOINT_STATES)}",
             "-r", f"{topics.CLOCK}:={SIM}{topics.CLOCK}"] if spec.relay else []
    run.ctx = init_context(domain)
    run.executor = SingleThreadedExecutor(context=run.ctx)
    node = Node("rcac_fault_bench", context=run.ctx)
    run.executor.add_node(node)
    relay = run.relay = Relay(node, h) if spec.relay else None
    probe = run.probe = Probe(node)

    def sim_child(tag=""):
        return Child("simulator", node_command("simulator", overrides=sim_over) + remap,
                     env, os.path.join(log_dir, f"{case}_simulator{tag}.log"))
    run.sim_child = sim_child
    run.ctrl = Child("controller", node_command("controller", overrides=ctrl_over), env,
                     os.path.join(log_dir, f"{case}_controller.log"))
    run.children += [run.ctrl, sim_child()]
    if not run.spin_for(60.0, lambda: all(s.get_publisher_count() for s in probe.subs[:2])
                        and (relay is None or relay.forwarded > 0), "while starting"):
        raise NodeFailed(f"{case}: the nodes did not connect (logs in {log_dir})")


def _run_windows(run, spec, duration, soak, verbose):
    """The run with its fault (:attr:`Case.window`); the controller's RSS samples."""
    spin_for, relay, h = run.spin_for, run.relay, run.h
    t0 = run.t0 = time.monotonic_ns()
    if relay is not None:
        relay.drop = spec.drop
        relay.jitter = spec.jitter
    third = run.third = duration / 3.0
    rss = [(0.0, rss_kb(run.ctrl.proc.pid))]
    if spec.window == "restart":
        spin_for(duration / 2.0)
        run.children[1].stop()
        spin_for(0.5)
        relay.first_state_after = (time.monotonic_ns(), None)
        run.t_restart = time.monotonic_ns()
        run.children[1] = run.sim_child("_restarted")
        spin_for(duration / 2.0 - 0.5)
    elif spec.window == "third":
        spin_for(third)
        spec.inject(run)
        if spec.plain_loop:
            run.plain = subprocess.Popen([sys.executable, "-c", PLAIN_LOOP, str(h),
                                          str(third)], stdout=subprocess.PIPE,
                                         text=True)
        run.window = (time.time_ns(), time.monotonic_ns())
        spin_for(third)
        run.window += (time.time_ns(), time.monotonic_ns())
        run.t_resume = time.monotonic_ns()
        if spec.clear is not None:
            spec.clear(run)
        spin_for(duration - 2 * third)
    else:
        step = 10.0 if soak else duration
        while (time.monotonic_ns() - t0) * 1e-9 < duration:
            spin_for(min(step, duration - (time.monotonic_ns() - t0) * 1e-9))
            rss.append(((time.monotonic_ns() - t0) * 1e-9, rss_kb(run.ctrl.proc.pid)))
            if soak and verbose:
                print(f"  soak {rss[-1][0] / 60:5.1f} min: controller RSS "
                      f"{rss[-1][1]} kB", flush=True)
    return rss


def _stop_all(run):
    """The fault's processes, the relay, the nodes and this process's context."""
    from rcac_ros.tools.launch import shut_down
    for p in run.busy + [p for p in (run.flood,) if p is not None]:
        p.kill()
        p.wait()
    if run.joiners is not None:     # its own session: with the nodes it started
        try:
            os.killpg(run.joiners.pid, signal.SIGKILL)
        except ProcessLookupError:  # the group is gone already
            pass
        run.joiners.wait()
    if run.relay is not None:
        run.relay.close()
    shut_down(run.children, run.executor, run.ctx)


def _collect_figures(run, spec, out, rss, t1, soak):
    """The case's figures from what the probe recorded (into ``out``)."""
    probe, relay, t0, h = run.probe, run.relay, run.t0, run.h
    src = np.array([e[0] for e in probe.efforts], dtype=np.int64)
    gaps = np.diff(src) * 1e-6 if src.size > 1 else np.array([np.inf])
    track = run.track = np.array([e for e in probe.tracking]).reshape(-1, 2)
    out.update(window_s=(t1 - t0) * 1e-9, efforts=int(src.size),
               watchdog_efforts=int(sum(e[2] for e in probe.efforts)),
               longest_gap_ms=float(gaps.max()), gaps_over_2h=int(np.sum(gaps > 2e3 * h)),
               tracking_rms=float(np.sqrt(np.mean(track[:, 1] ** 2))) if track.size else None,
               theta_bounded=bool(probe.theta_finite and probe.theta_max < BOUND),
               theta_max=probe.theta_max, dropped=relay.dropped if relay else 0)
    tail = track[track[:, 0] > t1 - 0.2 * (t1 - t0)] if track.size else track
    out["tracking_rms_last_fifth"] = float(np.sqrt(np.mean(tail[:, 1] ** 2))) \
        if tail.size else None
    out["tracking_t_s"] = ((track[:, 0] - t0) * 1e-9).tolist() if track.size else []
    out["tracking"] = track[:, 1].tolist() if track.size else []
    if spec.figures is not None:
        spec.figures(run, out)
    diag = probe.diagnostics.get("rcac_controller: control loop", {})
    for key in ("starved_spells", "delay_worst_ms", "late_ticks", "skipped_ticks",
                "watchdog_trips", "rejected_messages",
                "stamp_restarts"):
        if key in diag:
            out[f"controller_{key}"] = diag[key]
    sim = probe.diagnostics.get("rcac_simulator: simulation", {})
    for key in ("late_ticks", "skipped_ticks"):       # the controller's input, its own loop
        if key in sim:
            out[f"simulator_{key}"] = sim[key]
    good = [kb for _, kb in rss if kb]
    if len(good) > 2:
        base = good[1] if soak else good[0]       # soak: after the first 10 s
        out["rss_kb"] = good
        out["memory_growth"] = (good[-1] - base) / base


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


def judge(results):
    """Add the verdicts against the reference and the goals.

    The reference of a case is the run of ``nominal`` (the relay in the loop) or, for a
    case without the relay, of ``direct``, each if it was run (else the other). A case whose
    controller holds its start (``trajectory: topic`` with only the flood's trajectories,
    all refused) has no tracking to compare: its ``tracking_ratio`` and ``recovered`` are
    ``None``.
    """
    runs = {r["case"]: r["tracking_rms"] for r in results if r["case"] in ("nominal", "direct")}
    for r in results:
        spec = CASES[r["case"]]
        order = ("nominal", "direct") if spec.relay else ("direct", "nominal")
        r["reference"] = next((c for c in order if runs.get(c)), None)
        ref = runs.get(r["reference"])
        if spec.controller.get("trajectory") == "topic":
            r["tracking_ratio"] = r["recovered"] = None
            ref = None
        else:
            r["tracking_ratio"] = r["tracking_rms"] / ref if ref and r["tracking_rms"] else None
            last = r["tracking_rms_last_fifth"]
            r["recovered"] = bool(ref and last is not None
                                  and last <= GOALS["tracking_ratio"] * ref)
        if spec.check is not None:
            spec.check(r, ref)
    return results


def settle_time(t_s, error, after_s, bound):
    """Seconds from ``after_s`` until ``error`` stays within ``bound`` (``None``: never)."""
    t, e = np.asarray(t_s), np.asarray(error)
    keep = t >= after_s
    t, e = t[keep], e[keep]
    if not t.size or e[-1] > bound:
        return None
    above = np.flatnonzero(e > bound)
    return 0.0 if not above.size else float(t[above[-1] + 1] - after_s)


def _yes_no(flag):
    return "-" if flag is None else "yes" if flag else "NO"


def format_table(results, h):
    head = (f"{'case':<13} {'track RMS (rad)':>15} {'x ref':>9} {'longest gap':>11} "
            f"{'gaps>2h':>7} {'theta ok':>8} {'recovered':>9}  notes")
    lines = [head, "-" * len(head)]
    for r in results:
        ratio = "-" if r["tracking_ratio"] is None else f"{r['tracking_ratio']:.2f}"
        rms = "-" if r["tracking_rms"] is None else f"{r['tracking_rms']:.3g}"
        notes = []
        if r.get("reference") == "direct" and r["case"] != "direct" \
                and r["tracking_ratio"] is not None:
            notes.append("ref: direct")
        if r["case"] == "restart":
            rec = r.get("restart_recovery_s")
            notes.append("control back after " + ("never" if rec is None else f"{rec:.3f} s"))
        if r["case"] == "frozen_clock":
            back, settle = r.get("control_back_s"), r.get("settle_s")
            notes.append("control back after " + ("never" if back is None else f"{back:.3f} s")
                         + "; within 3x nominal after "
                         + ("- (not in the run)" if settle is None else f"{settle:.2f} s"))
        if r.get("dropped"):
            notes.append(f"{r['dropped']} states dropped")
        if r.get("watchdog_efforts"):
            notes.append(f"{r['watchdog_efforts']} safe efforts")
        if "window_efforts" in r:
            notes.append(f"in the faulty third: {r['window_safe']}/{r['window_efforts']} safe, "
                         f"longest gap {r['window_gap_ms']:.1f} ms (plain loop "
                         f"{r.get('plain_loop_gap_ms') or float('nan'):.1f} ms)")
        if r.get("window_ratio") is not None:
            notes.append(f"tracking in it {r['window_ratio']:.2f}x ref")
        if "window_ok" in r:
            notes.append("goal " + ("met" if r["window_ok"] else "NOT met"))
        if "controller_starved_spells" in r:
            notes.append(f"starved spells {r['controller_starved_spells']} (worst delay "
                         f"{r.get('controller_delay_worst_ms', '-')} ms)")
        if "memory_growth" in r:
            notes.append(f"RSS growth {100 * r['memory_growth']:.1f} %")
        if "controller_late_ticks" in r:
            notes.append(f"late/skipped ticks {r['controller_late_ticks']}/"
                         f"{r.get('controller_skipped_ticks', '-')}")
        if "simulator_late_ticks" in r:
            notes.append(f"simulator's {r['simulator_late_ticks']}/"
                         f"{r.get('simulator_skipped_ticks', '-')}")
        lines.append(f"{r['case']:<13} {rms:>15} {ratio:>9} {r['longest_gap_ms']:>8.1f} ms "
                     f"{r['gaps_over_2h']:>7} {'yes' if r['theta_bounded'] else 'NO':>8} "
                     f"{_yes_no(r['recovered']):>9}  {'; '.join(notes)}")
    lines.append(f"goals: tracking <= {GOALS['tracking_ratio']:g}x nominal (drops, jitter, "
                 f"noise); control back within {GOALS['restart_recovery_s']:g} s of a restart "
                 f"or of /clock resuming, tracking within 3x nominal {GOALS['settle_s']:g} s "
                 "after it; "
                 f"no gap > {GOALS['gap_periods'] * h * 1e3:g} ms; hostile flood: no safe "
                 "effort and no gap beyond the plain loop's + 2 periods; starved: tracking "
                 f"<= {GOALS['starved_ratio']:g}x the reference while loaded")
    return "\n".join(lines)


def plot(results, path):
    from rcac_ros.tools.plots import plt
    fig, axes = plt.subplots(len(results), 1, figsize=(9, 2.0 * len(results)), sharex=True,
                             squeeze=False)
    for ax, r in zip(axes[:, 0], results):
        ax.semilogy(r["tracking_t_s"], np.maximum(r["tracking"], 1e-12), lw=0.7)
        ax.set_ylabel("|q - q_d| (rad)", fontsize=7)
        ax.set_title(r["case"], fontsize=8, loc="left")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


#: the values of ``ROS_AUTOMATIC_DISCOVERY_RANGE`` the bench runs with
DISCOVERY_RANGES = ("LOCALHOST", "SUBNET")


def run_faults(duration=120.0, cases=CASES, controller=None, json_path=None, plot_path=None,
               soak_minutes=None, verbose=True, simulator=None, discovery_range="LOCALHOST"):
    """Run the cases (or the soak), print the table, return the results.

    ``discovery_range`` is ``ROS_AUTOMATIC_DISCOVERY_RANGE`` for every process: with
    ``LOCALHOST`` (the default: no traffic off the machine) rmw_fastrtps gives each
    participant its own shared-memory transport with Fast DDS's default health check, which
    can hold every writer of a participant up to 1/3 s when another participant starts
    (doc/failsafe.md, "Known limitations and deployment advice"); ``SUBNET`` is ROS's default.
    """
    if not duration > 3.0:
        raise ConfigError(f"duration: must be > 3 s, got {duration}")
    if discovery_range not in DISCOVERY_RANGES:
        raise ConfigError(f"discovery_range: {discovery_range!r} is not one of "
                          f"{', '.join(DISCOVERY_RANGES)}")
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise ConfigError(f"cases: unknown {unknown} (known: {', '.join(CASES)})")
    controller = dict(controller or {})
    warm_once()
    results = []
    if soak_minutes:
        cases, duration = ("direct",), soak_minutes * 60.0
    for case in cases:
        if verbose:
            print(f"rcac bench faults: {case} ({duration:g} s)", flush=True)
        results.append(run_case(case, duration, controller, soak=bool(soak_minutes),
                                verbose=verbose, simulator=simulator,
                                discovery_range=discovery_range))
        if verbose:
            r = results[-1]
            print(f"  tracking RMS {r['tracking_rms']}, longest gap {r['longest_gap_ms']:.1f} "
                  f"ms", flush=True)
    judge(results)
    if verbose:
        print(format_table(results, 0.002), flush=True)
    if json_path:
        with open(json_path, "w", encoding="utf-8") as f:
            json.dump(results, f, indent=1)
    if plot_path:
        plot(results, plot_path)
        if verbose:
            print(f"wrote {plot_path}")
    return results
