"""The fault bench's own node parts (:mod:`.faults`): the relay that injects the wires'
faults and the probe that reads the controller's outputs; a process's resident memory."""

import queue
import threading
import time

import numpy as np

from rcac_ros import topics

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
