"""Bags: ``rcac inspect`` on a synthetic bag, ``rcac record`` during a two-node run, SIGINT."""

import json
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from bagtest_support import read_rosbags, ros_env  # noqa: F401 - a fixture

from rcac_ros import topics
from rcac_ros.core.model import css_arm

PY = sys.executable
N = 7
DT_NS = 2_000_000      # 500 Hz
LAT_NS = 300_000       # state -> effort, 0.3 ms
T0_NS = 1_700_000_000_000_000_000
WATCHDOG = 5           # watchdog efforts before the first state


def _typestore():
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


def _time(ts, ns):
    time_type = ts.types["builtin_interfaces/msg/Time"]
    return time_type(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _multiarray(ts, data, dims):
    types = ts.types
    layout = types["std_msgs/msg/MultiArrayLayout"](
        dim=[types["std_msgs/msg/MultiArrayDimension"](label=label, size=size, stride=size)
             for label, size in dims], data_offset=0)
    return types["std_msgs/msg/Float64MultiArray"](layout=layout, data=np.asarray(data, float))


def _joint_state(ts, sim_ns, q, qd, effort):
    types = ts.types
    header = types["std_msgs/msg/Header"](stamp=_time(ts, sim_ns), frame_id="")
    return types["sensor_msgs/msg/JointState"](
        header=header, name=[f"joint{i + 1}" for i in range(N)],
        position=np.asarray(q, float), velocity=np.asarray(qd, float),
        effort=np.asarray(effort, float))


def write_synthetic_bag(path, steps, storage="mcap"):
    """A lockstep-like bag with known contents; returns the data that went in."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    ts = _typestore()
    types = ts.types
    rng = np.random.default_rng(3)
    ctrl = f"/{topics.CONTROLLER_NODE}/"
    spec = {
        "/joint_states": "sensor_msgs/msg/JointState",
        "/clock": "rosgraph_msgs/msg/Clock",
        "/effort_controller/commands": "std_msgs/msg/Float64MultiArray",
        ctrl + "tracking_error": "std_msgs/msg/Float64MultiArray",
        ctrl + "parameter_estimates": "std_msgs/msg/Float64MultiArray",
        ctrl + "prediction_error": "std_msgs/msg/Float64",
        ctrl + "prediction_errors": "std_msgs/msg/Float64MultiArray",
        ctrl + "desired_state": "sensor_msgs/msg/JointState",
        "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    }
    truth = css_arm().theta()
    errors = rng.normal(0.0, 1e-3, (steps, N))
    torques = rng.normal(0.0, 5.0, (steps, N))
    estimates = truth * np.linspace(0.0, 0.9, steps)[:, None, None]
    pred = rng.normal(0.0, 1.0, steps)
    preds = np.column_stack([pred, rng.normal(0.0, 10.0, steps)])  # channels joint1, power
    writer = Writer(path, version=9,
                    storage_plugin=StoragePlugin.MCAP if storage == "mcap"
                    else StoragePlugin.SQLITE3)
    writer.open()
    conns = {name: writer.add_connection(name, t, typestore=ts) for name, t in spec.items()}

    def put(name, stamp, msg):
        writer.write(conns[name], stamp, ts.serialize_cdr(msg, spec[name]))

    for k in range(WATCHDOG):   # the controller's safe efforts before the first state
        put("/effort_controller/commands", T0_NS - (WATCHDOG - k) * 10_000_000,
            _multiarray(ts, np.full(N, 1e6), [("joint watchdog", N)]))
    for k in range(steps):
        sim = k * DT_NS
        recv = T0_NS + k * DT_NS
        q = np.full(N, 0.01 * k)
        put("/clock", recv, types["rosgraph_msgs/msg/Clock"](clock=_time(ts, sim)))
        put("/joint_states", recv + 10_000, _joint_state(ts, sim, q, np.zeros(N), np.zeros(N)))
        r = recv + 10_000 + LAT_NS
        put(ctrl + "desired_state", r - 50_000,
            _joint_state(ts, sim, q - errors[k], np.zeros(N), np.zeros(N)))
        put(ctrl + "tracking_error", r - 40_000, _multiarray(ts, errors[k], [("joint", N)]))
        put(ctrl + "parameter_estimates", r - 30_000,
            _multiarray(ts, estimates[k].ravel(), [("link", N), ("parameter", 13)]))
        put(ctrl + "prediction_error", r - 20_000, types["std_msgs/msg/Float64"](data=pred[k]))
        put(ctrl + "prediction_errors", r - 20_000,
            _multiarray(ts, preds[k], [("joint1,power", 2)]))
        tag = f"joint stamp={sim // 1_000_000_000}.{sim % 1_000_000_000:09d}"
        put("/effort_controller/commands", r, _multiarray(ts, torques[k], [(tag, N)]))
        if k == 0:   # the simulator re-sends its first state; the controller answers again
            put("/joint_states", recv + 1_000_000,
                _joint_state(ts, sim, q, np.zeros(N), np.zeros(N)))
            put("/effort_controller/commands", recv + 1_300_000,
                _multiarray(ts, torques[k], [(tag, N)]))
        if k % 500 == 0:
            header = types["std_msgs/msg/Header"](stamp=_time(ts, sim), frame_id="")
            put("/diagnostics", recv + 100_000,
                types["diagnostic_msgs/msg/DiagnosticArray"](header=header, status=[]))
    writer.close()
    return {"errors": errors, "torques": torques, "estimates": estimates, "pred": pred,
            "preds": preds, "truth": truth, "spec": spec}


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_inspect_synthetic_bag(tmp_path, storage, capsys):
    from rcac_ros.tools.cli import main
    steps = 3000                       # 6 s of simulated time at 500 Hz
    bag = str(tmp_path / "bag")
    known = write_synthetic_bag(bag, steps, storage)
    plots = tmp_path / "plots"
    assert main(["inspect", bag, "--plots", str(plots)]) == 0
    out = capsys.readouterr().out

    # the summary: every topic with its count and its rate from the receive stamps
    for name, msgtype in known["spec"].items():
        count = steps if name != "/diagnostics" else (steps + 499) // 500
        count += WATCHDOG + 1 if name == "/effort_controller/commands" else 0
        count += 1 if name == "/joint_states" else 0
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(name + " "))
        fields = line.split()
        assert fields[1] == msgtype
        assert int(fields[2]) == count
        if name not in ("/diagnostics", "/effort_controller/commands"):
            assert float(fields[3]) == pytest.approx(500.0, abs=0.2)
    assert "Duration:" in out and "Sim time:" in out

    # metrics computed independently from what went into the bag
    doc = json.loads((plots / "metrics.json").read_text())
    m = doc["metrics"]
    e, tau, est, truth = known["errors"], known["torques"], known["estimates"], known["truth"]
    assert m["rms_tracking_error"] == pytest.approx(np.sqrt(np.mean(e ** 2)), rel=1e-12)
    assert m["max_tracking_error"] == pytest.approx(np.abs(e).max(), rel=1e-12)
    last = np.arange(steps) * 0.002 >= (steps - 1) * 0.002 - 5.0
    assert m["rms_tracking_error_last_5s"] == pytest.approx(np.sqrt(np.mean(e[last] ** 2)))
    assert m["max_abs_torque"] == pytest.approx(np.abs(tau).max(), rel=1e-12)
    assert m["parameter_error_norm_start"] == pytest.approx(np.linalg.norm(truth), rel=1e-12)
    assert m["parameter_error_norm_end"] == pytest.approx(
        np.linalg.norm(est[-1] - truth), rel=1e-12)
    assert m["link7_parameter_error_norm_end"] == pytest.approx(
        np.linalg.norm(est[-1, 6] - truth[6]), rel=1e-12)
    assert m["final_abs_prediction_error"] == pytest.approx(abs(known["pred"][-1]))
    # every channel's E (~/prediction_errors), named by the layout's label
    assert m["final_abs_prediction_error_joint1"] == abs(known["preds"][-1, 0])
    assert m["final_abs_prediction_error_power"] == abs(known["preds"][-1, 1])
    assert m["state_to_effort_latency_p50_ms"] == pytest.approx(LAT_NS * 1e-6, abs=1e-6)
    assert m["state_period_p50_ms"] == pytest.approx(DT_NS * 1e-6, abs=1e-6)
    assert m["unanswered_states"] == 0
    assert m["effort_commands"] == steps and m["watchdog_efforts"] == WATCHDOG
    assert m["joint_states"] == steps and m["resent_states"] == 1
    assert m["repeated_answers"] == 1
    assert m["sim_time_end_s"] == pytest.approx((steps - 1) * 0.002)
    assert doc["summary"]["topics"]["/joint_states"]["count"] == steps + 1

    # the figures exist and are PNG images
    for name in ("tracking_errors.png", "efforts.png", "estimates_link7.png",
                 "prediction_error.png", "prediction_errors.png", "loop_timing.png"):
        path = plots / name
        assert path.is_file(), name
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_inspect_rejects_missing_bag(tmp_path, capsys):
    from rcac_ros.tools.cli import main
    assert main(["inspect", str(tmp_path / "nope")]) == 2
    assert "bag:" in capsys.readouterr().err


# ---------------------------------------------------------------- live: two nodes + rcac record
class Procs:
    """Child processes, always stopped (SIGINT, then SIGKILL) at the end of a test."""

    def __init__(self, tmp_path, env):
        self.tmp_path, self.env, self.procs = tmp_path, env, []

    def start(self, name, cmd):
        path = self.tmp_path / f"{name}.log"
        with open(path, "w") as log:
            proc = subprocess.Popen(cmd, env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL)
        proc.log_path = path
        self.procs.append(proc)
        return proc

    def stop_all(self):
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()


def _output(proc):
    return proc.log_path.read_text()


def wait_for(cond, timeout, what, procs=()):
    end = time.monotonic() + timeout
    while not cond():
        for p in procs:
            assert p.poll() is None, f"{what}: a process exited early:\n{_output(p)}"
        assert time.monotonic() < end, f"timed out: {what}"
        time.sleep(0.05)


@pytest.fixture
def procs(tmp_path, ros_env):  # noqa: F811
    p = Procs(tmp_path, ros_env)
    yield p
    p.stop_all()


def _node(name, **over):
    from rcac_ros.tools.launch import node_command
    return node_command(name, overrides=over)


def _start_recorder(procs, bag):
    rec = procs.start("record", [PY, "-m", "rcac_ros.tools.cli", "record", "--out", str(bag)])
    wait_for(lambda: "recording" in _output(rec), 60, "recorder start", [rec])
    return rec


def _wait_controller_matched(rec, ctrl):
    """Wait until the recorder has matched every controller topic (endpoint discovery
    of a node with many endpoints takes a second or more on a loaded machine)."""
    names = [f"/{topics.CONTROLLER_NODE}/{t}" for t in
             ("parameter_estimates", "prediction_error", "tracking_error", "desired_state")]
    names.append("/" + topics.EFFORT_COMMANDS)
    wait_for(lambda: all(f"subscribed to {n}\n" in _output(rec) for n in names), 60,
             "recorder matched the controller", [rec, ctrl])


def _stamp_ns(t):
    return t.sec * 1_000_000_000 + t.nanosec


def test_record_two_node_lockstep_run(tmp_path, procs):
    """Every joint state in the recorded window has exactly one answer in the bag."""
    bag = tmp_path / "bag"
    duration = 2.0
    rec = _start_recorder(procs, bag)
    # a long watchdog timeout: no safe efforts interleaved with the answers
    ctrl = procs.start("controller", _node("controller", mode="lockstep", state_timeout=1.0))
    _wait_controller_matched(rec, ctrl)
    sim = procs.start("simulator", _node("simulator", mode="lockstep", duration=duration,
                                         min_subscribers=2))
    wait_for(lambda: sim.poll() is not None, 90, "simulator run", [rec, ctrl])
    assert sim.returncode == 0, _output(sim)
    ctrl.send_signal(signal.SIGINT)
    assert ctrl.wait(30) == 0
    rec.send_signal(signal.SIGINT)
    assert rec.wait(30) == 0, _output(rec)

    data = read_rosbags(str(bag))
    states = data["/joint_states"]
    stamps = [_stamp_ns(m.header.stamp) for _, m in states]
    steps = int(round(duration / 0.002))
    # the simulator publishes states 0..steps (state 0 possibly re-sent while discovery
    # settles); the recorder may join a few states late
    unique = sorted(set(stamps))
    assert unique == list(range(unique[0], steps * 2_000_000 + 1, 2_000_000))
    assert all(s == 0 for s in stamps if stamps.count(s) > 1)
    assert stamps == sorted(stamps)
    stamps = unique
    answers = {}
    for _, m in data["/effort_controller/commands"]:
        label = m.layout.dim[0].label
        if " stamp=" in label:
            sec, nsec = label.split(" stamp=")[1].split(".")
            answers.setdefault(int(sec) * 1_000_000_000 + int(nsec), []).append(m)
        assert len(m.data) == N
    # lockstep: one effort per state, within the recorded window
    answered = sorted(answers)
    lo = max(stamps[0], answered[0])
    # the recorder discovers the simulator while it starts: on a loaded machine it can
    # join a few hundred states late; the window must still be most of the run
    assert lo <= 0.6 * duration * 1e9
    assert [a for a in answered if a >= lo] == [s for s in stamps if s >= lo]
    for stamp, msgs in answers.items():   # one answer; a re-sent state 0 answered alike
        assert len(msgs) == 1 or (stamp == 0 and all(
            np.array_equal(m.data, msgs[0].data) for m in msgs)), stamp
    # /clock and the controller's monitors: one per step as well
    clock = [_stamp_ns(m.clock) for _, m in data["/clock"]]
    assert clock[-1] == stamps[-1] and len(set(clock)) == len(clock)
    desired = [_stamp_ns(m.header.stamp)
               for _, m in data[f"/{topics.CONTROLLER_NODE}/desired_state"]]
    # each of the controller's writers matches the recorder's reader on its own ("subscribed
    # to" is the reader's side): on a loaded machine one can match some states after the
    # others, and its stream is then the tail of the answers, joined within the same window
    assert desired == answered[len(answered) - len(desired):]
    assert desired[0] <= 0.6 * duration * 1e9
    for name in ("tracking_error", "parameter_estimates", "prediction_error"):
        count = len(data[f"/{topics.CONTROLLER_NODE}/{name}"])
        assert len([a for a in answered if a >= 0.6 * duration * 1e9]) <= count \
            <= len(answered), name
    est = data[f"/{topics.CONTROLLER_NODE}/parameter_estimates"][-1][1]
    assert [(d.label, d.size) for d in est.layout.dim] == [("link", N), ("parameter", 13)]
    # receive stamps increase per topic (the recorder writes in arrival order)
    for topic, msgs in data.items():
        assert all(a[0] <= b[0] for a, b in zip(msgs, msgs[1:])), topic


def test_sigint_during_recording_leaves_a_readable_bag(tmp_path, procs):
    bag = tmp_path / "bag"
    rec = _start_recorder(procs, bag)
    ctrl = procs.start("controller", _node("controller", mode="lockstep", state_timeout=1.0))
    _wait_controller_matched(rec, ctrl)
    procs.start("simulator", _node("simulator", mode="lockstep", duration=0.0))
    # mid-stream: the recorder reports every 5 s; wait for a report of 0.1 s of sim time or
    # more (the first /clock message alone can come just before a report)

    def recorded():
        times = re.findall(r"messages, sim time (\d+\.\d+) s", _output(rec))
        return bool(times) and float(times[-1]) >= 0.1
    wait_for(recorded, 90, "0.1 s of sim time recorded", [rec])
    rec.send_signal(signal.SIGINT)
    assert rec.wait(30) == 0, _output(rec)
    assert "closed" in _output(rec)
    data = read_rosbags(str(bag))          # every message deserialises
    assert len(data["/joint_states"]) > 10
    assert len(data["/clock"]) > 10
    assert len(data["/effort_controller/commands"]) > 10
    # the inspector reads it too
    from rcac_ros.tools.bags.inspect import inspect
    result = inspect(str(bag))
    assert result["summary"]["topics"]["/joint_states"]["count"] == len(data["/joint_states"])
