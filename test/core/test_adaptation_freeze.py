"""Freezing the adaptation (the ``~/set_adaptation`` service): estimates held, control intact."""

import numpy as np

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
