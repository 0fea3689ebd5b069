"""``rcac bench startup``: how long the package takes to start, with and without its cache.

Each figure is one fresh process, timed from its start (wall clock), with a numba cache
directory of its own (``NUMBA_CACHE_DIR``): *cold* is an empty one (a fresh install before
``python -m rcac_ros.tools.warm``), *warm* one that the cold run filled.

- ``import``: ``python -c "import rcac_ros.core"``;
- ``bad argument``: ``rcac experiment --duration -5`` (refused before anything compiles);
- ``controller``: the controller node with ``config/controller.yaml``, fed joint states by
  this process: when its ``~/get_state`` first answers (and what its diagnostics say then),
  and its first message on ``effort_controller/commands``; for the default law and, with
  ``--laws``, others (``channels: ["all"]``: the general kernel);
- ``warm-up``: ``python -m rcac_ros.tools.warm`` on an empty cache (wall, and CPU of its
  processes).
"""

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time

from rcac_ros import topics

#: law -> the controller's parameter overrides
LAWS = {"default": {}, "all": {"channels": ["all"]}, "joint_friction": {"joint_friction": True}}


def _env(cache):
    return dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONUNBUFFERED="1")


def time_command(cmd, cache):
    """Wall seconds, exit code and CPU seconds (children) of ``cmd`` with the cache ``cache``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    out = subprocess.run(cmd, env=_env(cache), capture_output=True, text=True, timeout=1800)
    wall = time.monotonic() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return {"seconds": round(wall, 3), "cpu_seconds": round(cpu, 2), "exit_code": out.returncode,
            "stderr_last": (out.stderr.strip().splitlines() or [""])[-1]}


def controller_start(cache, overrides, timeout=300.0):
    """Start the controller (cache ``cache``) and time its first answer and first effort."""
    import domain_coordinator
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from lifecycle_msgs.srv import GetState
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from rcac_ros.core.model import PAPER_Q0
    from rcac_ros.tools.launch import Child, child_env, init_context, node_command

    result = {"first_answer_s": None, "state_then": None, "diagnostics_then": None,
              "first_effort_s": None}
    with domain_coordinator.domain_id() as domain:
        ctx = init_context(domain)
        node = rclpy.create_node("rcac_bench_startup", context=ctx)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        seen = threading.Event()
        diag = []
        node.create_subscription(Float64MultiArray, "/" + topics.EFFORT_COMMANDS,
                                 lambda m: seen.set(), 10)
        node.create_subscription(
            DiagnosticArray, topics.DIAGNOSTICS,
            lambda m: diag.extend(s.message for s in m.status
                                  if s.name.endswith("control loop")), 10)
        pub = node.create_publisher(JointState, "/" + topics.JOINT_STATES, 10)
        client = node.create_client(GetState, f"/{topics.CONTROLLER_NODE}/get_state")
        env = dict(child_env(domain), NUMBA_CACHE_DIR=cache)
        log = os.path.join(tempfile.gettempdir(), f"rcac_bench_startup_{os.getpid()}.log")
        t0 = time.monotonic()
        child = Child("controller", node_command("controller", overrides=overrides), env, log)
        future = None
        try:
            while time.monotonic() - t0 < timeout and child.alive():
                executor.spin_once(timeout_sec=0.02)
                now = time.monotonic() - t0
                if result["first_answer_s"] is None:
                    if future is None and client.service_is_ready():
                        future = client.call_async(GetState.Request())
                    if future is not None and future.done():
                        result["first_answer_s"] = round(now, 3)
                        result["state_then"] = future.result().current_state.label
                if result["diagnostics_then"] is None and diag:
                    result["diagnostics_then"] = diag[0]
                msg = JointState()
                msg.header.stamp = node.get_clock().now().to_msg()
                msg.name = [f"joint{i + 1}" for i in range(len(PAPER_Q0))]
                msg.position = list(PAPER_Q0)
                msg.velocity = [0.0] * len(PAPER_Q0)
                pub.publish(msg)
                if seen.is_set():
                    result["first_effort_s"] = round(now, 3)
                    break
        finally:
            result["exit_code"] = child.stop()
            executor.shutdown()
            node.destroy_node()
            ctx.try_shutdown()
        if result["first_effort_s"] is None:
            result["log_tail"] = child.tail()
    return result


def run_startup_bench(laws=("default",), json_path=None, log=print):
    """Every figure of the module docstring; printed as a table, and as JSON to ``json_path``."""
    root = tempfile.mkdtemp(prefix="rcac_bench_startup_")
    py = sys.executable
    rows = {}

    def row(name, cold, warm=None, expect=0):
        rows[name] = {"cold": cold, "warm": warm}

        def fmt(r):
            if r is None:
                return "-"
            bad = "" if r["exit_code"] == expect else f" (exit {r['exit_code']})"
            return f"{r['seconds']:.2f} s{bad}"
        log(f"{name:<44} cold {fmt(cold):>12}   warm {fmt(warm):>12}")

    try:
        for law in laws:
            cache = os.path.join(root, f"cache_{law}")
            os.makedirs(cache)
            cold = controller_start(cache, LAWS[law])
            warm = controller_start(cache, LAWS[law])
            rows[f"controller_{law}"] = {"cold": cold, "warm": warm}
            log(f"controller ({law}): first answer {cold['first_answer_s']} s "
                f"({cold['state_then']}; {cold['diagnostics_then']}), first effort cold "
                f"{cold['first_effort_s']} s, warm {warm['first_effort_s']} s")
            for run in (cold, warm):
                if run["first_effort_s"] is None:
                    log(f"controller ({law}): no effort; its log ends:\n{run['log_tail']}")
        cache = os.path.join(root, "cache_import")
        os.makedirs(cache)
        imp = [py, "-c", "import rcac_ros.core"]
        row("import rcac_ros.core", time_command(imp, cache), time_command(imp, cache))
        imp = [py, "-c", "from rcac_ros.core import RecursiveCompositeController"]
        row("import the recursive law (compiles nothing)", time_command(imp, cache),
            time_command(imp, cache))
        bad = [py, "-m", "rcac_ros.tools.cli", "experiment", "--duration", "-5"]
        row("bad argument (rcac experiment --duration -5)", time_command(bad, cache), expect=2)
        cache = os.path.join(root, "cache_warm")
        os.makedirs(cache)
        row("warm-up (python -m rcac_ros.tools.warm)",
            time_command([py, "-m", "rcac_ros.tools.warm"], cache))
    finally:
        shutil.rmtree(root, ignore_errors=True)
    report = {"benchmark": "startup", "cpus": os.cpu_count(), "load_average": os.getloadavg(),
              "results": rows}
    if json_path:
        with open(json_path, "w") as f:
            json.dump(report, f, indent=1)
    return report


def failures(report):
    """What went wrong in a :func:`run_startup_bench` report, one line each (none: [])."""
    out = []
    for name, r in report["results"].items():
        if name.startswith("controller_"):
            out += [f"{name} ({which}): no effort" for which in ("cold", "warm")
                    if r[which]["first_effort_s"] is None]
        else:
            expect = 2 if name.startswith("bad argument") else 0
            out += [f"{name} ({which}): exit {r[which]['exit_code']}, expected {expect}"
                    for which in ("cold", "warm")
                    if r[which] is not None and r[which]["exit_code"] != expect]
    return out
