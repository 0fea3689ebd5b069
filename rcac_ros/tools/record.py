"""``rcac record``: record the package's topics into a rosbag2 bag.

The bag is written with ``rosbags`` (no ros2cli needed) from ``raw=True``
subscriptions, so the stored bytes are exactly the CDR the publishers sent.
Every message is stamped with its DDS receive time (system clock, ns), like
``ros2 bag record``. The writer is closed on Ctrl-C or SIGTERM, so the bag
stays readable.
"""

import datetime
import functools
import importlib
import os
import struct
import time

from rcac_ros import topics
from rcac_ros.errors import ConfigError
from rcac_ros.tools.launch import init_context, StopFlag

#: recorded topics (relative names are resolved against the controller node) -> message type
TOPIC_TYPES = (
    (topics.JOINT_STATES, "sensor_msgs/msg/JointState"),
    (topics.EFFORT_COMMANDS, "std_msgs/msg/Float64MultiArray"),
    (topics.CLOCK, "rosgraph_msgs/msg/Clock"),
    (topics.PARAMETER_ESTIMATES, "std_msgs/msg/Float64MultiArray"),
    (topics.PREDICTION_ERROR, "std_msgs/msg/Float64"),
    (topics.TRACKING_ERROR, "std_msgs/msg/Float64MultiArray"),
    (topics.DESIRED_STATE, "sensor_msgs/msg/JointState"),
    (topics.DIAGNOSTICS, "diagnostic_msgs/msg/DiagnosticArray"),
)

STORAGE_CHOICES = ("mcap", "sqlite3")


def recorded_topics(controller_node=topics.CONTROLLER_NODE):
    """Absolute names and types of the recorded topics.

    Parameters
    ----------
    controller_node : str
        Name of the controller node; its private topics (``~/x``) become
        ``/<controller_node>/x``.

    Returns
    -------
    list of (str, str)
        ``(topic, "pkg/msg/Type")`` pairs.
    """
    out = []
    for name, msgtype in TOPIC_TYPES:
        if name.startswith("~/"):
            out.append((f"/{controller_node}/{name[2:]}", msgtype))
        elif name.startswith("/"):
            out.append((name, msgtype))
        else:
            out.append((f"/{name}", msgtype))
    return out


def default_bag_path():
    """A fresh bag directory name in the working directory, as ``ros2 bag`` chooses it."""
    return os.path.abspath(datetime.datetime.now().strftime("rcac_bag_%Y_%m_%d-%H_%M_%S"))


def _msg_class(msgtype):
    pkg, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def clock_seconds(raw):
    """Seconds held by a CDR-serialised ``rosgraph_msgs/Clock`` (no deserialiser needed).

    Parameters
    ----------
    raw : bytes
        The serialised message (4-byte encapsulation header, then ``sec``, ``nanosec``).

    Returns
    -------
    float
    """
    endian = "<" if raw[1] == 1 else ">"
    sec, nsec = struct.unpack_from(endian + "iI", raw, 4)
    return sec + 1e-9 * nsec


class BagRecorder:
    """Subscribe (raw) to the package's topics and write every message into a bag.

    Parameters
    ----------
    path : str
        Bag directory to create; it must not exist.
    context : rclpy.context.Context
        An initialised rclpy context.
    storage : {"mcap", "sqlite3"}
        rosbag2 storage plugin.
    controller_node : str
        Name of the controller node (for its private topics).
    depth : int
        Subscription queue depth (keep-last). Large, so that a busy recorder
        buffers instead of dropping.
    node_name : str
        Name of the recorder node.

    Notes
    -----
    Subscriptions are reliable. A topic whose publishers all offer best-effort is
    re-subscribed best-effort when they are discovered (a reliable subscription
    would not match them), as ``ros2 bag record`` adapts its QoS.
    """

    def __init__(self, path, context, storage="mcap", controller_node=topics.CONTROLLER_NODE,
                 depth=1000, node_name="rcac_recorder"):
        from rclpy.node import Node
        from rclpy.qos import ReliabilityPolicy
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import get_typestore, Stores

        if storage not in STORAGE_CHOICES:
            raise ConfigError(f"storage: expected one of {STORAGE_CHOICES}, got {storage!r}")
        if os.path.exists(path):
            raise ConfigError(f"out: {path} already exists; rosbag2 needs a new directory")
        parent = os.path.dirname(os.path.abspath(path))
        os.makedirs(parent, exist_ok=True)
        self.path = os.path.abspath(path)
        self._qos = {
            ReliabilityPolicy.RELIABLE: topics.qos(depth),
            ReliabilityPolicy.BEST_EFFORT: topics.qos(depth, reliable=False),
        }
        self._best_effort = ReliabilityPolicy.BEST_EFFORT
        typestore = get_typestore(Stores.ROS2_JAZZY)
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        self.node = Node(node_name, context=context)
        self.topics = recorded_topics(controller_node)
        self.counts = {name: 0 for name, _ in self.topics}
        #: messages a single publisher sent that never arrived (sequence-number gaps)
        self.gaps = {name: 0 for name, _ in self.topics}
        self.first_stamp = None
        self.last_stamp = None
        #: latest simulated time seen on /clock (s), None before the first message
        self.sim_time = None
        self._last_seq = {}
        self._multi = set()   # topics seen with several publishers (no gap count)
        self._adapted = set()
        self._seen = set()
        self._subs = {}
        self._types = dict(self.topics)
        self._writer = Writer(self.path, version=9, storage_plugin=plugin)
        self._writer.open()
        self._closed = False
        self._conns = {}
        for name, msgtype in self.topics:
            self._conns[name] = self._writer.add_connection(name, msgtype, typestore=typestore)
            self._subscribe(name, ReliabilityPolicy.RELIABLE)

    def _subscribe(self, name, reliability):
        old = self._subs.pop(name, None)
        if old is not None:
            self.node.destroy_subscription(old)
        callback = functools.partial(self._on_message, name, self._conns[name])  # (data, info)
        self._subs[name] = self.node.create_subscription(
            _msg_class(self._types[name]), name, callback, self._qos[reliability], raw=True)

    def _on_message(self, name, conn, data, info):
        if self._closed:
            return
        stamp = info.get("received_timestamp") or time.time_ns()
        self._writer.write(conn, stamp, data)
        self.counts[name] += 1
        if self.first_stamp is None or stamp < self.first_stamp:
            self.first_stamp = stamp
        if self.last_stamp is None or stamp > self.last_stamp:
            self.last_stamp = stamp
        seq = info.get("publication_sequence_number")
        if seq and name not in self._multi:
            last = self._last_seq.get(name)
            if last is not None and seq <= last:   # several publishers: numbers interleave
                self._multi.add(name)
                self.gaps[name] = 0
            elif last is not None and seq > last + 1:
                self.gaps[name] += seq - last - 1
            self._last_seq[name] = seq
        if name == topics.CLOCK:
            self.sim_time = clock_seconds(data)

    def adapt_qos(self):
        """Re-subscribe best-effort to topics whose discovered publishers are all best-effort.

        Returns
        -------
        bool
            True when every recorded topic has at least one discovered publisher.
        """
        all_seen = True
        for name, _ in self.topics:
            infos = self.node.get_publishers_info_by_topic(name)
            if not infos:
                all_seen = False
                continue
            if name in self._adapted:
                continue
            self._adapted.add(name)
            if all(i.qos_profile.reliability == self._best_effort for i in infos):
                self._subscribe(name, self._best_effort)
        return all_seen

    def newly_matched(self):
        """Topics whose subscription got its first matched publisher since the last call."""
        now = set(self.matched())
        new = [n for n, _ in self.topics if n in now and n not in self._seen]
        self._seen |= now
        return new

    def matched(self, names=None):
        """Topics (of ``names``, default all) whose subscription has a matched publisher."""
        names = [n for n, _ in self.topics] if names is None else names
        return [n for n in names if self._subs[n].get_publisher_count() > 0]

    def wait_for_publishers(self, executor, names=None, timeout=30.0, alive=None):
        """Spin until every topic of ``names`` has a matched publisher.

        Parameters
        ----------
        executor : rclpy.executors.Executor
            Executor the recorder node was added to.
        names : list of str, optional
            Absolute topic names; default all recorded topics.
        timeout : float
            Seconds to wait.
        alive : callable, optional
            Called while waiting; waiting stops (returning False) when it returns False.

        Returns
        -------
        bool
            True when all matched before the timeout.
        """
        names = [n for n, _ in self.topics] if names is None else list(names)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.adapt_qos()
            if len(self.matched(names)) == len(names):
                return True
            if alive is not None and not alive():
                return False
            executor.spin_once(timeout_sec=0.02)
        return False

    @property
    def total(self):
        """Messages written so far."""
        return sum(self.counts.values())

    def close(self):
        """Stop recording and close the bag (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for sub in self._subs.values():
            self.node.destroy_subscription(sub)
        self._subs.clear()
        self._writer.close()
        self.node.destroy_node()


def format_counts(recorder):
    """One line per topic: name, type, messages written."""
    width = max(len(n) for n, _ in recorder.topics)
    lines = []
    for name, msgtype in recorder.topics:
        gap = f"  ({recorder.gaps[name]} missed)" if recorder.gaps[name] else ""
        lines.append(f"  {name:<{width}}  {msgtype:<36} {recorder.counts[name]:>8}{gap}")
    return "\n".join(lines)


def add_arguments(parser):
    parser.add_argument("--out", "-o", default=None,
                        help="bag directory to create (default: ./rcac_bag_<date>-<time>)")
    parser.add_argument("--storage", choices=STORAGE_CHOICES, default="mcap",
                        help="rosbag2 storage plugin (default: mcap)")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many seconds (default: until Ctrl-C)")
    parser.add_argument("--controller-node", default=topics.CONTROLLER_NODE,
                        help="controller node name, for its private topics "
                             f"(default: {topics.CONTROLLER_NODE})")


def run(args):
    from rclpy.executors import SingleThreadedExecutor

    if args.duration is not None and args.duration <= 0:
        raise ConfigError(f"duration: must be > 0 s, got {args.duration}")
    path = args.out or default_bag_path()
    stop = StopFlag()
    ctx = init_context()
    executor = SingleThreadedExecutor(context=ctx)
    recorder = None
    try:
        recorder = BagRecorder(path, ctx, storage=args.storage,
                               controller_node=args.controller_node)
        executor.add_node(recorder.node)
        print(f"rcac record: recording {len(recorder.topics)} topics into {recorder.path} "
              f"({args.storage}); Ctrl-C to stop", flush=True)
        start = time.monotonic()
        next_report = start + 5.0
        next_adapt = start
        while not stop:
            now = time.monotonic()
            if args.duration is not None and now - start >= args.duration:
                break
            if now >= next_adapt:
                recorder.adapt_qos()
                for name in recorder.newly_matched():
                    print(f"rcac record: subscribed to {name}", flush=True)
                next_adapt = now + 0.1
            if now >= next_report:
                sim = "" if recorder.sim_time is None else f", sim time {recorder.sim_time:.2f} s"
                print(f"  {now - start:6.1f} s: {recorder.total} messages{sim}", flush=True)
                next_report = now + 5.0
            executor.spin_once(timeout_sec=0.05)
    finally:
        if recorder is not None:
            recorder.close()
        executor.shutdown()
        ctx.try_shutdown()
        stop.restore()
    print(f"rcac record: closed {recorder.path}: {recorder.total} messages", flush=True)
    print(format_counts(recorder), flush=True)
    return 0
