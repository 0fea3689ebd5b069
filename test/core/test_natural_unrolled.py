"""The natural gain and the retraction unrolled on scalars (doc/design.md §8) against the
same equations written with 4x4 arrays and loops, bit for bit.

Reference: :func:`reference_gain` and :func:`reference_retract` below, the 4x4 loops of
the first implementation (through :func:`pseudo_inertia_into`, :func:`dual_into`,
:func:`cholesky4` and :func:`theta_from_pseudo`) and, for ``J^-1``, the loops of its
``L D L^T`` (:func:`reference_ldl_inverse`): the same operations in the same order.
Every branch of the retraction is reached: a full step, a step shortened to ``||Z|| = 1``,
halvings and the floor's factorisation, a step kept out (``a = 0``), a start that is not
positive definite and a step that is not finite; ``old`` and ``new`` share one array as in
the kernel.
"""

import math

import numpy as np
import pinocchio as pin
from numba import njit

from rcac_ros.core import theta_from_inertia
from rcac_ros.core.pseudo_inertia import (cholesky4, dual_into, natural_gain_apply,
                                          pseudo_inertia, pseudo_inertia_into, theta_from_pseudo)
from rcac_ros.core.retraction import COND_SHORTCUT, FLOOR, HALVINGS, NU_RATIO, retract


@njit(cache=False)
def reference_gain(th, o, g, go, out, oo, k, Pnu, po, J, G, T):
    """``P_eff(theta) g`` with 4x4 arrays: ``k J G(g) J`` and ``P_nu u_nu``."""
    pseudo_inertia_into(th, o, J)
    u0, u1, u2 = dual_into(g, go, G)
    for i in range(4):
        for j in range(4):
            T[i, j] = G[i, 0] * J[0, j] + G[i, 1] * J[1, j] + G[i, 2] * J[2, j] \
                + G[i, 3] * J[3, j]
    for i in range(4):
        for j in range(i, 4):
            v = k * (J[i, 0] * T[0, j] + J[i, 1] * T[1, j] + J[i, 2] * T[2, j]
                     + J[i, 3] * T[3, j])
            G[i, j] = v
            G[j, i] = v
    n0 = Pnu[po] * u0 + Pnu[po + 1] * u1 + Pnu[po + 2] * u2
    n1 = Pnu[po + 3] * u0 + Pnu[po + 4] * u1 + Pnu[po + 5] * u2
    n2 = Pnu[po + 6] * u0 + Pnu[po + 7] * u1 + Pnu[po + 8] * u2
    theta_from_pseudo(G, n0, n1, n2, out, oo)


@njit(cache=False)
def reference_ldl_inverse(J, L, K):
    """``K = J^-1`` with 4x4 arrays: ``J = L D L^T`` (L unit lower below the diagonal of
    ``L``, ``U = L D`` above it, transposed), ``M = L^-1`` in place of L's lower triangle,
    ``K = M^T D^-1 M``; False at the first pivot that is not > 0."""
    r = np.empty(4)
    for k in range(4):
        d = J[k, k]
        for m in range(k):
            d -= L[k, m] * L[m, k]                 # U_km L_km (U above, L below)
        if not d > 0.0:
            return False
        r[k] = 1.0 / d
        for i in range(k + 1, 4):
            u = J[i, k]
            for m in range(k):
                u -= L[m, i] * L[k, m]             # U_im L_km
            L[k, i] = u                             # U_ik kept above the diagonal
            L[i, k] = u * r[k]
    for i in range(1, 4):                           # M = L^-1 (unit lower), in place
        for j in range(i):
            v = -L[i, j]
            for k in range(j + 1, i):
                v -= L[i, k] * L[k, j]
            L[i, j] = v
    for p in range(4):
        for q in range(p, 4):
            v = r[q] if p == q else r[q] * L[q, p]
            for k in range(q + 1, 4):
                v += L[k, q] * (r[k] * L[k, p])
            K[p, q] = v
            K[q, p] = v
    return True


@njit(cache=False)
def reference_retract(old, oo, new, on, J, D, L, K):
    """The retraction with 4x4 arrays: ``J^-1`` (:func:`reference_ldl_inverse`), ``J^-1 D``,
    ``D J^-1 D``, the halvings with a Cholesky factorisation of ``J+ - FLOOR tr(J+) 1``."""
    pseudo_inertia_into(old, oo, J)
    pseudo_inertia_into(new, on, D)
    for i in range(4):
        for j in range(4):
            D[i, j] -= J[i, j]
    if not reference_ldl_inverse(J, L, K):
        theta_from_pseudo(J, new[on + 4], new[on + 5], new[on + 6], new, on)
        return 0.0
    tr_inv = K[0, 0] + K[1, 1] + K[2, 2] + K[3, 3]
    for i in range(4):
        for j in range(4):
            L[i, j] = K[i, 0] * D[0, j] + K[i, 1] * D[1, j] + K[i, 2] * D[2, j] \
                + K[i, 3] * D[3, j]
    z2 = 0.0
    for i in range(4):
        for j in range(4):
            z2 += L[i, j] * L[j, i]
    if not (math.isfinite(z2) and math.isfinite(new[on + 4] + new[on + 5] + new[on + 6])):
        for k in range(13):
            new[on + k] = old[oo + k]
        return 0.0
    for i in range(4):
        for j in range(i, 4):
            v = D[i, 0] * L[0, j] + D[i, 1] * L[1, j] + D[i, 2] * L[2, j] + D[i, 3] * L[3, j]
            K[i, j] = v
            K[j, i] = v
    for i in range(4):
        for j in range(4):
            L[i, j] = K[i, j]
    a = 1.0 if z2 <= 1.0 else 1.0 / math.sqrt(z2)
    for h in range(HALVINGS):
        half = 0.5 * a * a
        tr = 0.0
        for i in range(4):
            for j in range(i, 4):
                v = J[i, j] + a * D[i, j] + half * L[i, j]
                K[i, j] = v
                K[j, i] = v
            tr += K[i, i]
        if h == 0 and tr * tr_inv <= COND_SHORTCUT:
            break
        for i in range(4):
            K[i, i] -= FLOOR * tr
        if cholesky4(K, K):
            break
        a *= 0.5
    else:
        a = 0.0
    if a > 0.0:
        for i in range(4):
            for j in range(i, 4):
                v = J[i, j] + a * D[i, j] + half * L[i, j]
                J[i, j] = v
                J[j, i] = v
    bound = NU_RATIO * (J[0, 0] + J[1, 1] + J[2, 2] + J[3, 3])
    theta_from_pseudo(J, min(max(new[on + 4], -bound), bound),
                      min(max(new[on + 5], -bound), bound),
                      min(max(new[on + 6], -bound), bound), new, on)
    return a


def same_bits(a, b):
    """Equal values, NaNs in the same places and the same signs of zero."""
    return np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b))


def random_body(rng, spread=1.5):
    body = pin.Inertia.FromLogCholeskyParameters(
        pin.LogCholeskyParameters(rng.normal(scale=spread, size=10)))
    return theta_from_inertia(body.mass, body.lever, body.inertia)


def thin_body(rng):
    """A body with lambda_min(J) / tr(J) about 1e-11: tr(J) tr(J^-1) beyond the shortcut, so
    the floor's factorisation runs (and steps are halved or kept out)."""
    th = random_body(rng, 0.5)
    J = pseudo_inertia(th)
    w, V = np.linalg.eigh(J)
    w[0] = w.sum() * 10.0 ** rng.uniform(-12.5, -10.0)
    out = th.copy()
    theta_from_pseudo((V * w) @ V.T, th[4], th[5], th[6], out, 0)
    return out


def test_unrolled_retraction_is_the_4x4_one_bit_for_bit_on_every_branch():
    rng = np.random.default_rng(5)
    scratch = np.zeros((4, 4, 4))
    outcomes = {"full": 0, "shortened": 0, "halved": 0, "kept": 0, "not_pd": 0,
                "not_finite": 0, "factorised": 0}
    for case in range(4000):
        kind = case % 8
        th = thin_body(rng) if kind in (5, 6) else random_body(rng)
        scale = np.abs(th).max() * 10.0 ** rng.uniform(-8, 2)
        step = th + scale * rng.normal(size=13)
        if kind == 7 and case % 16 == 7:
            th = th.copy()
            th[0] = -abs(th[0]) - 1.0                    # J_hat not positive definite
        elif kind == 7:
            step[rng.integers(13)] = rng.choice([np.inf, -np.inf, np.nan])
        row = np.concatenate([th, step])                 # old, new in one array (kernel)
        ref = row.copy()
        a = retract(row, 0, row, 13)
        a_ref = reference_retract(ref, 0, ref, 13, *scratch)
        assert same_bits(row, ref), case
        assert a == a_ref or (np.isnan(a) and np.isnan(a_ref)), case
        J = pseudo_inertia(th)
        if not np.linalg.eigvalsh(J)[0] > 0:
            outcomes["not_pd"] += 1
        elif not np.all(np.isfinite(step)):
            outcomes["not_finite"] += 1
        else:
            M = np.linalg.solve(J, pseudo_inertia(step) - J)
            a0 = min(1.0, 1.0 / np.sqrt(np.trace(M @ M)))      # before any halving
            outcomes["full" if a == 1.0 else "kept" if a == 0.0
                     else "halved" if a < 0.75 * a0 else "shortened"] += 1
            if np.trace(J) * np.trace(np.linalg.inv(J)) > COND_SHORTCUT:
                outcomes["factorised"] += 1
        # the separate-array call (the Slotine-Li law's rows) gives the same
        old, new = th.copy(), step.copy()
        retract(old, 0, new, 0)
        assert same_bits(new, row[13:]), case
    assert min(outcomes.values()) >= 20, outcomes


def test_unrolled_natural_gain_is_the_4x4_one_bit_for_bit():
    rng = np.random.default_rng(6)
    scratch = np.zeros((3, 4, 4))
    for case in range(2000):
        th = random_body(rng) if case % 2 else rng.normal(size=13) * 10.0 ** rng.uniform(-3, 3)
        g = rng.normal(size=13) * 10.0 ** rng.uniform(-6, 6)
        Pnu = rng.normal(size=9)
        k = 10.0 ** rng.uniform(-3, 3)
        out, ref = np.empty(13), np.empty(13)
        natural_gain_apply(th, 0, g, 0, out, 0, k, Pnu, 0)
        reference_gain(th, 0, g, 0, ref, 0, k, Pnu, 0, *scratch)
        assert same_bits(out, ref), case
        # in one array, as the kernel's W_ci -> U_ci row, and in place
        for oo in (13, 0):
            row = np.concatenate([g, rng.normal(size=13)])
            want = row.copy()
            natural_gain_apply(th, 0, row, 0, row, oo, k, Pnu, 0)
            reference_gain(th, 0, want, 0, want, oo, k, Pnu, 0, *scratch)
            assert same_bits(row, want), (case, oo)
