"""Bags: ``rcac inspect`` on a synthetic bag, ``rcac record`` during a two-node run, SIGINT."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from rcac_ros import topics
from rcac_ros.core.model import css_arm

PY = sys.executable
N = 7
DT_NS = 2_000_000      # 500 Hz
LAT_NS = 300_000       # state -> effort, 0.3 ms
T0_NS = 1_700_000_000_000_000_000


def _typestore():
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


def _time(ts, ns):
    Time = ts.types["builtin_interfaces/msg/Time"]
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _multiarray(ts, data, dims):
    T = ts.types
    layout = T["std_msgs/msg/MultiArrayLayout"](
        dim=[T["std_msgs/msg/MultiArrayDimension"](label=label, size=size, stride=size)
             for label, size in dims], data_offset=0)
    return T["std_msgs/msg/Float64MultiArray"](layout=layout, data=np.asarray(data, float))


def _joint_state(ts, sim_ns, q, qd, effort):
    T = ts.types
    header = T["std_msgs/msg/Header"](stamp=_time(ts, sim_ns), frame_id="")
    return T["sensor_msgs/msg/JointState"](
        header=header, name=[f"joint{i + 1}" for i in range(N)],
        position=np.asarray(q, float), velocity=np.asarray(qd, float),
        effort=np.asarray(effort, float))


def write_synthetic_bag(path, steps, storage="mcap"):
    """A lockstep-like bag with known contents; returns the data that went in."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    ts = _typestore()
    T = ts.types
    rng = np.random.default_rng(3)
    ctrl = f"/{topics.CONTROLLER_NODE}/"
    spec = {
        "/joint_states": "sensor_msgs/msg/JointState",
        "/clock": "rosgraph_msgs/msg/Clock",
        "/effort_controller/commands": "std_msgs/msg/Float64MultiArray",
        ctrl + "tracking_error": "std_msgs/msg/Float64MultiArray",
        ctrl + "parameter_estimates": "std_msgs/msg/Float64MultiArray",
        ctrl + "prediction_error": "std_msgs/msg/Float64",
        ctrl + "desired_state": "sensor_msgs/msg/JointState",
        "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    }
    truth = css_arm().theta()
    errors = rng.normal(0.0, 1e-3, (steps, N))
    torques = rng.normal(0.0, 5.0, (steps, N))
    estimates = truth * np.linspace(0.0, 0.9, steps)[:, None, None]
    pred = rng.normal(0.0, 1.0, steps)
    writer = Writer(path, version=9,
                    storage_plugin=StoragePlugin.MCAP if storage == "mcap"
                    else StoragePlugin.SQLITE3)
    writer.open()
    conns = {name: writer.add_connection(name, t, typestore=ts) for name, t in spec.items()}

    def put(name, stamp, msg):
        writer.write(conns[name], stamp, ts.serialize_cdr(msg, spec[name]))

    for k in range(steps):
        sim = k * DT_NS
        recv = T0_NS + k * DT_NS
        q = np.full(N, 0.01 * k)
        put("/clock", recv, T["rosgraph_msgs/msg/Clock"](clock=_time(ts, sim)))
        put("/joint_states", recv + 10_000, _joint_state(ts, sim, q, np.zeros(N), np.zeros(N)))
        r = recv + 10_000 + LAT_NS
        put(ctrl + "desired_state", r - 50_000,
            _joint_state(ts, sim, q - errors[k], np.zeros(N), np.zeros(N)))
        put(ctrl + "tracking_error", r - 40_000, _multiarray(ts, errors[k], [("joint", N)]))
        put(ctrl + "parameter_estimates", r - 30_000,
            _multiarray(ts, estimates[k].ravel(), [("link", N), ("parameter", 13)]))
        put(ctrl + "prediction_error", r - 20_000, T["std_msgs/msg/Float64"](data=pred[k]))
        put("/effort_controller/commands", r, _multiarray(ts, torques[k], [("joint", N)]))
        if k % 500 == 0:
            header = T["std_msgs/msg/Header"](stamp=_time(ts, sim), frame_id="")
            put("/diagnostics", recv + 100_000,
                T["diagnostic_msgs/msg/DiagnosticArray"](header=header, status=[]))
    writer.close()
    return {"errors": errors, "torques": torques, "estimates": estimates, "pred": pred,
            "truth": truth, "spec": spec}


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_inspect_synthetic_bag(tmp_path, storage, capsys):
    from rcac_ros.cli import main
    steps = 3000                       # 6 s of simulated time at 500 Hz
    bag = str(tmp_path / "bag")
    known = write_synthetic_bag(bag, steps, storage)
    plots = tmp_path / "plots"
    assert main(["inspect", bag, "--plots", str(plots)]) == 0
    out = capsys.readouterr().out

    # the summary: every topic with its count and its rate from the receive stamps
    for name, msgtype in known["spec"].items():
        count = steps if name != "/diagnostics" else (steps + 499) // 500
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(name + " "))
        fields = line.split()
        assert fields[1] == msgtype
        assert int(fields[2]) == count
        if name != "/diagnostics":
            assert float(fields[3]) == pytest.approx(500.0, abs=0.1)
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
    assert m["state_to_effort_latency_p50_ms"] == pytest.approx(LAT_NS * 1e-6, abs=1e-6)
    assert m["state_period_p50_ms"] == pytest.approx(DT_NS * 1e-6, abs=1e-6)
    assert m["unanswered_states"] == 0
    assert m["sim_time_end_s"] == pytest.approx((steps - 1) * 0.002)
    assert doc["summary"]["topics"]["/joint_states"]["count"] == steps

    # the figures exist and are PNG images
    for name in ("tracking_errors.png", "efforts.png", "estimates_link7.png",
                 "prediction_error.png", "loop_timing.png"):
        path = plots / name
        assert path.is_file(), name
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_inspect_rejects_missing_bag(tmp_path, capsys):
    from rcac_ros.cli import main
    assert main(["inspect", str(tmp_path / "nope")]) == 2
    assert "bag:" in capsys.readouterr().err
