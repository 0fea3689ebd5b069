"""Freezing the adaptation (the ``~/set_adaptation`` service): estimates held, control intact."""

import numpy as np
import pytest

from rcac_ros.core import (PaperTrajectory, RecursiveCompositeController, Simulator, css_arm,
                           inverse_dynamics)

Q0 = np.array([0.3, np.pi / 2, np.pi / 3, -2 * np.pi / 3, np.pi / 3, np.pi / 2, 0.3])


def test_frozen_estimates_stay_and_the_law_uses_them():
    model = css_arm((0.0, 0.0, -9.81))
    rng = np.random.default_rng(5)
    other = model.replace(mass=model.mass * rng.uniform(0.5, 1.5, model.n),
                          com=model.com + rng.uniform(-0.1, 0.1, (model.n, 3)))
    theta0 = other.theta()      # a wrong but physical model: the estimates to freeze
    ctrl = RecursiveCompositeController(model, theta_hat0=theta0)
    ctrl.set_adaptation(False)
    assert not ctrl.adapting
    sim = Simulator(model, q0=Q0)
    traj = PaperTrajectory(Q0, reading="position", amplitude=0.2, period=2.0)
    for k in range(300):
        q_d, qd_d, qdd_d = traj(k * 0.002)
        ctrl.step(sim.q + 0.01, sim.qd, q_d, qd_d, qdd_d)     # a tracking error: eq 24 would move
        sim.step(np.zeros(model.n))
    np.testing.assert_array_equal(ctrl.theta_hat, theta0)
    # the torque still comes from the frozen estimates: at zero error it is their RNEA
    q, qd, qdd = rng.normal(size=(3, model.n))
    tau = ctrl.step(q, qd, q, qd, qdd)
    ref = inverse_dynamics(other, q, qd, qdd)
    np.testing.assert_allclose(tau, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    # resumed: the same error moves the estimates again
    ctrl.set_adaptation(True)
    ctrl.step(q + 0.05, qd, q, qd, qdd)
    assert ctrl.adapting and not np.allclose(ctrl.theta_hat, theta0)


# the joint terms at a fixed gain: the default one, scaled from the paper's K_D = 1e4 I6,
# reaches 7e7 on the CSS arm and amplifies the two kernels' different summation orders to
# 1.3e-10 relative (measured); the check is the kernels' equivalence, not the gain's
@pytest.mark.parametrize("options", [{}, {"joint_friction": True,
                                          "P_friction": (1.0, 10.0, 10.0)},
                                     {"geometry": "natural"}],
                         ids=["paper", "joint_terms", "natural"])
def test_a_freeze_keeps_the_fused_kernel_and_equals_the_general_one(options):
    """Freezing and resuming the paper's law does not switch kernels (nothing to compile in
    the loop), and the fused kernel's frozen steps are the general kernel's: the same
    torques, filters, prediction errors and (held) estimates, bit for bit (with the joint
    terms the two sum in another order: 1e-12 relative, as when adapting,
    test_joint_friction_law.py)."""
    model = css_arm()
    traj = PaperTrajectory(Q0)
    runs = []
    for fused in (True, False):
        ctrl = RecursiveCompositeController(model, **options)
        ctrl.use_fused_kernel(fused)
        sim = Simulator(model, q0=Q0)
        taus = []
        for k in range(600):
            if k in (200, 400):
                ctrl.set_adaptation(k == 400)       # frozen for steps 200-399
            assert (ctrl._entry.__name__.startswith("paper")) == fused
            q_d, qd_d, qdd_d = traj(k * 0.002)
            tau = ctrl.step(sim.q, sim.qd, q_d, qd_d, qdd_d)
            taus.append(tau.copy())
            if k == 399:
                held = ctrl.theta_hat.copy()
            sim.step(tau)
        runs.append((np.array(taus), held, ctrl.theta_hat, ctrl.E, ctrl.W))
    rtol = 1e-12 if options.get("joint_friction") else 0.0
    for a, b in zip(*runs):
        np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * np.max(np.abs(b)))
