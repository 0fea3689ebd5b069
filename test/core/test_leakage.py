"""Leakage toward theta_0 (sigma-modification, fixed and switching): closed forms, properties."""

import numpy as np
import pytest

from rcac_ros.core import GainError, PaperTrajectory, RecursiveCompositeController, Simulator, \
    css_arm

Q0 = np.array([0.1, -0.3, 0.5, 0.2, -0.4, 0.3, 0.1])
H = 0.002


def at_rest(ctrl, steps, record=None):
    """Hold q = q_d = Q0, qd = qd_d = qdd_d = 0: s_i = 0, so Y_ri^T s_i = 0 exactly."""
    z = np.zeros(7)
    out = []
    for _ in range(steps):
        ctrl.step(Q0, z, Q0, z, z)
        out.append(ctrl.theta_hat)
    return np.array(out)


def random_spd(rng, scale):
    A = rng.normal(size=(13, 13))
    return scale * (A @ A.T / 13 + np.eye(13))


@pytest.mark.parametrize("update", ["implicit", "explicit"])
@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.0, 0.0, -9.81)])
def test_fixed_leakage_decays_to_theta_0_at_the_closed_form_rate(update, gravity):
    """No tracking input (s = 0) and no prediction term (gamma = 0): the law reduces to
    ``theta_tilde+ = (I - h sigma P) theta_tilde`` per link, i.e. the exponential decay
    ``exp(-sigma P t)`` of ``d/dt theta_tilde = -sigma P theta_tilde`` sampled by Euler."""
    rng = np.random.default_rng(3)
    model = css_arm(gravity)
    P = np.array([random_spd(rng, 50.0) for _ in range(7)])
    theta_0 = rng.normal(size=(7, 13))
    start = theta_0 + rng.normal(size=(7, 13))
    sigma = 0.05
    ctrl = RecursiveCompositeController(model, P=P, gamma=0.0, theta_hat0=start,
                                        theta_0=theta_0, leakage=sigma, update=update)
    steps = 400
    got = at_rest(ctrl, steps)
    for i in range(7):
        step = np.eye(13) - H * sigma * P[i]
        want = theta_0[i] + np.linalg.matrix_power(step, steps) @ (start[i] - theta_0[i])
        assert np.allclose(got[-1, i], want, rtol=1e-11, atol=1e-11)
        # and the continuous solution, to Euler's O(h) per unit time
        w, V = np.linalg.eigh(P[i])
        cont = theta_0[i] + V @ (np.exp(-sigma * w * steps * H) * (V.T @ (start[i] - theta_0[i])))
        assert np.allclose(got[-1, i], cont, atol=2e-3 * np.abs(start[i] - theta_0[i]).max())


def test_theta_0_defaults_to_theta_hat0_and_survives_reset():
    """Without theta_0 the leakage pulls toward the initial estimates (a fixed point at rest);
    reset() to other estimates keeps theta_0, and the decay resumes toward it."""
    model = css_arm()
    start = np.full((7, 13), 2.0)
    ctrl = RecursiveCompositeController(model, P=100.0, gamma=0.0, theta_hat0=start,
                                        leakage=0.1)
    assert np.array_equal(at_rest(ctrl, 50)[-1], start)
    ctrl.reset(np.zeros((7, 13)))
    got = at_rest(ctrl, 100)[-1]
    assert np.allclose(got, 2.0 * (1.0 - (1.0 - H * 0.1 * 100.0) ** 100), rtol=1e-12)


def switching_reference(d0, steps, sigma, p, m0):
    """Norm of theta_hat - theta_0 under the switching sigma of Ioannou & Sun ch. 8, P = p I."""
    out, d = [], d0
    for _ in range(steps):
        s = 0.0 if d <= m0 else sigma * min(d / m0 - 1.0, 1.0)
        d = d * (1.0 - H * s * p)
        out.append(d)
    return np.array(out)


def test_switching_leakage_follows_its_three_regions():
    """From 3 M_0 out (M_0 per link): full sigma beyond 2 M_0, the linear ramp between, and
    the estimates never enter the ball (the leakage vanishes on its boundary); each step
    matches the scalar recursion of the switching law (theta_tilde keeps its direction,
    P = p I)."""
    rng = np.random.default_rng(4)
    model = css_arm()
    m0, sigma, p = np.linspace(1.0, 4.0, 7), 1.0, 100.0
    direction = rng.normal(size=(7, 13))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    theta_0 = rng.normal(size=(7, 13))
    ctrl = RecursiveCompositeController(model, P=p, gamma=0.0, theta_0=theta_0,
                                        theta_hat0=theta_0 + 3.0 * m0[:, None] * direction,
                                        leakage=sigma, leakage_bound=m0)
    steps = 3000
    dist = np.linalg.norm(at_rest(ctrl, steps) - theta_0, axis=2)     # (steps, 7)
    for i in range(7):
        want = switching_reference(3.0 * m0[i], steps, sigma, p, m0[i])
        assert np.allclose(dist[:, i], want, rtol=1e-10)
    assert np.all(np.diff(dist, axis=0) <= 0.0) and np.all(dist >= m0 * (1.0 - 1e-12))
    assert np.all(dist[-1] < 1.05 * m0)         # each link has reached its ball's boundary
    first = dist[0, 0] / (3.0 * m0[0])              # beyond 2 M_0: the full rate
    assert first == pytest.approx(1.0 - H * sigma * p, rel=1e-12)


def test_switching_leakage_is_inactive_inside_the_ball():
    """Estimates inside ``||theta_hat_i - theta_0i|| <= M_0`` all run: the law (through the
    general kernel, as leakage is on) is the paper's law (the fused kernel) bit for bit."""
    model = css_arm()
    traj = PaperTrajectory(Q0, reading="position")
    runs = []
    for kwargs in ({}, dict(leakage=1.0, leakage_bound=1e9)):
        ctrl = RecursiveCompositeController(model, **kwargs)
        sim = Simulator(model, q0=Q0)
        taus = []
        for k in range(500):
            taus.append(ctrl.step(sim.q, sim.qd, *traj(k * H)))
            sim.step(taus[-1])
        runs.append((np.array(taus), ctrl.theta_hat, ctrl.E))
    assert np.abs(runs[0][1]).max() > 1.0               # the estimates did move
    for a, b in zip(*runs):
        assert np.array_equal(a, b)


def test_leakage_pulls_a_closed_loop_toward_theta_0():
    """In a closed loop the fixed leakage keeps the estimates nearer theta_0 = 0 than the
    plain law does, and a stronger leakage nearer still (the price: a biased law)."""
    model = css_arm()
    traj = PaperTrajectory(Q0)
    norms = []
    for sigma in (0.0, 0.5, 4.0):
        ctrl = RecursiveCompositeController(model, leakage=sigma)
        sim = Simulator(model, q0=Q0)
        for k in range(1000):
            sim.step(ctrl.step(sim.q, sim.qd, *traj(k * H)))
        norms.append(np.linalg.norm(ctrl.theta_hat))
    assert norms[0] > norms[1] > norms[2] > 0.0


@pytest.mark.parametrize("kwargs,match", [
    (dict(leakage=-1.0), "leakage"),
    (dict(leakage_bound=-1.0), "leakage_bound: must be >= 0"),
    (dict(leakage_bound=[1.0, 2.0]), "leakage_bound: expected a scalar or 7 values"),
    (dict(leakage=5.0, P=100.0), r"leakage: h \* leakage \* lambda_max\(P\) = 1, must be < 1"),
    (dict(leakage=1.0, theta_0=np.zeros((6, 13))), "theta_0: expected shape"),
    (dict(leakage=1.0, theta_0=np.full((7, 13), np.nan)), "theta_0: contains NaN"),
])
def test_bad_leakage_options_name_the_field(kwargs, match):
    with pytest.raises(GainError, match=match):
        RecursiveCompositeController(css_arm(), **kwargs)
