"""``rcac demo``: the paper's experiment over ROS 2, two processes, one bag.

The simulator and the controller run as two processes talking over real DDS, in
lockstep (the simulator steps once per effort command, so the run is
deterministic and not paced by the wall clock). An in-process recorder writes
every topic into a rosbag2 bag; at the end the bag is summarised, the metrics of
``rcac experiment`` are computed from it and the figures are written.

The children get an isolated ``ROS_DOMAIN_ID`` (domain_coordinator) and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``; they are always stopped, even on
Ctrl-C or when one of them fails.
"""

import os
import re
import shutil
import signal
import sys
import time

from rcac_ros import topics
from rcac_ros.errors import ConfigError
from rcac_ros.tools.args import output_dir, positive_float
from rcac_ros.tools.launch import Child, child_env, init_context, node_command, NodeFailed, \
    StopFlag, wait_until_active
from rcac_ros.tools.bags.record import BagRecorder, format_counts

#: the run's end: after the last state and its answer, the recorder takes what is still in
#: flight until nothing has come for this long (s)
QUIET = 0.1
#: s at most for each of the two drains (the last state and its answer; the rest): a recorder
#: behind on a loaded machine takes its backlog, one message per executor call
DRAIN = 10.0


def _prepare_out(out):
    """Create ``out``; remove a bag a previous demo left in ``out/bag``."""
    os.makedirs(out, exist_ok=True)
    bag = os.path.join(out, "bag")
    if os.path.exists(bag):
        leftovers = set(os.listdir(bag)) - {"metadata.yaml"}
        kinds = (".mcap", ".db3", ".db3-wal", ".db3-shm", ".db3-journal", "metadata.yaml.tmp")
        if not all(f.endswith(kinds) for f in leftovers):
            raise ConfigError(f"out: {bag} exists and does not look like a bag; move it away")
        shutil.rmtree(bag)
    os.makedirs(os.path.join(out, "logs"), exist_ok=True)
    return bag


def demo_overrides(duration, dt):
    """Parameter overrides of the two nodes for the lockstep experiment."""
    # state_timeout: the controller's watchdog is for a real arm; in lockstep a 20 ms one
    # floods the effort topic while a descheduled simulator is not reading, and its
    # keep-last queue can then lose the real answer (a lockstep miss).
    controller = {"mode": "lockstep", "rate": 1.0 / dt, "state_timeout": 1.0}
    # min_subscribers 2: the simulator starts once the controller and our recorder both
    # subscribe to joint_states, so the bag holds the run from state 0; at most real time,
    # so that the recorder (nine topics at 1/dt each) keeps up and the bag holds every step;
    # lockstep_timeout 5 s: the run is the discrete loop of `rcac experiment`, so a controller
    # descheduled on a loaded machine (or discovering the simulator late, the first state
    # re-sent meanwhile) is waited for rather than its effort held (a lockstep miss)
    simulator = {"mode": "lockstep", "dt": float(dt), "duration": float(duration),
                 "min_subscribers": 2, "lockstep_max_speed": 1.0, "lockstep_timeout": 5.0}
    return controller, simulator


def warm_kernels(log, prog="rcac demo"):
    """Load (on the first run: compile) the numba kernels, once, before the nodes start.

    They are cached in the user's cache directory (:mod:`rcac_ros.core._jit`), so the nodes
    started next load them in a second; without this both nodes would compile at the same
    time at their start, longer than the wait for their topics. Compiles in two processes at
    a time (:mod:`rcac_ros.tools.warm`) and says how long it took."""
    from rcac_ros.tools.warm import warm
    log(f"{prog}: loading the kernels (the first run compiles them once: under a minute on "
        "2 cores)")
    t0 = time.monotonic()
    warm(log=lambda text: log(f"{prog}: {text}") if " failed " in text else None)
    log(f"{prog}: kernels ready in {time.monotonic() - t0:.0f} s")


def run_demo(duration=20.0, out="rcac_demo", storage="mcap", dt=0.002, progress=2.0,
             start_timeout=120.0, stall_timeout=30.0, log=None, controller_overrides=None,
             simulator_overrides=None, hook=None, prog="rcac demo"):
    """Run the two nodes in lockstep, record, stop everything; return the bag path.

    ``controller_overrides`` and ``simulator_overrides`` (name -> value) add to the
    lockstep parameters of :func:`demo_overrides` (e.g. the plant's model and engine);
    ``hook``: ``hook(context, executor)`` once the recorder runs (what ``rcac capture-demo``
    changes at run time), returning None or a callable that closes what it made, called when
    the run ends, before the context shuts down; a hook with ``subscribers`` (int) subscribes
    that many times to the joint states when it is ready, and the simulator waits for them;
    ``prog`` prefixes the log lines.

    Raises
    ------
    NodeFailed
        If a node exits early, discovery times out, or the simulated time stalls.
    """
    import domain_coordinator
    from rclpy.executors import SingleThreadedExecutor

    log = log or (lambda text: print(text, flush=True))

    if not duration > 0.0:
        raise ConfigError(f"duration: must be > 0 s, got {duration}")
    bag = _prepare_out(out)
    warm_kernels(log, prog)
    logs = os.path.join(out, "logs")
    ctrl_over, sim_over = demo_overrides(duration, dt)
    ctrl_over.update(controller_overrides or {})
    sim_over.update(simulator_overrides or {})
    sim_over["min_subscribers"] += getattr(hook, "subscribers", 0)
    close_hook = None
    stop = StopFlag()
    children = []
    recorder = None
    ctx = None
    executor = None
    saved_range = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"   # for our own context
    with domain_coordinator.domain_id() as domain:
        env = child_env(domain)
        try:
            ctx = init_context(domain)
            executor = SingleThreadedExecutor(context=ctx)
            recorder = BagRecorder(bag, ctx, storage=storage, log=log)
            executor.add_node(recorder.node)
            if hook is not None:
                close_hook = hook(ctx, executor)
            log(f"{prog}: ROS_DOMAIN_ID={domain}, {duration:g} s of simulated time in "
                f"lockstep (dt {dt * 1e3:g} ms); bag {bag}")

            def all_alive():
                return not stop and all(c.alive() for c in children)

            def check(what):
                for c in children:
                    if not c.alive() and not (c.name == "simulator" and c.returncode == 0):
                        raise NodeFailed(f"the {c.name} exited with code {c.returncode} "
                                         f"{what}; last lines of {c.log_path}:\n{c.tail()}")
                if stop:
                    raise KeyboardInterrupt

            joint_terms = topics.resolve(topics.FRICTION_ESTIMATES)   # joint_friction only
            ctrl_topics = [n for n, _ in recorder.topics
                           if n.startswith(f"/{topics.CONTROLLER_NODE}/")
                           and (n != joint_terms or ctrl_over.get("joint_friction"))]
            ctrl_topics.append("/" + topics.EFFORT_COMMANDS)
            ctrl_cmd = node_command("controller", overrides=ctrl_over)
            children.append(Child("controller", ctrl_cmd, env,
                                  os.path.join(logs, "controller.log")))
            if not recorder.wait_for_publishers(executor, ctrl_topics, start_timeout, all_alive):
                check("while starting")
                raise NodeFailed(f"the controller's topics were not discovered within "
                                 f"{start_timeout:g} s (see {children[0].log_path})")
            if not wait_until_active(recorder.node, executor, topics.CONTROLLER_NODE,
                                     start_timeout, all_alive):
                check("while starting")
                raise NodeFailed(f"the controller did not become active within "
                                 f"{start_timeout:g} s (see {children[0].log_path})")
            children.append(Child("simulator", node_command("simulator", overrides=sim_over),
                                  env, os.path.join(logs, "simulator.log")))
            sim_topics = ["/" + topics.JOINT_STATES, topics.CLOCK]
            if not recorder.wait_for_publishers(executor, sim_topics, start_timeout, all_alive):
                check("while starting")
                raise NodeFailed(f"the simulator's topics were not discovered within "
                                 f"{start_timeout:g} s (see {children[1].log_path})")
            t_start = time.monotonic()
            last_total, last_change = None, t_start
            next_report = t_start + progress
            sim_child = children[1]
            while sim_child.alive():   # the simulator exits 0 after `duration` of sim time
                executor.spin_once(timeout_sec=0.02)
                now = time.monotonic()
                if stop:
                    raise KeyboardInterrupt
                check("before the end of the run")
                if recorder.total != last_total:
                    last_total, last_change = recorder.total, now
                elif now - last_change > stall_timeout:
                    raise NodeFailed(f"nothing published for {stall_timeout:g} s (sim time "
                                     f"{recorder.sim_time} s); see the logs in {logs}")
                if now >= next_report:
                    sim = 0.0 if recorder.sim_time is None else recorder.sim_time
                    log(f"  sim {sim:6.2f} / {duration:g} s   wall {now - t_start:6.1f} s   "
                        f"{recorder.total} messages")
                    next_report = now + progress
            check("before the end of the run")
            wall = time.monotonic() - t_start
            # drain what is still in flight: the last states (the simulator publishes states
            # 0..steps) and the controller's answers to them
            states = topics.resolve(topics.JOINT_STATES)
            answers = topics.resolve(topics.DESIRED_STATE)
            last_state = int(round(duration / dt)) * int(round(dt * 1e9))
            drain_end = time.monotonic() + DRAIN
            while time.monotonic() < drain_end and not stop \
                    and (recorder.last_state_stamp != last_state
                         or recorder.counts[answers] < recorder.counts[states]):
                executor.spin_once(timeout_sec=0.02)
            # then every other topic's last messages: the executor takes one message per
            # call, so the answers' topic can be complete before the others are; until
            # nothing has come for QUIET s
            last_total, quiet_end = recorder.total, time.monotonic() + QUIET
            while time.monotonic() < min(quiet_end, drain_end + DRAIN) and not stop:
                executor.spin_once(timeout_sec=0.01)
                if recorder.total != last_total:
                    last_total, quiet_end = recorder.total, time.monotonic() + QUIET
            sim = recorder.sim_time or 0.0
            log(f"{prog}: {sim:.3f} s simulated in {wall:.1f} s wall "
                f"({sim / max(wall, 1e-9):.2f}x real time)")
        finally:
            codes = {}
            for c in reversed(children):  # the simulator first: no new states
                codes[c.name] = c.stop()
            if close_hook is not None:
                close_hook()
            if recorder is not None:
                recorder.close()
            if executor is not None:
                executor.shutdown()
            if ctx is not None:
                ctx.try_shutdown()
            stop.restore()
            if saved_range is None:
                os.environ.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)
            else:
                os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = saved_range
    misses = re.search(r"lockstep misses (\d+)", children[1].tail(5)) if len(children) > 1 \
        else None
    if misses and int(misses.group(1)):
        log(f"{prog}: warning: the simulator held an effort {misses.group(1)} times (no "
            "answer within lockstep_timeout: the machine is overloaded); the run is no longer "
            "the exact discrete loop of rcac experiment")
    log(f"{prog}: recorded {recorder.total} messages")
    log(format_counts(recorder))
    for name, code in codes.items():
        if code not in (0, -signal.SIGINT, 130):
            log(f"{prog}: warning: the {name} exited with code {code} when stopped "
                f"(log {os.path.join(logs, name + '.log')})")
    return bag


def add_arguments(parser):
    parser.add_argument("--duration", type=positive_float, default=20.0,
                        help="simulated seconds (default: 20, the paper's experiment)")
    parser.add_argument("--out", "-o", type=output_dir, default="rcac_demo",
                        help="output directory: bag/, logs/, figures, metrics.json "
                             "(default: ./rcac_demo)")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap",
                        help="rosbag2 storage plugin (default: mcap)")


def run(args):
    out = os.path.abspath(args.out)
    try:
        bag = run_demo(args.duration, out, args.storage)
    except KeyboardInterrupt:
        print(f"rcac demo: interrupted; both nodes stopped; the bag is closed in "
              f"{os.path.join(out, 'bag')} (rcac inspect reads it)", file=sys.stderr)
        return 130
    except NodeFailed as err:
        print(f"rcac demo: error: {err}", file=sys.stderr)
        return 1
    # imported here, not first: reading a bag needs neither on a bad argument
    from rcac_ros.tools.bags.inspect import format_metrics, inspect
    from rcac_ros.tools.bags.read import format_summary
    result = inspect(bag, plots_dir=out)
    print(format_summary(bag, result["summary"]))
    start = result["metrics"].get("sim_time_start_s")
    if start:
        print(f"rcac demo: note: the recorder matched the simulator's topics late (DDS "
              f"discovery on a loaded machine): joint_states and /clock start at t = "
              f"{start:.3f} s; the controller's topics, and the metrics, cover the whole run")
    print("Metrics (as rcac experiment):")
    print(format_metrics(result["metrics"]))
    watchdog = result["metrics"].get("watchdog_efforts")
    if watchdog:
        print(f"rcac demo: note: watchdog_efforts {watchdog}: the controller's safe effort while "
              "it had no valid state (before the simulator's first state, or in a silence), "
              "tagged: the simulator ignores them and the metrics leave them out")
    for line in result["notes"]:
        print(f"rcac demo: note: {line}")
    print("Wrote:")
    print(f"  bag      {bag}")
    print(f"  metrics  {result['metrics_path']}")
    for path in result["plots"]:
        print(f"  figure   {path}")
    print(f"  logs     {os.path.join(out, 'logs')}")
    return 0
