"""The recursive law with ``geometry="natural"`` and ``natural_metric="barrier"``: the gain
``P_mix = (A^T H A / (c k) + P^-1)^-1`` (doc/design.md §8).

References: numpy's solve with the Hessian of ``-log det J`` built here from its trace
formula ``H_ab = tr(J^-1 E_a J^-1 E_b)`` on J's 10 entries (J from the 13 parameters by
the closed form of doc/design.md §8, written out below); the Euclidean law with the fixed
gain ``P_mix`` (the same step before the retraction, whose closed form is then checked);
the Euclidean law's step followed by that closed form (``c`` huge); numpy's eigenvalues of
every J at every step; the log-det metric's own runs (the default, bit for bit).
"""

import numpy as np
import pytest

from chains import random_chain
from rcac_ros.core import GainError, RecursiveCompositeController, Simulator, css_arm
from rcac_ros.core._packing import (BAR_F, BAR_Q, CONST_COLS, NAT_P_NU, P_FACTOR, STATE_COLS,
                                    THETA_HAT)
from rcac_ros.core.natural_step import (L_CK, L_F, L_G, L_P_NU, L_PG, L_Q, L_U, L_W, LANE_ROWS,
                                        LANES, RETRACT_ROWS, barrier_apply, barrier_factor,
                                        barrier_lanes, natural_ls_apply, natural_ls_factor,
                                        retract_lanes, retract_links)
from rcac_ros.core.model import PAPER_GAINS
from rcac_ros.core.pseudo_inertia import BARRIER_C, barrier_blocks, default_start, nu_gain
from rcac_ros.core.retraction import FLOOR, HALVINGS, NU_RATIO, retract_short

from test_natural_geometry import euclidean_twin, run

BARRIER = dict(geometry="natural", natural_metric="barrier")
#: J's 10 entries, in the order of A's rows
ENTRIES = ((0, 0), (1, 1), (2, 2), (3, 3), (0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3))


def J_of(t):
    """J(theta) written out from doc/design.md §8 (0-based t)."""
    return np.array([[t[4] + (-t[10] + t[11] + t[12]) / 2, t[7], t[8], t[1]],
                     [t[7], t[5] + (t[10] - t[11] + t[12]) / 2, t[9], t[2]],
                     [t[8], t[9], t[6] + (t[10] + t[11] - t[12]) / 2, t[3]],
                     [t[1], t[2], t[3], t[0]]])


#: theta -> J's 10 entries (10 x 13)
A = np.array([[J_of(e)[i, j] for e in np.eye(13)] for i, j in ENTRIES])


def entry_basis(a):
    """E_a: the symmetric 4x4 whose entry a (both halves) is 1."""
    i, j = ENTRIES[a]
    E = np.zeros((4, 4))
    E[i, j] = E[j, i] = 1.0
    return E


def p_mix(theta, k, c, P):
    """``(A^T H A / (c k) + P^-1)^-1`` by numpy, H from the trace formula."""
    Ji = np.linalg.inv(J_of(theta))
    H = np.array([[np.trace(Ji @ entry_basis(a) @ Ji @ entry_basis(b)) for b in range(10)]
                  for a in range(10)])
    return np.linalg.inv(A.T @ H @ A / (c * k) + np.linalg.inv(P))


def kernel_gain(theta, P, kk, barrier):
    """The kernel's gain (the functions adapt_link calls) as a function of g: with
    ``barrier``, the factor of ``H_J / kk + (A P A^T)^-1`` on J's entries, nu eliminated
    (the barrier metric), then its block solve; else the factor of ``K = I + S^T H S / kk``
    by whitening (the natural least-squares law's, ``S = chol(P)``), then ``S K^-1 S^T g``."""
    row = np.zeros(CONST_COLS)
    st = np.zeros(STATE_COLS)
    st[THETA_HAT:THETA_HAT + 13] = theta
    st[P_FACTOR:P_FACTOR + 169] = np.linalg.cholesky(P).ravel()
    Q, F = barrier_blocks(P[None])
    row[BAR_Q:BAR_Q + 55] = Q[0]
    row[BAR_F:BAR_F + 30] = F[0].ravel()
    row[NAT_P_NU:NAT_P_NU + 9] = nu_gain(P[None])[0].ravel()
    if barrier:
        barrier_factor(row, 0, st, 0, kk)
    else:
        natural_ls_factor(st, kk, np.empty(13), np.empty((4, 4, 4)))

    def apply(g):
        out = np.empty(13)
        if barrier:
            barrier_apply(row, 0, st, 0, g, 0, out, 0)
        else:
            natural_ls_apply(st, g, 0, out, 0, np.empty(13))
        return out
    return apply


def test_the_kernel_gain_is_numpys_solve_and_below_p():
    """The kernel's gain against ``np.linalg.solve(A^T H A / (c k) + P^-1, g)`` on random
    bodies, diagonal gains over four decades and full random gains (both factorisations:
    the barrier metric's on J's entries, and the whitening of natural least squares), k and c
    over several: the residual of the system at rounding (1e-15 of ``||M|| ||out||``) and
    the two solutions within 1e-12 relative, or within ``eps cond(M)`` times a small factor
    where ``M`` is worse conditioned (then neither solver is closer: the share within 1e-12
    is checked too); and ``g^T P_mix g <= g^T P g``."""
    rng = np.random.default_rng(3)
    worst = worst_residual = 0.0
    errors = []
    for seed in range(4):
        for theta in random_chain(np.random.default_rng(seed), 5).theta():
            Ji = np.linalg.inv(J_of(theta))
            H = np.array([[np.trace(Ji @ entry_basis(a) @ Ji @ entry_basis(b))
                           for b in range(10)] for a in range(10)])
            X = rng.normal(size=(13, 13))
            for P in (np.diag(10.0 ** rng.uniform(-2.0, 2.0, 13)), X @ X.T + np.eye(13)):
                for k in (1e-3, 0.3, 50.0):
                    for c in (1.0, 100.0, 1e4):
                        M = A.T @ H @ A / (c * k) + np.linalg.inv(P)
                        tol = max(1e-12, 20.0 * np.finfo(float).eps * np.linalg.cond(M))
                        fns = [kernel_gain(theta, P, c * k, b) for b in (True, False)]
                        for g in rng.normal(size=(3, 13)) * 10.0 ** rng.uniform(-3, 3, (3, 1)):
                            want = np.linalg.solve(M, g)
                            for fn in fns:
                                out = fn(g)
                                err = np.linalg.norm(out - want) / np.linalg.norm(want)
                                assert err < tol
                                errors.append(err)
                                worst = max(worst, err / tol)
                                worst_residual = max(worst_residual, np.linalg.norm(M @ out - g)
                                                     / (np.linalg.norm(M, 2)
                                                        * np.linalg.norm(out)))
                                assert g @ out <= g @ P @ g * (1.0 + 1e-12)   # P_mix <= P
    assert worst_residual < 1e-15 and worst > 0.0
    assert np.mean(np.array(errors) < 1e-12) > 0.5


def test_the_lanes_are_the_per_link_kernel_bit_for_bit():
    """``barrier_lanes`` (LANES links side by side, the fused law's path) against
    ``barrier_factor`` and ``barrier_apply`` per link (the general kernel's path) on random
    bodies, full random gains, k, c and right-hand sides over many scales: the same
    numbers, bit for bit (the same operations in the same order), and the solve of
    ``P_mix^-1 out = g`` (numpy) within 1e-9."""
    from rcac_ros.core.pseudo_inertia import pseudo_inertia
    rng = np.random.default_rng(8)
    slots = ((0, 0), (1, 1), (2, 2), (3, 3), (0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3))
    X = np.empty(LANE_ROWS * LANES)
    lane = lambda row, l: LANES * row + l                      # noqa: E731
    bodies = random_chain(np.random.default_rng(1), LANES).theta()
    want = []
    for l, theta in enumerate(bodies):
        Y = rng.normal(size=(13, 13))
        P = Y @ Y.T + np.eye(13) * 10.0 ** rng.uniform(-2, 2)
        ck = 10.0 ** rng.uniform(-3, 4)
        row = np.zeros(CONST_COLS)
        st = np.zeros(STATE_COLS)
        st[THETA_HAT:THETA_HAT + 13] = theta
        Q, F = barrier_blocks(P[None])
        row[BAR_Q:BAR_Q + 55], row[BAR_F:BAR_F + 30] = Q[0], F[0].ravel()
        row[NAT_P_NU:NAT_P_NU + 9] = nu_gain(P[None])[0].ravel()
        g, w = rng.normal(size=(2, 13)) * 10.0 ** rng.uniform(-3, 3, (2, 1))
        barrier_factor(row, 0, st, 0, ck)
        out = np.empty((2, 13))
        barrier_apply(row, 0, st, 0, g, 0, out[0], 0)
        barrier_apply(row, 0, st, 0, w, 0, out[1], 0)
        want.append(out)
        J = pseudo_inertia(theta)
        for k, (i, j) in enumerate(slots):
            X[lane(k, l)] = J[i, j]
        X[lane(L_CK, l)] = ck
        for base, v in ((L_Q, Q[0]), (L_F, F[0].ravel()), (L_P_NU, row[NAT_P_NU:NAT_P_NU + 9]),
                        (L_G, g), (L_W, w)):
            X[lane(base + np.arange(len(v)), l)] = v
        M = np.linalg.inv(p_mix(theta, 1.0, ck, P))
        for x, z in zip((g, w), out):
            assert np.linalg.norm(M @ z - x) <= 1e-9 * np.linalg.norm(M, 2) * np.linalg.norm(z)
    barrier_lanes(X)
    for l, out in enumerate(want):
        assert np.array_equal(X[lane(L_PG + np.arange(13), l)], out[0])
        assert np.array_equal(X[lane(L_U + np.arange(13), l)], out[1])


def step_args(n, rng):
    q = rng.uniform(-0.5, 0.5, n)
    return (q, rng.uniform(-0.3, 0.3, n), q + 0.05, np.zeros(n), np.full(n, 0.2))


@pytest.mark.parametrize("channels", [[1], "all"])
def test_barrier_step_is_the_euclidean_step_with_p_mix(channels):
    """Three steps on a random 5-link body from 0.9x its parameters (the later ones with
    live prediction terms: the implicit solve's columns U = P_mix W^T): the barrier law's
    step is the Euclidean law's with the fixed gain P_mix(theta_hat), all 13 parameters,
    when that step keeps J above half of J_hat (the shortened retraction does not act,
    doc/design.md §8)."""
    rng = np.random.default_rng(2)
    model = random_chain(rng, 5)
    kw = dict(K_D=50.0, P=0.5, gamma=1.0, Lambda=5.0, channels=channels,
              theta_hat0=0.9 * model.theta())
    nat = RecursiveCompositeController(model, barrier_c=30.0, **BARRIER, **kw)
    euc = RecursiveCompositeController(model, **kw)
    args = step_args(model.n, rng)
    for step in range(3):
        th = nat.theta_hat
        P = np.array([p_mix(th[i], nat.natural_gain[i], 30.0, nat.P[i])
                      for i in range(model.n)])
        euclidean_twin(euc, nat, P, filters=step >= 1)
        tau_e, tau_n = euc.step(*args), nat.step(*args)
        assert np.allclose(tau_e, tau_n, rtol=1e-12, atol=1e-9)
        assert nat.retraction_length == 1.0
        move = np.abs(euc.theta_hat - th).max()
        assert move > 1e-6
        assert np.abs(nat.theta_hat - euc.theta_hat).max() < 1e-9 * move


def test_huge_c_gives_the_euclidean_step():
    """One step from the same state: as c grows, the barrier law's step tends to the
    Euclidean law's (fixed P): the gap falls monotonically, as 1/c once the barrier's share
    of the metric is small everywhere (the matched k leaves it up to 1e3 times the
    quadratic's along J's thin directions), to rounding at c = 1e16."""
    rng = np.random.default_rng(4)
    model = random_chain(rng, 5)
    kw = dict(K_D=50.0, P=0.5, gamma=1.0, Lambda=5.0, channels="all",
              theta_hat0=0.9 * model.theta())
    args = step_args(model.n, rng)
    warm = RecursiveCompositeController(model, **BARRIER, **kw)
    for _ in range(3):                               # live filters and prediction errors
        warm.step(*args)
    th = warm.theta_hat
    euc = RecursiveCompositeController(model, **kw)
    euclidean_twin(euc, warm, euc.P, filters=True)
    euc._scal[12] = 1.0                              # P is diagonal
    euc.step(*args)
    want = euc.theta_hat
    move = np.abs(want - th).max()
    gaps = []
    for c in (1e2, 1e4, 1e6, 1e8, 1e12, 1e16):
        nat = RecursiveCompositeController(model, barrier_c=c, **BARRIER, **kw)
        euclidean_twin(nat, warm, nat.P, filters=True)   # the state of `warm`, its own gain
        nat._scal[12] = 1.0
        nat.step(*args)
        assert nat.retraction_length == 1.0
        gaps.append(np.abs(nat.theta_hat - want).max())
    gaps = np.array(gaps) / move
    assert np.all(np.diff(gaps) < 0.0) and gaps[0] > 0.1
    assert 1e-5 < gaps[4] / gaps[3] < 1e-3           # 1/c once H / (c k) << P^-1
    assert gaps[-1] < 1e-11


def test_shortened_retraction_is_the_longest_halved_step_above_half_of_j():
    """``retract_short`` against numpy's eigenvalues, on random bodies and steps from 1e-3
    to 1e3 times J's size: the result is J_hat + a Delta with a the largest of 1, 1/2, ...
    for which ``J_hat + a Delta - 1/2 J_hat - FLOOR tr 1`` is positive definite (so J+ >=
    J_hat / 2), nu clipped to ``|nu| <= NU_RATIO tr(J+)``; a step that is not finite is not
    taken. Cases whose verdict is within 1e-9 of the edge are left out (Cholesky and eigh
    may differ there)."""
    rng = np.random.default_rng(11)
    model = random_chain(rng, 6)
    shortened = whole = 0
    for _ in range(400):
        th = model.theta()[rng.integers(model.n)] * rng.uniform(0.2, 2.0)
        J = J_of(th)
        step = rng.normal(size=13) * np.abs(th).max() * 10.0 ** rng.uniform(-3, 3)
        new = th + step
        D = J_of(new) - J

        def margin(a):
            Jp = J + a * D
            w = np.linalg.eigvalsh(Jp - 0.5 * J - FLOOR * np.trace(Jp) * np.eye(4))
            return w[0] / np.abs(np.linalg.eigvalsh(Jp)).max()
        a = 1.0
        while margin(a) <= 0.0 and a > 2.0 ** -HALVINGS:
            a *= 0.5
        if margin(a) <= 0.0 or abs(margin(a)) < 1e-9 or (a < 1.0 and
                                                         abs(margin(2 * a)) < 1e-9):
            continue
        out = new.copy()
        got = retract_short(th, 0, out, 0)
        assert got == a
        want = J + a * D
        assert np.allclose(J_of(out), want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
        bound = NU_RATIO * np.trace(want)
        assert np.allclose(out[4:7], np.clip(new[4:7], -bound, bound), rtol=1e-12)
        assert np.linalg.eigvalsh(J_of(out) - 0.5 * J)[0] > -1e-12 * np.abs(J).max()
        shortened += a < 1.0
        whole += a == 1.0
    assert shortened > 50 and whole > 50
    th = model.theta()[0]
    out = th + np.r_[np.nan, np.zeros(12)]
    assert retract_short(th, 0, out, 0) == 0.0 and np.array_equal(out, th)


def test_retraction_in_lanes_is_the_per_link_one_bit_for_bit():
    """``retract_lanes`` (the fused law's: whole steps tried LANES links side by side, the
    others by ``retract_short``) against ``retract_links`` (link by link) on 11 links (two
    groups, the second padded), random bodies and steps from 1e-3 to 1e3 times J's size,
    some not finite: every parameter and the smallest step length, bit for bit; runs with
    every step whole and runs with steps shortened."""
    from rcac_ros.core._packing import I_BARRIER_C, I_RETRACT_MIN, THETA_PREV, new_data
    rng = np.random.default_rng(12)
    model = random_chain(rng, 11)
    whole = shortened = 0
    for trial in range(60):
        data = new_data(model.n)
        data[model.n, I_BARRIER_C] = 1000.0
        for i, th in enumerate(model.theta() * rng.uniform(0.2, 2.0, (model.n, 1))):
            step = rng.normal(size=13) * np.abs(th).max() * 10.0 ** rng.uniform(-3, 3)
            if trial % 2 == 0:          # J+ = (1 + u) J_hat: every step whole
                step = rng.uniform(-0.4, 0.4) * th
            elif rng.uniform() < 0.05:
                step[rng.integers(13)] = rng.choice([np.nan, np.inf, -np.inf])
            data[i, CONST_COLS + THETA_PREV:CONST_COLS + THETA_PREV + 13] = th
            data[i, CONST_COLS + THETA_HAT:CONST_COLS + THETA_HAT + 13] = th + step
        want = data.copy()
        retract_links(want)
        got = data.copy()
        X = np.full(RETRACT_ROWS * LANES, np.nan)
        retract_lanes(got, X)
        assert np.array_equal(got, want, equal_nan=True)
        a = want[model.n, I_RETRACT_MIN]
        whole += a == 1.0
        shortened += a < 1.0
    assert whole > 5 and shortened > 5


@pytest.mark.parametrize("c", [100.0, 1e3, 1e4])
def test_css_arm_all_channels_from_half_a_radian_stays_bounded(c):
    """The case the curved retraction diverged on (doc/design.md §8): the CSS arm (not a
    body), the paper's gains, all channels, a 0.5 rad start error. With c >= 100 the
    second-order term ``1/2 Delta J^-1 Delta`` of the log-det metric's retraction, always
    positive semi-definite, grew J_hat by up to 25 % per period and the loop diverged
    within 64 periods; the shortened Euclidean step keeps it bounded for every c (the
    Euclidean law's own bound: the estimates within 2x of its) and every J_hat a body."""
    model = css_arm()
    ctrl = RecursiveCompositeController(model, channels="all", barrier_c=c, **BARRIER)
    euc = RecursiveCompositeController(model, channels="all", theta_hat0=ctrl.theta_hat)
    lam = []
    assert run(ctrl, model, 1500, check=lambda k: lam.append(k.lambda_min.min())) == 1500
    assert run(euc, model, 1500) == 1500
    assert min(lam) > 0.0 and ctrl.consistent.all()
    assert np.abs(ctrl.theta_hat).max() < 2.0 * np.abs(euc.theta_hat).max()


@pytest.mark.parametrize("channels", [[1], "all"])
def test_consistent_at_every_step_under_huge_gains_errors_and_noise(channels):
    """Gains 1e4 x the paper's, gamma 1000x, a 0.5 rad start error, noisy measurements,
    starts 1e3 and 1e-3 times the default body, c from 1 to 1e12 (the Euclidean gain plus
    the retraction): every link's J is positive definite (Cholesky, and numpy's eigenvalues)
    after every step, for as long as the loop runs."""
    model = css_arm()
    rng = np.random.default_rng(7)
    gains = dict(PAPER_GAINS, P=1e6, gamma=100.0)
    start = default_start(model.theta())
    lam = []

    def check(ctrl):
        assert ctrl.consistent.all() and np.all(np.isfinite(ctrl.theta_hat))
        lam.append(min(np.linalg.eigvalsh(J_of(t))[0] for t in ctrl.theta_hat))
        assert lam[-1] > 0.0
    for scale in (1.0, 1e3, 1e-3):
        for c in (1.0, 100.0, 1e12):
            ctrl = RecursiveCompositeController(model, channels=channels, barrier_c=c,
                                                theta_hat0=scale * start, **BARRIER, **gains)
            assert run(ctrl, model, 200, noise=1e-2, rng=rng, check=check) > 10


def test_default_metric_is_the_barrier_with_the_gradient_and_log_det_with_least_squares():
    """Without ``natural_metric`` the natural law is the barrier metric's with
    ``adaptation="gradient"`` (c = BARRIER_C) and natural least squares' own (``"log_det"``)
    with ``adaptation="least_squares"``, to the last bit (the option changes nothing else in
    the kernel's data); the Slotine-Li law takes the same default."""
    from rcac_ros.core import SlotineLiCompositeController
    model = css_arm()
    for extra, metric in ((dict(channels="all"), "barrier"), (dict(), "barrier"),
                          (dict(adaptation="least_squares", forgetting=1.0), "log_det")):
        a = RecursiveCompositeController(model, geometry="natural", **extra)
        b = RecursiveCompositeController(model, geometry="natural", natural_metric=metric,
                                         **extra)
        assert np.array_equal(a._data, b._data)
        ta, tb = [], []
        run(a, model, 100, check=lambda c: ta.append(c.theta_hat))
        run(b, model, 100, check=lambda c: tb.append(c.theta_hat))
        assert len(ta) == 100 and np.array_equal(np.array(ta), np.array(tb))
        assert (a.natural_metric, a.barrier_c) == \
            (metric, BARRIER_C if metric == "barrier" else None)
    assert SlotineLiCompositeController(model, geometry="natural").natural_metric == "barrier"
    euclidean = RecursiveCompositeController(model)
    assert (euclidean.natural_metric, euclidean.barrier_c) == ("log_det", None)


def test_bad_options_are_one_line_gain_errors():
    model = css_arm()
    cases = [(dict(geometry="natural", natural_metric="quadratic"), "natural_metric: expected"),
             (dict(BARRIER, barrier_c=1e-300), "barrier_c: must be >= 1e-06"),
             (dict(natural_metric="barrier"), "only with geometry='natural'"),
             (dict(BARRIER, adaptation="least_squares"), "needs adaptation='gradient'"),
             (dict(BARRIER, barrier_c=0.0), "barrier_c: must be > 0"),
             (dict(BARRIER, barrier_c=-1.0), "barrier_c: must be > 0"),
             (dict(BARRIER, barrier_c=np.inf), "barrier_c: must be finite"),
             (dict(BARRIER, barrier_c="big"), "barrier_c: expected a number"),
             (dict(geometry="natural", natural_metric="log_det", barrier_c=10.0),
              "barrier_c: only with"),
             (dict(geometry="natural", adaptation="least_squares", barrier_c=10.0),
              "barrier_c: only with")]
    for kw, msg in cases:
        with pytest.raises(GainError, match=msg) as e:
            RecursiveCompositeController(model, **kw)
        assert "\n" not in str(e.value)
    ctrl = RecursiveCompositeController(model, **BARRIER)
    assert ctrl.barrier_c == 1000.0 and ctrl.natural_metric == "barrier"


def test_barrier_tracks_a_body_and_stays_consistent():
    """A random 5-link body, 4 s of sines from 0.5x its parameters: the barrier law's
    estimates stay bodies at every step (numpy's eigenvalues) and it tracks (final error
    below the start's)."""
    rng = np.random.default_rng(6)
    model = random_chain(rng, 5)
    n, h = model.n, 0.002
    ctrl = RecursiveCompositeController(model, K_D=50.0, P=0.5, gamma=1.0, Lambda=5.0,
                                        channels="all", theta_hat0=0.5 * model.theta(),
                                        **BARRIER)
    sim = Simulator(model, dt=h, q0=np.full(n, 0.2))
    w = 0.7 * np.arange(1, n + 1)
    err = []
    for k in range(2000):
        t = k * h
        tau = ctrl.step(sim.q, sim.qd, 0.3 * np.sin(w * t), 0.3 * w * np.cos(w * t),
                        -0.3 * w * w * np.sin(w * t))
        sim.step(tau)
        assert all(np.linalg.eigvalsh(J_of(th))[0] > 0.0 for th in ctrl.theta_hat)
        err.append(np.abs(sim.q - 0.3 * np.sin(w * (t + h))).max())
    assert max(err[-250:]) < 0.2 * max(err[:250])


def test_slotine_li_barrier_is_the_recursive_law_with_all_channels():
    """The non-recursive law with the barrier metric (its gains P_mix from numpy's
    inverse of ``H / (c k) + P^-1``, H from the trace form) is the recursive law with
    channels="all" and the barrier metric (a Cholesky factor of ``K``, H from its closed
    form), step by step, from a 0.2 rad error on the CSS arm; bodies at every step."""
    from rcac_ros.core import PaperTrajectory, SlotineLiCompositeController
    from rcac_ros.core.model import PAPER_Q0
    model = css_arm()
    sl = SlotineLiCompositeController(model, barrier_c=30.0, **BARRIER, **PAPER_GAINS)
    rc = RecursiveCompositeController(model, channels="all", barrier_c=30.0, **BARRIER,
                                      **PAPER_GAINS)
    assert (sl.natural_metric, sl.barrier_c) == ("barrier", 30.0)
    assert np.allclose(sl.natural_gain, rc.natural_gain)
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0)
    sim = Simulator(model, dt=0.002, q0=q0 + 0.2)
    th0 = sl.theta_hat
    for k in range(150):
        args = (sim.q.copy(), sim.qd.copy()) + tuple(traj(k * 0.002))
        tau = sl.step(*args)
        assert np.allclose(rc.step(*args), tau, rtol=1e-8, atol=1e-6)
        assert np.allclose(rc.theta_hat, sl.theta_hat, rtol=1e-8, atol=1e-8)
        assert sl.consistent.all()
        sim.step(tau)
    assert np.abs(sl.theta_hat - th0).max() > 1e-3 and sl.retraction_length > 0.0
    with pytest.raises(GainError, match="natural_metric: 'barrier' only with"):
        SlotineLiCompositeController(model, natural_metric="barrier")
    with pytest.raises(GainError, match="barrier_c: only with"):
        SlotineLiCompositeController(model, geometry="natural", natural_metric="log_det",
                                     barrier_c=10.0)
