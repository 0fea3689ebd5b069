"""``rcac inspect``: verify and summarise a bag of the package's topics, compute metrics, plot.

The bag (or the single bag in a folder) is first verified (:func:`.verify.verify`: CRCs, counts,
sqlite's integrity check); a damaged or cut bag is one line and exit 2, and ``--recover``
salvages it (:func:`.recover.recover`). The summary starts with the header ``ros2 bag info``
prints, then lists every topic (type, count, rate from the message stamps) and the bag's
duration. The metrics are those of ``rcac experiment`` that the bag allows (tracking errors,
estimate errors against the model's true parameters, prediction error, torques) plus the loop
timing (period between joint states, latency from a joint state to the effort that answers
it), from the publishers' send stamps when the bag holds them.

Times on the plots are simulated time: a joint state carries it in its header;
the controller's outputs take the header stamp of the ``desired_state`` published
in the same callback (nearest receive stamp), else that of the latest joint
state received before them.
"""

import json
import os

import numpy as np

from rcac_ros import topics
from rcac_ros.errors import BagError, ConfigError
from rcac_ros.tools import metrics as measure
from rcac_ros.tools.args import positive_int
from rcac_ros.tools.bags.recover import default_recovered_path, format_recovery, recover
from rcac_ros.tools.bags.verify import bag_info, find_bag, Report, verify

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


def _latest_before(ref_recv, ref_t, recv):
    idx = np.searchsorted(ref_recv, recv, side="right") - 1
    return ref_t[np.clip(idx, 0, len(ref_t) - 1)]


def _nearest(ref_recv, ref_t, recv):
    idx = np.clip(np.searchsorted(ref_recv, recv), 1, len(ref_recv) - 1) if len(ref_recv) > 1 \
        else np.zeros(len(recv), dtype=int)
    if len(ref_recv) > 1:
        left = np.abs(recv - ref_recv[idx - 1]) <= np.abs(ref_recv[idx] - recv)
        idx = np.where(left, idx - 1, idx)
    return ref_t[idx]


class Timeline:
    """Maps receive stamps to simulated time (see the module docstring).

    Stamps that look like wall-clock time (a timer-mode controller on a real arm) are
    shifted to start at 0 at the first joint state.
    """

    def __init__(self, data, controller_node=topics.CONTROLLER_NODE):
        self.t0_recv = min((td.recv[0] for td in data.values() if td.count), default=0)
        js = data.get(topics.resolve(topics.JOINT_STATES))
        ds = data.get(topics.resolve(topics.DESIRED_STATE, controller_node))
        clock = data.get(topics.CLOCK)
        self.state = None
        if js is not None and js.count and np.any(js.stamp != 0.0):
            self.state = (js.recv, js.stamp)
        elif clock is not None and clock.count:
            self.state = (clock.recv, clock.stamp)
        self.controller = None
        if ds is not None and ds.count and np.any(ds.stamp != 0.0):
            self.controller = (ds.recv, ds.stamp)
        self.offset = 0.0
        if self.state is not None and self.state[1][0] > 1e6:
            self.offset = float(self.state[1][0])

    def _shift(self, t):
        return np.asarray(t, dtype=float) - self.offset

    def state_time(self, td):
        """Time of simulator-side messages (joint states, clock)."""
        if td.msgtype in ("sensor_msgs/msg/JointState", "rosgraph_msgs/msg/Clock") \
                and td.count and np.any(td.stamp != 0.0):
            return self._shift(td.stamp)
        if self.state is not None:
            return self._shift(_latest_before(*self.state, td.recv))
        return 1e-9 * (td.recv - self.t0_recv)

    def controller_time(self, td, tagged=None):
        """Time of controller outputs (the state they answer).

        ``tagged`` (s, NaN where absent) are stamps carried by the messages themselves
        (the lockstep tag of an effort); they win where present.
        """
        if self.controller is not None:
            t = _nearest(*self.controller, td.recv)
        elif self.state is not None:
            t = _latest_before(*self.state, td.recv)
        else:
            return 1e-9 * (td.recv - self.t0_recv)
        if tagged is not None:
            t = np.where(np.isnan(tagged), t, tagged)
        return self._shift(t)


def effort_tags(td):
    """Lockstep tags of effort commands (see ``rcac_ros.topics.effort_label``).

    Returns
    -------
    watchdog : ndarray of bool
        Safe efforts the controller's watchdog sent (not answers to a state).
    stamp : ndarray of float
        The stamp (s) of the state an effort answers, NaN when untagged.
    """
    watchdog = np.zeros(td.count, dtype=bool)
    stamp = np.full(td.count, np.nan)
    for k, label in enumerate(td.labels):
        tag = topics.effort_tag(label)
        if tag is not None and tag[0] == "watchdog":
            watchdog[k] = True
        elif tag is not None:
            sec, nsec = divmod(tag[1], 1_000_000_000)
            stamp[k] = sec + 1e-9 * nsec     # as _stamp(header): matched to state stamps
    return watchdog, stamp


def _first_copies(keys):
    """Mask of the first occurrence of every key (NaN keys are always kept)."""
    keys = np.asarray(keys, dtype=float)
    keep = np.ones(len(keys), dtype=bool)
    seen = set()
    for k, key in enumerate(keys):
        if np.isnan(key):
            continue
        if key in seen:
            keep[k] = False
        seen.add(key)
    return keep


def _subset(td, mask):
    out = TopicData(td.name, td.msgtype)
    out.recv = td.recv[mask]
    out.values = td.values[mask] if isinstance(td.values, np.ndarray) else \
        [v for v, m in zip(td.values, mask) if m]
    out.labels = td.labels[mask] if len(td.labels) == len(mask) else td.labels
    out.stamp = td.stamp[mask] if len(td.stamp) == len(mask) else td.stamp
    if isinstance(td.velocity, np.ndarray) and len(td.velocity) == len(mask):
        out.velocity = td.velocity[mask]
    if td.sent is not None:
        out.sent, out.seq = td.sent[mask], td.seq[mask]
    out.names = td.names
    out.dims = td.dims
    return out


def loop_timing(data, eff=None, js=None, tagged=None):
    """Period between joint states and state -> effort latency.

    The times are the publishers' send stamps when the bag holds them (an mcap written by
    ``rcac record``): the simulator's publish times and the controller's, on the same host
    clock. Otherwise they are the recorder's receive stamps, which a descheduled recorder
    takes in a burst for messages queued meanwhile: a cluster near 0 ms that is the
    recorder's, not the loop's.

    With ``tagged`` (the stamp, s, of the state each effort answers: the lockstep tag)
    a state is paired with the effort that answers it; otherwise with the first effort
    received after it and before the next joint state. Unanswered states are counted.
    ``eff`` (default the bag's effort topic) should hold only the controller's answers,
    not watchdog efforts.

    Returns
    -------
    dict or None
        ``{"period_ms": array, "latency_ms": array, "unanswered": int, "clock": str}``;
        ``clock`` is ``"send"`` or ``"receive"``.
    """
    js = data.get("/" + topics.JOINT_STATES) if js is None else js
    eff = data.get("/" + topics.EFFORT_COMMANDS) if eff is None else eff
    if js is None or js.count < 2:
        return None
    send = js.sent is not None and (eff is None or not eff.count or eff.sent is not None)
    js_t = js.sent if send else js.recv
    eff_t = None if eff is None else (eff.sent if send else eff.recv)
    period = 1e-6 * np.diff(js_t).astype(float)
    latency = np.empty(0)
    unanswered = js.count
    if eff is not None and eff.count and tagged is not None and len(js.stamp) == js.count \
            and np.all(np.isfinite(tagged)):
        answer = {int(round(t * 1e9)): r for t, r in zip(tagged, eff_t)}
        keys = [int(round(t * 1e9)) for t in js.stamp]
        ok = np.array([k in answer for k in keys], dtype=bool)
        latency = 1e-6 * np.array([answer[k] - r for k, r in zip(keys, js_t) if k in answer],
                                  dtype=float)
        unanswered = int(np.count_nonzero(~ok))
    elif eff is not None and eff.count:
        idx = np.searchsorted(eff.recv, js.recv, side="left")
        ok = idx < eff.count
        nxt = np.append(js.recv[1:], np.iinfo(np.int64).max)
        ok[ok] &= eff.recv[idx[ok]] < nxt[ok]
        latency = 1e-6 * (eff.recv[idx[ok]] - js.recv[ok]).astype(float)
        unanswered = int(np.count_nonzero(~ok))
    return {"period_ms": period, "latency_ms": latency, "unanswered": unanswered,
            "clock": "send" if send else "receive"}


def sequence_gaps(td):
    """Messages the publisher numbered that are not in the bag (None: not known).

    From the publication sequence numbers an mcap written by ``rcac record`` holds; only
    for a topic with one publisher (numbers that increase).
    """
    if td is None or td.seq is None or td.count < 2 or np.any(td.seq == 0):
        return None
    d = np.diff(td.seq)
    if np.any(d <= 0):
        return None
    return int(np.sum(d - 1))


def load_truth(model):
    """The true parameters (n, 13) of ``model`` (a preset, "none", a YAML or URDF path)."""
    if model in (None, "", "none"):
        return None
    from rcac_ros.core.load import is_urdf, load_model
    from rcac_ros.core.model import PRESETS
    if model not in PRESETS and not is_urdf(model) and not os.path.exists(model):
        raise ConfigError(f"model: {model} is neither a preset ({', '.join(PRESETS)}), 'none' "
                          "nor an existing file")
    return load_model(model).theta()


def _estimates(td):
    """Parameter estimates as (T, n, 13), using the layout dims when present."""
    vals = td.values
    if not isinstance(vals, np.ndarray) or vals.ndim != 2 or vals.shape[1] % 13:
        raise BagError(f"bag: {td.name} does not hold n x 13 parameter estimates")
    n = vals.shape[1] // 13
    if td.dims and len(td.dims) == 2 and td.dims[0][1] * td.dims[1][1] == vals.shape[1]:
        n = td.dims[0][1]
    return vals.reshape(len(vals), n, -1)


def analyse(data, theta_true=None, controller_node=topics.CONTROLLER_NODE):
    """Metrics of ``rcac experiment`` that the bag allows, and the series to plot.

    Parameters
    ----------
    data : dict
        From :func:`read_bag`.
    theta_true : ndarray (n, 13), optional
        True parameters, for the estimate errors.
    controller_node : str

    Returns
    -------
    metrics : dict
    series : dict
        name -> (t, values) for the plots.
    """
    tl = Timeline(data, controller_node)
    metrics, series = {}, {}
    _tracking(data, tl, controller_node, metrics, series)
    eff, tagged, effort_counts = _efforts(data, tl, metrics, series)
    _estimates_and_predictions(data, tl, controller_node, theta_true, metrics, series)
    js = _joint_states(data, tl, metrics)
    if eff is not None:
        metrics.update(effort_counts)
    _timing(data, eff, js, tagged, metrics, series)
    return metrics, series


def _tracking(data, tl, controller_node, metrics, series):
    """``~/tracking_error``: the tracking metrics."""
    te = data.get(topics.resolve(topics.TRACKING_ERROR, controller_node))
    if te is not None and te.count and isinstance(te.values, np.ndarray):
        t, e = tl.controller_time(te), te.values
        series["tracking_error"] = (t, e)
        metrics.update(measure.tracking(t, e))


def _efforts(data, tl, metrics, series):
    """The effort commands: the watchdog's and the repeated answers set apart, the torque
    metrics of the others. Returns those (:class:`TopicData` or ``None``), their tags and
    their counts (metrics added by :func:`analyse` after the joint states')."""
    eff = data.get("/" + topics.EFFORT_COMMANDS)
    watchdog_efforts = 0
    repeated_answers = 0
    tagged = None
    missed = sequence_gaps(eff)
    if missed is not None:
        metrics["recorder_missed_efforts"] = missed
    if eff is not None and eff.count:
        watchdog, tagged = effort_tags(eff)
        watchdog_efforts = int(np.count_nonzero(watchdog))
        eff = _subset(eff, ~watchdog)
        tagged = tagged[~watchdog]
        first = _first_copies(tagged)   # a re-sent state is answered again: keep one answer
        repeated_answers = int(np.count_nonzero(~first))
        eff = _subset(eff, first)
        tagged = tagged[first]
    if eff is not None and eff.count and isinstance(eff.values, np.ndarray):
        series["effort"] = (tl.controller_time(eff, tagged), eff.values)
        metrics.update(measure.torque(eff.values))
    counts = {"effort_commands": None if eff is None else eff.count,
              "watchdog_efforts": watchdog_efforts, "repeated_answers": repeated_answers}
    return eff, tagged, counts


def _estimates_and_predictions(data, tl, controller_node, theta_true, metrics, series):
    """``~/parameter_estimates`` (errors against ``theta_true``), ``~/prediction_error``
    and every channel's ``~/prediction_errors``."""
    pe = data.get(topics.resolve(topics.PARAMETER_ESTIMATES, controller_node))
    if pe is not None and pe.count:
        est = _estimates(pe)
        series["parameter_estimates"] = (tl.controller_time(pe), est)
        if theta_true is not None and theta_true.shape == est.shape[1:]:
            metrics.update(measure.estimates(est, theta_true))
    pr = data.get(topics.resolve(topics.PREDICTION_ERROR, controller_node))
    if pr is not None and pr.count:
        series["prediction_error"] = (tl.controller_time(pr), pr.values)
        metrics.update(measure.prediction(pr.values))
    # every channel (older bags: none)
    prs = data.get(topics.resolve(topics.PREDICTION_ERRORS, controller_node))
    if prs is not None and prs.count and isinstance(prs.values, np.ndarray) \
            and prs.values.ndim == 2:
        names = topics.channel_names(prs.dims[0][0]) if prs.dims else []
        if len(names) != prs.values.shape[1]:
            names = [f"channel {c + 1}" for c in range(prs.values.shape[1])]
        series["prediction_errors"] = (tl.controller_time(prs), prs.values, names)
        for name, e in zip(names, prs.values[-1]):
            metrics[f"final_abs_prediction_error_{name.replace(' ', '_')}"] = float(abs(e))


def _joint_states(data, tl, metrics):
    """The joint states (a re-sent first one set apart): the simulated time span and
    counts. Returns them (:class:`TopicData` or ``None``)."""
    js = data.get("/" + topics.JOINT_STATES)
    resent_states = 0
    if js is not None and js.count and np.any(js.stamp != 0.0):
        first = _first_copies(js.stamp)     # a lockstep simulator may re-send its first state
        resent_states = int(np.count_nonzero(~first))
        js = _subset(js, first)
    if js is not None and js.count:
        ts = tl.state_time(js)
        metrics["sim_time_start_s"] = float(ts[0])
        metrics["sim_time_end_s"] = float(ts[-1])
        metrics["joint_states"] = js.count
        metrics["resent_states"] = resent_states
    return js


def _timing(data, eff, js, tagged, metrics, series):
    """The loop timing (:func:`loop_timing`): state periods and state-to-effort latencies."""
    timing = loop_timing(data, eff, js, tagged)
    if timing is not None:
        series["timing"] = timing
        for key, prefix in (("period_ms", "state_period"),
                            ("latency_ms", "state_to_effort_latency")):
            if len(timing[key]):
                metrics.update(measure.percentiles(timing[key], prefix))
        metrics["unanswered_states"] = timing["unanswered"]
        metrics["timing_stamps"] = timing["clock"]


def notes(metrics, summ):
    """Plain-language explanations of figures that look alarming (list of lines)."""
    out = []
    unanswered = metrics.get("unanswered_states", 0)
    if unanswered:
        missed = metrics.get("recorder_missed_efforts")
        sim = (summ.get("diagnostics") or {}).get("rcac_simulator: simulation") or \
            next((v for k, v in (summ.get("diagnostics") or {}).items()
                  if "simulat" in k), {})
        held = sim.get("lockstep_misses")
        text = (f"unanswered_states {unanswered}: joint states whose answering effort is not "
                "in the bag.")
        if missed:
            text += (f" The recorder missed {missed} effort messages (gaps in the controller's "
                     "publication sequence numbers): efforts are published reliable keep-last "
                     "10, so a recorder descheduled for more than 10 messages loses some.")
        if held is not None:
            text += (f" The simulator held an effort {held} times (lockstep_misses)"
                     + (": the controller answered every state it received; the gap is the "
                        "recorder's." if str(held) == "0" else "."))
        out.append(text)
    if metrics.get("timing_stamps") == "receive":
        out.append("loop timing from the recorder's receive stamps: a descheduled recorder "
                   "stamps queued messages in a burst (the cluster near 0 ms)")
    return out


def joint_names(data):
    js = data.get("/" + topics.JOINT_STATES)
    return js.names if js is not None else None


def plot_timing(timing, path):
    """Histograms of the joint-state period and the state -> effort latency, captioned with
    the stamps they come from (see :func:`loop_timing`)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rcac_ros.tools.plots import save

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, key, title in ((axes[0], "period_ms", "period between joint states"),
                           (axes[1], "latency_ms", "joint state -> effort latency")):
        x = timing[key]
        if len(x):
            hi = np.percentile(x, 99.9) * 1.2 + 1e-3
            ax.hist(np.clip(x, 0, hi), bins=80, range=(0, hi), color="C0")
            ax.axvline(np.median(x), color="C1", ls="--",
                       label=f"median {np.median(x):.3f} ms")
            ax.axvline(np.percentile(x, 99), color="C3", ls=":",
                       label=f"p99 {np.percentile(x, 99):.3f} ms")
            ax.legend()
        ax.set_xlabel("ms")
        ax.set_ylabel("count")
        ax.set_title(title)
    if timing.get("clock") == "send":
        caption = ("From the publishers' send stamps (simulator: joint state published; "
                   "controller: effort published), same host clock.")
    else:
        caption = ("From the recorder's receive stamps: when the recorder is descheduled, the "
                   "messages queued meanwhile are stamped together,\nso a cluster near 0 ms "
                   "is the recorder catching up, not the loop.")
    fig.text(0.01, 0.01, caption, fontsize=8, va="bottom")
    save(fig, path, 110, rect=(0, 0.08, 1, 1))


def write_plots(series, out_dir, theta_true=None, names=None, link=None, label="ROS 2"):
    """Write the figures of the offline experiment from the bag's series.

    Returns
    -------
    list of str
        Paths written.
    """
    from rcac_ros.tools import plots

    os.makedirs(out_dir, exist_ok=True)
    written = []
    if "tracking_error" in series:
        t, e = series["tracking_error"]
        path = os.path.join(out_dir, "tracking_errors.png")
        plots.plot_tracking_errors(t, {label: e}, path, joint_names=names)
        written.append(path)
    if "effort" in series:
        t, tau = series["effort"]
        path = os.path.join(out_dir, "efforts.png")
        plots.plot_series(t, {label: tau}, path, "joint efforts (effort_controller/commands)",
                          "torque (N m)", legend=names)
        written.append(path)
    if "parameter_estimates" in series:
        t, est = series["parameter_estimates"]
        k = est.shape[1] - 1 if link is None else link - 1
        if not 0 <= k < est.shape[1]:
            raise ConfigError(f"link: must be in 1..{est.shape[1]}, got {link}")
        truth = None
        if theta_true is not None and theta_true.shape == est.shape[1:]:
            truth = theta_true[k]
        path = os.path.join(out_dir, f"estimates_link{k + 1}.png")
        plots.plot_parameter_estimates(t, {label: est[:, k, :]}, truth, path, link=k + 1)
        written.append(path)
    if "prediction_error" in series:
        t, pr = series["prediction_error"]
        path = os.path.join(out_dir, "prediction_error.png")
        plots.plot_series(t, {label: np.asarray(pr).reshape(-1, 1)}, path,
                          "prediction error |E| (eq 24), log scale", "|E| (N m)", logy=True)
        written.append(path)
    if "prediction_errors" in series:
        t, prs, channels = series["prediction_errors"]
        path = os.path.join(out_dir, "prediction_errors.png")
        plots.plot_series(t, {label: prs}, path,
                          "prediction error |E_c| per channel (eq 24), log scale",
                          "|E_c| (N m; W for power)", logy=True, legend=channels)
        written.append(path)
    if "timing" in series:
        path = os.path.join(out_dir, "loop_timing.png")
        plot_timing(series["timing"], path)
        written.append(path)
    return written


def inspect(path, plots_dir=None, model="css_arm", link=None,
            controller_node=topics.CONTROLLER_NODE):
    """Read, summarise and (optionally) plot a bag; write metrics.json beside the plots.

    Returns
    -------
    dict
        ``{"summary", "metrics", "plots", "metrics_path"}``.
    """
    theta_true = load_truth(model)               # a bad --model stops before the bag is read
    path = find_bag(path)
    report = Report(path, "")
    data = read_bag(path, report)
    summ = summary(data)
    summ["info"] = bag_info(path)
    summ["checks"] = list(report.checks)
    metrics, series = analyse(data, theta_true, controller_node)
    result = {"summary": summ, "metrics": metrics, "plots": [], "metrics_path": None,
              "bag": path, "notes": notes(metrics, summ)}
    if plots_dir is not None:
        result["plots"] = write_plots(series, plots_dir, theta_true, joint_names(data), link)
        result["metrics_path"] = os.path.join(plots_dir, "metrics.json")
        with open(result["metrics_path"], "w") as f:
            json.dump({"bag": os.path.abspath(path), "summary": summ, "metrics": metrics}, f,
                      indent=2)
    return result


def format_metrics(metrics):
    width = max([len(k) for k in metrics] + [1])
    lines = []
    for key, value in metrics.items():
        text = f"{value:.6g}" if isinstance(value, float) else str(value)
        lines.append(f"  {key:<{width}}  {text}")
    return "\n".join(lines)


def add_arguments(parser):
    parser.add_argument("bag", help="rosbag2 directory (or a folder holding one bag)")
    parser.add_argument("--recover", action="store_true",
                        help="salvage a bag cut by a crash or damaged (complete mcap chunks, "
                             "committed sqlite transactions) into a new bag, then inspect it")
    parser.add_argument("--recover-out", default=None, metavar="DIR",
                        help="the recovered bag (default: BAG_recovered)")
    parser.add_argument("--plots", default=None, metavar="DIR",
                        help="write the figures and metrics.json into DIR")
    parser.add_argument("--model", default="css_arm",
                        help="true model for the estimate errors: 'css_arm' (default, the paper's "
                             "arm), 'none', or a model YAML / URDF")
    parser.add_argument("--link", type=positive_int, default=None,
                        help="link (1-based) whose estimates are plotted (default: the last)")
    parser.add_argument("--controller-node", default=topics.CONTROLLER_NODE,
                        help=f"controller node name (default: {topics.CONTROLLER_NODE})")


def run(args):
    bag = args.bag
    if args.recover:
        bag = find_bag(bag)
        report = recover(bag, args.recover_out or default_recovered_path(bag))
        print(format_recovery(bag, report), flush=True)
        bag = report.path
    result = inspect(bag, args.plots, args.model, args.link, args.controller_node)
    print(format_summary(result["bag"], result["summary"]))
    if result["metrics"]:
        print("Metrics:")
        print(format_metrics(result["metrics"]))
    for line in result["notes"]:
        print(f"Note: {line}")
    for path in result["plots"]:
        print(f"wrote {path}")
    if result["metrics_path"]:
        print(f"wrote {result['metrics_path']}")
    return 0
