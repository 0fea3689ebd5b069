"""The two nodes in lockstep against the same loop without ROS (no tests here): shared by the
integration test on the built-in simulator and the MuJoCo one (doc/testing.md)."""

import os

import numpy as np

from test_nodes_support import (CONFIG, DEEP, JOINTS, NS, PAPER_Q0, Probe, run_to_end,
                                spin_until, start)

from std_msgs.msg import Float64MultiArray  # noqa: E402

from rcac_ros.core.composite import RecursiveCompositeController  # noqa: E402
from rcac_ros.core.model import css_arm, PAPER_GAINS  # noqa: E402
from rcac_ros.core.trajectory import PaperTrajectory  # noqa: E402

#: the period of config/controller.yaml and config/simulator.yaml (s)
H = 0.002


def matched(executor, subs):
    """Wait until every subscription of ``subs`` is matched to a publisher."""
    assert spin_until(executor, lambda: all(s.get_publisher_count() > 0 for s in subs),
                      timeout=60.0)


def offline(steps, plant, reading="velocity"):
    """The controller of config/controller.yaml on ``plant``, without ROS, the loop the two
    nodes run: ``(states, tracking errors, final estimates)``, a row per step."""
    ctrl = RecursiveCompositeController(css_arm(), **dict(PAPER_GAINS, h=H))
    traj = PaperTrajectory(PAPER_Q0, reading=reading)
    qs, errs = [], []
    for k in range(steps + 1):
        q_d, qd_d, qdd_d = traj(k * H)
        qs.append(plant.q.copy())
        errs.append(plant.q - q_d)
        tau = ctrl.step(plant.q, plant.qd, q_d, qd_d, qdd_d)
        if k < steps:
            plant.step(tau)
    return np.array(qs), np.array(errs), ctrl.theta_hat


def tracking_probe(context, executor):
    """A probe, added to ``executor``, that records the joint states and the controller's
    tracking errors: ``(probe, tracking errors (a list it fills), their subscription)``."""
    probe = Probe(context, record=("states",))
    track = []
    sub = probe.create_subscription(Float64MultiArray, "/rcac_controller/tracking_error",
                                    lambda m: track.append(np.array(m.data)), DEEP)
    executor.add_node(probe)
    return probe, track, sub


def lockstep_run(executor, probe, subs, drained, *sim_overrides):
    """Start the controller node (config/controller.yaml), wait until the probe's ``subs``
    match its publishers, then the simulator node (config/simulator.yaml and
    ``sim_overrides``) in lockstep with every state reader; run until the simulator ends and
    ``drained()`` holds.

    Returns
    -------
    tuple
        ``(readers, (sim exit code, output), (controller exit code, output))``.
    """
    ctrl = start("controller_node", params_file=os.path.join(CONFIG, "controller.yaml"))
    matched(executor, subs)
    # the simulator starts once its state publisher has matched every subscription the
    # graph shows (the controller's, the probe's, and any other): with a fixed 2, one
    # full-suite run started it before the probe matched, which then saw no state
    assert spin_until(executor, lambda: probe.count_subscribers("/joint_states") >= 2,
                      timeout=60.0)
    readers = probe.count_subscribers("/joint_states")
    sim = start("simulator_node", *sim_overrides, f"min_subscribers:={readers}",
                # a process stalled 0.5 s on a loaded machine is not a lost effort: wait
                # long enough that only a real loss is a miss
                "lockstep_timeout:=5.0", params_file=os.path.join(CONFIG, "simulator.yaml"))
    sim_result, ctrl_result = run_to_end(executor, sim, ctrl, drained)
    return readers, sim_result, ctrl_result


def assert_lockstep_states(states, ref_q, steps, readers, sim_out):
    """The simulator ran ``steps`` steps with an effort for every state (no lockstep miss,
    none late), and every state received is ``ref_q`` at the same step (bit-for-bit up to
    the float rounding of the time stamps), 90 % of them at least."""
    line = [ln for ln in sim_out.splitlines() if "finished:" in ln]
    assert line and f"finished: {steps} steps" in line[0], sim_out
    assert "lockstep misses 0, late efforts 0" in line[0], line[0]
    seen = 0
    for msg in states:
        k = round((msg.header.stamp.sec * NS + msg.header.stamp.nanosec) / (H * NS))
        assert list(msg.name) == JOINTS
        np.testing.assert_allclose(msg.position, ref_q[k], rtol=0, atol=1e-9)
        seen += 1
    assert seen >= steps * 0.9, (seen, readers, sim_out)
