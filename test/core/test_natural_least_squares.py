"""The recursive law with ``geometry="natural"`` and ``adaptation="least_squares"``: the gain
``(H(theta_hat) / k + Gamma)^-1`` (doc/design.md §8).

References: the Euclidean law with the fixed gain computed by numpy from the trace formula
of the Hessian (``log_det_hessian``) and the least-squares factor, then the retraction's
closed form; the Euclidean least-squares law (its gain update, and the same law when
``H / k`` is negligible); Cholesky of every J at every step; the payload scenario of
``rcac compare`` against the Euclidean least-squares law.
"""

import numpy as np
import pytest

from chains import random_chain
from rcac_ros.core import RecursiveCompositeController, Simulator, css_arm
from rcac_ros.core.model import PAPER_GAINS, PAPER_Q0
from rcac_ros.core.pseudo_inertia import is_body, log_det_hessian, pseudo_inertia

from test_natural_geometry import (assert_bodies_at_every_step, assert_retracted_step,
                                   euclidean_twin, run)

LS = dict(adaptation="least_squares", forgetting=1.0)


def natural_ls_gain(theta, k, P_ls):
    """``(H(theta) / k + P_ls^-1)^-1`` by numpy (doc/design.md §8)."""
    return np.linalg.inv(log_det_hessian(theta) / k + np.linalg.inv(P_ls))


@pytest.mark.parametrize("gamma, k, P", [(0.0, None, 100.0), (0.1, None, 100.0),
                                         (0.1, 1e12, 1.0)])
def test_natural_ls_step_is_the_euclidean_step_with_the_metric_then_the_retraction(gamma, k, P):
    """Two steps: the Euclidean law with the fixed gain ``(H(theta_hat) / k + Gamma)^-1``
    gives theta_lin; the natural least-squares law gives the parameters of ``J + Delta +
    1/2 Delta J^-1 Delta`` and nu(theta_lin); its least-squares factor evolves as the
    Euclidean least-squares law's. ``k = 1e12``: H / k is negligible, the step before the
    retraction is the Euclidean least-squares step (with a gain small enough that the
    retraction does not shorten it)."""
    model = css_arm()
    nat = RecursiveCompositeController(model, geometry="natural", gamma=gamma, P=P,
                                       natural_gain=k, **LS)
    th0 = nat.theta_hat
    ls = RecursiveCompositeController(model, gamma=gamma, P=P, theta_hat0=th0, **LS)
    euc = RecursiveCompositeController(model, P=nat.gain, gamma=gamma, theta_hat0=th0)
    q = np.array(PAPER_Q0) + 0.05
    qd = np.linspace(-0.3, 0.3, model.n)
    args = (q, qd, np.array(PAPER_Q0), np.zeros(7), np.full(7, 0.2))
    for step in range(2):                   # the second step has a live prediction term
        th_start = nat.theta_hat
        assert np.allclose(nat.gain, ls.gain, rtol=1e-12, atol=0.0)
        P = np.array([natural_ls_gain(th_start[i], nat.natural_gain[i], nat.gain[i])
                      for i in range(model.n)])
        ls.step(*args)
        euclidean_twin(euc, nat, P, filters=step == 1)
        assert_retracted_step(nat, euc, args, rtol=1e-8, atol_D=1e-8, nu_rtol=1e-8,
                              nu_atol_step=1e-8)
    assert np.allclose(nat.gain, ls.gain, rtol=1e-12, atol=0.0)


def test_the_gain_is_below_both_the_least_squares_and_the_natural_gradient_gains():
    """``(H / k + Gamma)^-1 <= Gamma^-1`` and ``<= k H^-1`` on J (Loewner order): the law
    steps no further than either (doc/design.md §8), checked on numpy's gain."""
    model = css_arm()
    nat = RecursiveCompositeController(model, geometry="natural", **LS)
    th = nat.theta_hat
    for i in range(model.n):
        P_ls = nat.gain[i]
        P = natural_ls_gain(th[i], nat.natural_gain[i], P_ls)
        assert np.linalg.eigvalsh(P_ls - P).min() > -1e-9 * np.abs(P_ls).max()
        H = log_det_hessian(th[i])
        # on J: x^T H x / k >= x^T P^-1 x - x^T P_ls^-1 x  <=>  H / k + P_ls^-1 = P^-1
        x = np.random.default_rng(i).normal(size=(13, 20))
        lhs = np.einsum("ij,ik,kj->j", x, np.linalg.inv(P), x)
        assert np.all(lhs >= np.einsum("ij,ik,kj->j", x, H, x) / nat.natural_gain[i] - 1e-9)


@pytest.mark.parametrize("channels", [[1], "all"])
def test_consistent_at_every_step_under_huge_gains_errors_and_noise(channels):
    """Gains 1e4 x the paper's, fast forgetting and a huge P_max, a 0.5 rad start error,
    noisy measurements, a natural gain from matched to 1e12 (H / k negligible: the
    least-squares steps leave the cone and are retracted): every link's J is positive
    definite (Cholesky) after every step, for as long as the loop runs."""
    model = css_arm()
    rng = np.random.default_rng(5)
    gains = dict(PAPER_GAINS, P=1e6, gamma=100.0)
    for k in (None, 1e3, 1e12):
        ctrl = RecursiveCompositeController(model, geometry="natural", channels=channels,
                                            adaptation="least_squares", forgetting=50.0,
                                            P_max=1e9, natural_gain=k, **gains)
        assert_bodies_at_every_step(ctrl, model, 300, 1e-2, rng)


def test_every_option_keeps_bodies_and_least_squares_prediction_is_refused():
    """Explicit update, leakage, projection, the power channel and the joint terms with
    natural least squares: a body per link at every step. With the paper's gains the
    explicit update diverges (doc/design.md §6: the Euclidean law in 6 steps, this one in
    46) and so do the natural joint terms on this arm (doc/design.md §8, in 29 steps, as
    with the natural gradient law): there, every step until the loop stops."""
    from rcac_ros.core import GainError
    model = css_arm()
    variants = [dict(update="explicit"), dict(leakage=1e-3), dict(theta_bounds="mass"),
                dict(channels=[2, "power"]), dict(joint_friction=True)]
    for extra in variants:
        gains = dict(PAPER_GAINS, **extra)
        ctrl = RecursiveCompositeController(model, geometry="natural", **LS, **gains)

        def check(c):
            assert is_body(c.theta_hat).all(), extra
        steps = run(ctrl, model, 100, check=check)
        assert steps == 100 or (steps > 20 and ("update" in extra or "joint_friction" in extra))
    with pytest.raises(GainError, match="'least_squares', got 'least_squares_prediction'"):
        RecursiveCompositeController(model, geometry="natural",
                                     adaptation="least_squares_prediction")


def desired(t, n):
    w = 0.7 * np.arange(1, n + 1)
    return 0.3 * np.sin(w * t), 0.3 * w * np.cos(w * t), -0.3 * w * w * np.sin(w * t)


def test_negligible_barrier_gives_the_euclidean_least_squares_law():
    """``natural_gain`` = 1e12 on a body (a random 5-link chain, start 0.95 x the truth,
    2 s of sines): the Euclidean least-squares law stays inside the cone and the natural
    one follows it. Each step they differ by the retraction's second-order term
    ``1/2 Delta J^-1 Delta`` only (previous test), so the gap in J after the run (summed
    over the links, which couple through the prediction errors) must stay within twice
    the sum of those terms along the Euclidean run (the estimates of both laws see the
    same measurements, so a difference is not fed back through the plant); the matched
    natural gain, whose metric differs, ends more than 10x further away."""
    rng = np.random.default_rng(1)
    model = random_chain(rng, 5)
    n, h = model.n, 0.002
    th0 = 0.95 * model.theta()
    kw = dict(K_D=50.0, P=0.1, gamma=1.0, lam=10.0, h=h, Lambda=5.0, theta_hat0=th0, **LS)
    euc = RecursiveCompositeController(model, **kw)
    near = RecursiveCompositeController(model, geometry="natural", natural_gain=1e12, **kw)
    matched = RecursiveCompositeController(model, geometry="natural", **kw)
    sim = Simulator(model, dt=h, q0=np.full(n, 0.05))
    q, qd = sim.q.copy(), sim.qd.copy()
    second = np.zeros(n)
    for k in range(1000):
        args = (q, qd) + desired(k * h, n)
        prev = euc.theta_hat
        tau = euc.step(*args)
        near.step(*args)
        matched.step(*args)
        assert near.retraction_length == 1.0
        for i in range(n):
            J = pseudo_inertia(prev[i])
            D = pseudo_inertia(euc.theta_hat[i] - prev[i])
            second[i] += 0.5 * np.linalg.norm(D @ np.linalg.solve(J, D))
        q, qd = sim.step(tau)
    assert euc.consistent.all()
    J_euc = pseudo_inertia(euc.theta_hat)
    gap = np.linalg.norm(pseudo_inertia(near.theta_hat) - J_euc, axis=(1, 2))
    gap_matched = np.linalg.norm(pseudo_inertia(matched.theta_hat) - J_euc, axis=(1, 2))
    moved = np.linalg.norm(J_euc - pseudo_inertia(th0), axis=(1, 2))
    assert gap.sum() <= 2.0 * second.sum()          # the links couple through E and the loop
    assert gap.sum() < 0.05 * moved.sum()
    assert gap_matched.sum() > 10.0 * 2.0 * second.sum()


def test_payload_scenario_consistent_and_identifies_the_payload_mass():
    """``rcac compare``'s payload scenario (the Panda, 2 kg at t = 5 s, 20 s), as it runs:
    natural least squares does not diverge, is a body at every step, and ends with a
    payload mass error no larger than the Euclidean least-squares law's (doc/design.md
    §8's figures)."""
    from rcac_ros.tools.demos.compare import make_controller, metrics, payload_scenario, run_law
    scenario = payload_scenario()
    out = {}
    for law in ("ls_paper", "ls_natural"):
        ctrl = make_controller(scenario, law)
        out[law] = metrics(run_law(scenario, ctrl, 20.0), scenario)
    nat, euc = out["ls_natural"], out["ls_paper"]
    assert nat["diverged_at"] is None and nat["consistent_every_step"]
    assert not euc["consistent_every_step"]           # what the natural geometry adds
    assert nat["payload_mass_error"] <= euc["payload_mass_error"]
    assert nat["rms"] < 2.0 * euc["rms"]
