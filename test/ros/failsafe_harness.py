"""Black-box harness of the fault tests: node processes over real DDS, and an in-process probe.

The probe spins in its own thread, so that a test can publish at a steady rate while the
replies are recorded with their DDS source stamps (the sender's clock, not the probe's).
"""

import contextlib
import threading
import time

import numpy as np

from test_nodes_support import (DEEP, H_NS, JOINTS, node_cmd, NS, PAPER_Q0, QOS,  # noqa: F401
                                ROOT, ros_domain, ROSOUT, stamp, start, stop)

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rcl_interfaces.msg import Log  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from trajectory_msgs.msg import JointTrajectory  # noqa: E402

TRAJECTORY = "/rcac_controller/joint_trajectory"


class Probe(Node):
    """Publishes states, clock and trajectories; records efforts, logs, desired states."""

    def __init__(self, context):
        super().__init__("failsafe_probe", context=context)
        self.lock = threading.Lock()
        self.efforts = []           # (source ns, receive ns, label, data)
        self.logs = []
        self.desired = []           # (stamp ns, position)
        self.diagnostics = {}
        self.pub_state = self.create_publisher(JointState, "/joint_states", QOS)
        self.pub_clock = self.create_publisher(Clock, "/clock", QOS)
        self.pub_traj = self.create_publisher(JointTrajectory, TRAJECTORY, QOS)
        self.sub_effort = self.create_subscription(
            Float64MultiArray, "/effort_controller/commands", self._on_effort, DEEP, raw=True)
        self.create_subscription(Log, "/rosout", self._on_log, ROSOUT)
        self.create_subscription(JointState, "/rcac_controller/desired_state",
                                 self._on_desired, DEEP)
        self.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, QOS)

    def _on_effort(self, data, info):
        msg = deserialize_message(data, Float64MultiArray)
        label = msg.layout.dim[0].label if msg.layout.dim else ""
        with self.lock:
            self.efforts.append((info["source_timestamp"], info["received_timestamp"], label,
                                 np.array(msg.data)))

    def _on_log(self, msg):
        with self.lock:
            self.logs.append(msg)

    def _on_desired(self, msg):
        with self.lock:
            self.desired.append((msg.header.stamp.sec * NS + msg.header.stamp.nanosec,
                                 np.array(msg.position)))

    def _on_diag(self, msg):
        for status in msg.status:
            self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}

    def state(self, t_ns, q=PAPER_Q0, qd=None):
        """Publish a JointState at stamp ``t_ns``."""
        msg = JointState(name=list(JOINTS), position=[float(x) for x in q],
                         velocity=[0.0] * len(q) if qd is None else [float(x) for x in qd])
        msg.header.stamp = stamp(t_ns)
        self.pub_state.publish(msg)

    def clock(self, t_ns):
        self.pub_clock.publish(Clock(clock=stamp(t_ns)))

    def answered(self, t_ns):
        label = f"stamp={t_ns // NS}.{t_ns % NS:09d}"
        with self.lock:
            return any(label in e[2] for e in self.efforts)

    def answers(self):
        """Efforts tagged as answers to a state."""
        with self.lock:
            return [e for e in self.efforts if "stamp=" in e[2]]

    def watchdog_efforts(self):
        with self.lock:
            return [e for e in self.efforts if e[2].endswith("watchdog")]

    def warned(self, text, node="rcac_controller"):
        """Whether a WARN (or worse) log line of ``node`` contains ``text``."""
        with self.lock:
            return any(m.level >= Log.WARN and m.name.endswith(node) and text in m.msg
                       for m in self.logs)

    def logged(self, text):
        with self.lock:
            return any(text in m.msg for m in self.logs)


@contextlib.contextmanager
def session():
    """A domain, a context and a probe spinning in a thread; yields the probe."""
    with ros_domain() as did:
        ctx = rclpy.Context()
        rclpy.init(context=ctx, domain_id=did)
        probe = Probe(ctx)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(probe)
        stop = threading.Event()

        def spin():
            while not stop.is_set():
                executor.spin_once(timeout_sec=0.01)
        thread = threading.Thread(target=spin, daemon=True)
        thread.start()
        try:
            yield probe
        finally:
            stop.set()
            thread.join(5.0)
            executor.remove_node(probe)
            probe.destroy_node()
            executor.shutdown()
            rclpy.try_shutdown(context=ctx)


def wait(cond, timeout=20.0, step=0.005):
    """Poll ``cond()`` until true or ``timeout`` s; return its last value."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(step)
    return cond()


@contextlib.contextmanager
def controller(probe, *overrides):
    """A controller process matched with the probe; yields the process."""
    proc = start("controller_node", *overrides)
    try:
        assert wait(lambda: probe.pub_state.get_subscription_count() > 0
                    and probe.sub_effort.get_publisher_count() > 0
                    or proc.poll() is not None, timeout=60.0)
        assert proc.poll() is None, stop(proc)[1]
        yield proc
    finally:
        code, out = stop(proc)
        proc.output = out


def first_answer(probe, t_ns, q=PAPER_Q0, timeout=20.0):
    """Send the state at ``t_ns`` until answered (the first can be lost in discovery)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        probe.state(t_ns, q)
        if wait(lambda: probe.answered(t_ns), timeout=0.3):
            return
    raise AssertionError(f"no answer to the state at {t_ns} ns")


def feed(probe, stamps, q=PAPER_Q0, period=0.002):
    """Publish states at ``stamps`` on a steady ``period`` (like a driver: no waiting)."""
    nxt = time.monotonic()
    for t_ns in stamps:
        probe.state(t_ns, q)
        nxt += period
        time.sleep(max(0.0, nxt - time.monotonic()))


@contextlib.contextmanager
def state_driver(probe, q=PAPER_Q0, period=0.002):
    """For the block, a thread publishes the state ``q`` every ``period``, stamped on the
    steady clock (a driver at 500 Hz)."""
    stop = threading.Event()

    def states():
        nxt = time.monotonic()
        while not stop.is_set():
            probe.state(time.monotonic_ns(), q)
            nxt += period
            time.sleep(max(0.0, nxt - time.monotonic()))
    feeder = threading.Thread(target=states, daemon=True)
    feeder.start()
    try:
        yield
    finally:
        stop.set()
        feeder.join(5.0)


def set_parameter(probe, name, value, timeout=10.0):
    """Set one controller parameter at run time; return ``(successful, reason)``."""
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    client = AsyncParameterClient(probe, "rcac_controller")
    assert client.wait_for_services(timeout_sec=timeout)
    future = client.set_parameters([Parameter(name, value=value)])
    assert wait(future.done, timeout=timeout)
    result = future.result().results[0]
    return result.successful, result.reason
