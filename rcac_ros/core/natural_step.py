"""The natural geometry's adaptation step (doc/design.md §8): eq 24's step 1 with the gain
``P_eff(theta_hat_i)`` of the chosen metric, and the retraction after the step.

- :func:`natural_gain_step`, :func:`natural_gain_row`: ``R_i = theta_hat_i - h P_eff g`` and
  ``U_ci = P_eff W_ci^T`` for link i, with the log-det metric, natural least squares
  (:func:`natural_ls_factor`) or the barrier metric (:func:`barrier_factor`);
- :func:`natural_gain_rows`: the same for every link of the paper's law (the fused kernel);
- :func:`retract_links`: every link's step made consistent (:mod:`rcac_ros.core.retraction`).

These are compiled once and called, not inlined, by the kernels of every law that has the
natural geometry (compile time; a call per link costs nothing measurable per step).
"""

import numpy as np

from ._jit import njit
from ._packing import (BAR_F, BAR_Q, I_BARRIER_C, I_H, I_RETRACT_MIN, NAT_K,
                       NAT_LS_CHOL, NAT_LS_N, NAT_P_NU, P_FACTOR, THETA_HAT, THETA_PREV, U_ROW,
                       W_ROW)
from .pseudo_inertia import (J_SLOTS, inverse_cholesky4, natural_gain_apply, pseudo_inertia_into,
                             whitened_into)
from .retraction import retract, retract_short


#: the entry (row, column) of J that theta_0 .. theta_9 each set alone: the coordinates j
#: of the barrier metric (``pseudo_inertia.J_SLOTS``, doc/design.md §8), and their weights
#: ``w`` (1/2 on the diagonal); arrays, which numba reads as constants
_J_ROW = np.array([i for i, _ in J_SLOTS], dtype=np.int64)
_J_COL = np.array([j for _, j in J_SLOTS], dtype=np.int64)
_J_W = np.array([0.5 if i == j else 1.0 for i, j in J_SLOTS])

#: the natural geometry's gain in :func:`natural_gain_step` (doc/design.md §8): the log-det
#: metric, natural least squares, the barrier metric
LOG_DET, NATURAL_LS, BARRIER = 0, 1, 2


@njit(cache=True)
def natural_gain_step(row, st, metric, k_metric, grad, h, R, i, Pg, t, M4):
    """Natural geometry, eq 24 step 1's explicit part for link i: ``R_i = theta_hat_i - h
    P_eff(theta_hat_i) grad`` (doc/design.md §8). ``metric``: :data:`NATURAL_LS`, the gain
    ``S K^-1 S^T`` of :func:`natural_ls_factor` with ``k_metric = k_i``; :data:`BARRIER`,
    ``P_mix`` of :func:`barrier_factor` with ``k_metric = c k_i``; both factored here for
    the step; :data:`LOG_DET`, ``k_i (Hessian of -log det)^-1`` on J and ``P_nu`` on nu."""
    if metric == BARRIER:
        barrier_factor(row, st, k_metric, M4)
        barrier_apply(row, st, grad, 0, Pg, 0, t)
    elif metric == NATURAL_LS:
        natural_ls_factor(st, k_metric, Pg, M4)
        natural_ls_apply(st, grad, 0, Pg, 0, t)
    else:
        natural_gain_apply(st, THETA_HAT, grad, 0, Pg, 0, row[NAT_K], row, NAT_P_NU)
    for k in range(13):
        R[i, k] = st[THETA_HAT + k] - h * Pg[k]


@njit(cache=True)
def natural_gain_row(row, st, metric, f, t):
    """``U_ci = P_eff(theta_hat_i) W_ci^T`` in channel c's row ``f = filt[c, i]``, with the
    gain :func:`natural_gain_step` used (its factor already in the state)."""
    if metric == BARRIER:
        barrier_apply(row, st, f, W_ROW, f, U_ROW, t)
    elif metric == NATURAL_LS:
        natural_ls_apply(st, f, W_ROW, f, U_ROW, t)
    else:
        natural_gain_apply(st, THETA_HAT, f, W_ROW, f, U_ROW, row[NAT_K], row, NAT_P_NU)


@njit(cache=True)
def natural_gain_rows(const, state, filt0, G, R, scal, Pg, t, M4):
    """Eq 24, step 1 of the paper's law (one channel, joint 1) in the natural geometry, every
    link: ``R_i = theta_hat_i - h P_eff,i G_i`` and ``U_i = P_eff,i W_i^T`` (``filt0``: the
    channel's rows), ``G_i`` already holding ``Y_ri^T s_i - gamma W_i^T y``, and
    ``theta_hat_i`` kept for the retraction; ``P_eff`` of either metric, as
    :func:`adapt_link` computes it (doc/design.md §8). ``Pg``, ``t``: 13 scratch each;
    ``M4``: 4x4 scratch. Not inlined: the fused kernel calls it once per step, so its
    Euclidean instances do not compile it (compile time)."""
    h = scal[I_H]
    c = scal[I_BARRIER_C]
    metric = BARRIER if c > 0.0 else LOG_DET
    for i in range(state.shape[0]):
        st = state[i]
        row = const[i]
        for k in range(13):
            st[THETA_PREV + k] = st[THETA_HAT + k]
        # the barrier's (H / (c k_i) + P_i^-1)^-1, factored; else k_i H^-1 and P_nu
        natural_gain_step(row, st, metric, c * row[NAT_K], G[i], h, R, i, Pg, t, M4)
        natural_gain_row(row, st, metric, filt0[i], t)


@njit(cache=True)
def retract_links(state, scal):
    """Natural geometry, step 3: every link's step ``theta_prev -> theta_hat`` made
    consistent by the retraction of :func:`~rcac_ros.core.retraction.retract`, or with
    the metric ``"barrier"`` by the shortened Euclidean step of
    :func:`~rcac_ros.core.retraction.retract_short` (doc/design.md §8); the smallest
    step length goes to ``scal[I_RETRACT_MIN]``."""
    a_min = 1.0
    short = scal[I_BARRIER_C] > 0.0
    for i in range(state.shape[0]):
        st = state[i]
        if short:
            a = retract_short(st, THETA_PREV, st, THETA_HAT)
        else:
            a = retract(st, THETA_PREV, st, THETA_HAT)
        a_min = min(a_min, a)
    scal[I_RETRACT_MIN] = a_min


@njit(cache=True, inline="always")
def factor_start(st, J, R):
    """The start of :func:`natural_ls_factor`: ``J = J(theta_hat_i)``
    and its inverse Cholesky factor into ``R``; True. False if ``theta_hat_i`` is not a body
    (never: it is one after every step), with ``K = I`` in ``st[NAT_LS_CHOL]`` (the gain
    ``S S^T``)."""
    pseudo_inertia_into(st, THETA_HAT, J)
    if inverse_cholesky4(J, R):
        return True
    for a in range(13):
        for b in range(13):
            st[NAT_LS_CHOL + 13 * a + b] = 1.0 if a == b else 0.0
    return False


@njit(cache=True, inline="always")
def cholesky_entry(st, a, b, v):
    """Entry (a, b), b <= a, of K's Cholesky factor in ``st[NAT_LS_CHOL]`` (lower,
    row-major, in place) from ``K_ab = v``, the rows above a and the entries left of b
    done."""
    for m in range(b):
        v -= st[NAT_LS_CHOL + 13 * a + m] * st[NAT_LS_CHOL + 13 * b + m]
    if a == b:
        st[NAT_LS_CHOL + 14 * a] = np.sqrt(v)
    else:
        st[NAT_LS_CHOL + 13 * a + b] = v / st[NAT_LS_CHOL + 14 * b]


@njit(cache=True)
def barrier_factor(row, st, ck, M4):
    """The barrier metric's gain of link i (doc/design.md §8), factored: with ``theta =
    T (j, nu)`` (j: J's entries at :data:`~rcac_ros.core.pseudo_inertia.J_SLOTS`), ``P_mix
    = (H / (c k) + P^-1)^-1 = T M^-1 T^T`` and ``M = [[H_J / (c k) + X, C], [C^T, E]]``,
    ``H_J`` the Hessian of ``-log det J`` in j; eliminating nu leaves the 10x10

        S = H_J / (c k) + (A P A^T)^-1     (``row[BAR_Q]``, constant: X - C E^-1 C^T)

    whose Cholesky factor goes to ``st[NAT_LS_CHOL]`` (10x10 lower, row-major, its diagonal
    inverted). ``H_J``'s entries are ``tr(J^-1 E_p J^-1 E_q) = 2 w_p w_q (Ji_il Ji_jk +
    Ji_ik Ji_jl)`` between the unit symmetric 4x4s ``E_p`` (entries (i, j) and (j, i);
    ``w = 1/2`` on the diagonal). ``S >= (A P A^T)^-1 > 0``: the factorisation exists. If
    ``theta_hat_i`` is not a body (never: it is one after every step) ``H_J`` is left out
    and the gain is ``P``. ``ck``: ``c k_i``; ``M4``: 4x4 scratch. O(1): one 4x4 inverse
    factor, 55 entries and one 10x10 factorisation. Not inlined (compile time)."""
    J, R, Ji = M4[0], M4[1], M4[2]
    pseudo_inertia_into(st, THETA_HAT, J)
    w = 2.0 / ck
    if inverse_cholesky4(J, R):
        for p in range(4):              # J^-1 = R^T R (R lower)
            for q in range(p + 1):
                acc = 0.0
                for m in range(p, 4):
                    acc += R[m, p] * R[m, q]
                Ji[p, q] = acc
                Ji[q, p] = acc
    else:
        w = 0.0
        Ji[:, :] = 0.0
    C = NAT_LS_CHOL
    oa = 0
    for a in range(10):                 # S's row a, then its Cholesky row (in place)
        i, j = _J_ROW[a], _J_COL[a]
        wa = _J_W[a] * w
        for b in range(a + 1):
            u, v = _J_ROW[b], _J_COL[b]
            x = row[BAR_Q + oa + b] + wa * _J_W[b] * (Ji[i, v] * Ji[j, u] + Ji[i, u] * Ji[j, v])
            for m in range(b):
                x -= st[C + 10 * a + m] * st[C + 10 * b + m]
            if b == a:
                st[C + 11 * a] = 1.0 / np.sqrt(x)
            else:
                st[C + 10 * a + b] = x * st[C + 11 * b]
        oa += a + 1


@njit(cache=True, inline="always")
def barrier_apply(row, st, x, xo, out, oo, t):
    """``out[oo:oo+13] = P_mix x[xo:xo+13]`` with the factor of :func:`barrier_factor`
    (``t``: 13 scratch; x is read whole before out is written): ``b = T^T x``, then the
    block solve ``z_j = S^-1 (b_j - F b_nu)``, ``z_nu = P_nu b_nu - F^T z_j`` (``F =
    row[BAR_F]``, ``P_nu = E^-1 = row[NAT_P_NU]``), then ``out = T z``: ``theta_k = j_k``
    but for ``theta_4..6 = nu`` and ``theta_10 = j_5 + j_6 - nu_1 - nu_2`` (cyclically)."""
    x10, x11, x12 = x[xo + 10], x[xo + 11], x[xo + 12]
    n0, n1, n2 = x[xo + 4] - x11 - x12, x[xo + 5] - x10 - x12, x[xo + 6] - x10 - x11
    for a in range(10):                 # b_j - F b_nu
        if a == 4:
            v = x11 + x12
        elif a == 5:
            v = x10 + x12
        elif a == 6:
            v = x10 + x11
        else:
            v = x[xo + a]
        f = BAR_F + 3 * a
        t[a] = v - (row[f] * n0 + row[f + 1] * n1 + row[f + 2] * n2)
    C = NAT_LS_CHOL
    for a in range(10):                 # S^-1: forward, then backward substitution
        acc = t[a]
        for b in range(a):
            acc -= st[C + 10 * a + b] * t[b]
        t[a] = acc * st[C + 11 * a]
    for a in range(9, -1, -1):
        acc = t[a]
        for b in range(a + 1, 10):
            acc -= st[C + 10 * b + a] * t[b]
        t[a] = acc * st[C + 11 * a]
    p = NAT_P_NU
    m0 = row[p] * n0 + row[p + 1] * n1 + row[p + 2] * n2
    m1 = row[p + 3] * n0 + row[p + 4] * n1 + row[p + 5] * n2
    m2 = row[p + 6] * n0 + row[p + 7] * n1 + row[p + 8] * n2
    for a in range(10):                 # z_nu = P_nu b_nu - F^T z_j
        f = BAR_F + 3 * a
        m0 -= row[f] * t[a]
        m1 -= row[f + 1] * t[a]
        m2 -= row[f + 2] * t[a]
    for a in range(4):
        out[oo + a] = t[a]
    for a in range(7, 10):
        out[oo + a] = t[a]
    out[oo + 4], out[oo + 5], out[oo + 6] = m0, m1, m2
    out[oo + 10] = t[5] + t[6] - m1 - m2
    out[oo + 11] = t[4] + t[6] - m0 - m2
    out[oo + 12] = t[4] + t[5] - m0 - m1


@njit(cache=True, inline="always")
def natural_ls_factor(st, k, col, M4):
    """The natural least-squares gain of link i (doc/design.md §8), factored:

        P_i = (H(theta_hat_i) / k_i + Gamma_i)^-1 = S_i K_i^-1 S_i^T,
        K_i = I + S_i^T H(theta_hat_i) S_i / k_i,

    with ``Gamma_i = P_ls,i^-1 = (S_i S_i^T)^-1`` the least-squares information of
    :mod:`rcac_ros.core.least_squares` (forgetting included) and ``H`` the Hessian of
    ``-log det J`` in the 13 parameters. ``K_i >= I``, so its Cholesky factor (into
    ``st[NAT_LS_CHOL]``, lower, row-major) always exists, and ``P_i <= S_i S_i^T``.
    ``H``'s entries between S's columns are inner products of the whitened ``J(S e_j)``
    (:func:`~rcac_ros.core.pseudo_inertia.whitened_into`, 10 numbers each, kept at
    ``st[NAT_LS_N]``). ``col``: 13 scratch; ``M4``: 4x4 scratch. O(1): 13 whitenings, one
    13x13 product of rank 10 and one 13x13 Cholesky factorisation.
    """
    J, R, X = M4[0], M4[1], M4[2]
    if not factor_start(st, J, R):
        return
    for j in range(13):
        for r in range(13):
            col[r] = st[P_FACTOR + 13 * r + j]
        whitened_into(R, col, 0, X, st, NAT_LS_N + 10 * j)
    inv_k = 1.0 / k
    for a in range(13):                 # Cholesky of K, row by row (lower, in place)
        oa = NAT_LS_N + 10 * a
        for b in range(a + 1):
            ob = NAT_LS_N + 10 * b
            acc = 0.0
            for e in range(10):
                acc += st[oa + e] * st[ob + e]
            cholesky_entry(st, a, b, acc * inv_k + (1.0 if a == b else 0.0))


@njit(cache=True, inline="always")
def natural_ls_apply(st, x, xo, out, oo, t):
    """``out[oo:oo+13] = S_i K_i^-1 S_i^T x[xo:xo+13]``: the natural least-squares gain of
    :func:`natural_ls_factor` applied to x (``t``: 13 scratch)."""
    for c in range(13):                 # t = S^T x
        acc = 0.0
        for r in range(13):
            acc += st[P_FACTOR + 13 * r + c] * x[xo + r]
        t[c] = acc
    for a in range(13):                 # K^-1 t: forward, then backward substitution
        acc = t[a]
        for b in range(a):
            acc -= st[NAT_LS_CHOL + 13 * a + b] * t[b]
        t[a] = acc / st[NAT_LS_CHOL + 14 * a]
    for a in range(12, -1, -1):
        acc = t[a]
        for b in range(a + 1, 13):
            acc -= st[NAT_LS_CHOL + 13 * b + a] * t[b]
        t[a] = acc / st[NAT_LS_CHOL + 14 * a]
    for r in range(13):                 # out = S t
        acc = 0.0
        for c in range(13):
            acc += st[P_FACTOR + 13 * r + c] * t[c]
        out[oo + r] = acc
