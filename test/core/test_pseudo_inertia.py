"""Pseudo-inertia, the natural gain and the consistent retraction (doc/design.md §8).

References: Pinocchio's ``Inertia``, ``PseudoInertia`` and ``LogCholeskyParameters``; the
regressor identity of doc/design.md §2 against Pinocchio's spatial inertia; the Hessian of
``-log det J`` written from its trace formula; scipy's matrix exponential.
"""

import numpy as np
import pinocchio as pin
import pytest
from scipy.linalg import expm

from rcac_ros.core import InputError, css_arm, link_regressor, theta_from_inertia
from rcac_ros.core.pseudo_inertia import (NU_BASIS, body_theta, check_body, default_start,
                                          dual_into, is_body, lambda_min, log_det_hessian,
                                          matched_gain, natural_gain_apply, nearest_body, nu_gain,
                                          pseudo_inertia, theta_from_pseudo, standard_parameters,
                                          theta_from_parts)
from rcac_ros.core.retraction import FLOOR, retract


def random_bodies(rng, count, spread=1.5):
    """Pinocchio bodies from random log-Cholesky parameters (spread over many scales)."""
    out = []
    for _ in range(count):
        lc = pin.LogCholeskyParameters(rng.normal(scale=spread, size=10))
        out.append(pin.Inertia.FromLogCholeskyParameters(lc))
    return out


def theta_of(inertia):
    return theta_from_inertia(inertia.mass, inertia.lever, inertia.inertia)


def test_standard_parameters_and_pseudo_inertia_match_pinocchio():
    rng = np.random.default_rng(1)
    for body in random_bodies(rng, 50) + [pin.Inertia.Random() for _ in range(20)]:
        th = theta_of(body)
        pi = body.toDynamicParameters()
        assert np.allclose(standard_parameters(th), pi, rtol=1e-12, atol=1e-12 * abs(pi).max())
        J = pin.PseudoInertia.FromInertia(body).toMatrix()
        assert np.allclose(pseudo_inertia(th), J, rtol=1e-12, atol=1e-12 * abs(J).max())
        # a body's 13 parameters are determined by pi: nu = h^2 / m
        assert np.allclose(body_theta(pi), th, rtol=1e-10, atol=1e-12 * abs(th).max())


def test_parts_round_trip_and_theta_from_pseudo_inverts_the_map():
    rng = np.random.default_rng(2)
    th = rng.normal(size=(100, 13))
    assert np.allclose(theta_from_parts(standard_parameters(th), th[:, 4:7]), th, atol=1e-13)
    # J(theta + B nu) = J(theta): NU_BASIS spans the null space of theta -> J
    assert np.allclose(pseudo_inertia(NU_BASIS.T), 0.0)
    assert np.linalg.matrix_rank(np.array([pseudo_inertia(e).ravel() for e in np.eye(13)])) == 10


def test_regressor_of_a_body_from_pi_is_newton_euler_and_sees_nu_through_one_sum():
    """Y(Vdot, V, w) body_theta(pi) = I a + v x* (I v) (Pinocchio), and the columns Y B of the
    nu directions are equal (the rank-11 direction t5 + t6 + t7, doc/design.md §2)."""
    rng = np.random.default_rng(3)
    for body in random_bodies(rng, 20):
        th = body_theta(body.toDynamicParameters())
        V, A = rng.normal(size=(2, 6))
        ref = body * pin.Motion(A) + pin.Motion(V).cross(body * pin.Motion(V))
        Y = link_regressor(A, V, V[3:])
        assert np.allclose(Y @ th, ref.vector, rtol=1e-10, atol=1e-10)
        Yr = link_regressor(A, rng.normal(size=6), V[3:])       # w_r != w
        YB = Yr @ NU_BASIS
        assert np.allclose(YB[:, 0], YB[:, 1]) and np.allclose(YB[:, 0], YB[:, 2])
        assert np.allclose(YB[:3], 0.0) and np.linalg.norm(YB) > 0


def test_is_body_and_lambda_min_agree_with_physical_checks():
    rng = np.random.default_rng(4)
    bodies = np.array([theta_of(b) for b in random_bodies(rng, 200)])
    assert is_body(bodies).all() and (lambda_min(bodies) > 0).all()
    # the CSS arm's Table 1 breaks the triangle inequality (doc/design.md §5): no body
    css = css_arm().theta()
    assert not is_body(css).any() and (lambda_min(css) < 0).all()
    # a triangle violation, a negative mass, a negative principal moment
    bad = [theta_from_inertia(1.0, [0.1, 0, 0], np.diag([0.1, 0.1, 0.3])),
           theta_from_inertia(-1.0, [0, 0, 0], np.eye(3)),
           theta_from_inertia(1.0, [0, 0, 0], np.diag([1.0, 1.0, -0.1]))]
    assert not is_body(np.array(bad)).any()
    assert is_body(theta_from_inertia(1.0, [0.1, 0, 0], np.diag([0.1, 0.1, 0.19])))
    assert not is_body(np.full(13, np.nan))


def test_check_body_names_the_link():
    th = np.array([theta_from_inertia(1.0, [0, 0, 0], np.eye(3))] * 3)
    check_body(th)
    th[1, 0] = -1.0
    with pytest.raises(InputError, match="theta_hat0: link 2 is not a physical body"):
        check_body(th)


def test_dual_matrix_pairs_like_the_gradient():
    """g . d = tr(G(g) J(d)) + u_nu(g) . nu(d) for every d (the definition of G)."""
    rng = np.random.default_rng(5)
    G = np.zeros((4, 4))
    for _ in range(50):
        g, d = rng.normal(size=(2, 13))
        u = dual_into(g, 0, G)
        assert np.allclose(G, G.T)
        assert g @ d == pytest.approx(np.trace(G @ pseudo_inertia(d)) + np.dot(u, d[4:7]),
                                      abs=1e-12)


def natural_gain_matrix(th, k, Pnu):
    """P_eff(th) column by column from the compiled routine."""
    out = np.zeros((13, 13))
    for c, e in enumerate(np.eye(13)):
        natural_gain_apply(th, 0, e, 0, out[:, c], 0, k, Pnu.ravel(), 0)
    return out


def test_natural_gain_is_k_times_the_inverse_hessian_of_log_det():
    """P_eff is symmetric positive definite, H P_eff H = k H with H the Hessian of
    -log det J (the trace formula). H squares J's condition number: moderate bodies."""
    rng = np.random.default_rng(6)
    for body in random_bodies(rng, 20, spread=0.5):
        th = theta_of(body)
        k = 10.0 ** rng.uniform(-3, 3)
        B = rng.normal(size=(3, 3))
        Pnu = B @ B.T + 0.1 * np.eye(3)
        P = natural_gain_matrix(th, k, Pnu)
        scale = np.abs(P).max()
        assert np.allclose(P, P.T, atol=1e-10 * scale)
        assert np.linalg.eigvalsh(0.5 * (P + P.T)).min() > -1e-12 * scale
        H = log_det_hessian(th)
        assert np.allclose(H @ P @ H, k * H, rtol=1e-7, atol=1e-7 * np.abs(k * H).max())


def test_natural_gain_of_nu_only_gradient_moves_only_nu():
    """A gradient that pairs to zero with every J direction (G(g) = 0) moves nu only."""
    rng = np.random.default_rng(7)
    th = theta_of(random_bodies(rng, 1)[0])
    g = np.zeros(13)
    g[4:7] = rng.normal(size=3)
    P = natural_gain_matrix(th, 2.0, 3.0 * np.eye(3))
    d = P @ g
    assert np.allclose(pseudo_inertia(d), 0.0, atol=1e-14)
    assert np.allclose(d[4:7], 3.0 * g[4:7])


def retracted(old, new):
    out = new.copy()
    a = retract(old, 0, out, 0)
    return out, a


def test_retraction_is_the_exponential_map_to_second_order():
    """J+ = L expm(Z) L^T + O(|Z|^3): halving the step divides the gap by 8; nu unchanged."""
    rng = np.random.default_rng(8)
    th = theta_of(random_bodies(rng, 1)[0])
    J = pseudo_inertia(th)
    L = np.linalg.cholesky(J)
    S = rng.normal(size=(4, 4))
    d = np.zeros(13)
    theta_from_pseudo(L @ (S + S.T) @ L.T, *rng.normal(size=3), d, 0)
    gaps = []
    for eps in (1e-2, 5e-3, 2.5e-3):
        step = eps * d
        new, a = retracted(th, th + step)
        assert a == 1.0 and np.allclose(new[4:7], (th + step)[4:7])
        Z = np.linalg.solve(L, np.linalg.solve(L, pseudo_inertia(step)).T)
        gaps.append(np.abs(pseudo_inertia(new) - L @ expm(Z) @ L.T).max())
    assert 6.0 < gaps[0] / gaps[1] < 10.0 and 6.0 < gaps[1] / gaps[2] < 10.0


def test_retraction_cannot_leave_the_cone_under_attack():
    """Huge steps, noise, thousands of repetitions: every J+ is positive definite (Cholesky),
    with 1/2 J <= J+ <= 5/2 J (generalised eigenvalues, up to rounding)."""
    rng = np.random.default_rng(9)
    for body in random_bodies(rng, 20):
        th = theta_of(body)
        for _ in range(300):
            size = 10.0 ** rng.uniform(-6, 8) * np.abs(th).max()
            step = size * rng.normal(size=13)
            step[4:7] = rng.normal(size=3) * np.abs(th).max()    # nu of the size of theta
            new, a = retracted(th, th + step)
            assert 0.0 < a <= 1.0
            assert is_body(new)
            J, Jn = pseudo_inertia(th), pseudo_inertia(new)
            L = np.linalg.cholesky(J)
            ev = np.linalg.eigvalsh(np.linalg.solve(L, np.linalg.solve(L, Jn).T))
            tol = 1e-14 * np.linalg.cond(J) ** 2      # the rounding of this check itself
            assert ev.min() >= 0.5 - tol and ev.max() <= 2.5 + tol


def test_natural_step_with_huge_gain_and_error_stays_a_body():
    """theta_lin = theta - h P_eff g with gains and gradients up to 1e12, then retraction,
    3000 times in a row (a random walk): a body at every step, above the numerical floor."""
    rng = np.random.default_rng(10)
    th = theta_of(random_bodies(rng, 1)[0])
    for _ in range(3000):
        k = 10.0 ** rng.uniform(-3, 6)
        g = 10.0 ** rng.uniform(-3, 6) * rng.normal(size=13)
        step = natural_gain_matrix(th, k, np.eye(3)) @ g
        th, _ = retracted(th, th - 0.002 * step)
        J = pseudo_inertia(th)
        assert is_body(th) and np.all(np.isfinite(th))
        assert np.linalg.eigvalsh(J)[0] >= 0.99 * FLOOR * np.trace(J)


def test_nearest_body_and_default_start():
    css = css_arm().theta()
    near = nearest_body(css)
    assert is_body(near).all()
    assert np.allclose(near[:, :4], css[:, :4])                   # same mass and first moment
    start = default_start(css)
    assert is_body(start).all() and np.allclose(start[:, 0], 0.5 * css[:, 0])
    bodies = np.array([theta_of(b) for b in random_bodies(np.random.default_rng(11), 10)])
    keep = lambda_min(bodies) > 0.01 * np.trace(pseudo_inertia(bodies)[:, :3, :3], axis1=1,
                                                axis2=2)
    assert np.allclose(nearest_body(bodies)[keep], body_theta(standard_parameters(bodies))[keep])


def test_matched_gain_recovers_a_gain_of_the_natural_form():
    """If P's pseudo-inertia part is k0 H^-1 (H: Hessian of -log det J at the start), the
    matched natural gain is k0; nu_gain inverts the metric restricted to nu."""
    rng = np.random.default_rng(12)
    th = theta_of(random_bodies(rng, 1)[0])
    k0 = 7.3
    P = natural_gain_matrix(th, k0, np.eye(3)) + 1e-3 * NU_BASIS @ NU_BASIS.T
    assert matched_gain(P[None], th[None])[0] == pytest.approx(k0, rel=1e-8)
    P = np.eye(13) * 100.0
    Pnu = nu_gain(P[None])[0]
    assert np.allclose(np.linalg.inv(Pnu), NU_BASIS.T @ NU_BASIS / 100.0)


def test_ldl_inverse_and_definiteness_of_a_4x4_match_numpy():
    """``inverse_ldl_entries`` (``J^-1`` from ``J = L D L^T``, no square root) against numpy's
    inverse on the pseudo-inertias of random bodies over many scales (conditioning up to
    1e10: within ``eps cond(J)`` times a small factor), and ``positive_definite4``'s verdict
    against numpy's smallest eigenvalue on random symmetric 4x4s (cases within 1e-9 of the
    edge left out); an indefinite J gives ``ok`` False and zero entries."""
    from rcac_ros.core.pseudo_inertia import inverse_ldl_entries, positive_definite4
    rng = np.random.default_rng(5)
    order = ((0, 0), (1, 1), (2, 2), (3, 3), (0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3))
    upper = ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3))
    worst = 0.0
    for body in random_bodies(rng, 300, spread=2.0):
        J = pseudo_inertia(theta_of(body))
        ok, *k = inverse_ldl_entries(*(J[i, j] for i, j in order))
        want = np.linalg.inv(J)
        tol = 50.0 * np.finfo(float).eps * np.linalg.cond(J)
        err = np.abs(np.array(k) - np.array([want[i, j] for i, j in upper])).max()
        assert ok and err <= tol * np.abs(want).max()
        worst = max(worst, err / (tol * np.abs(want).max()))
        assert positive_definite4(*(J[i, j] for i, j in order))
    assert worst > 0.0
    seen = {True: 0, False: 0}
    for _ in range(2000):
        X = rng.normal(size=(4, 4))
        A = X @ X.T + rng.uniform(-1.0, 1.0) * np.abs(X).max() ** 2 * np.eye(4)
        lam = np.linalg.eigvalsh(A)
        if abs(lam[0]) < 1e-9 * np.abs(lam).max():
            continue
        got = positive_definite4(*(A[i, j] for i, j in order))
        assert got == (lam[0] > 0.0)
        seen[got] += 1
        ok, *k = inverse_ldl_entries(*(A[i, j] for i, j in order))
        assert ok == (lam[0] > 0.0) and (ok or not any(k))
    assert min(seen.values()) > 200
