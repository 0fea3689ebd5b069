"""The metrics and the loop timing of a bag read by :mod:`.read` (``rcac inspect``).

The metrics are those of ``rcac experiment`` that the bag allows (tracking errors, estimate
errors against the model's true parameters, prediction error, torques) plus the loop timing
(period between joint states, latency from a joint state to the effort that answers it),
from the publishers' send stamps when the bag holds them.

Times are simulated time: a joint state carries it in its header; the controller's outputs
take the header stamp of the ``desired_state`` published in the same callback (nearest
receive stamp), else that of the latest joint state received before them.
"""

import os

import numpy as np

from rcac_ros import topics
from rcac_ros.errors import BagError, ConfigError
from rcac_ros.tools.runs import metrics as measure
from rcac_ros.tools.bags.read import TopicData


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
