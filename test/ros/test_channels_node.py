"""The controller node's prediction channels (doc/nodes.md): parameters, ~/prediction_errors,
diagnostics, against an offline core run of the same closed loop."""

import os
import subprocess

import numpy as np
import pytest

from test_nodes_support import (CONFIG, DEEP, H_NS, node_cmd, PAPER_Q0, Probe, ROOT, ros_context,
                                ros_domain, run_to_end, spin_until, start)

from rclpy.lifecycle import TransitionCallbackReturn  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import Float64, Float64MultiArray  # noqa: E402

from rcac_ros.core.model import css_arm, PAPER_GAINS  # noqa: E402
from rcac_ros.core.composite import RecursiveCompositeController  # noqa: E402
from rcac_ros.core.simulator import Simulator  # noqa: E402
from rcac_ros.core.trajectory import PaperTrajectory  # noqa: E402
from rcac_ros.errors import ConfigError  # noqa: E402
from rcac_ros.nodes.controller.node import ControllerNode  # noqa: E402

H = 0.002
DURATION = 1.0


def offline_E(steps, channels):
    """The same closed loop without ROS: core Simulator + controller; E at every step."""
    model = css_arm()
    sim = Simulator(model, dt=H, q0=PAPER_Q0)
    ctrl = RecursiveCompositeController(model, channels=channels, **dict(PAPER_GAINS, h=H))
    traj = PaperTrajectory(PAPER_Q0, reading="velocity")
    E = []
    for k in range(steps + 1):
        tau = ctrl.step(sim.q, sim.qd, *traj(k * H))
        E.append(ctrl.E)
        if k < steps:
            sim.step(tau)
    return np.array(E)


def test_all_channels_publish_n_prediction_errors_equal_to_the_offline_run():
    """channels: [all] in lockstep with the simulator node (processes, real DDS): every step's
    ~/prediction_errors holds the 7 E_c of the offline run; ~/prediction_error is E_1."""
    steps = round(DURATION / H)
    ref = offline_E(steps, "all")
    assert ref.shape == (steps + 1, 7)
    with ros_context() as (ctx, ex):
        probe = Probe(ctx, record=())
        every, first = [], []
        subs = [probe.create_subscription(Float64MultiArray, "/rcac_controller/prediction_errors",
                                          every.append, DEEP),
                probe.create_subscription(Float64, "/rcac_controller/prediction_error",
                                          lambda m: first.append(m.data), DEEP)]
        ex.add_node(probe)
        # a watchdog trip restarts the filters (E then differs from the offline run): under
        # load a state can come later than the default 20 ms, so allow the maximum, 1 s
        ctrl = start("controller_node", "channels:=[all]", "state_timeout:=1.0",
                     params_file=os.path.join(CONFIG, "controller.yaml"))
        assert spin_until(ex, lambda: all(s.get_publisher_count() > 0 for s in subs),
                          timeout=60.0)
        sim = start("simulator_node", f"duration:={DURATION}", "min_subscribers:=1",
                    "lockstep_timeout:=5.0",        # a loaded machine stalls for 0.1 s+
                    params_file=os.path.join(CONFIG, "simulator.yaml"))
        (sim_code, sim_out), (ctrl_code, ctrl_out) = run_to_end(
            ex, sim, ctrl, lambda: len(every) >= steps + 1 and len(first) >= steps + 1)
    assert sim_code == 0, sim_out
    assert ctrl_code == 0, ctrl_out
    assert "lockstep misses 0" in sim_out, sim_out     # no effort held: the same loop
    dims = [(d.label, d.size, d.stride) for d in every[0].layout.dim]
    assert dims == [(",".join(f"joint{j}" for j in range(1, 8)), 7, 7)]
    got = np.array([m.data for m in every[:steps + 1]])
    scale = np.max(np.abs(ref))
    assert scale > 1.0                  # E is not trivially zero (the estimates start at 0)
    assert "control resumed" not in ctrl_out, ctrl_out    # no trip during the run
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * scale)
    np.testing.assert_array_equal(np.array(first[:steps + 1]), got[:, 0])


def make(ctx, ex, **params):
    node = ControllerNode(context=ctx, parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])
    probe = Probe(ctx, record=("efforts",))
    ex.add_node(node)
    ex.add_node(probe)
    assert spin_until(ex, lambda: probe.pub_state.get_subscription_count() > 0)
    return node, probe


def test_mixed_channels_label_the_topic_and_the_diagnostics_report_each():
    """channels: [1, power] (in-process): the layout names both, the values are the core's
    E after the step, and the diagnostics carry every channel's E."""
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, channels=["1", "power"], update="explicit")
        got = []
        probe.create_subscription(Float64MultiArray, "/rcac_controller/prediction_errors",
                                  got.append, DEEP)
        assert spin_until(ex, lambda: probe.subs["efforts"].get_publisher_count() > 0)
        assert node.ctrl.channels == (1, "power") and node.ctrl.update == "explicit"
        for k in range(1, 40):
            seen = len(got)
            for _ in range(40):         # re-send if lost in discovery (a repeat is not stepped)
                probe.state(k * H_NS, PAPER_Q0 + 0.01 * np.sin(k * 0.1), np.full(7, 0.05))
                if spin_until(ex, lambda: len(got) > seen, timeout=0.5):
                    break
        assert len(got) >= 30
        last = got[-1]
        assert [(d.label, d.size) for d in last.layout.dim] == [("joint1,power", 2)]
        np.testing.assert_array_equal(last.data, node.ctrl.E)
        assert np.all(np.abs(node.ctrl.E) > 0.0)
        values = {kv.key: kv.value for kv in node.diagnostics().values}
    assert values["channels"] == "joint1,power"
    assert float(values["prediction_error_joint1"]) == pytest.approx(last.data[0], rel=1e-5)
    assert float(values["prediction_error_power"]) == pytest.approx(last.data[1], rel=1e-5)
    assert values["prediction_error"] == values["prediction_error_joint1"]


@pytest.mark.parametrize("name, value, words", [
    ("channels", ["8"], "out of range 1..7"),
    ("channels", ["one"], "is not a joint number"),
    ("channels", ["1", "power", "1"], "listed twice"),
    ("channels", ["all", "3"], "listed twice"),
    ("update", "semi", "'implicit' or 'explicit'"),
    ("adaptation", "ls", "must be"),
    ("forgetting", -1.0, "out of range"),
    ("P_max", 0.0, "must be > 0"),
    ("dead_zone_E", -0.1, "out of range"),
    ("theta_bounds", "box", "'none' or 'mass'"),
    ("leakage", -1.0, "out of range"),
])
def test_a_bad_option_is_refused_naming_it(name, value, words):
    with ros_context() as (ctx, _):
        with pytest.raises(ConfigError) as err:
            ControllerNode(context=ctx, parameter_overrides=[Parameter(name, value=value)])
    text = str(err.value)
    assert text.startswith(name + ":") and words in text and "\n" not in text, text


def test_managed_configure_fails_with_the_reason():
    with ros_context() as (ctx, _):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("autostart", value=False), Parameter("channels", value=["0"])])
        try:
            assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
            assert node.config_error.startswith("channels: joint 0: joints are numbered from 1"), \
                node.config_error
        finally:
            node.destroy_node()


def test_bad_channels_at_start_up_give_one_line_and_exit_2():
    with ros_domain():
        proc = subprocess.run(node_cmd("controller_node", 'channels:=["1","torque"]',
                                       params_file=os.path.join(CONFIG, "controller.yaml")),
                              capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    errors = [ln for ln in proc.stderr.splitlines() if "error" in ln]
    assert len(errors) == 1 and "error: channels: 'torque' is not a joint number" in errors[0], \
        proc.stderr


CORE_OPTIONS = dict(channels=(2, "power"), update="explicit", adaptation="least_squares",
                    forgetting=0.5, P_max=900.0, dead_zone_s=0.02, dead_zone_E=100.0,
                    theta_bounds="mass", leakage=0.05, leakage_bound=2.0)
CORE_DEFAULTS = dict(channels=(1,), update="implicit", adaptation="gradient", forgetting=0.0,
                     P_max=None, dead_zone_s=0.0, dead_zone_E=0.0, theta_bounds=None,
                     leakage=0.0, leakage_bound=0.0)


def core_run(ctrl, steps=200):
    """Step ``ctrl`` on small random states about q0 (the dead zones act in part of them)."""
    rng = np.random.default_rng(8)
    E = []
    for _ in range(steps):
        q, qd = PAPER_Q0 + 0.005 * rng.standard_normal(7), 0.005 * rng.standard_normal(7)
        ctrl.step(q, qd, PAPER_Q0, np.zeros(7), np.zeros(7))
        E.append(ctrl.E)
    return np.array(E), ctrl.theta_hat


def test_every_option_reaches_the_core_controller():
    """The node's core controller steps exactly as one built offline with the same options,
    and differs from one built without any single one of them (so each one reached it)."""
    params = dict(CORE_OPTIONS, channels=["2", "power"])
    with ros_context() as (ctx, _):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter(k, value=v) for k, v in params.items()])
        try:
            E, theta = core_run(node.ctrl)
        finally:
            node.destroy_node()

    def offline(**options):
        return core_run(RecursiveCompositeController(css_arm(), **dict(PAPER_GAINS, h=H),
                                                     **options))
    E_ref, theta_ref = offline(**CORE_OPTIONS)
    np.testing.assert_array_equal(E, E_ref)
    np.testing.assert_array_equal(theta, theta_ref)
    assert np.all(theta[:, 0] >= 0.0)                   # the mass projection
    for name, default in CORE_DEFAULTS.items():
        other = offline(**dict(CORE_OPTIONS, **{name: default}))[1]
        assert np.max(np.abs(other - theta)) > 1e-3, name
