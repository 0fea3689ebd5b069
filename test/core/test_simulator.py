"""The plant: energy conservation, integration order, torque hold and limits, trajectories."""

import numpy as np
import pytest
from chains import random_chain

from rcac_ros.core import (InputError, PaperTrajectory, PolynomialTrajectory, Simulator,
                           SinusoidTrajectory, css_arm, energy)


@pytest.mark.parametrize("model", [css_arm((0.0, 0.0, -9.81)),
                                   random_chain(np.random.default_rng(4), 8)],
                         ids=["css", "random8"])
def test_unforced_simulator_conserves_energy(model):
    rng = np.random.default_rng(0)
    q0, qd0 = rng.normal(size=(2, model.n)) * np.array([[1.0], [0.5]])
    sim = Simulator(model, dt=1e-3, q0=q0, qd0=qd0)
    e0 = sum(energy(model, q0, qd0))
    scale = max(abs(e0), energy(model, q0, qd0)[0])
    drift = 0.0
    for _ in range(2000):
        q, qd = sim.step(np.zeros(model.n))
        drift = max(drift, abs(sum(energy(model, q, qd)) - e0))
    assert drift < 1e-6 * scale


def test_rk4_is_fourth_order():
    model = css_arm((0.0, 0.0, -9.81))
    q0 = np.linspace(-1, 1, 7)
    tau = np.linspace(-300, 300, 7)

    def final(substeps):
        sim = Simulator(model, dt=0.05, q0=q0, substeps=substeps)
        for _ in range(10):
            sim.step(tau)
        return sim.q

    ref = final(64)
    e1, e2 = np.abs(final(4) - ref).max(), np.abs(final(8) - ref).max()
    assert 12.0 < e1 / e2 < 20.0                  # 2^4 = 16


def test_torque_is_clipped_and_validated():
    model = css_arm()
    a = Simulator(model, q0=np.zeros(7), effort_limit=10.0)
    b = Simulator(model, q0=np.zeros(7))
    a.step(np.full(7, 1e4))
    b.step(np.full(7, 10.0))
    assert np.array_equal(a.q, b.q)
    with pytest.raises(InputError, match="tau: expected shape"):
        a.step(np.zeros(6))
    q = a.q.copy()
    with pytest.raises(InputError, match="tau: contains NaN"):
        a.step(np.full(7, np.nan))
    assert np.array_equal(q, a.q) and a.t == pytest.approx(0.002)
    with pytest.raises(InputError, match="dt"):
        Simulator(model, dt=0.0)
    with pytest.raises(InputError, match="dt: expected a number"):
        Simulator(model, dt="x")
    with pytest.raises(InputError, match="substeps"):
        Simulator(model, substeps=0)
    with pytest.raises(InputError, match="substeps: must be finite"):
        Simulator(model, substeps=float("nan"))
    with pytest.raises(InputError, match="effort_limit: expected a scalar or 7 values"):
        Simulator(model, effort_limit=[1.0, 2.0])


@pytest.mark.parametrize("traj", [
    PaperTrajectory(np.arange(7.0), "velocity"), PaperTrajectory(np.arange(7.0), "position"),
    SinusoidTrajectory(np.zeros(3), [0.1, 0.2, 0.3], [0.5, 1.0, 2.0], [0.0, 1.0, 2.0]),
    PolynomialTrajectory.quintic([0.0, 1.0], [1.0, -1.0], 2.0),
], ids=["paper-velocity", "paper-position", "sinusoid", "quintic"])
def test_trajectory_derivatives_are_consistent(traj):
    eps = 1e-6
    for t in (0.3, 1.1, 1.7):
        q, qd, qdd = traj(t)
        qp, qdp, _ = traj(t + eps)
        qm, qdm, _ = traj(t - eps)
        assert np.allclose((qp - qm) / (2 * eps), qd, atol=1e-7)
        assert np.allclose((qdp - qdm) / (2 * eps), qdd, atol=1e-6)


def test_paper_trajectory_readings():
    q0 = np.arange(7.0)
    v = PaperTrajectory(q0, "velocity")
    assert np.allclose(v(0.0)[0], q0) and np.allclose(v(0.0)[1], 0.0)
    assert np.allclose(v(5.0)[1], 5 * np.pi / 180)       # qd_d = A sin(pi t / 10)
    p = PaperTrajectory(q0, "position")
    assert np.allclose(p(5.0)[0], 5 * np.pi / 180)        # q_d = A sin(pi t / 10)
    with pytest.raises(InputError, match="reading"):
        PaperTrajectory(q0, "acceleration")
    with pytest.raises(InputError, match="period: expected a number"):
        PaperTrajectory(q0, period="20")
    with pytest.raises(InputError, match="amplitude: must be finite"):
        PaperTrajectory(q0, amplitude=float("nan"))
    with pytest.raises(InputError, match="amplitude: expected a scalar or 3 values"):
        SinusoidTrajectory(np.zeros(3), [1.0, 2.0], 1.0)


def test_quintic_is_rest_to_rest_and_holds():
    traj = PolynomialTrajectory.quintic([0.0], [2.0], 1.0)
    assert traj(0.0)[0] == pytest.approx([0.0]) and traj(1.0)[0] == pytest.approx([2.0])
    assert traj(0.0)[1] == pytest.approx([0.0]) and traj(1.0)[1] == pytest.approx([0.0])
    assert traj(5.0)[0] == pytest.approx([2.0]) and traj(5.0)[1] == pytest.approx([0.0])


def test_joint_friction_and_armature_in_the_simulator_closed_form():
    """One joint about a vertical axis (g = 0): (I_zz + armature) qdd = tau - d qd
    - f tanh(qd / v_c), integrated independently by scipy (doc/design.md §7)."""
    from scipy.integrate import solve_ivp
    from rcac_ros.core import RobotModel
    izz, arm, d, f, vc = 0.05, 0.1, 0.4, 0.3, 0.1
    model = RobotModel([[0.0, 0.0, 0.0]], [np.eye(3)], [1.0], [[0.0, 0.0, 0.0]],
                       [np.diag([0.04, 0.04, izz])], armature=arm, damping=d, friction=f,
                       friction_velocity=vc)
    tau = lambda t: 0.8 * np.sin(3.0 * t)    # noqa: E731 (the joint turns both ways)

    def rhs(t, x, u):
        return [x[1], (u - d * x[1] - f * np.tanh(x[1] / vc)) / (izz + arm)]
    sim = Simulator(model, dt=0.002, substeps=4)
    x = np.array([0.0, 0.0])
    signs = set()
    for k in range(1000):
        t = k * 0.002
        sim.step([tau(t)])
        x = solve_ivp(rhs, (t, t + 0.002), x, args=(tau(t),), rtol=1e-12, atol=1e-14,
                      method="DOP853").y[:, -1]
        signs.add(np.sign(x[1]))
    assert signs >= {-1.0, 1.0}
    assert abs(sim.q[0] - x[0]) < 1e-8 and abs(sim.qd[0] - x[1]) < 1e-8
