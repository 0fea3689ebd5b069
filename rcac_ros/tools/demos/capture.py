"""``rcac capture-demo``: the space-station arm grasps a payload nobody told the controller of.

The CSS arm of the paper (zero gravity, the nodes' preset with its effort limits), the
simulator and the controller over ROS 2 in lockstep (:func:`rcac_ros.tools.demos.demo.run_demo`:
two processes, one bag), the paper's motion and gains. At ``--at`` s the simulator's
``payload.*`` parameters are set through its parameter services (what ``ros2 param set``
does): the plant's last link holds ``--mass`` kg from the next step on; the controller is not
told. ``--release`` sets ``payload.mass`` to 0 later. The capture is read back from the
bag (``/rcac_simulator/payload``, stamped with the step that first carries it).

Figures (:mod:`.capture_figures`, the same for the release): the RMS tracking error over the
:data:`PRE_WINDOW` s before the event; the peak error norm after it; the recovery time (from
the event until the RMS over the trailing :data:`WINDOW` s stays within :data:`FACTOR` times
the pre-event RMS); the last link's mass and first-moment estimate errors at the end of the
phase; the largest effort against the preset's limits (where and when a limit is first
reached). The same run offline (:func:`rcac_ros.tools.runs.closed_loop.closed_loop`, capture at
the time the ROS run had it) for the direct, composite, ``channels="all"`` and Slotine-Li
laws. ``--mass-table`` runs the default law offline over :data:`TABLE_MASSES`, the paper's
motion slowed by :func:`slowdown` for each mass. Everything goes into ``capture.json``.
"""

import json
import math
import os
import sys

import numpy as np

from rcac_ros.tools.demos.capture_figures import (FACTOR, GOAL_MASS, GOAL_RECOVERY,
                                                  PRE_WINDOW, WINDOW, all_figures,
                                                  mass_markdown, norm_rows, phases, table)

#: defaults: payload mass (kg, ten times the last link's), capture and run length (s)
MASS, AT, DURATION = 1000.0, 10.0, 30.0
#: default payload: its centre of mass in the last link's frame (m) and the side of the solid
#: cube it is (m), whose inertia about its centre is mass * side^2 / 6 on each axis
COM, SIDE = (0.0, 0.0, 2.0), 2.0
#: the laws run offline: label -> law of rcac compare (:data:`~.compare.LAWS`)
LAWS = {"direct": "direct", "composite": "paper", "all": "all", "slotine_li": "slotine_li"}
#: payload masses of the table, kg (0.1 t to 20 t)
TABLE_MASSES = (100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0, 10000.0, 20000.0)
#: the share of each joint's effort limit the desired motion's own inverse dynamics may take
#: (the rest is left to the feedback and the adaptation's transient): :func:`slowdown`
EFFORT_SHARE = 0.5
#: the name of the JSON file the tool writes
JSON_NAME = "capture.json"


def cube_inertia(mass, side=SIDE):
    """The six inertia values of a solid cube of ``side`` m about its centre, kg m^2."""
    i = mass * side * side / 6.0
    return [i, i, i, 0.0, 0.0, 0.0]


# ------------------------------------------------------------------ the plants' truth
def truth(mass, com, inertia):
    """``(arm, loaded, payload)``: the preset CSS arm, the same holding the payload."""
    from rcac_ros.core.model import css_arm_preset
    from rcac_ros.core.payload import Payload, arm_reach, with_payload
    arm = css_arm_preset()
    payload = Payload(mass, com, inertia, reach=arm_reach(arm))
    return arm, with_payload(arm, payload), payload


# ------------------------------------------------------------------ offline
def slowdown(model, share=EFFORT_SHARE, period=20.0, samples=2001):
    """The time scale ``s >= 1`` of the paper's motion for ``model`` (the arm with its payload).

    A real arm moves a heavy payload slowly: its motion is planned so that the torques it
    needs stay within the joints' limits. In zero gravity the inverse dynamics along
    ``q_d(t / s)`` are ``tau(t / s) / s^2`` exactly (``M qdd`` and the Coriolis terms both scale
    as ``1 / s^2``), so the smallest ``s`` that keeps the desired motion's own torques within
    ``share`` of each joint's limit is ``sqrt(max_j max_t |tau_j| / (share limit_j))``. The
    slowed motion is the paper's with amplitude ``A / s`` and period ``s`` times 20 s (the
    same path, ``s`` times slower). Gravity must be zero (the CSS arm's).
    """
    from rcac_ros.core import PAPER_Q0, PaperTrajectory, inverse_dynamics
    if np.any(model.gravity != 0.0):
        raise ValueError("slowdown: the 1/s^2 scaling holds in zero gravity only")
    traj = PaperTrajectory(np.array(PAPER_Q0), period=period)
    worst = 0.0
    for t in np.linspace(0.0, period, samples):
        q, qd, qdd = traj(t)
        tau = inverse_dynamics(model, q, qd, qdd)
        worst = max(worst, float(np.max(np.abs(tau) / model.effort_limit)))
    return max(1.0, math.sqrt(worst / share)), worst


def offline_run(law, arm, events, duration, scale=1.0, progress=None):
    """One law of :data:`LAWS` on the arm, the plant changing at ``events`` ((t, model)...);
    the series of :func:`figures` (``track``, ``effort``, ``estimates``)."""
    from rcac_ros.core import PAPER_GAINS, PAPER_Q0, PaperTrajectory
    from rcac_ros.tools.runs.closed_loop import closed_loop
    from rcac_ros.tools.demos.compare import make_controller, Scenario
    q0 = np.array(PAPER_Q0)
    base = PaperTrajectory(q0)
    traj = PaperTrajectory(q0, amplitude=base.amplitude / scale, period=20.0 * scale)
    scenario = Scenario("capture", arm, dict(PAPER_GAINS), traj, q0, np.zeros(arm.n))
    ctrl = make_controller(scenario, LAWS[law])
    run = closed_loop(ctrl, traj, duration, plant=arm, q0=q0, qd0=np.zeros(arm.n),
                      events=events, progress=progress, progress_every=500)
    t = run["t"]
    # the estimates after period k are those before period k + 1
    theta = np.concatenate([run["theta_hat"][1:], ctrl.theta_hat[None]])[:, -1]
    return {"track": (t, run["q"] - run["q_d"]), "effort": (t, run["tau"]),
            "estimates": (t, theta), "status": run["status"]}


def offline_laws(arm, loaded, at, release, duration, scale=1.0, progress=True):
    """Every law of :data:`LAWS` on the run (the motion ``scale`` times slower):
    ``({law: figures}, {law: series})``."""
    events = [(at, loaded)] + ([(release, arm)] if release is not None else [])
    report, series = {}, {}
    for law in LAWS:
        run = offline_run(law, arm, events, duration, scale=scale,
                          progress=f"{law:>10s}" if progress else None)
        report[law] = all_figures(run["track"], run["effort"], run["estimates"], at, release,
                                  duration, arm, loaded)
        report[law]["status"] = run["status"]
        series[law] = run
    return report, series


def mass_table(com, inertia_of, at, duration, masses=TABLE_MASSES, progress=True):
    """The default (composite) law over ``masses``, the motion slowed for each
    (:func:`slowdown` of the loaded arm): one row per mass."""
    rows = []
    for mass in masses:
        arm, loaded, _ = truth(mass, com, inertia_of(mass))
        s, need = slowdown(loaded)
        run = offline_run("composite", arm, [(at, loaded)], duration, scale=s,
                          progress=f"{mass / 1000:6.1f} t" if progress else None)
        fig = all_figures(run["track"], run["effort"], run["estimates"], at, None, duration,
                          arm, loaded)["capture"]
        rows.append({"payload_mass_kg": mass, "slowdown": s,
                     "desired_effort_over_limit_unslowed": need,
                     "status": run["status"], **fig})
    return rows


# ------------------------------------------------------------------ ROS run
def read_run(bag, arm):
    """The series of :func:`figures` and the payload messages from the demo's bag."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import get_typestore, Stores
    from rcac_ros import topics
    from rcac_ros.tools.bags.analyse import analyse
    from rcac_ros.tools.bags.read import read_bag
    from rcac_ros.tools.bags.verify import find_bag
    bag = find_bag(bag)
    data = read_bag(bag)
    _, series = analyse(data, arm.theta())
    changes = []
    name = topics.resolve(topics.PAYLOAD, topics.SIMULATOR_NODE)
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == name]
        # (rosbags reads every topic when given no connection)
        for conn, _, raw in reader.messages(connections=conns) if conns else ():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            changes.append({"t": msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec,
                            "mass": msg.inertia.m})
    missing = [k for k in ("tracking_error", "parameter_estimates") if k not in series]
    if missing:
        from rcac_ros.tools.launch import NodeFailed
        log = os.path.join(os.path.dirname(os.path.abspath(bag)), "logs", "controller.log")
        tail = open(log).read()[-3000:] if os.path.isfile(log) else "(no controller log)"
        counts = {name: s.count for name, s in data.items()}
        raise NodeFailed(f"the bag holds no {' and no '.join(missing)} of the controller "
                         f"(messages per topic: {counts}); the end of {log}:\n{tail}")
    track = series["tracking_error"]
    t_est, est = series["parameter_estimates"]
    # the controller publishes its desired state (stamped with the state it answers), its
    # tracking error and its estimates once per step, in that order: with none lost, the
    # k-th of each belongs to the k-th stamp (the bag's receive times may bunch up when the
    # recorder runs behind, which a nearest-receive-time match gets wrong)
    desired = data.get(topics.resolve(topics.DESIRED_STATE))
    if desired is not None and desired.count:
        stamps = desired.stamp
        if len(track[0]) == desired.count:
            track = (stamps, track[1])
        if len(t_est) == desired.count:
            t_est = stamps
    return {"track": track, "effort": series["effort"],
            "estimates": (t_est, est[:, -1]), "payload_changes": changes,
            "watchdog_trips": watchdog_during_run(data)}


def watchdog_during_run(data):
    """The controller's safe efforts (tagged ``watchdog``) between its first and its last
    answer to a state: its start-up safe efforts (no state yet) and those after the
    simulator's end are not trips of the run."""
    from rcac_ros import topics
    from rcac_ros.tools.bags.analyse import effort_tags
    eff = data.get("/" + topics.EFFORT_COMMANDS)
    if eff is None or not eff.count:
        return None
    watchdog, _ = effort_tags(eff)
    answers = np.nonzero(~watchdog)[0]
    if answers.size == 0:
        return None
    return int(np.count_nonzero(watchdog[answers[0]:answers[-1]]))


def capture_hook(at, release, payload, log):
    """The :func:`~rcac_ros.tools.demos.demo.run_demo` hook that sets the payload at ``at`` s
    and releases it at ``release`` s of sim time; ``hook.futures`` gets each request.
    The hook returns what closes its node when the run ends.

    Its node reads ``/clock`` (keep-last 1) and sends the requests from a thread of its own:
    the recorder's executor may run behind the simulator (it takes every message of every
    topic), so the sim time it has seen would send them late. A request waits until the
    simulator's parameter service is matched (DDS matches each side on its own, and a request
    sent before would be lost). So that the run does not start before (discovery can take
    seconds on a loaded machine), the node subscribes to the joint states once the service is
    matched, and ``hook.subscribers`` (1) tells the demo to make the simulator wait for it."""
    import threading
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from rosgraph_msgs.msg import Clock as ClockMsg
    from sensor_msgs.msg import JointState
    from rcac_ros import topics
    from rcac_ros.core.payload import inertia_values
    capture = [Parameter("payload.com", value=[float(v) for v in payload.com]),
               Parameter("payload.inertia",
                         value=[float(v) for v in inertia_values(payload.inertia)]),
               Parameter("payload.mass", value=float(payload.mass))]
    plan = [(at, capture)] + ([(release, [Parameter("payload.mass", value=0.0)])]
                              if release is not None else [])
    futures = []
    done = threading.Event()

    def hook(ctx, executor):
        node = Node("rcac_capture_demo", context=ctx)
        own = SingleThreadedExecutor(context=ctx)
        own.add_node(node)
        client = AsyncParameterClient(node, topics.SIMULATOR_NODE)

        waiting = []

        def on_clock(msg):
            if gate and gate[-1] is not None:   # the run has started: the gate has served
                node.destroy_subscription(gate[-1])
                gate.append(None)
            sim_time = msg.clock.sec + 1e-9 * msg.clock.nanosec
            if not plan or sim_time < plan[0][0]:
                return
            if not client.services_are_ready():     # a request sent before the service
                if not waiting:                       # is matched is lost: send it once
                    waiting.append(sim_time)          # it is, late (the bag has the time)
                    log(f"rcac capture-demo: sim {sim_time:.3f} s: waiting for "
                        f"{topics.SIMULATOR_NODE}'s parameter service")
                return
            _, request = plan.pop(0)
            log(f"rcac capture-demo: sim {sim_time:.3f} s: setting "
                + ", ".join(f"{p.name}={p.value}" for p in request))
            futures.append(client.set_parameters(request))

        gate = []
        node.create_subscription(ClockMsg, topics.CLOCK, on_clock, topics.qos(depth=1))

        def spin():
            try:
                while not done.is_set():
                    own.spin_once(timeout_sec=0.05)
                    if not gate and client.services_are_ready():    # the run may start
                        gate.append(node.create_subscription(
                            JointState, topics.JOINT_STATES, lambda _: None,
                            topics.qos(depth=1, reliable=False), raw=True))
                    if not plan and all(f.done() for f in futures):
                        done.set()
            except Exception as exc:  # noqa: BLE001 - reported; the run's checks go on
                if ctx.ok() and not done.is_set():
                    log(f"rcac capture-demo: the payload requests stopped: "
                        f"{type(exc).__name__}: {exc}")

        thread = threading.Thread(target=spin, name="capture-requests", daemon=True)
        thread.start()

        def close():
            done.set()
            thread.join(timeout=1.0)
            own.shutdown()
            node.destroy_node()
        return close

    hook.futures = futures
    hook.subscribers = 1
    return hook


# ------------------------------------------------------------------ plots
def plot(path, runs, events, arm, loaded, title):
    """Tracking error norm, efforts over limits, last link's mass and first moments vs truth."""
    from rcac_ros.tools.plots import plt, save
    fig, axes = plt.subplots(1, 6, figsize=(30, 4.5))
    for label, r in runs.items():
        t, e = r["track"]
        axes[0].semilogy(t, norm_rows(e) + 1e-12, lw=0.8, label=label)
        te, tau = r["effort"]
        axes[1].plot(te, np.max(np.abs(tau) / arm.effort_limit, axis=1), lw=0.6, label=label)
        ts, th = r["estimates"]
        for k in range(4):
            axes[k + 2].plot(ts, th[:, k], lw=0.9, label=label)
    t_all = next(iter(runs.values()))["track"][0]
    held = np.zeros(len(t_all), dtype=bool)
    for kind, t_ev in events:
        held = np.where(t_all >= t_ev, kind == "capture", held)
    true = np.where(held[:, None], loaded.theta()[-1][:4], arm.theta()[-1][:4])
    names = ("mass m (kg)", "m c_x (kg m)", "m c_y (kg m)", "m c_z (kg m)")
    for k, name in enumerate(names):
        axes[k + 2].plot(t_all, true[:, k], "k--", lw=1.0, label="true")
        axes[k + 2].set_title(f"link {arm.n} {name}")
    axes[0].set_title("|q - q_d| (rad)")
    axes[1].set_title("max_j |tau_j| / limit_j")
    axes[1].axhline(1.0, color="r", lw=0.8)
    for ax in axes:
        for kind, t_ev in events:
            ax.axvline(t_ev, color="grey", lw=0.8, ls=":")
            ax.text(t_ev, 1.0, f" {kind}", transform=ax.get_xaxis_transform(), va="top",
                    fontsize=7, color="grey")
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title)
    save(fig, path, 110)
    return path


# ------------------------------------------------------------------ command line
def add_arguments(parser):
    from rcac_ros.tools.args import (finite_float, non_negative_float, output_dir,
                                     positive_float)
    parser.add_argument("--mass", type=positive_float, default=MASS,
                        help=f"payload mass, kg (default {MASS:g}, ten times the last link)")
    parser.add_argument("--at", type=positive_float, default=AT,
                        help=f"capture time, s of sim time, > 0: the reference RMS is taken "
                             f"over the {PRE_WINDOW:g} s before it (default {AT:g})")
    parser.add_argument("--duration", type=positive_float, default=DURATION,
                        help=f"simulated seconds (default {DURATION:g})")
    parser.add_argument("--release", type=non_negative_float, default=None,
                        help="release time (payload.mass 0), s (default: held to the end)")
    parser.add_argument("--com", type=finite_float, nargs=3, default=COM,
                        metavar=("X", "Y", "Z"),
                        help="payload centre of mass in the last link's frame, m (default "
                             f"{' '.join(f'{c:g}' for c in COM)})")
    parser.add_argument("--inertia", type=finite_float, nargs=6, default=None,
                        metavar=("IXX", "IYY", "IZZ", "IXY", "IXZ", "IYZ"),
                        help="payload inertia about its centre of mass, kg m^2 (default: a "
                             f"solid cube of side {SIDE:g} m, mass * {SIDE:g}^2 / 6 per axis)")
    parser.add_argument("--out", type=output_dir, default="results/capture_demo",
                        help="output directory")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap",
                        help="rosbag2 storage plugin (default: mcap)")
    parser.add_argument("--no-ros", action="store_true",
                        help="the offline runs only (no nodes, no bag)")
    parser.add_argument("--bag", default=None,
                        help="read the ROS run from this bag of an earlier capture-demo (the "
                             "same options) instead of running the nodes")
    parser.add_argument("--slow", action="store_true",
                        help="run the paper's motion slower, as for the mass table: the desired "
                             "motion's torques with the payload within half the limits")
    parser.add_argument("--mass-table", action="store_true",
                        help="also the offline table over 0.1 t to 20 t, motion slowed per mass")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")


def check_arguments(args):
    """One-line errors on the arguments, before anything heavy is imported; then
    :func:`truth` of the checked payload."""
    from rcac_ros.errors import ConfigError
    if args.at >= args.duration:
        raise ConfigError(f"--at: the capture must come before the end of the run "
                          f"(--duration {args.duration:g} s), got {args.at:g} s")
    if args.release is not None and not args.at < args.release < args.duration:
        raise ConfigError(f"--release: must be after --at ({args.at:g} s) and before the end "
                          f"({args.duration:g} s), got {args.release:g} s")
    if args.bag is not None and not os.path.isdir(args.bag):
        raise ConfigError(f"--bag: no such directory {args.bag!r}")
    if args.bag is not None and args.no_ros:
        raise ConfigError("--bag: reads a ROS run; --no-ros asks for none")
    inertia = args.inertia if args.inertia is not None else cube_inertia(args.mass)
    try:                                # numpy only, no kernels
        return truth(args.mass, args.com, inertia)
    except ConfigError as exc:          # named as the command line names it
        raise ConfigError(str(exc).replace("payload.", "--")) from None


def run(args):
    arm, loaded, payload = check_arguments(args)
    log = (lambda text: None) if args.quiet else (lambda text: print(text, flush=True))
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    at, release = args.at, args.release
    report = {"settings": {"model": "css_arm (preset, effort limits "
                           f"{arm.effort_limit.tolist()} N m, zero gravity)",
                           "payload": payload.as_dict(), "at_s": at, "release_s": release,
                           "duration_s": args.duration, "pre_window_s": PRE_WINDOW,
                           "recovery_window_s": WINDOW, "recovery_factor": FACTOR,
                           "goal_recovery_s": GOAL_RECOVERY, "goal_mass_relative": GOAL_MASS,
                           "effort_share_of_slowdown": EFFORT_SHARE}}
    scale, need = slowdown(loaded) if args.slow else (1.0, None)
    report["settings"].update(slowdown=scale, desired_effort_over_limit_unslowed=need)
    slowed = {}
    if args.slow:
        from rcac_ros.core import PAPER_Q0, PaperTrajectory
        base = PaperTrajectory(np.array(PAPER_Q0))
        slowed = {"paper.amplitude": base.amplitude / scale, "paper.period": 20.0 * scale}
        log(f"rcac capture-demo: the paper's motion {scale:.3f} times slower (amplitude "
            f"{slowed['paper.amplitude']:.6g} rad/s, period {slowed['paper.period']:.6g} s)")
    events = [("capture", at)] + ([("release", release)] if release is not None else [])
    plots, tables = [], []
    if not args.no_ros:
        from rcac_ros.tools.demos.demo import run_demo
        from rcac_ros.tools.launch import NodeFailed
        hook = capture_hook(at, release, payload, log)
        try:
            bag = args.bag or run_demo(args.duration, out, args.storage, log=log, hook=hook,
                                       prog="rcac capture-demo",
                                       controller_overrides=slowed)
        except KeyboardInterrupt:
            print("rcac capture-demo: interrupted; both nodes stopped", file=sys.stderr)
            return 130
        except NodeFailed as err:
            print(f"rcac capture-demo: error: {err}", file=sys.stderr)
            return 1
        for f in hook.futures:
            for r in f.result().results if f.done() else ():
                if not r.successful:
                    print(f"rcac capture-demo: error: the simulator refused the payload: "
                          f"{r.reason}", file=sys.stderr)
                    return 1
        try:
            ros = read_run(bag, arm)
        except NodeFailed as err:
            print(f"rcac capture-demo: error: {err}", file=sys.stderr)
            return 1
        changes = ros["payload_changes"]
        held = [c["t"] for c in changes if c["mass"] > 0.0]
        freed = [c["t"] for c in changes if c["mass"] == 0.0 and held and c["t"] > held[0]]
        if not held or (release is not None and not freed):
            print("rcac capture-demo: error: the bag holds no payload change at the times "
                  f"asked ({changes})", file=sys.stderr)
            return 1
        at = held[0]
        release = freed[0] if release is not None else None
        events = [("capture", at)] + ([("release", release)] if release is not None else [])
        report["ros"] = all_figures(ros["track"], ros["effort"], ros["estimates"], at, release,
                                    args.duration, arm, loaded, ros["watchdog_trips"])
        report["ros"]["payload_changes"] = changes
        report["ros"]["watchdog_efforts_during_run"] = ros["watchdog_trips"]
        report["ros"]["bag"] = bag
        plots.append(plot(os.path.join(out, "capture_ros.png"), {"ROS 2 (composite)": ros},
                          events, arm, loaded,
                          f"rcac capture-demo over ROS 2: {args.mass:g} kg grasped at "
                          f"t = {at:.3f} s"))
        log(f"rcac capture-demo: payload held from t = {at:.3f} s (the bag's "
            "/rcac_simulator/payload)" + (f", released at {release:.3f} s" if release else ""))
    offline, series = offline_laws(arm, loaded, at, release, args.duration, scale,
                                   not args.quiet)
    report["offline"] = offline
    plots.append(plot(os.path.join(out, "capture_laws.png"), series, events, arm, loaded,
                      f"the same capture offline: {args.mass:g} kg at t = {at:.3f} s"))
    columns = dict({"ROS 2 (composite)": report["ros"]} if "ros" in report else {}, **offline)
    for name, _, _ in phases(at, release, args.duration):
        tables.append(table(columns, name))
    if args.mass_table:
        rows = mass_table(args.com, (cube_inertia if args.inertia is None
                                     else (lambda m: args.inertia)), args.at, args.duration,
                          progress=not args.quiet)
        report["mass_table"] = rows
        tables.append(mass_markdown(rows))
    path = os.path.join(out, JSON_NAME)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(report, f, indent=2)
    with open(os.path.join(out, "capture.md"), "w", encoding="utf-8") as f:
        f.write("\n".join(tables))
    print("\n".join(tables))
    if "ros" in report:
        run_effort = report["ros"]["run_effort"]
        if run_effort["limit_first_reached_s"] is not None:
            print(f"rcac capture-demo: the controller's effort reached the preset's limit on "
                  f"joint {run_effort['limit_first_reached_joint']} at t = "
                  f"{run_effort['limit_first_reached_s']:.3f} s ({run_effort['steps_at_limit']} "
                  "steps at a limit): the simulator clips it there")
    print("Wrote:")
    print(f"  figures  {path}, {os.path.join(out, 'capture.md')}")
    for p in plots:
        print(f"  figure   {p}")
    return 0
