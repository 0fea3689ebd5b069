"""The ROS 2 loop benchmark behind ``rcac bench ros``.

The simulator (``mode: realtime``, stepping every dt on absolute deadlines of the steady
clock) and the controller (``mode: timer`` at ``rate``, the same kind of loop) run free as
two processes over DDS, as they would on a real arm. With ``controller_mode="on_state"``
the controller instead answers each joint state as it arrives (its ``lockstep`` mode; the
realtime simulator ignores the tags). An in-process probe subscribes (raw) to the joint
states, the effort commands and ``/diagnostics`` and measures, after a warm-up:

* the achieved controller and simulator rates;
* the period between efforts (source stamps: the controller's own timing) p50/p99/max;
* the state -> effort latency: for each effort, the age of the newest joint state the
  probe had received when the effort arrived (receive stamps; it includes the phase
  between the two timers, 0 to one period) and the one-way DDS transport latency
  (receive minus source stamp);
* deadline misses: effort periods longer than 1.5 periods, and ticks missing against
  the nominal rate; the controller's and the simulator's own counters from their
  diagnostics (ticks more than half a period late, ticks skipped when more than 25
  periods behind; cumulative since start, warm-up included);
* what the controller adds, as ratios of two figures of the same run, which the load of the
  machine moves together (doc/nodes.md, "Timing"): the effort period p99 over the state
  period p99 (source stamps: the hop from the simulator to the controller counts against
  it); the controller's own share, from its diagnostics: the p99 period of its efforts as
  sent over that of the states as DDS received them (since its activation, warm-up
  included); and the latency p50 over the one-way
  latency of a plain DDS ping (:mod:`rcac_ros.tools.bench.echo`, a third process that echoes
  a 7-joint JointState; half the round trip, every 20 ms).
"""

import json
import math
import os
import sys
import tempfile
import time

import numpy as np

from rcac_ros import topics
from rcac_ros.errors import ConfigError
from rcac_ros.tools.launch import Child, child_env, init_context, node_command, NodeFailed, \
    shut_down, StopFlag, wait_until_active
from rcac_ros.tools.runs.metrics import percentiles
from rcac_ros.tools.warm import warm_once

#: controller parameters of the benchmark. The paper's K_D = 1e4 is tuned for lockstep (no
#: delay); free-running, the effort lands up to one period late and that loop diverges within
#: a second on the CSS arm. The benchmark measures timing, so it uses a gain that stays
#: stable. The monitor topics (estimates, errors, desired state) go out at 50 Hz, not with
#: every effort: the control loop does not need them.
BENCH_CONTROLLER = {"K_D": 1000.0, "monitor_decimation": 10}

#: the bench's names of the controller's timing: its own timer, or one answer per state
CONTROLLER_MODES = {"timer": "timer", "on_state": "lockstep", "lockstep": "lockstep"}

#: goals on the 2-core machine (doc/tools.md, "rcac bench ros"); the ratio is what the
#: controller adds to the jitter of its input (the simulator's states as received), whatever
#: the load
GOALS = {"rate_hz": 499.0, "period_p99_ms": 2.5, "latency_p50_ms": 1.0, "period_ratio": 1.1}

#: seconds between two pings of the plain DDS echo
PING_PERIOD = 0.02


def subscribe_diagnostics(node, latest, qos):
    """Subscribe ``node`` to the diagnostics; each status's values land in
    ``latest[status name]`` (a dict of key -> value, the latest of each status)."""
    from diagnostic_msgs.msg import DiagnosticArray

    def on_diagnostics(msg):
        for status in msg.status:
            latest[status.name] = {kv.key: kv.value for kv in status.values}
    return node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diagnostics, qos)


class Probe:
    """Raw subscriptions that keep (source, receive) stamps of states and efforts."""

    def __init__(self, context, depth=1000):
        from rclpy.node import Node
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from rcac_ros.tools.bench.echo import PING, PONG

        qos = topics.qos(depth)
        self.node = Node("rcac_bench_probe", context=context)
        self.recording = False
        self.states = []     # (source, receive) ns
        self.efforts = []    # (source, receive, watchdog)
        self.latest_state_recv = None
        self.diagnostics = {}
        self.ping_rtt = []   # ns: receive(pong) - send(ping), through the plain DDS echo
        self._ping_msg = JointState(name=[f"joint{i}" for i in range(1, 8)],
                                    position=[0.0] * 7, velocity=[0.0] * 7)
        self._ping = self.node.create_publisher(JointState, PING, topics.qos(10))
        self.node.create_timer(PING_PERIOD, self._send_ping)
        self._subs = [
            self.node.create_subscription(JointState, topics.resolve(topics.JOINT_STATES),
                                          self._on_state, qos, raw=True),
            self.node.create_subscription(Float64MultiArray,
                                          topics.resolve(topics.EFFORT_COMMANDS),
                                          self._on_effort, qos, raw=True),
            subscribe_diagnostics(self.node, self.diagnostics, qos),
            self.node.create_subscription(JointState, PONG, self._on_pong, topics.qos(10)),
        ]

    def _send_ping(self):
        t = time.time_ns()          # the clock of the DDS receive stamps
        self._ping_msg.header.stamp.sec, self._ping_msg.header.stamp.nanosec = divmod(t, 10**9)
        self._ping.publish(self._ping_msg)

    def _on_pong(self, msg, info):
        if self.recording:
            sent = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            self.ping_rtt.append(info["received_timestamp"] - sent)

    def _on_state(self, data, info):
        recv = info["received_timestamp"]
        self.latest_state_recv = recv
        if self.recording:
            self.states.append((info["source_timestamp"], recv))

    def _on_effort(self, data, info):
        if not self.recording:
            return
        watchdog = topics.is_watchdog_effort(data)
        recv = info["received_timestamp"]
        self.efforts.append((info["source_timestamp"], recv, watchdog))

    def matched(self):
        return all(s.get_publisher_count() > 0 for s in self._subs[:2] + self._subs[3:]) \
            and self._ping.get_subscription_count() > 0


def state_age(state_recv, effort_recv):
    """ns, per effort: its receive stamp minus that of the newest state received before it.

    From the DDS receive stamps after the run, not in the callbacks: a loaded probe runs its
    callbacks late and not in arrival order (a backlog of states first, then of efforts),
    while the stamps are those of the samples' arrival. Efforts before the first state are
    left out.
    """
    state_recv = np.sort(np.asarray(state_recv, np.int64))
    effort_recv = np.asarray(effort_recv, np.int64)
    i = np.searchsorted(state_recv, effort_recv, side="right") - 1
    ok = i >= 0
    return (effort_recv[ok] - state_recv[i[ok]]).astype(float)


def analyse(probe, window_s, rate):
    """The benchmark figures from the probe's stamps (see the module docstring)."""
    h_ms = 1e3 / rate
    eff = np.array([(s, r) for s, r, w in probe.efforts if not w], dtype=np.int64).reshape(-1, 2)
    st = np.array(probe.states, dtype=np.int64).reshape(-1, 2)
    out = {"window_s": window_s, "nominal_rate_hz": rate,
           "efforts": int(len(eff)),
           "watchdog_efforts": int(sum(1 for e in probe.efforts if e[2])),
           "states": int(len(st))}
    out["controller_rate_hz"] = len(eff) / window_s
    out["simulator_rate_hz"] = len(st) / window_s
    period = 1e-6 * np.diff(eff[:, 0]).astype(float) if len(eff) > 1 else np.empty(0)
    out.update(percentiles(period, "period"))
    state_period = 1e-6 * np.diff(st[:, 0]).astype(float) if len(st) > 1 else np.empty(0)
    out.update(percentiles(state_period, "state_period"))
    out.update(percentiles(1e-6 * state_age(st[:, 1], eff[:, 1]), "state_to_effort_latency"))
    out.update(percentiles(1e-6 * (eff[:, 1] - eff[:, 0]).astype(float), "effort_transport"))
    out.update(percentiles(1e-6 * (st[:, 1] - st[:, 0]).astype(float), "state_transport"))
    out.update(percentiles(0.5e-6 * np.asarray(probe.ping_rtt, float), "ping_one_way"))
    out["pings"] = len(probe.ping_rtt)
    out["period_ratio"] = _ratio(out["period_p99_ms"], out["state_period_p99_ms"])
    out["latency_ratio"] = _ratio(out["state_to_effort_latency_p50_ms"],
                                  out["ping_one_way_p50_ms"])
    out["late_periods"] = int(np.count_nonzero(period > 1.5 * h_ms))
    out["missing_ticks"] = max(0, int(round(window_s * rate)) - len(eff))
    for node, name, keys in (
            ("controller", f"{topics.CONTROLLER_NODE}: control loop",
             ("deadline_misses", "late_ticks", "skipped_ticks", "compute_overruns",
              "compute_time_p50_us", "compute_time_p99_us", "watchdog_trips",
              "gc_pause_max_ms", "gc_full_collections", "phase_error_us",
              "input_period_p99_us", "effort_period_p99_us")),
            ("simulator", f"{topics.SIMULATOR_NODE}: simulation",
             ("late_ticks", "skipped_ticks"))):
        status = probe.diagnostics.get(name, {})
        for key in keys:
            if key in status:
                try:
                    out[f"{node}_{key}"] = float(status[key])
                except ValueError:
                    pass
    out["own_period_ratio"] = _ratio(out.get("controller_effort_period_p99_us"),
                                     out.get("controller_input_period_p99_us"))
    out["meets_goal"] = bool(
        out["controller_rate_hz"] >= GOALS["rate_hz"]
        and out["period_p99_ms"] is not None and out["period_p99_ms"] <= GOALS["period_p99_ms"]
        and out["state_to_effort_latency_p50_ms"] is not None
        and out["state_to_effort_latency_p50_ms"] <= GOALS["latency_p50_ms"])
    out["meets_ratio_goal"] = bool(out["period_ratio"] is not None
                                   and out["period_ratio"] <= GOALS["period_ratio"])
    return out


def _ratio(a, b):
    return None if a is None or b is None or not b > 0.0 or not math.isfinite(a / b) \
        else a / b


def format_table(r):
    """The benchmark as a table, with the goals."""
    def ms(key):
        v = r.get(key)
        return "-" if v is None else f"{v:.3f}"

    def ratio(key):
        v = r.get(key)
        return "-" if v is None else f"{v:.2f}"

    rows = [
        ("controller rate (Hz)", f"{r['controller_rate_hz']:.1f}", f">= {GOALS['rate_hz']:g}"),
        ("simulator rate (Hz)", f"{r['simulator_rate_hz']:.1f}", ""),
        ("effort period p50 (ms)", ms("period_p50_ms"), ""),
        ("effort period p99 (ms)", ms("period_p99_ms"), f"<= {GOALS['period_p99_ms']:g}"),
        ("effort period max (ms)", ms("period_max_ms"), ""),
        ("state period p99 / max (ms)", f"{ms('state_period_p99_ms')} / "
         f"{ms('state_period_max_ms')}", ""),
        ("state -> effort latency p50 (ms)", ms("state_to_effort_latency_p50_ms"),
         f"<= {GOALS['latency_p50_ms']:g}"),
        ("state -> effort latency p99 (ms)", ms("state_to_effort_latency_p99_ms"), ""),
        ("one-way DDS latency p50, state / effort (ms)",
         f"{ms('state_transport_p50_ms')} / {ms('effort_transport_p50_ms')}", ""),
        ("plain DDS ping, one way p50 / p99 (ms)",
         f"{ms('ping_one_way_p50_ms')} / {ms('ping_one_way_p99_ms')}", ""),
        ("effort period p99 / state period p99", ratio("period_ratio"),
         f"<= {GOALS['period_ratio']:g}"),
        ("the controller's own: effort sent p99 / state received p99",
         "-" if r.get("own_period_ratio") is None else f"{r['own_period_ratio']:.3f}", ""),
        ("latency p50 / ping one way p50", ratio("latency_ratio"), ""),
        ("periods > 1.5 h", str(r["late_periods"]), ""),
        ("missing ticks (vs nominal)", str(r["missing_ticks"]), ""),
    ]
    paced = ("controller", "simulator") if r.get("controller_mode", "timer") == "timer" \
        else ("simulator",)
    for node in paced:
        if f"{node}_late_ticks" in r and f"{node}_skipped_ticks" in r:
            rows.append((f"{node} ticks late > h/2 / skipped (its diagnostics)",
                         f"{r[f'{node}_late_ticks']:.0f} / {r[f'{node}_skipped_ticks']:.0f}",
                         ""))
    if "controller_compute_overruns" in r:
        rows.append(("controller compute > h (its diagnostics)",
                     f"{r['controller_compute_overruns']:.0f}", ""))
    if "controller_compute_time_p99_us" in r:
        rows.append(("controller compute p50 / p99 (us)",
                     f"{r['controller_compute_time_p50_us']:.0f} / "
                     f"{r['controller_compute_time_p99_us']:.0f}", ""))
    if "controller_gc_pause_max_ms" in r:
        rows.append(("controller garbage collections: full / longest pause (ms)",
                     f"{r['controller_gc_full_collections']:.0f} / "
                     f"{r['controller_gc_pause_max_ms']:.3f}", ""))
    w = max(len(a) for a, _, _ in rows)
    mode = r.get("controller_mode", "timer")
    mode = f"timer, {r['nominal_rate_hz']:g} Hz" if mode == "timer" else "on each state"
    lines = [f"ROS 2 loop: controller ({mode}) + simulator "
             f"(realtime), {r['window_s']:.0f} s measured",
             f"  {'':<{w}}  {'measured':>15}  goal"]
    lines += [f"  {a:<{w}}  {b:>15}  {c}" for a, b, c in rows]
    lines.append(f"  goal met: {'yes' if r['meets_goal'] else 'no'}; ratio goal met: "
                 f"{'yes' if r['meets_ratio_goal'] else 'no'}")
    return "\n".join(lines)


def run_ros_bench(duration=60.0, json_path=None, rate=500.0, warmup=3.0, start_timeout=60.0,
                  log_dir=None, verbose=True, controller_overrides=None, controller_mode="timer",
                  simulator_overrides=None):
    """Run the two nodes free-running and measure the loop; print a table.

    Parameters
    ----------
    duration : float
        Seconds measured (after ``warmup``).
    json_path : str, optional
        Write the figures there as JSON.
    rate : float
        Controller rate and simulator step rate, Hz.
    warmup : float
        Seconds discarded after the first effort.
    start_timeout : float
        Seconds allowed for the nodes to start and connect.
    log_dir : str, optional
        Where the nodes' logs go (default: a temporary directory).
    controller_overrides : dict, optional
        Controller parameters on top of :data:`BENCH_CONTROLLER`.
    simulator_overrides : dict, optional
        Simulator parameters on top of the bench's (``realtime`` mode at ``rate``).
    controller_mode : {"timer", "on_state"}
        ``timer``: the controller's own ``rate`` Hz loop (doc/nodes.md, "Timing");
        ``on_state`` (alias ``lockstep``, the controller mode it uses): it answers every
        joint state as it arrives (event-driven), which removes the phase between the two
        loops from the latency.

    Returns
    -------
    dict
        The figures (see :func:`analyse`).
    """
    import domain_coordinator
    from rclpy.executors import SingleThreadedExecutor

    if not duration > 0.0:
        raise ConfigError(f"duration: must be > 0 s, got {duration}")
    if not rate > 0.0:
        raise ConfigError(f"rate: must be > 0 Hz, got {rate}")
    warm_once()
    log_dir = log_dir or tempfile.mkdtemp(prefix="rcac_ros_bench_")
    os.makedirs(log_dir, exist_ok=True)
    stop = StopFlag()
    children, ctx, executor = [], None, None
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    with domain_coordinator.domain_id() as domain:
        env = child_env(domain)
        try:
            ctx = init_context(domain)
            executor = SingleThreadedExecutor(context=ctx)
            probe = Probe(ctx)
            executor.add_node(probe.node)
            if controller_mode not in CONTROLLER_MODES:
                raise ConfigError(f"controller_mode: 'timer' or 'on_state', got "
                                  f"{controller_mode!r}")
            over = dict(BENCH_CONTROLLER, mode=CONTROLLER_MODES[controller_mode],
                        rate=float(rate))
            over.update(controller_overrides or {})
            ctrl = node_command("controller", overrides=over)
            sim = node_command("simulator", overrides=dict(
                {"mode": "realtime", "dt": 1.0 / rate, "duration": 0.0},
                **(simulator_overrides or {})))
            children.append(Child("controller", ctrl, env,
                                  os.path.join(log_dir, "controller.log")))
            children.append(Child("simulator", sim, env, os.path.join(log_dir, "simulator.log")))
            children.append(Child("DDS echo", [sys.executable, "-m", "rcac_ros.tools.bench.echo"],
                                  env, os.path.join(log_dir, "echo.log")))

            def spin_until(cond, timeout, what):
                end = time.monotonic() + timeout
                while not cond():
                    if stop:
                        raise KeyboardInterrupt
                    for c in children:
                        if not c.alive():
                            raise NodeFailed(f"the {c.name} exited with code {c.returncode} "
                                             f"{what}; last lines of {c.log_path}:\n{c.tail()}")
                    if time.monotonic() > end:
                        raise NodeFailed(f"timed out {what} (logs in {log_dir})")
                    executor.spin_once(timeout_sec=0.01)

            if verbose:
                print(f"rcac bench ros: starting the nodes (ROS_DOMAIN_ID={domain}, "
                      f"logs {log_dir})", flush=True)
            spin_until(lambda: probe.matched() and probe.latest_state_recv is not None,
                       start_timeout, "while starting")
            # the controller's publishers exist from its configure; it answers once active
            if not wait_until_active(probe.node, executor, topics.CONTROLLER_NODE,
                                     start_timeout, alive=children[0].alive):
                raise NodeFailed(f"the controller did not become active within "
                                 f"{start_timeout:g} s; last lines of "
                                 f"{children[0].log_path}:\n{children[0].tail()}")
            t_warm = time.monotonic() + warmup
            spin_until(lambda: time.monotonic() >= t_warm, warmup + 10.0, "during warm-up")
            if verbose:
                print(f"rcac bench ros: measuring for {duration:g} s", flush=True)
            probe.recording = True
            t0 = time.monotonic()
            spin_until(lambda: time.monotonic() - t0 >= duration, duration + 10.0,
                       "while measuring")
            probe.recording = False
            window = time.monotonic() - t0
            # one more diagnostics message (1 Hz) with the final counters
            t_diag = time.monotonic()
            spin_until(lambda: time.monotonic() - t_diag > 1.2, 5.0, "at the end")
        finally:
            shut_down(children, executor, ctx)
            stop.restore()
    result = analyse(probe, window, rate)
    result["controller_mode"] = "timer" if controller_mode == "timer" else "on_state"
    if verbose:
        print(format_table(result), flush=True)
    if json_path:
        os.makedirs(os.path.dirname(os.path.abspath(json_path)), exist_ok=True)
        with open(json_path, "w") as f:
            json.dump(result, f, indent=2)
    return result


def _main(argv):
    """``python -m rcac_ros.tools.bench.ros [SECONDS [JSON [timer|on_state [NAME=VALUE]...]]]``."""
    secs = float(argv[0]) if argv else 60.0
    json_path = argv[1] if len(argv) > 1 and argv[1] else None
    mode = argv[2] if len(argv) > 2 else "timer"
    extra = {}
    for item in argv[3:]:
        key, _, value = item.partition("=")
        extra[key] = int(value) if value.lstrip("-").isdigit() else float(value)
    run_ros_bench(secs, json_path, controller_mode=mode, controller_overrides=extra)


if __name__ == "__main__":
    _main(sys.argv[1:])
