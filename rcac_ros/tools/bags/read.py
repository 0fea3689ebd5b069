"""Read a bag of the package's topics into arrays, and its summary (``rcac inspect``).

The bag is first verified (:func:`.verify.verify`); its messages are read with rosbags into one
:class:`TopicData` per topic (receive stamps, header stamps, publishers' send stamps when the
bag holds them, the decoded arrays). The summary starts with the header ``ros2 bag info``
prints, then lists every topic (type, count, rate from the message stamps) and the bag's
duration.
"""

import numpy as np

from rcac_ros import topics
from rcac_ros.errors import BagError
from rcac_ros.tools.bags.verify import find_bag, verify

#: diagnostics values shown in the summary (all are kept in metrics.json)
DIAG_KEYS = ("mode", "steps", "real_time_factor", "lockstep_misses", "late_efforts",
             "compute_time_p50_us", "compute_time_p99_us", "deadline_misses", "late_ticks",
             "watchdog_trips", "rejected_messages")


class TopicData:
    """Messages of one topic: receive stamps (ns) and the decoded fields we use."""

    def __init__(self, name, msgtype):
        self.name = name
        self.msgtype = msgtype
        self.recv = []
        self.stamp = []      # header stamp (s), for stamped types
        self.values = []     # per message: array (or float)
        self.names = None    # joint names (JointState)
        self.velocity = []
        self.dims = None     # MultiArray layout dims [(label, size), ...]
        self.labels = []     # MultiArray: label of the first dimension, per message
        self.sent = None     # publisher's send stamps (ns), when the bag holds them (mcap)
        self.seq = None      # publication sequence numbers, idem (0: unknown)

    @property
    def count(self):
        return len(self.recv)

    def finish(self):
        """Convert the lists to arrays (ragged values stay a list)."""
        self.recv = np.asarray(self.recv, dtype=np.int64)
        self.stamp = np.asarray(self.stamp, dtype=float)
        self.labels = np.asarray(self.labels, dtype=object)
        if self.sent is not None:
            self.sent = np.asarray(self.sent, dtype=np.int64)
            self.seq = np.asarray(self.seq, dtype=np.int64)
        try:
            self.values = np.asarray(self.values, dtype=float)
        except ValueError:
            pass
        try:
            self.velocity = np.asarray(self.velocity, dtype=float)
        except ValueError:
            pass
        return self


def _stamp(header):
    return header.stamp.sec + 1e-9 * header.stamp.nanosec


def read_bag(path, report=None):
    """Verify, then read a bag into :class:`TopicData` per topic.

    The bag is first checked with what its format offers (:func:`.verify.verify`: chunk
    CRCs, counts against metadata.yaml, sqlite's integrity check); a cut or corrupt bag
    raises :class:`rcac_ros.errors.BagError` with one line naming the problem. The
    messages are then read with rosbags. For mcap, the publishers' send stamps and sequence
    numbers (``publish_time``, ``sequence``, stored by ``rcac record``) come from the
    ``mcap`` library's scan.

    Parameters
    ----------
    path : str
        rosbag2 directory (mcap or sqlite3), or a folder holding exactly one.
    report : verify.Report, optional
        Filled with what the verification found.

    Returns
    -------
    dict
        topic -> TopicData, for every connection in the bag.
    """
    path = find_bag(path)
    sent = _verify(path, report)
    data = _read_messages(path)
    _add_send_stamps(data, sent)
    return {k: v.finish() for k, v in data.items()}


def _verify(path, report):
    """Verify the bag (filling ``report``); the mcap scan's ``(log_time, publish_time,
    sequence)`` of each message, by topic (empty for sqlite3)."""
    sent = {}

    def collect(channel, schemas, msg):
        sent.setdefault(channel.topic, []).append((msg.log_time, msg.publish_time,
                                                   msg.sequence))

    checked = verify(path, on_message=collect)
    if report is not None:
        report.__dict__.update(checked.__dict__)
    return sent


#: the message types whose fields are read (the others are counted only)
DECODED = {"sensor_msgs/msg/JointState", "std_msgs/msg/Float64MultiArray",
           "std_msgs/msg/Float64", "rosgraph_msgs/msg/Clock",
           "diagnostic_msgs/msg/DiagnosticArray"}


def _read_messages(path):
    """Every message of the bag read with rosbags: topic -> :class:`TopicData` (lists)."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import get_typestore, Stores

    typestore = get_typestore(Stores.ROS2_JAZZY)
    data = {}
    try:
        reader = Reader(path)
        reader.open()
    except Exception as err:  # rosbags raises several types for unreadable bags
        raise BagError(f"bag: cannot open {path}: {err}") from err
    try:
        for conn in reader.connections:
            data.setdefault(conn.topic, TopicData(conn.topic, conn.msgtype))
        for conn, stamp, raw in reader.messages():
            td = data[conn.topic]
            td.recv.append(stamp)
            if conn.msgtype not in DECODED:
                continue
            _add_message(td, conn.msgtype, typestore.deserialize_cdr(raw, conn.msgtype))
    finally:
        reader.close()
    return data


def _add_message(td, msgtype, msg):
    """The fields of one decoded message (of :data:`DECODED`) that ``td`` keeps."""
    if msgtype == "sensor_msgs/msg/JointState":
        td.stamp.append(_stamp(msg.header))
        td.values.append(np.array(msg.position, dtype=float))
        td.velocity.append(np.array(msg.velocity, dtype=float))
        if td.names is None:
            td.names = list(msg.name)
    elif msgtype == "std_msgs/msg/Float64MultiArray":
        td.values.append(np.array(msg.data, dtype=float))
        td.labels.append(msg.layout.dim[0].label if msg.layout.dim else "")
        if td.dims is None:
            td.dims = [(d.label, int(d.size)) for d in msg.layout.dim]
    elif msgtype == "std_msgs/msg/Float64":
        td.values.append(float(msg.data))
    elif msgtype == "diagnostic_msgs/msg/DiagnosticArray":
        td.last_status = getattr(td, "last_status", {})
        for status in msg.status:
            td.last_status[status.name] = {kv.key: kv.value for kv in status.values}
    else:  # Clock
        td.stamp.append(msg.clock.sec + 1e-9 * msg.clock.nanosec)


def _add_send_stamps(data, sent):
    """The publishers' send stamps and sequence numbers (from :func:`_verify`), where the
    bag holds them for every message of a topic."""
    for topic, rows in sent.items():
        td = data.get(topic)
        if td is None or len(rows) != td.count or all(r[1] == r[0] for r in rows):
            continue            # no send stamps (a bag written by another tool)
        rows.sort(key=lambda r: r[0])     # rosbags yields receive-stamp order
        td.sent = [r[1] for r in rows]
        td.seq = [r[2] for r in rows]


def summary(data):
    """Per-topic counts and rates, and the bag's duration.

    Returns
    -------
    dict
        ``{"duration_s", "messages", "sim_duration_s", "topics": {name: {type, count,
        rate_hz}}}``; ``rate_hz`` is (count - 1) / (last - first receive stamp).
    """
    out = {"topics": {}}
    first, last, total = None, None, 0
    for name, td in sorted(data.items()):
        rate = None
        if td.count >= 2 and td.recv[-1] > td.recv[0]:
            rate = (td.count - 1) / (1e-9 * (td.recv[-1] - td.recv[0]))
        out["topics"][name] = {"type": td.msgtype, "count": td.count, "rate_hz": rate}
        total += td.count
        if td.count:
            first = td.recv.min() if first is None else min(first, td.recv.min())
            last = td.recv.max() if last is None else max(last, td.recv.max())
    out["messages"] = total
    diag = data.get(topics.DIAGNOSTICS)
    out["diagnostics"] = dict(getattr(diag, "last_status", {})) if diag is not None else {}
    out["duration_s"] = 0.0 if first is None else 1e-9 * float(last - first)
    clock = data.get(topics.CLOCK)
    out["sim_duration_s"] = (float(clock.stamp[-1] - clock.stamp[0])
                             if clock is not None and clock.count >= 1 else None)
    return out


def format_summary(path, summ):
    """The summary as text: ``ros2 bag info``'s header, then counts, rates and checks."""
    lines = []
    if summ.get("info"):
        lines += [summ["info"], ""]
    lines += [f"Bag:       {path}",
              f"Duration:  {summ['duration_s']:.3f} s (message stamps)"]
    if summ["sim_duration_s"] is not None:
        lines.append(f"Sim time:  {summ['sim_duration_s']:.3f} s (/clock)")
    lines.append(f"Messages:  {summ['messages']}")
    width = max([len(n) for n in summ["topics"]] + [5])
    lines.append(f"  {'topic':<{width}}  {'type':<36} {'count':>8} {'rate (Hz)':>10}")
    for name, info in summ["topics"].items():
        rate = "-" if info["rate_hz"] is None else f"{info['rate_hz']:.1f}"
        lines.append(f"  {name:<{width}}  {info['type']:<36} {info['count']:>8} {rate:>10}")
    if summ.get("diagnostics"):
        lines.append("Diagnostics (last message per status):")
        for name, values in summ["diagnostics"].items():
            shown = ", ".join(f"{k}={v}" for k, v in values.items() if k in DIAG_KEYS)
            lines.append(f"  {name}: {shown}")
    if summ.get("checks"):
        lines.append(f"Checked:   {', '.join(summ['checks'])}")
    return "\n".join(lines)
