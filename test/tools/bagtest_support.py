"""Shared parts of the bag tests: an isolated ROS domain, ``rcac`` as a real subprocess, a
publisher of numbered messages in the test process (real DDS between the processes), and
readers of a bag through two libraries (rosbags, and ``mcap`` + ``mcap-ros2-support``)."""

import os
import subprocess
import sys
import threading
import time

import pytest

PY = sys.executable


def cli_module():
    """The ``rcac`` entry module of this tree."""
    try:
        import rcac_ros.tools.cli  # noqa: F401
        return "rcac_ros.tools.cli"
    except ImportError:
        return "rcac_ros.cli"


def rcac(*args, env=None, timeout=120):
    """Run ``rcac ARGS`` to completion; a CompletedProcess with text output."""
    return subprocess.run([PY, "-m", cli_module(), *args], env=env, capture_output=True,
                          text=True, timeout=timeout, stdin=subprocess.DEVNULL)


@pytest.fixture
def ros_env():
    """A unique ROS_DOMAIN_ID (also for this process), discovery on localhost only."""
    domain_coordinator = pytest.importorskip("domain_coordinator")
    with domain_coordinator.domain_id() as domain:
        env = os.environ.copy()
        env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                   PYTHONUNBUFFERED="1")
        env.pop("ROS_LOCALHOST_ONLY", None)
        saved = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        env["_DOMAIN"] = str(domain)
        try:
            yield env
        finally:
            if saved is None:
                os.environ.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)
            else:
                os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = saved


class Recorder:
    """``rcac record`` as a child process, its output in a file."""

    def __init__(self, tmp_path, env, *args):
        self.log_path = tmp_path / "record.log"
        with open(self.log_path, "w") as log:
            self.proc = subprocess.Popen([PY, "-m", cli_module(), "record", *args], env=env,
                                         stdout=log, stderr=subprocess.STDOUT,
                                         stdin=subprocess.DEVNULL)
        self.started_ns = time.time_ns()

    def output(self):
        return self.log_path.read_text()

    def stop(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)


def wait_for(cond, timeout, what, proc=None):
    end = time.monotonic() + timeout
    while not cond():
        if proc is not None:
            assert proc.proc.poll() is None, f"{what}: exited early:\n{proc.output()}"
        assert time.monotonic() < end, f"timed out: {what}"
        time.sleep(0.02)


class Publisher:
    """Publishes numbered ``/clock`` and ``/joint_states`` messages from this process.

    Message ``k`` carries ``clock = k * dt`` (and the same header stamp); :attr:`sent` holds
    the wall time (ns) each ``k`` was published at.
    """

    def __init__(self, domain, dt=0.002, state_qos_depth=1000, state_best_effort=False,
                 state_transient_local=False):
        import rclpy
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState

        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=int(domain))
        self.node = rclpy.create_node("bag_test_publisher", context=self.ctx)
        reliable = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                              reliability=ReliabilityPolicy.RELIABLE)
        state_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=state_qos_depth,
                               reliability=ReliabilityPolicy.BEST_EFFORT if state_best_effort
                               else ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.TRANSIENT_LOCAL
                               if state_transient_local else DurabilityPolicy.VOLATILE)
        self.clock_pub = self.node.create_publisher(Clock, "/clock", reliable)
        self.state_pub = self.node.create_publisher(JointState, "/joint_states", state_qos)
        self._Clock, self._JointState = Clock, JointState
        self.dt = dt
        self.sent = []
        self._stop = threading.Event()
        self._thread = None

    def matched(self):
        return self.clock_pub.get_subscription_count() > 0 \
            and self.state_pub.get_subscription_count() > 0

    def _msgs(self, k):
        ns = int(round(k * self.dt * 1e9))
        clock = self._Clock()
        clock.clock.sec, clock.clock.nanosec = divmod(ns, 1_000_000_000)
        state = self._JointState()
        state.header.stamp.sec, state.header.stamp.nanosec = clock.clock.sec, clock.clock.nanosec
        state.name = ["joint1"]
        state.position = [float(k)]
        return clock, state

    def _run(self):
        k = len(self.sent)
        next_t = time.monotonic()
        while not self._stop.is_set():
            clock, state = self._msgs(k)
            self.clock_pub.publish(clock)
            self.state_pub.publish(state)
            self.sent.append(time.time_ns())
            k += 1
            next_t += self.dt
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)

    def start(self):
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def stop(self):
        if self._thread is not None:
            self._stop.set()
            self._thread.join(5)
            self._thread = None

    def close(self):
        self.stop()
        self.node.destroy_node()
        self.ctx.try_shutdown()


def clock_k(msg, dt=0.002):
    return int(round((msg.clock.sec + 1e-9 * msg.clock.nanosec) / dt))


def read_rosbags(bag):
    """topic -> [(log time ns, message)] through rosbags."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import get_typestore, Stores
    ts = get_typestore(Stores.ROS2_JAZZY)
    out = {}
    with Reader(bag) as reader:
        for conn, stamp, raw in reader.messages():
            out.setdefault(conn.topic, []).append((stamp, ts.deserialize_cdr(raw, conn.msgtype)))
    return out


def read_mcap_ros2(mcap_file):
    """topic -> [(log time ns, publish time ns, message)] through mcap + mcap-ros2-support."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    out = {}
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
        for _schema, channel, message, decoded in reader.iter_decoded_messages():
            out.setdefault(channel.topic, []).append(
                (message.log_time, message.publish_time, decoded))
    return out


def bag_file(bag):
    """The single storage file of a bag directory."""
    files = [f for f in os.listdir(bag) if f.endswith((".mcap", ".db3"))]
    assert len(files) == 1, files
    return os.path.join(bag, files[0])
