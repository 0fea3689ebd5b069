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
import subprocess
import sys
import time

from rcac_ros import topics
from rcac_ros.tools.record import BagRecorder, format_counts, init_context, StopFlag
from rcac_ros.errors import ConfigError, RcacError

#: node -> (executable, module, params file)
NODES = {
    "controller": ("controller", "rcac_ros.nodes.controller_node", "controller.yaml"),
    "simulator": ("simulator", "rcac_ros.nodes.simulator_node", "simulator.yaml"),
}


class NodeFailed(RcacError):
    """A child node exited early, or the run made no progress."""


def config_file(name):
    """Path of a shipped config file: the installed share directory, else the source tree."""
    candidates = []
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(os.path.join(get_package_share_directory("rcac_ros"), "config", name))
    except Exception:  # noqa: BLE001 - not installed with colcon: use the source tree
        pass
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))     # rcac_ros/
    candidates.append(os.path.join(os.path.dirname(package), "config", name))  # source tree
    candidates.append(os.path.join(sys.prefix, "share", "rcac_ros", "config", name))  # pip
    for path in candidates:
        if os.path.isfile(path):
            return path
    raise ConfigError(f"config: cannot find {name} (looked in {', '.join(candidates)})")


def node_command(node, params=None, overrides=None):
    """Command line of a node: the installed executable, else ``python -m``.

    Parameters
    ----------
    node : {"controller", "simulator"}
    params : str, optional
        Parameters file; default the shipped ``config/<node>.yaml``.
    overrides : dict, optional
        ``-p name:=value`` overrides.

    Returns
    -------
    list of str
    """
    exe, module, yaml_name = NODES[node]
    cmd = None
    candidates = [os.path.join(os.path.dirname(sys.executable), exe)]
    try:
        from ament_index_python.packages import get_package_prefix
        candidates.insert(0, os.path.join(get_package_prefix("rcac_ros"), "lib", "rcac_ros",
                                          exe))
    except Exception:  # noqa: BLE001 - not in an ament index
        pass
    for path in candidates:
        if os.path.isfile(path) and os.access(path, os.X_OK):
            cmd = [path]
            break
    if cmd is None:
        cmd = [sys.executable, "-m", module]
    cmd += ["--ros-args", "--params-file", params or config_file(yaml_name)]
    for key, value in (overrides or {}).items():
        cmd += ["-p", f"{key}:={_param_text(value)}"]
    return cmd


def _param_text(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_param_text(v) for v in value) + "]"
    return str(value)


class Child:
    """A node process in its own session, its output in a log file."""

    def __init__(self, name, cmd, env, log_path):
        self.name = name
        self.cmd = cmd
        self.log_path = log_path
        self._log = open(log_path, "w")
        self._log.write("$ " + " ".join(cmd) + "\n")
        self._log.flush()
        self.proc = subprocess.Popen(cmd, env=env, stdout=self._log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True)

    def alive(self):
        return self.proc.poll() is None

    @property
    def returncode(self):
        return self.proc.poll()

    def stop(self, timeout=5.0):
        """SIGINT, then SIGTERM, then SIGKILL; returns the exit code."""
        for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 3.0),
                          (signal.SIGKILL, 3.0)):
            if self.proc.poll() is not None:
                break
            try:
                os.killpg(self.proc.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.proc.wait(wait)
            except subprocess.TimeoutExpired:
                continue
        code = self.proc.poll()
        self._log.close()
        return code

    def tail(self, lines=15):
        try:
            with open(self.log_path) as f:
                return "".join(f.readlines()[-lines:])
        except OSError:
            return ""


def child_env(domain_id):
    env = os.environ.copy()
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _prepare_out(out):
    """Create ``out``; remove a bag a previous demo left in ``out/bag``."""
    os.makedirs(out, exist_ok=True)
    bag = os.path.join(out, "bag")
    if os.path.exists(bag):
        leftovers = set(os.listdir(bag)) - {"metadata.yaml"}
        if not all(f.endswith((".mcap", ".db3", ".db3-wal", ".db3-shm")) for f in leftovers):
            raise ConfigError(f"out: {bag} exists and does not look like a bag; move it away")
        shutil.rmtree(bag)
    os.makedirs(os.path.join(out, "logs"), exist_ok=True)
    return bag


def demo_overrides(duration, dt):
    """Parameter overrides of the two nodes for the lockstep experiment."""
    # state_timeout: the controller's watchdog is for a real arm; in lockstep a 20 ms one
    # floods the effort topic while a descheduled simulator is not reading, and its
    # keep-last queue can then lose the real answer (a lockstep miss).
    controller = {"mode": "lockstep", "rate": 1.0 / dt, "state_timeout": 2.0}
    # min_subscribers 2: the simulator starts once the controller and our recorder both
    # subscribe to joint_states, so the bag holds the run from state 0
    simulator = {"mode": "lockstep", "dt": float(dt), "duration": float(duration),
                 "min_subscribers": 2}
    return controller, simulator


def run_demo(duration=20.0, out="rcac_demo", storage="mcap", dt=0.002, progress=2.0,
             start_timeout=60.0, stall_timeout=30.0, log=None):
    """Run the two nodes in lockstep, record, stop everything; return the bag path.

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
    logs = os.path.join(out, "logs")
    ctrl_over, sim_over = demo_overrides(duration, dt)
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
            recorder = BagRecorder(bag, ctx, storage=storage)
            executor.add_node(recorder.node)
            log(f"rcac demo: ROS_DOMAIN_ID={domain}, {duration:g} s of simulated time in "
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

            ctrl_topics = [n for n, _ in recorder.topics
                           if n.startswith(f"/{topics.CONTROLLER_NODE}/")]
            ctrl_topics.append("/" + topics.EFFORT_COMMANDS)
            ctrl_cmd = node_command("controller", overrides=ctrl_over)
            children.append(Child("controller", ctrl_cmd, env,
                                  os.path.join(logs, "controller.log")))
            if not recorder.wait_for_publishers(executor, ctrl_topics, start_timeout, all_alive):
                check("while starting")
                raise NodeFailed(f"the controller's topics were not discovered within "
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
            # drain what is still in flight: the controller's answer to the last state
            states = "/" + topics.JOINT_STATES
            answers = f"/{topics.CONTROLLER_NODE}/{topics.DESIRED_STATE[2:]}"
            drain_end = time.monotonic() + 2.0
            while time.monotonic() < drain_end and not stop \
                    and recorder.counts[answers] < recorder.counts[states]:
                executor.spin_once(timeout_sec=0.02)
            sim = recorder.sim_time or 0.0
            log(f"rcac demo: {sim:.3f} s simulated in {wall:.1f} s wall "
                f"({sim / max(wall, 1e-9):.2f}x real time)")
        finally:
            codes = {}
            for c in reversed(children):  # the simulator first: no new states
                codes[c.name] = c.stop()
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
        log(f"rcac demo: warning: the simulator held an effort {misses.group(1)} times (no "
            "answer within lockstep_timeout: the machine is overloaded); the run is no longer "
            "the exact discrete loop of rcac experiment")
    log(f"rcac demo: recorded {recorder.total} messages")
    log(format_counts(recorder))
    for name, code in codes.items():
        if code not in (0, -signal.SIGINT, 130):
            log(f"rcac demo: warning: the {name} exited with code {code} when stopped "
                f"(log {os.path.join(logs, name + '.log')})")
    return bag


def add_arguments(parser):
    parser.add_argument("--duration", type=float, default=20.0,
                        help="simulated seconds (default: 20, the paper's experiment)")
    parser.add_argument("--out", "-o", default="rcac_demo",
                        help="output directory: bag/, logs/, figures, metrics.json "
                             "(default: ./rcac_demo)")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap",
                        help="rosbag2 storage plugin (default: mcap)")


def run(args):
    from rcac_ros.tools.inspect_bag import format_metrics, format_summary, inspect

    out = os.path.abspath(args.out)
    try:
        bag = run_demo(args.duration, out, args.storage)
    except KeyboardInterrupt:
        print(f"rcac demo: interrupted; both nodes stopped; the partial bag is in "
              f"{os.path.join(out, 'bag')} (rcac inspect reads it)", file=sys.stderr)
        return 130
    except NodeFailed as err:
        print(f"rcac demo: error: {err}", file=sys.stderr)
        return 1
    result = inspect(bag, plots_dir=out)
    print(format_summary(bag, result["summary"]))
    start = result["metrics"].get("sim_time_start_s")
    if start:
        print(f"rcac demo: note: the recorder matched the simulator's topics late (DDS "
              f"discovery on a loaded machine): joint_states and /clock start at t = "
              f"{start:.3f} s; the controller's topics, and the metrics, cover the whole run")
    print("Metrics (as rcac experiment):")
    print(format_metrics(result["metrics"]))
    print("Wrote:")
    print(f"  bag      {bag}")
    print(f"  metrics  {result['metrics_path']}")
    for path in result["plots"]:
        print(f"  figure   {path}")
    print(f"  logs     {os.path.join(out, 'logs')}")
    return 0
