"""The recursive law with ``geometry="natural"``: consistent estimates at every step
(doc/design.md §8).

References: the Euclidean law with the frozen gain ``P_eff`` (the same step before the
retraction, whose second-order term is then checked exactly), Pinocchio-free properties
(Cholesky of every J at every step) and the closed form of the default start.
"""

import numpy as np
import pytest

from rcac_ros.core import (GainError, InputError, PaperTrajectory, RecursiveCompositeController,
                           Simulator, css_arm)
from rcac_ros.core.model import PAPER_GAINS, PAPER_Q0
from rcac_ros.core.pseudo_inertia import (default_start, is_body, natural_gain_apply,
                                          pseudo_inertia)


def run(ctrl, model, steps, noise=0.0, rng=None, check=None):
    """Close the loop from a 0.5 rad error for ``steps`` periods (optional noise)."""
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0)
    sim = Simulator(model, dt=ctrl.h, q0=q0 + 0.5)
    q, qd = sim.q.copy(), sim.qd.copy()
    for k in range(steps):
        q_d, qd_d, qdd_d = traj(k * ctrl.h)
        qm = q + (noise * rng.normal(size=q.shape) if noise else 0.0)
        qdm = qd + (noise * 10 * rng.normal(size=q.shape) if noise else 0.0)
        if not (np.all(np.isfinite(qm)) and np.all(np.isfinite(qdm))):
            return k                          # the plant diverged: no more steps to check
        tau = ctrl.step(qm, qdm, q_d, qd_d, qdd_d)
        if not np.all(np.isfinite(tau)):
            return k
        q, qd = sim.step(np.clip(tau, -1e300, 1e300))
        if check is not None:
            check(ctrl)
    return steps


def assert_bodies_at_every_step(ctrl, model, steps, noise, rng):
    """:func:`run` with noise, checking after every step that every link's J is positive
    definite (Cholesky) and the estimates finite; at least 10 steps ran and the smallest
    lambda_min(J_hat) stayed > 0."""
    worst = []

    def check(c):
        assert c.consistent.all()
        assert np.all(np.isfinite(c.theta_hat))
        worst.append(c.lambda_min.min())
    run(ctrl, model, steps, noise=noise, rng=rng, check=check)
    assert len(worst) > 10 and min(worst) > 0.0


def euclidean_twin(euc, nat, P, filters):
    """Set the Euclidean law ``euc`` to the natural law ``nat``'s estimates with the gain
    ``P`` (n, 13, 13) (and, with ``filters``, its filters of eqs 21-24): its next step is
    the natural step's linearly implicit part, before the retraction."""
    euc.reset(nat.theta_hat)
    if filters:
        euc._filt[:] = nat._filt
        euc._chan[:] = nat._chan
        euc._scal[9] = nat._scal[9]
        euc._state[:, 19:21] = nat._state[:, 19:21]
    euc._const[:, 49:218] = P.reshape(-1, 169)
    euc._scal[12] = 0.0                                  # P is not diagonal


def assert_retracted_step(nat, euc, args, rtol, atol_J=0.0, atol_D=0.0, nu_rtol=0.0,
                          nu_atol=0.0, nu_atol_step=0.0):
    """One step of both (:func:`euclidean_twin`): the same effort, and the natural law's
    estimates are the retraction J + D + 1/2 D J^-1 D of the Euclidean step (D its change
    of J) with nu(theta_lin), the retraction not shortened (doc/design.md §8). Absolute
    tolerances relative to the largest entry of J, of D, of the step."""
    th_start = nat.theta_hat
    tau_e = euc.step(*args)
    tau_n = nat.step(*args)
    assert np.allclose(tau_e, tau_n, rtol=1e-12, atol=1e-9)
    lin = euc.theta_hat
    assert nat.retraction_length == 1.0
    for i in range(th_start.shape[0]):
        J = pseudo_inertia(th_start[i])
        D = pseudo_inertia(lin[i] - th_start[i])
        want = J + D + 0.5 * D @ np.linalg.solve(J, D)
        got = pseudo_inertia(nat.theta_hat[i])
        assert np.allclose(got, want, rtol=rtol,
                           atol=atol_J * np.abs(J).max() + atol_D * np.abs(D).max())
        assert np.allclose(nat.theta_hat[i, 4:7], lin[i, 4:7], rtol=nu_rtol,
                           atol=nu_atol + nu_atol_step * np.abs(lin[i] - th_start[i]).max())
    assert np.abs(lin - th_start).max() > 1e-6        # the step did something


def p_eff(theta, k, Pnu):
    """The natural gain P_eff(theta) (13 x 13) of one link, column by column."""
    out = np.zeros((13, 13))
    for c, e in enumerate(np.eye(13)):
        natural_gain_apply(theta, 0, e, 0, out[:, c], 0, k, Pnu.ravel(), 0)
    return 0.5 * (out + out.T)


def test_default_start_and_bad_starts():
    model = css_arm()
    ctrl = RecursiveCompositeController(model, geometry="natural", natural_metric="log_det")
    assert np.array_equal(ctrl.theta_hat, default_start(model.theta()))
    assert ctrl.consistent.all() and (ctrl.lambda_min > 0).all()
    with pytest.raises(InputError, match="theta_hat0: link 1 is not a physical body"):
        RecursiveCompositeController(model, geometry="natural", natural_metric="log_det",
                                     theta_hat0=np.zeros((7, 13)))
    with pytest.raises(InputError, match="link 7 is not a physical body"):
        th = default_start(model.theta())
        th[6, 0] = -1.0
        ctrl.reset(th)
    with pytest.raises(GainError, match="geometry: expected"):
        RecursiveCompositeController(model, geometry="riemann")
    with pytest.raises(GainError, match="natural_gain: only with"):
        RecursiveCompositeController(model, natural_gain=1.0)
    with pytest.raises(GainError, match="natural_gain: must be > 0"):
        RecursiveCompositeController(model, geometry="natural", natural_metric="log_det",
                                     natural_gain=0.0)


@pytest.mark.parametrize("gamma", [0.0, 0.1])
def test_natural_step_is_the_euclidean_step_with_p_eff_then_the_retraction(gamma):
    """One step: the Euclidean law with P = P_eff(theta_hat0) gives theta_lin; the natural
    law gives the parameters of J + Delta + 1/2 Delta J^-1 Delta, Delta = J(theta_lin -
    theta_hat0), and nu(theta_lin) (doc/design.md §8)."""
    model = css_arm()
    nat = RecursiveCompositeController(model, geometry="natural", natural_metric="log_det",
                                       gamma=gamma)
    th0 = nat.theta_hat
    P = np.array([p_eff(th0[i], nat.natural_gain[i],
                        nat._const[i, 260:269].reshape(3, 3)) for i in range(model.n)])
    euc = RecursiveCompositeController(model, P=P, gamma=gamma, theta_hat0=th0)
    q = np.array(PAPER_Q0) + 0.05
    qd = np.linspace(-0.3, 0.3, model.n)
    args = (q, qd, np.array(PAPER_Q0), np.zeros(7), np.full(7, 0.2))
    for step in range(2):                   # the second step has a live prediction term
        th_start = nat.theta_hat
        P = np.array([p_eff(th_start[i], nat.natural_gain[i],
                            nat._const[i, 260:269].reshape(3, 3)) for i in range(model.n)])
        euclidean_twin(euc, nat, P, filters=step == 1)
        assert_retracted_step(nat, euc, args, rtol=1e-9, atol_J=1e-9, nu_rtol=1e-12,
                              nu_atol=1e-12)


def test_consistent_at_every_step_under_huge_gains_errors_and_noise():
    """Gains 1e4 x the paper's, a 0.5 rad start error, noisy measurements, all channels:
    every link's J is positive definite (Cholesky) after every step."""
    model = css_arm()
    rng = np.random.default_rng(3)
    gains = dict(PAPER_GAINS, P=1e6, gamma=100.0)
    for channels in ([1], "all"):
        ctrl = RecursiveCompositeController(model, geometry="natural", natural_metric="log_det",
                                            channels=channels,
                                            natural_gain=1e3, **gains)
        assert_bodies_at_every_step(ctrl, model, 300, 1e-2, rng)


def test_every_adaptation_variant_keeps_bodies():
    """Explicit update, leakage and projection with the natural geometry: a body per link
    at every step; least squares on the prediction term only is refused (doc/design.md §8;
    least squares: test/core/test_natural_least_squares.py)."""
    model = css_arm()
    variants = [dict(update="explicit"), dict(leakage=1e-3), dict(theta_bounds="mass"),
                dict(channels=[2, "power"])]
    for extra in variants:
        gains = dict(PAPER_GAINS, **extra)
        ctrl = RecursiveCompositeController(model, geometry="natural", natural_metric="log_det",
                                            **gains)

        def check(c):
            assert is_body(c.theta_hat).all(), extra
        assert run(ctrl, model, 100, check=check) == 100
    with pytest.raises(GainError, match="geometry: 'natural' needs adaptation='gradient' or "
                                        "'least_squares', got 'least_squares_prediction'"):
        RecursiveCompositeController(model, geometry="natural", natural_metric="log_det",
                                     adaptation="least_squares_prediction")


def test_slotine_li_natural_keeps_bodies_and_matches_the_recursive_law_with_all_channels():
    """The non-recursive law with the natural geometry is the recursive law with
    channels="all" and the natural geometry, step by step (both are the same law), and its
    estimates are bodies at every step."""
    from rcac_ros.core import SlotineLiCompositeController
    model = css_arm()
    sl = SlotineLiCompositeController(model, geometry="natural", natural_metric="log_det",
                                      **PAPER_GAINS)
    rc = RecursiveCompositeController(model, geometry="natural", natural_metric="log_det",
                                      channels="all", **PAPER_GAINS)
    assert np.allclose(sl.natural_gain, rc.natural_gain)
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0)
    sim = Simulator(model, dt=0.002, q0=q0 + 0.2)
    for k in range(150):
        q, qd = sim.q.copy(), sim.qd.copy()
        args = (q, qd) + tuple(traj(k * 0.002))
        tau = sl.step(*args)
        assert np.allclose(rc.step(*args), tau, rtol=1e-8, atol=1e-6)
        assert np.allclose(rc.theta_hat, sl.theta_hat, rtol=1e-8, atol=1e-8)
        assert sl.consistent.all()
        sim.step(tau)
