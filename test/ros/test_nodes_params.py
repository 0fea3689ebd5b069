"""The nodes declare exactly the table's parameters; run-time changes go through its checks."""

import dataclasses

import numpy as np
import pytest

from test_nodes_support import ros_context

from rclpy.exceptions import ParameterUninitializedException  # noqa: E402  (after support)
from rclpy.parameter import Parameter  # noqa: E402

from rcac_ros import params  # noqa: E402
from rcac_ros.errors import ConfigError  # noqa: E402
from rcac_ros.nodes.controller.node import ControllerNode  # noqa: E402
from rcac_ros.nodes.simulator.node import SimulatorNode  # noqa: E402

RCLPY_OWN = {"use_sim_time", "start_type_description_service"}


@pytest.mark.parametrize("node_class, node", [(ControllerNode, "controller"),
                                              (SimulatorNode, "simulator")])
def test_declared_parameters_and_descriptors_follow_the_table(node_class, node):
    with ros_context() as (ctx, _):
        n = node_class(context=ctx)
        try:
            names = set(n.list_parameters([], 0).names) - RCLPY_OWN
            assert names == {p.name for p in params.TABLE[node]}
            for p in params.TABLE[node]:
                desc = n.describe_parameter(p.name)
                assert desc.read_only == p.read_only, p.name
                assert desc.description == p.description, p.name
                if p.type == "double" and p.lo is not None:
                    r = desc.floating_point_range[0]
                    assert (r.from_value, r.to_value) == (p.lo, p.hi), p.name
                if p.type == "integer" and p.lo is not None:
                    r = desc.integer_range[0]
                    assert (r.from_value, r.to_value) == (p.lo, p.hi), p.name
                if p.default is not None:
                    assert n.get_parameter(p.name).value == p.default, p.name
                else:
                    with pytest.raises(ParameterUninitializedException):
                        n.get_parameter(p.name)
        finally:
            n.destroy_node()


def test_controller_applies_a_valid_change_and_refuses_an_invalid_one():
    with ros_context() as (ctx, _):
        n = ControllerNode(context=ctx)
        try:
            ok = n.set_parameters([Parameter("state_timeout", value=0.5)])[0]
            assert ok.successful and n.config.state_timeout == 0.5
            assert n.watchdog.state_timeout == 0.5
            bad = n.set_parameters([Parameter("state_timeout", value=0.0)])[0]
            assert not bad.successful and bad.reason.startswith("state_timeout:")
            assert n.config.state_timeout == 0.5
            ok = n.set_parameters([Parameter("monitor_decimation", value=10)])[0]
            assert ok.successful and n.config.publish_every == 10
            frozen = n.set_parameters([Parameter("K_D", value=5.0)])[0]
            assert not frozen.successful                       # read-only
            assert n.get_parameter("K_D").value == params.row("controller", "K_D").default
        finally:
            n.destroy_node()


def test_controller_config_is_frozen_and_read_only():
    """The parameters come out as one frozen config: no field can be set, no array or
    mapping of it written, and the node keeps no copy of its fields beside it."""
    with ros_context() as (ctx, _):
        n = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("joints", value=[f"joint{k}" for k in range(7, 0, -1)])])
        try:
            cfg = n.config
            with pytest.raises(dataclasses.FrozenInstanceError):
                cfg.h = 1.0
            for name in ("out", "order", "effort_limit", "safe_effort", "theta0", "paper_q0"):
                value = getattr(cfg, name)
                assert value is None or not value.flags.writeable, name
            with pytest.raises(ValueError):
                cfg.effort_limit[0] = 0.0
            with pytest.raises(TypeError):
                cfg.paper["period"] = 1.0
            assert list(cfg.out) == list(range(6, -1, -1))      # joints given reversed
            np.testing.assert_array_equal(cfg.order, cfg.out)   # a reversal is its own inverse
            assert not any(hasattr(n, name) for name in ("h", "publish_every", "theta0",
                                                         "channel_names", "_out", "_order"))
        finally:
            n.destroy_node()


def test_controller_natural_metric_reaches_the_core_and_a_misuse_is_one_line():
    """``natural_metric``/``barrier_c`` (doc/design.md §8) configure the core law; its
    default ``auto`` is the barrier with the gradient law and natural least squares' own
    metric with least squares; the barrier without the natural geometry is refused at
    start-up with one line naming it."""
    with ros_context() as (ctx, _):
        for extra, want in (
                ([Parameter("natural_metric", value="barrier"),
                  Parameter("barrier_c", value=10.0)], ("barrier", 10.0)),
                ([], ("barrier", 1000.0)),
                ([Parameter("natural_metric", value="log_det")], ("log_det", None)),
                ([Parameter("adaptation", value="least_squares")], ("log_det", None))):
            n = ControllerNode(context=ctx, parameter_overrides=[
                Parameter("geometry", value="natural")] + extra)
            try:
                assert (n.ctrl.geometry, n.ctrl.natural_metric, n.ctrl.barrier_c) == \
                    ("natural",) + want
            finally:
                n.destroy_node()
        with pytest.raises(ConfigError) as err:
            ControllerNode(context=ctx, parameter_overrides=[
                Parameter("natural_metric", value="barrier")])
        text = str(err.value)
        assert "natural_metric: 'barrier' only with geometry='natural'" in text, text
        assert "\n" not in text, text


def test_joint_friction_alone_scales_each_joints_gain_at_the_first_state():
    """``joint_friction: true`` and nothing else: the joint terms' gain is the library's
    default, each joint's scaled from its feedback at the first state (doc/design.md §7),
    not one triple for every joint."""
    from rcac_ros.core.joint_friction import feedback_scaled_gain
    with ros_context() as (ctx, _):
        n = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("joint_friction", value=True)])
        try:
            assert n.kernels.wait()             # the node compiles before any step
            ctrl = n.ctrl
            q0 = np.linspace(0.1, 0.7, ctrl.n)
            ctrl.step(q0, np.zeros(ctrl.n), q0, np.zeros(ctrl.n), np.zeros(ctrl.n))
            np.testing.assert_allclose(ctrl.P_friction,
                                       feedback_scaled_gain(ctrl.model, ctrl.K_D, q0))
            assert np.ptp(ctrl.P_friction[:, 1]) > 0.0      # joints get different gains
        finally:
            n.destroy_node()


def test_controller_friction_adaptation_reaches_the_core_and_a_misuse_is_one_line():
    """``friction_adaptation``/``friction_forgetting`` (doc/design.md §7) and
    ``hold_compensation`` (§6) configure the core law; joint least squares in the natural
    geometry is refused at start-up with one line naming it."""
    with ros_context() as (ctx, _):
        n = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("joint_friction", value=True),
            Parameter("friction_adaptation", value="least_squares"),
            Parameter("friction_forgetting", value=2.0),
            Parameter("hold_compensation", value=True)])
        try:
            assert (n.ctrl.friction_adaptation, n.ctrl.friction_forgetting,
                    n.ctrl.hold_compensation) == ("least_squares", 2.0, True)
        finally:
            n.destroy_node()
        with pytest.raises(ConfigError) as err:
            ControllerNode(context=ctx, parameter_overrides=[
                Parameter("joint_friction", value=True), Parameter("geometry", value="natural"),
                Parameter("friction_adaptation", value="least_squares")])
        text = str(err.value)
        assert "friction_adaptation: 'least_squares' needs geometry='euclidean'" in text, text
        assert "\n" not in text, text


def test_options_that_act_only_with_others_are_named_when_set_alone():
    """A value off its default for an option that does nothing in the configuration (the
    forgetting of a gradient law, a lookahead in lockstep) is named; at the defaults, or
    where each acts, nothing is."""
    from rcac_ros.nodes.controller.params import inert_options
    v = {p.name: p.default for p in params.CONTROLLER}
    assert inert_options(v) == []
    v.update({"forgetting": 0.5, "P_max": 10.0, "P_friction": (1.0, 1.0, 1.0),
              "friction_forgetting": 2.0, "timer.lookahead": 0.01, "timer.phase_offset": 0.0,
              "mode": "lockstep", "adaptation": "gradient", "joint_friction": False})
    assert [name for name, _ in inert_options(v)] == [
        "forgetting", "P_max", "P_friction", "friction_forgetting", "timer.lookahead",
        "timer.phase_offset"]
    v.update(adaptation="least_squares", joint_friction=True,
             friction_adaptation="least_squares", mode="timer")
    assert inert_options(v) == []
