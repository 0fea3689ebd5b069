"""Shared helpers for the node tests (no tests here): isolated ROS contexts, probes, waits."""

import contextlib
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time as TimeMsg  # noqa: E402
from rcl_interfaces.msg import Log  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

PAPER_Q0 = np.array([0.3, math.pi / 2, math.pi / 3, -2 * math.pi / 3, math.pi / 3,
                     math.pi / 2, 0.3])
JOINTS = [f"joint{i}" for i in range(1, 8)]
NS = 1_000_000_000
H_NS = 2_000_000
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, "config")
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                 reliability=ReliabilityPolicy.RELIABLE)
#: the test side keeps more, so that a slow test process loses nothing
DEEP = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5000,
                  reliability=ReliabilityPolicy.RELIABLE)
#: /rosout keeps its history (transient local): a late-matched reader still gets every line
ROSOUT = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                    reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.TRANSIENT_LOCAL)


@contextlib.contextmanager
def ros_domain():
    """Set a unique ROS_DOMAIN_ID and localhost-only discovery for the block (and children)."""
    dc = pytest.importorskip("domain_coordinator")
    saved = {k: os.environ.get(k) for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")}
    with dc.domain_id() as did:
        os.environ["ROS_DOMAIN_ID"] = str(did)
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        try:
            yield did
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v


@contextlib.contextmanager
def ros_context():
    """A fresh rclpy context on a unique domain; yields ``(context, executor)``."""
    with ros_domain() as did:
        ctx = rclpy.Context()
        rclpy.init(context=ctx, domain_id=did)
        executor = SingleThreadedExecutor(context=ctx)
        try:
            yield ctx, executor
        finally:
            # destroy the nodes: a node left alive keeps its name's /rosout publisher
            for node in executor.get_nodes():
                executor.remove_node(node)
                node.destroy_node()
            executor.shutdown()
            rclpy.try_shutdown(context=ctx)


def two_link_urdf(shoulder=(-3, 3), elbow=(-3, 3), velocity=2):
    """A planar two-link arm's URDF (efforts 50 and 30 N m); joint limits as given."""
    return f"""<robot name="two_link">
  <link name="base"/>
  <link name="upper"><inertial><origin xyz="0.2 0 0"/><mass value="2.0"/>
    <inertia ixx="0.01" iyy="0.05" izz="0.05" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="fore"><inertial><origin xyz="0.15 0 0"/><mass value="1.0"/>
    <inertia ixx="0.005" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 0 1"/>
    <limit lower="{shoulder[0]}" upper="{shoulder[1]}" effort="50" velocity="{velocity}"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 0 1"/>
    <limit lower="{elbow[0]}" upper="{elbow[1]}" effort="30" velocity="{velocity}"/></joint>
</robot>"""


#: the node processes the tests start, by the names they use
NODE_MODULES = {"controller_node": "rcac_ros.nodes.controller.node",
                "simulator_node": "rcac_ros.nodes.simulator.node"}


def node_cmd(module, *overrides, params_file=None, ros_args=()):
    """The command line of node ``module`` (a key of NODE_MODULES) with ``-p`` overrides
    (and other ROS arguments, ``ros_args``)."""
    cmd = [sys.executable, "-m", NODE_MODULES[module], "--ros-args", *ros_args]
    if params_file is not None:
        cmd += ["--params-file", str(params_file)]
    for o in overrides:
        cmd += ["-p", o]
    return cmd


def start(module, *overrides, params_file=None):
    """Start a node process (output piped)."""
    return subprocess.Popen(node_cmd(module, *overrides, params_file=params_file),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            cwd=ROOT)


def stop(proc, timeout=20.0):
    """SIGINT, then wait up to ``timeout`` s (then kill); return ``(exit code, output)``."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return proc.returncode, out


def run_to_end(executor, sim, ctrl, drained):
    """Spin until the simulator process ``sim`` has ended and ``drained()`` holds (the
    controller answers the last state too), then stop both processes (also when a wait fails).

    Returns
    -------
    tuple
        ``((sim exit code, output), (controller exit code, output))``.
    """
    try:
        assert spin_until(executor, lambda: sim.poll() is not None, timeout=90.0)
        assert spin_until(executor, drained, timeout=10.0)
    finally:
        sim_result = stop(sim)
        ctrl_result = stop(ctrl)
    return sim_result, ctrl_result


def spin_until(executor, cond, timeout=20.0):
    """Spin until ``cond()`` is true; return whether it became true within ``timeout`` s.

    Nodes paced by a ``DeadlineLoop`` (their ``loop``: controller timer mode, simulator
    realtime mode) are driven as ``run()`` drives them in a node process.
    """
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        loops = [n.loop for n in executor.get_nodes() if getattr(n, "loop", None) is not None]
        if not loops:
            executor.spin_once(timeout_sec=0.01)
            continue
        waits = [w for w in (loop.due() for loop in loops) if w is not None]
        executor.spin_once(timeout_sec=min([0.01] + [max(w, 0) * 1e-9 for w in waits]))
    return cond()


def distinct(states):
    """``states`` with each stamp once, in order: the lockstep simulator sends state 0 again
    while it waits for its first answer (a copy), which a slow probe may read after the
    answer it sent."""
    seen, out = set(), []
    for m in states:
        ns = m.header.stamp.sec * NS + m.header.stamp.nanosec
        if ns not in seen:
            seen.add(ns)
            out.append(m)
    return out


def stamp(ns):
    """Integer nanoseconds as a builtin_interfaces/Time."""
    return TimeMsg(sec=ns // NS, nanosec=ns % NS)


class Probe(Node):
    """The test's side of the wires: publishes joint states, records efforts and logs."""

    def __init__(self, context, effort_topic="effort_controller/commands",
                 state_topic="joint_states", record=("efforts", "states", "logs")):
        super().__init__("probe", context=context)
        self.efforts = []                  # (label, data)
        self.states = []
        self.logs = []
        self.pub_state = self.create_publisher(JointState, state_topic, QOS)
        self.pub_effort = self.create_publisher(Float64MultiArray, effort_topic, QOS)
        self.subs = {}
        if "efforts" in record:
            self.subs["efforts"] = self.create_subscription(
                Float64MultiArray, effort_topic, self._on_effort, DEEP)
        if "states" in record:
            self.subs["states"] = self.create_subscription(
                JointState, state_topic, self.states.append, DEEP)
        if "logs" in record:
            self.subs["logs"] = self.create_subscription(Log, "/rosout", self.logs.append,
                                                         ROSOUT)

    def _on_effort(self, msg):
        label = msg.layout.dim[0].label if msg.layout.dim else ""
        self.efforts.append((label, np.array(msg.data)))

    def state(self, t_ns, q, qd=None, names=None):
        """Publish a JointState at stamp ``t_ns``."""
        msg = JointState(name=list(names or JOINTS), position=[float(x) for x in q],
                         velocity=[] if qd is None else [float(x) for x in qd])
        msg.header.stamp = stamp(t_ns)
        self.pub_state.publish(msg)
        return msg

    def warned(self, text, node="rcac_controller"):
        """Whether a WARN (or worse) log line of ``node`` contains ``text``."""
        return any(m.level >= Log.WARN and m.name.endswith(node) and text in m.msg
                   for m in self.logs)
