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
stall         the controller's process stopped for 5 s after a third of the run (SIGSTOP)
joiners       every 2 s of a third of the run a new process (a node with a publisher on
              ``/joint_states``) joins the graph and leaves after 1.5 s, while a plain
              500 Hz loop measures the machine's own stalls
============  ===================================================================

The flood, starved and joiners cases leave the relay out: the simulator (real time with
``--rt``, as an arm's driver) publishes to the controller directly, so that a stall of this
process (Python, not real time) is not counted as one of the controller's input.

Each case is one entry of :data:`~.fault_cases.CASES` (a :class:`~.fault_cases.Case`: the
fault, its window, its figures and its checks; :mod:`.fault_cases`); the relay and the
probe: :mod:`.fault_parts`; verdicts, table and plot: :mod:`.fault_report`.

Per case it reports the tracking RMS (the controller's ``~/tracking_error``, norm over
the joints) against nominal, the longest gap between efforts (sender's stamps), whether
the estimates stayed finite and bounded, and whether control recovered: the last fifth
of the run tracks within 3x nominal; after the restart, also the first non-watchdog
effort within 1 s of the first new state; after the frozen ``/clock`` (or the stall),
instead: the first non-watchdog effort within 1 s of ``/clock`` resuming (or of the process
continued), and the tracking error back within 3x the nominal RMS (and staying there)
within 5 s of it (doc/failsafe.md).
``rcac bench soak MINUTES`` runs the direct case that long and reports the controller's memory
growth (RSS) and late ticks.
"""

import json
import os
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np

from rcac_ros import topics
from rcac_ros.errors import ConfigError
from rcac_ros.tools.bench.fault_cases import CASES, GOALS, window_figures  # noqa: F401
from rcac_ros.tools.bench.fault_parts import SIM, Probe, Relay, rss_kb
from rcac_ros.tools.bench.fault_report import format_table, judge, plot  # noqa: F401
from rcac_ros.tools.launch import spawn
from rcac_ros.tools.warm import warm_once

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
BOUND = 1e6                 # |theta_hat| above this: not bounded


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
    from rcac_ros.tools.launch import Child, node_command, NodeFailed, wait_until_active

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
    # its publishers exist from the configure; it answers once active (kernels loaded)
    if not wait_until_active(node, run.executor, topics.CONTROLLER_NODE, 60.0,
                             alive=run.ctrl.alive):
        raise NodeFailed(f"{case}: the controller did not become active within 60 s:\n"
                         f"{run.ctrl.tail()}")


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
            run.plain = spawn([sys.executable, "-c", PLAIN_LOOP, str(h), str(third)],
                              stdout=subprocess.PIPE, text=True)
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
                "watchdog_trips", "watchdog_replans", "loop_stalls", "rejected_messages",
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
