"""The 13-parameter regressor: its identity, C's skew symmetry, and the joint-1 torque split."""

import numpy as np
import pytest
from chains import random_chain

from rcac_ros.core import (coriolis_gravity_regressor, css_arm, inverse_dynamics, link_matrices,
                           link_regressor, mass_regressor, theta_from_inertia)
from rcac_ros.core.model import rpy_matrix
from rcac_ros.core.regressor import bias_row, momentum_row, reference_wrench, regressor_row


def random_link(rng):
    Q = rpy_matrix(rng.uniform(-3, 3, 3))
    a, b = rng.uniform(0.1, 1.0, 2)
    I = Q @ np.diag([a, b, rng.uniform(abs(a - b), a + b)]) @ Q.T
    return theta_from_inertia(rng.uniform(0.5, 5.0), rng.normal(size=3), I)


def test_regressor_identity_and_skew_symmetry():
    rng = np.random.default_rng(11)
    for _ in range(50):
        theta = random_link(rng)
        Vdot_r, V_r = rng.normal(size=(2, 6))
        w, g = rng.normal(size=(2, 3))
        M, C, G = link_matrices(theta, w, g)
        Y = link_regressor(Vdot_r, V_r, w, g)
        assert np.allclose(Y @ theta, M @ Vdot_r + C @ V_r + G, rtol=1e-12, atol=1e-11)
        assert np.allclose(C, -C.T, atol=1e-12)
        assert np.allclose(M, M.T) and np.linalg.eigvalsh(M).min() > 0
        V = np.concatenate([V_r[:3], w])
        assert np.allclose(mass_regressor(V) @ theta, M @ V, atol=1e-11)
        assert np.allclose(coriolis_gravity_regressor(V, g) @ theta, C @ V + G, atol=1e-11)


def test_closed_form_rows_equal_regressor_products():
    """The controller's closed forms equal the products with the explicit 6x13 regressor."""
    rng = np.random.default_rng(12)
    for _ in range(50):
        a, V = rng.normal(size=(2, 6))
        g = rng.normal(size=3)
        phi, psi = np.empty(13), np.empty(13)
        momentum_row(phi, *a, *V)
        bias_row(psi, *a, *V, *g)
        assert np.allclose(phi, a @ mass_regressor(V), atol=1e-12)
        assert np.allclose(psi, a @ coriolis_gravity_regressor(V, g), atol=1e-12)
        # eq 19b's Y_r theta and eq 24's Y_r^T s, as the controller computes them
        theta, s = random_link(rng), rng.normal(size=6)
        Vdot_r, V_r = rng.normal(size=(2, 6))
        w = rng.normal(size=3)
        Y = link_regressor(Vdot_r, V_r, w, g)
        wrench = np.array(reference_wrench(theta, 0, *Vdot_r, *V_r, *w, *g))
        assert np.allclose(wrench, Y @ theta, rtol=1e-12, atol=1e-11)
        row = np.empty(13)
        regressor_row(row, *s, *Vdot_r, *V_r, *w, *g)
        assert np.allclose(row, s @ Y, atol=1e-12)


def test_regressor_has_rank_11_or_10():
    rng = np.random.default_rng(13)
    stack = np.vstack([link_regressor(*rng.normal(size=(2, 6)), rng.normal(size=3))
                       for _ in range(30)])
    assert np.linalg.matrix_rank(stack) == 11
    rows = []
    for _ in range(30):
        Vd, V = rng.normal(size=(2, 6))
        rows.append(link_regressor(Vd, V, V[3:]))
    assert np.linalg.matrix_rank(np.vstack(rows)) == 10


# --- an independent numpy transcription of eqs 9-12 and 15-16 ------------------------------

def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def transforms(model, q, qd):
    """iT_{i-1} (eq 10) and its derivative (eq 12) as explicit 6x6 matrices."""
    T, Td = [], []
    for i in range(model.n):
        c, s = np.cos(q[i]), np.sin(q[i])
        C = (model.R_fix[i] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])).T
        P = skew(model.p[i])
        W = skew([0, 0, qd[i]])
        T.append(np.block([[C, -C @ P], [np.zeros((3, 3)), C]]))
        Td.append(np.block([[-W @ C, W @ C @ P], [np.zeros((3, 3)), -W @ C]]))
    return T, Td


def test_matrix_recursion_and_joint1_torque_split():
    """Eqs 9-16 as 6x6 products reproduce RNEA, and tau_1 = sum_j a_j^T F*_j (doc/design.md §4)."""
    rng = np.random.default_rng(14)
    for model in (css_arm((0.0, 0.0, -9.81)), random_chain(rng, 9)):
        n = model.n
        q, qd, qdd = rng.normal(size=(3, n))
        T, Td = transforms(model, q, qd)
        z6 = np.array([0, 0, 0, 0, 0, 1.0])
        V, Vd, a = np.zeros(6), np.zeros(6), None
        g = model.gravity.copy()
        Fstar, A = [], []
        theta = model.theta()
        for i in range(n):
            Vd = T[i] @ Vd + Td[i] @ V + z6 * qdd[i]            # eq 11
            V = T[i] @ V + z6 * qd[i]                            # eq 9
            g = T[i][:3, :3] @ g
            a = z6 if i == 0 else T[i] @ a
            M, C, G = link_matrices(theta[i], V[3:], g)
            Fstar.append(M @ Vd + C @ V + G)                     # eq 13
            A.append(a)
        F = np.zeros(6)
        tau = np.zeros(n)
        for i in range(n - 1, -1, -1):
            F = (T[i + 1].T @ F if i < n - 1 else F) + Fstar[i]  # eq 15
            tau[i] = z6 @ F                                       # eq 16
        ref = inverse_dynamics(model, q, qd, qdd)
        assert np.allclose(tau, ref, rtol=1e-10, atol=1e-9 * np.abs(ref).max())
        tau1 = sum(A[j] @ Fstar[j] for j in range(n))
        assert tau1 == pytest.approx(ref[0], rel=1e-10)
