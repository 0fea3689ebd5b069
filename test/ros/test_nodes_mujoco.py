"""The simulator node on the MuJoCo engine (``engine: mujoco``, doc/plants.md).

In process: the lockstep protocol steps the MuJoCo plant (the offline plant's states to the
bit, the built-in simulator's to 1e-9). Over DDS: the controller node tracks the node's arm
as the offline loop on the MuJoCo plant does, and as on the built-in one (the two plants
agree on a rigid arm).
"""

import numpy as np
import pytest
from chains import needs_mujoco

from lockstep_support import assert_lockstep_states, H, lockstep_run, offline, tracking_probe
from test_nodes_support import distinct, NS, PAPER_Q0, Probe, ros_context, spin_until

from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from rcac_ros.core.model import css_arm  # noqa: E402
from rcac_ros.core.simulator import Simulator  # noqa: E402
from rcac_ros.errors import ConfigError  # noqa: E402
from rcac_ros.nodes.simulator.node import SimulatorNode  # noqa: E402

from rcac_ros.plants.mujoco_plant import MujocoPlant  # noqa: E402

DURATION = 1.0


@needs_mujoco
def test_lockstep_steps_the_mujoco_plant():
    rng = np.random.default_rng(5)
    taus = rng.normal(0.0, 50.0, (5, 7))
    ref = MujocoPlant(css_arm(), dt=H, q0=PAPER_Q0)
    builtin = Simulator(css_arm(), dt=H, q0=PAPER_Q0)
    with ros_context() as (ctx, ex):
        node = SimulatorNode(context=ctx, parameter_overrides=[
            Parameter("engine", value="mujoco"), Parameter("lockstep_timeout", value=5.0)])
        probe = Probe(ctx)
        ex.add_node(node)
        ex.add_node(probe)
        assert isinstance(node.sim, MujocoPlant)
        for k, tau in enumerate(taus):
            assert spin_until(ex, lambda: len(distinct(probe.states)) == k + 1)
            state = distinct(probe.states)[-1]
            assert state.header.stamp.sec * NS + state.header.stamp.nanosec == k * H * NS
            np.testing.assert_array_equal(state.position, ref.q)
            np.testing.assert_allclose(state.position, builtin.q, rtol=0, atol=1e-9)
            probe.pub_effort.publish(Float64MultiArray(data=list(tau)))
            ref.step(tau)
            builtin.step(tau)
        assert spin_until(ex, lambda: len(distinct(probe.states)) == len(taus) + 1)
        np.testing.assert_array_equal(probe.states[-1].position, ref.q)
        assert node.misses == 0


def test_a_bad_engine_is_one_line():
    with ros_context() as (ctx, _):
        with pytest.raises(ConfigError) as err:
            SimulatorNode(context=ctx, parameter_overrides=[Parameter("engine", value="ode")])
    assert str(err.value) == "engine: must be 'builtin' or 'mujoco', got 'ode'"


@needs_mujoco
def test_the_controller_tracks_the_mujoco_arm_over_dds():
    steps = round(DURATION / H)
    ref_q, ref_err, _ = offline(steps, MujocoPlant(css_arm(), dt=H, q0=PAPER_Q0))
    builtin_q, _, _ = offline(steps, Simulator(css_arm(), dt=H, q0=PAPER_Q0))
    assert np.abs(ref_q - builtin_q).max() < 1e-9          # the engines agree on this arm
    with ros_context() as (ctx, ex):
        probe, track, sub = tracking_probe(ctx, ex)
        readers, (sim_code, sim_out), (ctrl_code, ctrl_out) = lockstep_run(
            ex, probe, [sub], lambda: len(track) >= steps + 1, "engine:=mujoco",
            f"duration:={DURATION}")
    assert sim_code == 0, sim_out
    assert ctrl_code == 0, ctrl_out
    assert "mujoco engine" in sim_out
    assert_lockstep_states(probe.states, ref_q, steps, readers, sim_out)
    track = np.array(track[:steps + 1])
    np.testing.assert_allclose(np.sqrt(np.mean(track ** 2, axis=0)),
                               np.sqrt(np.mean(ref_err ** 2, axis=0)), rtol=1e-6)
    # tracked: within a tenth of the desired motion's excursion over the run
    excursion = np.abs(ref_q - ref_err - PAPER_Q0).max()
    assert np.abs(track).max() < 0.1 * excursion
