"""Least-squares gain (square-root form, bounded-gain forgetting), dead zones and projection."""

import numpy as np
import pytest

from rcac_ros.core import PaperTrajectory, RecursiveCompositeController, Simulator, css_arm
from rcac_ros.core.least_squares import bounded_gain_forgetting, potter_update
from rcac_ros.core.model import PAPER_Q0

Q0 = np.array(PAPER_Q0)


@pytest.mark.parametrize("d, rtol, atol", [(13, 1e-9, 1e-12), (3, 1e-10, 1e-13)])
def test_potter_update_is_the_information_update(d, rtol, atol):
    """S S^T after the update equals inv(inv(P) + h w^T w) (numpy's inverse as reference):
    a link's 13x13 factor and a joint's 3x3 (doc/design.md §7)."""
    rng = np.random.default_rng(31 if d == 13 else 41)
    f, Sf = np.empty(d), np.empty(d)
    for _ in range(30):
        A = rng.normal(size=(d, d))
        P = A @ A.T / d + 0.1 * np.eye(d)
        S = np.linalg.cholesky(P).ravel().copy()
        w, h = rng.normal(size=d) * 10.0, 0.002
        potter_update(S, w, h, f, Sf)
        P1 = S.reshape(d, d) @ S.reshape(d, d).T
        ref = np.linalg.inv(np.linalg.inv(P) + h * np.outer(w, w))
        assert np.allclose(P1, ref, rtol=rtol, atol=atol * np.abs(ref).max())


def test_square_root_form_stays_positive_definite():
    """10^4 updates along nearly one direction with a huge weight (P's condition number
    grows past 1e12): the factored form stays symmetric positive definite."""
    rng = np.random.default_rng(32)
    P = np.diag(10.0 ** rng.uniform(-3, 3, 13))
    S = np.sqrt(P).ravel().copy()
    f, Sf = np.empty(13), np.empty(13)
    d = rng.normal(size=13)
    for k in range(10000):
        w = 1e4 * (d + 1e-9 * rng.normal(size=13))
        potter_update(S, w, 0.002, f, Sf)
    P1 = S.reshape(13, 13) @ S.reshape(13, 13).T
    ev = np.linalg.eigvalsh(P1)
    assert ev.min() > 0.0 and ev.max() / ev.min() > 1e12
    # the direction d is known to ~ 1/(h |w|^2 10^4), the others are untouched
    assert d @ P1 @ d / (d @ d) < 1e-9


def test_bounded_gain_forgetting_keeps_the_trace_at_most_k0():
    S = np.eye(13).ravel() * 3.0                 # trace 117
    for _ in range(5000):                         # no excitation: P grows back to k_0
        tr = bounded_gain_forgetting(S, 0.002, 2.0, 200.0)
        assert tr <= 200.0 * (1.0 + 1e-12)
    assert tr > 190.0
    S = np.eye(13).ravel() * 5.0                  # trace 325 > k_0: brought down at once
    assert bounded_gain_forgetting(S, 0.002, 2.0, 200.0) == pytest.approx(200.0)


def run(model, steps, traj, **kwargs):
    ctrl = RecursiveCompositeController(model, **kwargs)
    sim = Simulator(model, q0=Q0)
    hist = []
    for k in range(steps):
        before = ctrl.gain
        sim.step(ctrl.step(sim.q, sim.qd, *traj(k * ctrl.h)))
        hist.append((before, ctrl.W, ctrl.gain, ctrl.theta_hat))
    return ctrl, hist


@pytest.mark.parametrize("channels", [[1], "all"])
def test_controller_least_squares_step_is_the_continuous_law_discretised(channels):
    """Each step: P+^-1 = beta (P^-1 + h sum_c W_ci^T W_ci) per link, trace(P) <= P_max."""
    model = css_arm()
    traj = PaperTrajectory(Q0, reading="position")
    ctrl, hist = run(model, 300, traj, P=1.0, adaptation="least_squares", forgetting=1.0,
                     channels=channels)
    for before, W, after, _ in hist[5:]:
        for i in range(model.n):
            info = np.linalg.inv(before[i]) + 0.002 * W[:, i].T @ W[:, i]
            lhs = np.linalg.inv(after[i])
            beta = np.trace(lhs) / np.trace(info)
            assert 0.0 < beta <= 1.0 + 1e-12
            assert np.allclose(lhs, beta * info, rtol=1e-6, atol=1e-9 * np.abs(lhs).max())
            assert np.trace(after[i]) <= 13.0 * (1.0 + 1e-9)
            assert np.linalg.eigvalsh(after[i]).min() > 0.0
    # it did shrink in the excited directions
    assert min(np.linalg.eigvalsh(P).min() for P in hist[-1][2]) < 1e-2


def test_least_squares_on_the_prediction_term_keeps_the_tracking_gain():
    """With gamma = 0 the prediction term is off: least squares on it alone is the direct law."""
    model = css_arm()
    traj = PaperTrajectory(Q0)
    a, _ = run(model, 300, traj, gamma=0.0, adaptation="least_squares_prediction",
               forgetting=1.0)
    b, _ = run(model, 300, traj, gamma=0.0)
    assert np.allclose(a.theta_hat, b.theta_hat, rtol=1e-12, atol=1e-12)
    c, _ = run(model, 300, traj, gamma=0.0, adaptation="least_squares", forgetting=1.0)
    assert not np.allclose(c.theta_hat, b.theta_hat, rtol=1e-3)       # the check can fail


def test_dead_zone_on_E_above_every_error_is_the_direct_law():
    model = css_arm()
    traj = PaperTrajectory(Q0, reading="position")
    a, _ = run(model, 400, traj, dead_zone_E=1e30, channels=[1, "power"])
    b, _ = run(model, 400, traj, gamma=0.0, channels=[1, "power"])
    assert np.array_equal(a.theta_hat, b.theta_hat)
    assert not a.adapted[1].any() and a.adapted[0]


def test_dead_zones_above_every_signal_stop_adaptation():
    model = css_arm()
    traj = PaperTrajectory(Q0, reading="position")
    theta0 = 0.5 * model.theta()
    a, hist = run(model, 400, traj, dead_zone_E=1e30, dead_zone_s=1e30, theta_hat0=theta0)
    assert np.array_equal(a.theta_hat, theta0)
    b, _ = run(model, 400, traj, dead_zone_E=1e-3, dead_zone_s=1e-3, theta_hat0=theta0)
    assert not np.array_equal(b.theta_hat, theta0)                   # small zones: it adapts


def test_projection_keeps_masses_nonnegative_and_the_box():
    model = css_arm((0.0, 0.0, -9.81))
    traj = PaperTrajectory(Q0, reading="position")
    _, free = run(model, 600, traj)
    assert min(h[3][:, 0].min() for h in free) < -1.0                # it would go negative
    _, proj = run(model, 600, traj, theta_bounds="mass")
    assert min(h[3][:, 0].min() for h in proj) >= 0.0
    lo = np.full(13, -5.0)
    hi = np.full(13, 5.0)
    lo[0] = 1.0
    _, box = run(model, 600, traj, theta_bounds=(lo, hi), theta_hat0=np.full((7, 13), 2.0))
    th = np.array([h[3] for h in box])
    assert th.min() >= -5.0 and th.max() <= 5.0 and th[:, :, 0].min() >= 1.0
    assert np.isclose(th.max(), 5.0) or np.isclose(th.min(), -5.0)   # a bound was hit
