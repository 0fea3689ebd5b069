"""``rcac record``: record the package's topics into a rosbag2 bag that survives a crash.

Messages come from ``raw=True`` subscriptions, so the stored bytes are exactly the CDR the
publishers sent, and are written by :class:`rcac_ros.tools.bags.writer.BagWriter`: mcap through
the ``mcap`` library (real chunk CRCs) or sqlite3. Every second the open chunk is written
(or the transaction committed) and ``metadata.yaml`` updated, so a ``kill -9`` loses at
most the last second; ``rcac inspect --recover`` salvages such a bag. Ctrl-C or SIGTERM
closes the bag normally.

Like ``ros2 bag record``:

- messages are stamped with their DDS receive time (system clock, ns), or with ROS time
  (``/clock``) under ``--use-sim-time``; the publisher's send time and sequence number go
  into the mcap message's ``publish_time`` and ``sequence``;
- each topic is written with the QoS profiles its publishers offer (read when its first
  message arrives);
- ``metadata.yaml`` says ``ros_distro: jazzy``.

Subscriptions are created before anything else (no numba, the writer after them), and the
recorder prints, per topic, when its publisher was matched and its first message arrived.
"""

import bisect
import datetime
import functools
import importlib
import os
import struct
import time

from rcac_ros import topics
from rcac_ros.errors import ConfigError
from rcac_ros.tools.args import node_name, output_dir, positive_float
from rcac_ros.tools.bags.writer import BagWriter, FLUSH_PERIOD, qos_dicts, STORAGES
from rcac_ros.tools.launch import init_context, StopFlag

#: recorded topics (relative names are resolved against the controller node) -> message type
TOPIC_TYPES = (
    (topics.JOINT_STATES, "sensor_msgs/msg/JointState"),
    (topics.EFFORT_COMMANDS, "std_msgs/msg/Float64MultiArray"),
    (topics.CLOCK, "rosgraph_msgs/msg/Clock"),
    (topics.PARAMETER_ESTIMATES, "std_msgs/msg/Float64MultiArray"),
    (topics.PREDICTION_ERROR, "std_msgs/msg/Float64"),
    (topics.PREDICTION_ERRORS, "std_msgs/msg/Float64MultiArray"),
    (topics.TRACKING_ERROR, "std_msgs/msg/Float64MultiArray"),
    (topics.DESIRED_STATE, "sensor_msgs/msg/JointState"),
    (topics.DIAGNOSTICS, "diagnostic_msgs/msg/DiagnosticArray"),
    (topics.resolve(topics.PAYLOAD, topics.SIMULATOR_NODE), "geometry_msgs/msg/InertiaStamped"),
    (topics.FRICTION_ESTIMATES, "std_msgs/msg/Float64MultiArray"),
)

STORAGE_CHOICES = STORAGES


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
    return [(topics.resolve(name, controller_node), msgtype) for name, msgtype in TOPIC_TYPES]


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


def header_stamp_ns(raw):
    """Header stamp (ns) of a CDR-serialised stamped message (``std_msgs/Header`` first)."""
    endian = "<" if raw[1] == 1 else ">"
    sec, nsec = struct.unpack_from(endian + "iI", raw, 4)
    return sec * 1_000_000_000 + nsec


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
    use_sim_time : bool
        Stamp messages with ROS time (``/clock``) instead of the receive time.
    flush_period : float
        Seconds between two flushes of the bag (what a crash can lose).
    log : callable, optional
        Called with one line of text per event (first message of a topic); default print.

    Notes
    -----
    Subscriptions are reliable. A topic whose publishers all offer best-effort is
    re-subscribed best-effort when they are discovered (a reliable subscription
    would not match them), as ``ros2 bag record`` adapts its QoS. The simulator's
    ``~/payload`` (transient local, depth 10) is read transient local: a recorder that
    matches it after its first message (the payload at start) still records that one.

    A publisher's keep-last history bounds how far behind a reliable subscriber may fall:
    the package publishes efforts and ``/clock`` with keep-last 10, so a recorder that is
    descheduled for 10 messages loses some (counted as ``missed`` from the publication
    sequence numbers); the control loop itself is not affected.
    """

    def __init__(self, path, context, storage="mcap", controller_node=topics.CONTROLLER_NODE,
                 depth=1000, node_name="rcac_recorder", use_sim_time=False,
                 flush_period=FLUSH_PERIOD, log=None):
        from rclpy.event_handler import SubscriptionEventCallbacks
        from rclpy.node import Node
        from rclpy.parameter import Parameter
        from rclpy.qos import ReliabilityPolicy

        if storage not in STORAGE_CHOICES:
            raise ConfigError(f"storage: expected one of {STORAGE_CHOICES}, got {storage!r}")
        if os.path.exists(path):
            raise ConfigError(f"out: {path} already exists; rosbag2 needs a new directory")
        self.path = os.path.abspath(path)
        self._log = log or (lambda text: print(text, flush=True))
        self._events = SubscriptionEventCallbacks
        self._qos = {
            ReliabilityPolicy.RELIABLE: topics.qos(depth),
            ReliabilityPolicy.BEST_EFFORT: topics.qos(depth, reliable=False),
        }
        self._best_effort = ReliabilityPolicy.BEST_EFFORT
        self._latched = {topics.resolve(topics.PAYLOAD, topics.SIMULATOR_NODE):
                         topics.qos(10, transient_local=True)}
        self.use_sim_time = bool(use_sim_time)
        #: the start on the clock of the receive stamps (the bag's), ns
        self.t0_ns = time.time_ns()
        self.node = Node(node_name, context=context, parameter_overrides=[
            Parameter("use_sim_time", Parameter.Type.BOOL, self.use_sim_time)])
        self._clock = self.node.get_clock()
        #: (receive time, sim time) ns of the /clock messages, for stamping with ROS time
        self._clock_recv, self._clock_sim = [], []
        self.topics = recorded_topics(controller_node)
        self._types = dict(self.topics)
        self.counts = {name: 0 for name, _ in self.topics}
        #: messages a single publisher sent that never arrived (sequence-number gaps)
        self.gaps = {name: 0 for name, _ in self.topics}
        #: seconds since start when each topic got its first matched publisher (the event's
        #: callback) / message (its receive stamp), both on the receive stamps' clock
        self.matched_at = {}
        self.first_at = {}
        self.first_stamp = None
        self.last_stamp = None
        #: latest simulated time seen on /clock (s), None before the first message
        self.sim_time = None
        #: header stamp (ns) of the latest joint state, None before the first
        self.last_state_stamp = None
        self._states = "/" + topics.JOINT_STATES
        self._last_seq = {}
        self._multi = set()   # topics seen with several publishers (no gap count)
        self._adapted = set()
        self._seen = set()
        self._subs = {}
        self._closed = False
        self._writer = None
        # subscribe first: discovery and matching run while the writer is set up. /clock
        # first: the executor serves ready subscriptions in creation order, so a message is
        # stamped after the /clock messages received before it are known (--use-sim-time)
        for name in sorted((n for n, _ in self.topics), key=lambda n: n != topics.CLOCK):
            self._subscribe(name, ReliabilityPolicy.RELIABLE)
        self._writer = BagWriter(self.path, storage, flush_period=flush_period)

    def _subscribe(self, name, reliability):
        old = self._subs.pop(name, None)
        if old is not None:
            self.node.destroy_subscription(old)
        callback = functools.partial(self._on_message, name)  # (data, info)
        events = self._events(matched=functools.partial(self._on_matched, name))
        self._subs[name] = self.node.create_subscription(
            _msg_class(self._types[name]), name, callback,
            self._latched.get(name, self._qos[reliability]), raw=True, event_callbacks=events)

    def _on_matched(self, name, info):
        if info.current_count > 0 and name not in self.matched_at:
            self.matched_at[name] = 1e-9 * (time.time_ns() - self.t0_ns)

    def _register(self, name):
        infos = self.node.get_publishers_info_by_topic(name)
        self._writer.add_topic(name, self._types[name], qos_dicts(i.qos_profile for i in infos))

    def _on_message(self, name, data, info):
        if self._closed:
            return
        received = info.get("received_timestamp") or time.time_ns()
        if name not in self._writer.topics:
            self._register(name)
            now = 1e-9 * (received - self.t0_ns)
            self.first_at[name] = now
            matched = self.matched_at.setdefault(name, now)
            self._log(f"rcac record: first message on {name} at {now:.3f} s (its publisher "
                      f"matched at {matched:.3f} s)")
        if name == topics.CLOCK:
            self.sim_time = clock_seconds(data)
            self._clock_recv.append(received)
            self._clock_sim.append(int(round(self.sim_time * 1e9)))
            if len(self._clock_recv) > 8192:
                del self._clock_recv[:4096], self._clock_sim[:4096]
        stamp = self._sim_stamp(received) if self.use_sim_time else received
        seq = info.get("publication_sequence_number") or 0
        self._writer.write(name, stamp, data, info.get("source_timestamp") or received, seq)
        self._writer.tick()
        self.counts[name] += 1
        if self.first_stamp is None or stamp < self.first_stamp:
            self.first_stamp = stamp
        if self.last_stamp is None or stamp > self.last_stamp:
            self.last_stamp = stamp
        if name == self._states:
            self.last_state_stamp = header_stamp_ns(data)
        if seq and name not in self._multi:
            last = self._last_seq.get(name)
            if last is not None and seq <= last:   # several publishers: numbers interleave
                self._multi.add(name)
                self.gaps[name] = 0
            elif last is not None and seq > last + 1:
                self.gaps[name] += seq - last - 1
            self._last_seq[name] = seq

    def _sim_stamp(self, received):
        """ROS time when a message was received: the latest /clock received before it (the
        executor may run the /clock callback after the message's; ros2 bag record stamps
        with the clock at callback time instead)."""
        k = bisect.bisect_right(self._clock_recv, received) - 1
        if k < 0:
            return self._clock.now().nanoseconds
        return self._clock_sim[k]

    def tick(self):
        """Flush the bag when a flush period has passed (call at least once a second)."""
        if not self._closed:
            self._writer.tick()

    def adapt_qos(self):
        """Re-subscribe best-effort to topics whose discovered publishers are all best-effort.

        Returns
        -------
        bool
            True when every recorded topic has at least one discovered publisher.
        """
        all_seen = True
        for name, _ in self.topics:
            if name in self._adapted:
                continue
            infos = self.node.get_publishers_info_by_topic(name)
            if not infos:
                all_seen = False
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
            self.tick()
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
        for name, _ in self.topics:      # topics without messages are listed too
            if self._writer is not None and name not in self._writer.topics:
                self._register(name)
        for sub in self._subs.values():
            self.node.destroy_subscription(sub)
        self._subs.clear()
        if self._writer is not None:
            self._writer.close()
        self.node.destroy_node()


def format_counts(recorder):
    """One line per topic: name, type, messages written (and sequence gaps, explained)."""
    width = max(len(n) for n, _ in recorder.topics)
    lines = []
    for name, msgtype in recorder.topics:
        gap = f"  ({recorder.gaps[name]} missed)" if recorder.gaps[name] else ""
        lines.append(f"  {name:<{width}}  {msgtype:<36} {recorder.counts[name]:>8}{gap}")
    if any(recorder.gaps.values()):
        lines.append("  missed: messages the publisher sent that never reached the recorder "
                     "(gaps in the publication sequence numbers): the recorder fell more than "
                     "the publisher's keep-last depth behind")
    return "\n".join(lines)


def add_arguments(parser):
    parser.add_argument("--out", "-o", type=output_dir, default=None,
                        help="bag directory to create (default: ./rcac_bag_<date>-<time>)")
    parser.add_argument("--storage", choices=STORAGE_CHOICES, default="mcap",
                        help="rosbag2 storage plugin (default: mcap)")
    parser.add_argument("--duration", type=positive_float, default=None,
                        help="stop after this many seconds (default: until Ctrl-C)")
    parser.add_argument("--use-sim-time", action="store_true",
                        help="stamp messages with ROS time from /clock (as ros2 bag record "
                             "--use-sim-time); default: the receive time")
    parser.add_argument("--controller-node", type=node_name, default=topics.CONTROLLER_NODE,
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
                               controller_node=args.controller_node,
                               use_sim_time=args.use_sim_time)
        executor.add_node(recorder.node)
        stamps = "ROS time (/clock)" if args.use_sim_time else "receive time"
        print(f"rcac record: recording {len(recorder.topics)} topics into {recorder.path} "
              f"({args.storage}, stamped with the {stamps}); Ctrl-C to stop", flush=True)
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
            recorder.tick()
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
