"""The recursive composite controller: exactness, equivalences, stability, the paper's claims."""

import numpy as np
import pytest
from chains import random_chain

from rcac_ros.core import (GainError, InputError, PaperTrajectory, RecursiveCompositeController,
                           Simulator, SlotineLiCompositeController, css_arm, inverse_dynamics)
from rcac_ros.tools.demos.experiment import PAPER_Q0, run_experiment

Q0 = np.array(PAPER_Q0)


def closed_loop(model, controller, steps, q0, trajectory, h=0.002, record=None):
    sim = Simulator(model, dt=h, q0=q0)
    for k in range(steps):
        q_d, qd_d, qdd_d = trajectory(k * h)
        tau = controller.step(sim.q, sim.qd, q_d, qd_d, qdd_d)
        if record is not None:
            record(k, sim, controller, tau)
        sim.step(tau)
    return sim


@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.0, 0.0, -9.81)])
def test_exact_model_and_zero_error_gives_inverse_dynamics(gravity):
    """With theta_hat = theta and q = q_d, qd = qd_d, eq 19b is the RNEA of qdd_d."""
    rng = np.random.default_rng(1)
    for model in (css_arm(gravity), random_chain(rng, 11, gravity)):
        q, qd, qdd = rng.normal(size=(3, model.n))
        for cls in (RecursiveCompositeController, SlotineLiCompositeController):
            ctrl = cls(model, theta_hat0=model.theta())
            tau = ctrl.step(q, qd, q, qd, qdd)
            ref = inverse_dynamics(model, q, qd, qdd)
            assert np.allclose(tau, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


def random_spd(rng, size, scale):
    A = rng.normal(size=(size, size))
    return scale * (A @ A.T / size + np.eye(size))


def compare_closed_loops(model, steps, rtol=1e-9, **gains):
    rng = np.random.default_rng(model.n)
    q0 = rng.normal(size=model.n) * 0.5
    traj = PaperTrajectory(q0, reading="position", amplitude=0.3, period=4.0)
    a = RecursiveCompositeController(model, **gains)
    b = SlotineLiCompositeController(model, **gains)
    sa = Simulator(model, q0=q0)
    sb = Simulator(model, q0=q0)
    for k in range(steps):
        q_d, qd_d, qdd_d = traj(k * 0.002)
        ta = a.step(sa.q, sa.qd, q_d, qd_d, qdd_d)
        tb = b.step(sb.q, sb.qd, q_d, qd_d, qdd_d)
        assert np.allclose(ta, tb, rtol=rtol, atol=rtol * np.abs(ta).max())
        assert a.E[0] == pytest.approx(b.E[0], rel=rtol, abs=rtol)  # joint 1, built two ways
        sa.step(ta)
        sb.step(tb)
    assert np.allclose(a.theta_hat, b.theta_hat, rtol=1e-8, atol=1e-10)
    assert not np.allclose(a.theta_hat, 0.0)                    # it did adapt


def test_recursive_equals_slotine_li_when_gamma_is_zero():
    """Both compute the same direct law (Y^T s = sum Y_ri^T s_i): closed loops agree."""
    rng = np.random.default_rng(2)
    model = random_chain(rng, 6, gravity=(0.0, 0.0, -9.81))
    compare_closed_loops(model, 1500, K_D=50.0, P=2.0, gamma=0.0)
    # full (non-diagonal) gains take the kernel's dense paths
    compare_closed_loops(model, 500, K_D=random_spd(rng, 6, 50.0), P=random_spd(rng, 13, 2.0),
                         gamma=0.0, Lambda=rng.uniform(0.5, 2.0, 6))


def test_recursive_equals_slotine_li_for_one_joint():
    """n = 1: joint 1 is every joint, so the two composite laws coincide for gamma > 0 too
    (Sherman-Morrison in one, Woodbury with a Cholesky solve in the other)."""
    rng = np.random.default_rng(3)
    model = random_chain(rng, 1, gravity=(0.0, -9.81, 0.0))
    compare_closed_loops(model, 1500, K_D=random_spd(rng, 6, 20.0),
                         P=random_spd(rng, 13, 5.0), gamma=0.7, lam=20.0)


@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.0, 0.0, -9.81)])
def test_prediction_error_vanishes_with_true_parameters(gravity):
    """theta_hat held at theta: E = sum W_j theta_j - y stays ~0 (the whole filter derivation)."""
    model = css_arm(gravity)
    ctrl = RecursiveCompositeController(model, P=1e-12, theta_hat0=model.theta())
    E, y = [], []
    traj = PaperTrajectory(Q0, reading="position")      # large errors: rich excitation
    closed_loop(model, ctrl, 2000, Q0, traj,
                record=lambda k, s, c, t: (E.append(c.E), y.append(c.y)))
    assert max(np.abs(y)) > 100.0
    assert max(np.abs(E)) < 1e-7 * max(np.abs(y))       # O(h^2) of the filter holds
    # and the direct law from theta_hat = 0 does not have it: the check can fail
    direct = RecursiveCompositeController(model, gamma=0.0)
    closed_loop(model, direct, 500, Q0, traj)
    assert abs(direct.E) > 1.0


def test_lyapunov_function_does_not_increase():
    """Eqs 25-26 along a closed loop with a fine step, from a large initial error."""
    model = css_arm()
    h = 5e-4
    ctrl = RecursiveCompositeController(model, h=h)
    values = []
    closed_loop(model, ctrl, 2000, Q0, PaperTrajectory(Q0, reading="position"), h=h,
                record=lambda k, s, c, t: values.append(c.lyapunov(model.theta())))
    v = np.array(values)
    assert v[-1] < 0.5 * v[0]
    assert np.max(np.diff(v)) <= 1e-12 * v[0]


def test_paper_claims_composite_beats_direct():
    """Section 4: lower RMS tracking error and a far smaller prediction error (20 s)."""
    _, runs, report = run_experiment(duration=20.0, progress=False)
    d, c = report["direct"], report["composite"]
    assert c["rms_tracking_error"] < d["rms_tracking_error"]
    assert c["rms_tracking_error_last_5s"] < d["rms_tracking_error_last_5s"]
    assert c["final_abs_prediction_error"] < 1e-3 * d["final_abs_prediction_error"]
    assert c["max_tracking_error"] < 0.01               # rad: both track the 5 deg/s motion
    assert np.all(np.isfinite(runs["composite"]["tau"]))


def test_step_input_errors_name_the_field():
    model = css_arm()
    ctrl = RecursiveCompositeController(model)
    z = np.zeros(7)
    with pytest.raises(InputError, match="qd_d: expected length 7"):
        ctrl.step(z, z, z, np.zeros(6), z)
    with pytest.raises(InputError, match="q: contains NaN"):
        ctrl.step(np.full(7, np.nan), z, z, z, z)
    with pytest.raises(InputError, match="qdd_d: contains NaN or Inf"):
        ctrl.step(z, z, z, z, [0, 0, 0, np.inf, 0, 0, 0])
    with pytest.raises(InputError, match="qd"):
        ctrl.step(z, "abc", z, z, z)
    before = ctrl.theta_hat
    with pytest.raises(InputError):
        ctrl.step(z, z, z, z, np.zeros((7, 1)))
    assert np.array_equal(before, ctrl.theta_hat)       # a rejected input changes nothing
    assert ctrl.step(list(z), z, z, z, z.astype(np.float32)).shape == (7,)  # converted once


@pytest.mark.parametrize("kwargs,match", [
    (dict(K_D=-1.0), "K_D\\[0\\]: not positive definite"),
    (dict(K_D=np.ones((6, 6))), "K_D\\[0\\]: not positive definite"),
    (dict(K_D=np.arange(36.0).reshape(6, 6)), "K_D\\[0\\]: not symmetric"),
    (dict(P=np.zeros(13)), "P\\[0\\]: not positive definite"),
    (dict(P=np.ones((3, 13, 13))), "P: expected shape"),
    (dict(Lambda=[1, 1, 1]), "Lambda"),
    (dict(Lambda=-2.0), "Lambda: every entry must be > 0"),
    (dict(gamma=-0.1), "gamma: must be >= 0"),
    (dict(gamma=float("nan")), "gamma"),
    (dict(lam=0.0), "lam: must be > 0"),
    (dict(h=-1.0), "h: must be > 0"),
    (dict(K_D="abc"), "K_D: not a numeric array"),
    (dict(P=[[1.0, 2.0], [3.0]]), "P: not a numeric array"),
    (dict(K_D=np.eye(3)), "K_D: expected shape"),
    (dict(gamma="0.1"), "gamma: expected a number"),
])
def test_bad_gains_raise_gain_error(kwargs, match):
    for cls in (RecursiveCompositeController, SlotineLiCompositeController):
        with pytest.raises(GainError, match=match):
            cls(css_arm(), **kwargs)


def test_bad_initial_estimate():
    with pytest.raises(InputError, match="theta_hat0: expected shape"):
        RecursiveCompositeController(css_arm(), theta_hat0=np.zeros((7, 10)))
    with pytest.raises(InputError, match="theta_hat0: contains NaN"):
        RecursiveCompositeController(css_arm(), theta_hat0=np.full((7, 13), np.nan))


def test_prediction_error_stays_exact_when_the_torque_saturates():
    """With an effort limit, y must filter the torque the arm felt, not the one computed."""
    model = css_arm()
    traj = PaperTrajectory(Q0, reading="position")

    def run(report_applied):
        ctrl = RecursiveCompositeController(model, P=1e-12, theta_hat0=model.theta())
        sim = Simulator(model, q0=Q0, effort_limit=300.0)
        worst, saturated = 0.0, 0
        for k in range(500):
            tau = ctrl.step(sim.q, sim.qd, *traj(k * 0.002))
            worst = max(worst, abs(ctrl.E))
            sim.step(tau)
            saturated += abs(tau[0]) > 300.0
            if report_applied:
                ctrl.set_applied_torque(sim.applied)
        return worst, saturated

    worst, saturated = run(True)
    assert saturated > 400 and worst < 1e-6 * 300.0
    assert run(False)[0] > 1e3          # without the feedback, E is wrong by the clipped part


def test_restart_filters_keeps_estimates_and_exact_prediction():
    """A gap the controller did not see (0.1 s of 2 kN m) breaks the filters; a restart
    makes E exact again and keeps theta_hat."""
    model = css_arm()
    traj = PaperTrajectory(Q0)

    def run(restart):
        ctrl = RecursiveCompositeController(model, P=1e-12, theta_hat0=model.theta())
        sim = Simulator(model, q0=Q0)
        worst = 0.0
        for k in range(300):
            if k == 150:
                for _ in range(50):
                    sim.step(np.full(7, 2000.0))
                if restart:
                    ctrl.restart_filters()
            tau = ctrl.step(sim.q, sim.qd, *traj(k * 0.002))
            worst = max(worst, abs(ctrl.E) / max(1.0, abs(ctrl.y)))
            sim.step(tau)
        return worst, ctrl.theta_hat

    worst, theta = run(True)
    assert worst < 1e-4
    assert np.allclose(theta, model.theta())
    assert run(False)[0] > 1.0
