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
from ._packing import (BAR_F, BAR_Q, CONST_COLS, FILT_COLS, I_BARRIER_C, I_H, I_RETRACT_MIN,
                       LINK_COLS, NAT_K, NAT_LS_CHOL, NAT_LS_N, NAT_P_NU, P_FACTOR, THETA_HAT,
                       THETA_PREV, U_ROW, W_ROW)
from .pseudo_inertia import (cholesky_entries, inverse_cholesky4, inverse_entries,
                             natural_gain_apply, pseudo_entries, pseudo_inertia_into,
                             whitened_into)
from .retraction import retract, retract_short


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
        barrier_factor(row, 0, st, 0, k_metric)
        barrier_apply(row, 0, st, 0, grad, 0, Pg, 0)
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
        barrier_apply(row, 0, st, 0, f, W_ROW, f, U_ROW)
    elif metric == NATURAL_LS:
        natural_ls_apply(st, f, W_ROW, f, U_ROW, t)
    else:
        natural_gain_apply(st, THETA_HAT, f, W_ROW, f, U_ROW, row[NAT_K], row, NAT_P_NU)


@njit(cache=True)
def natural_gain_rows(data, filt, G, R, Pg):
    """Eq 24, step 1 of the paper's law (one channel, joint 1) in the natural geometry, every
    link: ``R_i = theta_hat_i - h P_eff,i G_i`` and ``U_i = P_eff,i W_i^T`` (channel 0's rows
    of ``filt``), ``G_i`` already holding ``Y_ri^T s_i - gamma W_i^T y``, and
    ``theta_hat_i`` kept for the retraction; ``P_eff`` of either metric, as
    :func:`adapt_link` computes it (doc/design.md §8). ``data``, ``filt``: the kernel's
    packed arrays, read at plain offsets of their flat views (no per-link view); ``Pg``: 13
    scratch. Not inlined: the fused kernel calls it once per step, so its Euclidean
    instances do not compile it (compile time)."""
    n = data.shape[0] - 1
    d = data.reshape(data.size)
    fl = filt.reshape(filt.size)
    g = G.reshape(G.size)
    h = d[n * LINK_COLS + I_H]
    c = d[n * LINK_COLS + I_BARRIER_C]
    for i in range(n):
        co = i * LINK_COLS                      # link i's constants, then its state
        so = co + CONST_COLS
        fo = i * FILT_COLS                      # channel 0, link i
        for k in range(13):
            d[so + THETA_PREV + k] = d[so + THETA_HAT + k]
        if c > 0.0:     # the barrier's (H / (c k_i) + P_i^-1)^-1, factored, on G_i and W_i
            barrier_factor(d, co, d, so, c * d[co + NAT_K])
            barrier_apply(d, co, d, so, g, 13 * i, Pg, 0)
            barrier_apply(d, co, d, so, fl, fo + W_ROW, fl, fo + U_ROW)
        else:           # k_i H^-1 and P_nu
            k_i = d[co + NAT_K]
            natural_gain_apply(d, so + THETA_HAT, g, 13 * i, Pg, 0, k_i, d, co + NAT_P_NU)
            natural_gain_apply(d, so + THETA_HAT, fl, fo + W_ROW, fl, fo + U_ROW, k_i, d,
                               co + NAT_P_NU)
        for k in range(13):
            R[i, k] = d[so + THETA_HAT + k] - h * Pg[k]


@njit(cache=True)
def retract_links(data):
    """Natural geometry, step 3: every link's step ``theta_prev -> theta_hat`` made
    consistent by the retraction of :func:`~rcac_ros.core.retraction.retract`, or with
    the metric ``"barrier"`` by the shortened Euclidean step of
    :func:`~rcac_ros.core.retraction.retract_short` (doc/design.md §8); the smallest
    step length goes to the scalar ``I_RETRACT_MIN``. ``data``: the kernel's packed array,
    read at plain offsets of its flat view."""
    n = data.shape[0] - 1
    d = data.reshape(data.size)
    a_min = 1.0
    short = d[n * LINK_COLS + I_BARRIER_C] > 0.0
    for i in range(n):
        so = i * LINK_COLS + CONST_COLS
        if short:
            a = retract_short(d, so + THETA_PREV, d, so + THETA_HAT)
        else:
            a = retract(d, so + THETA_PREV, d, so + THETA_HAT)
        a_min = min(a_min, a)
    d[n * LINK_COLS + I_RETRACT_MIN] = a_min


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
def barrier_factor(c, co, s, so, ck):
    """The barrier metric's gain of link i (doc/design.md §8), factored: with ``theta =
    T (j, nu)`` (j: J's entries at :data:`~rcac_ros.core.pseudo_inertia.J_SLOTS`), ``P_mix
    = (H / (c k) + P^-1)^-1 = T M^-1 T^T`` and ``M = [[H_J / (c k) + X, C], [C^T, E]]``,
    ``H_J`` the Hessian of ``-log det J`` in j; eliminating nu leaves the 10x10

        S = H_J / (c k) + (A P A^T)^-1     (``BAR_Q``, constant: X - C E^-1 C^T)

    whose Cholesky factor goes to ``s[so + NAT_LS_CHOL:]`` (10x10 lower, row-major, its
    diagonal inverted). ``H_J``'s entries are ``tr(J^-1 E_p J^-1 E_q) = 2 w_p w_q (Ji_il
    Ji_jk + Ji_ik Ji_jl)`` between the unit symmetric 4x4s ``E_p`` (entries (i, j) and
    (j, i); ``w = 1/2`` on the diagonal). ``S >= (A P A^T)^-1 > 0``: the factorisation
    exists. If ``theta_hat_i`` is not a body (never: it is one after every step) ``H_J`` is
    left out and the gain is ``P``.

    Link i's constants are ``c[co:co + CONST_COLS]``, its state ``s[so:so + STATE_COLS]``
    (a flat view of the packed array, or a row and 0); ``ck``: ``c k_i``. O(1): one 4x4
    inverse factor (``J^-1 = R^T R``, :func:`~rcac_ros.core.pseudo_inertia.inverse_cholesky4`),
    55 entries and one 10x10 factorisation, unrolled on scalars in the operations and order
    of their loops (``S``'s factor entry (a, b) is ``s{a}_{b}``, ``J^-1``'s (p, q) ``i{p}{q}``,
    p >= q). Not inlined (compile time)."""
    j00, j11, j22, j33, j01, j02, j12, j03, j13, j23 = pseudo_entries(s, so + THETA_HAT)
    ok, l00, l10, l11, l20, l21, l22, l30, l31, l32, l33 = cholesky_entries(
        j00, j11, j22, j33, j01, j02, j12, j03, j13, j23)
    w = 2.0 / ck
    if ok:                              # J^-1 = R^T R, R = L^-1 (inverse_cholesky4)
        i00, i10, i20, i30, i11, i21, i31, i22, i32, i33 = inverse_entries(
            l00, l10, l11, l20, l21, l22, l30, l31, l32, l33)
    else:
        w = 0.0
        i00 = i10 = i11 = i20 = i21 = i22 = i30 = i31 = i32 = i33 = 0.0
    wh, wq = 0.5 * w, 0.25 * w          # w w_p w_q (exact: powers of 2)
    q = co + BAR_Q
    o = so + NAT_LS_CHOL
    # S's row a, then its Cholesky row: s{a}_{b} = (S_ab - sum_m s{a}_m s{b}_m) / l_bb
    s0_0 = 1.0 / np.sqrt(c[q + 0] + wq * (i33 * i33 + i33 * i33))
    s1_0 = (c[q + 1] + wh * (i30 * i33 + i30 * i33)) * s0_0
    s1_1 = 1.0 / np.sqrt(c[q + 2] + w * (i30 * i30 + i00 * i33) - s1_0 * s1_0)
    s2_0 = (c[q + 3] + wh * (i31 * i33 + i31 * i33)) * s0_0
    s2_1 = (c[q + 4] + w * (i31 * i30 + i10 * i33) - s2_0 * s1_0) * s1_1
    s2_2 = 1.0 / np.sqrt(c[q + 5] + w * (i31 * i31 + i11 * i33) - s2_0 * s2_0 - s2_1 * s2_1)
    s3_0 = (c[q + 6] + wh * (i32 * i33 + i32 * i33)) * s0_0
    s3_1 = (c[q + 7] + w * (i32 * i30 + i20 * i33) - s3_0 * s1_0) * s1_1
    s3_2 = (c[q + 8] + w * (i32 * i31 + i21 * i33) - s3_0 * s2_0 - s3_1 * s2_1) * s2_2
    s3_3 = (1.0 / np.sqrt(c[q + 9] + w * (i32 * i32 + i22 * i33) - s3_0 * s3_0 - s3_1 * s3_1
            - s3_2 * s3_2))
    s4_0 = (c[q + 10] + wq * (i30 * i30 + i30 * i30)) * s0_0
    s4_1 = (c[q + 11] + wh * (i30 * i00 + i00 * i30) - s4_0 * s1_0) * s1_1
    s4_2 = (c[q + 12] + wh * (i30 * i10 + i10 * i30) - s4_0 * s2_0 - s4_1 * s2_1) * s2_2
    s4_3 = ((c[q + 13] + wh * (i30 * i20 + i20 * i30) - s4_0 * s3_0 - s4_1 * s3_1
            - s4_2 * s3_2) * s3_3)
    s4_4 = (1.0 / np.sqrt(c[q + 14] + wq * (i00 * i00 + i00 * i00) - s4_0 * s4_0 - s4_1 * s4_1
            - s4_2 * s4_2 - s4_3 * s4_3))
    s5_0 = (c[q + 15] + wq * (i31 * i31 + i31 * i31)) * s0_0
    s5_1 = (c[q + 16] + wh * (i31 * i10 + i10 * i31) - s5_0 * s1_0) * s1_1
    s5_2 = (c[q + 17] + wh * (i31 * i11 + i11 * i31) - s5_0 * s2_0 - s5_1 * s2_1) * s2_2
    s5_3 = ((c[q + 18] + wh * (i31 * i21 + i21 * i31) - s5_0 * s3_0 - s5_1 * s3_1
            - s5_2 * s3_2) * s3_3)
    s5_4 = ((c[q + 19] + wq * (i10 * i10 + i10 * i10) - s5_0 * s4_0 - s5_1 * s4_1 - s5_2 * s4_2
            - s5_3 * s4_3) * s4_4)
    s5_5 = (1.0 / np.sqrt(c[q + 20] + wq * (i11 * i11 + i11 * i11) - s5_0 * s5_0 - s5_1 * s5_1
            - s5_2 * s5_2 - s5_3 * s5_3 - s5_4 * s5_4))
    s6_0 = (c[q + 21] + wq * (i32 * i32 + i32 * i32)) * s0_0
    s6_1 = (c[q + 22] + wh * (i32 * i20 + i20 * i32) - s6_0 * s1_0) * s1_1
    s6_2 = (c[q + 23] + wh * (i32 * i21 + i21 * i32) - s6_0 * s2_0 - s6_1 * s2_1) * s2_2
    s6_3 = ((c[q + 24] + wh * (i32 * i22 + i22 * i32) - s6_0 * s3_0 - s6_1 * s3_1
            - s6_2 * s3_2) * s3_3)
    s6_4 = ((c[q + 25] + wq * (i20 * i20 + i20 * i20) - s6_0 * s4_0 - s6_1 * s4_1 - s6_2 * s4_2
            - s6_3 * s4_3) * s4_4)
    s6_5 = ((c[q + 26] + wq * (i21 * i21 + i21 * i21) - s6_0 * s5_0 - s6_1 * s5_1 - s6_2 * s5_2
            - s6_3 * s5_3 - s6_4 * s5_4) * s5_5)
    s6_6 = (1.0 / np.sqrt(c[q + 27] + wq * (i22 * i22 + i22 * i22) - s6_0 * s6_0 - s6_1 * s6_1
            - s6_2 * s6_2 - s6_3 * s6_3 - s6_4 * s6_4 - s6_5 * s6_5))
    s7_0 = (c[q + 28] + wh * (i30 * i31 + i30 * i31)) * s0_0
    s7_1 = (c[q + 29] + w * (i30 * i10 + i00 * i31) - s7_0 * s1_0) * s1_1
    s7_2 = (c[q + 30] + w * (i30 * i11 + i10 * i31) - s7_0 * s2_0 - s7_1 * s2_1) * s2_2
    s7_3 = ((c[q + 31] + w * (i30 * i21 + i20 * i31) - s7_0 * s3_0 - s7_1 * s3_1
            - s7_2 * s3_2) * s3_3)
    s7_4 = ((c[q + 32] + wh * (i00 * i10 + i00 * i10) - s7_0 * s4_0 - s7_1 * s4_1 - s7_2 * s4_2
            - s7_3 * s4_3) * s4_4)
    s7_5 = ((c[q + 33] + wh * (i10 * i11 + i10 * i11) - s7_0 * s5_0 - s7_1 * s5_1 - s7_2 * s5_2
            - s7_3 * s5_3 - s7_4 * s5_4) * s5_5)
    s7_6 = ((c[q + 34] + wh * (i20 * i21 + i20 * i21) - s7_0 * s6_0 - s7_1 * s6_1 - s7_2 * s6_2
            - s7_3 * s6_3 - s7_4 * s6_4 - s7_5 * s6_5) * s6_6)
    s7_7 = (1.0 / np.sqrt(c[q + 35] + w * (i10 * i10 + i00 * i11) - s7_0 * s7_0 - s7_1 * s7_1
            - s7_2 * s7_2 - s7_3 * s7_3 - s7_4 * s7_4 - s7_5 * s7_5 - s7_6 * s7_6))
    s8_0 = (c[q + 36] + wh * (i30 * i32 + i30 * i32)) * s0_0
    s8_1 = (c[q + 37] + w * (i30 * i20 + i00 * i32) - s8_0 * s1_0) * s1_1
    s8_2 = (c[q + 38] + w * (i30 * i21 + i10 * i32) - s8_0 * s2_0 - s8_1 * s2_1) * s2_2
    s8_3 = ((c[q + 39] + w * (i30 * i22 + i20 * i32) - s8_0 * s3_0 - s8_1 * s3_1
            - s8_2 * s3_2) * s3_3)
    s8_4 = ((c[q + 40] + wh * (i00 * i20 + i00 * i20) - s8_0 * s4_0 - s8_1 * s4_1 - s8_2 * s4_2
            - s8_3 * s4_3) * s4_4)
    s8_5 = ((c[q + 41] + wh * (i10 * i21 + i10 * i21) - s8_0 * s5_0 - s8_1 * s5_1 - s8_2 * s5_2
            - s8_3 * s5_3 - s8_4 * s5_4) * s5_5)
    s8_6 = ((c[q + 42] + wh * (i20 * i22 + i20 * i22) - s8_0 * s6_0 - s8_1 * s6_1 - s8_2 * s6_2
            - s8_3 * s6_3 - s8_4 * s6_4 - s8_5 * s6_5) * s6_6)
    s8_7 = ((c[q + 43] + w * (i10 * i20 + i00 * i21) - s8_0 * s7_0 - s8_1 * s7_1 - s8_2 * s7_2
            - s8_3 * s7_3 - s8_4 * s7_4 - s8_5 * s7_5 - s8_6 * s7_6) * s7_7)
    s8_8 = (1.0 / np.sqrt(c[q + 44] + w * (i20 * i20 + i00 * i22) - s8_0 * s8_0 - s8_1 * s8_1
            - s8_2 * s8_2 - s8_3 * s8_3 - s8_4 * s8_4 - s8_5 * s8_5 - s8_6 * s8_6 - s8_7 * s8_7))
    s9_0 = (c[q + 45] + wh * (i31 * i32 + i31 * i32)) * s0_0
    s9_1 = (c[q + 46] + w * (i31 * i20 + i10 * i32) - s9_0 * s1_0) * s1_1
    s9_2 = (c[q + 47] + w * (i31 * i21 + i11 * i32) - s9_0 * s2_0 - s9_1 * s2_1) * s2_2
    s9_3 = ((c[q + 48] + w * (i31 * i22 + i21 * i32) - s9_0 * s3_0 - s9_1 * s3_1
            - s9_2 * s3_2) * s3_3)
    s9_4 = ((c[q + 49] + wh * (i10 * i20 + i10 * i20) - s9_0 * s4_0 - s9_1 * s4_1 - s9_2 * s4_2
            - s9_3 * s4_3) * s4_4)
    s9_5 = ((c[q + 50] + wh * (i11 * i21 + i11 * i21) - s9_0 * s5_0 - s9_1 * s5_1 - s9_2 * s5_2
            - s9_3 * s5_3 - s9_4 * s5_4) * s5_5)
    s9_6 = ((c[q + 51] + wh * (i21 * i22 + i21 * i22) - s9_0 * s6_0 - s9_1 * s6_1 - s9_2 * s6_2
            - s9_3 * s6_3 - s9_4 * s6_4 - s9_5 * s6_5) * s6_6)
    s9_7 = ((c[q + 52] + w * (i11 * i20 + i10 * i21) - s9_0 * s7_0 - s9_1 * s7_1 - s9_2 * s7_2
            - s9_3 * s7_3 - s9_4 * s7_4 - s9_5 * s7_5 - s9_6 * s7_6) * s7_7)
    s9_8 = ((c[q + 53] + w * (i21 * i20 + i10 * i22) - s9_0 * s8_0 - s9_1 * s8_1 - s9_2 * s8_2
            - s9_3 * s8_3 - s9_4 * s8_4 - s9_5 * s8_5 - s9_6 * s8_6 - s9_7 * s8_7) * s8_8)
    s9_9 = (1.0 / np.sqrt(c[q + 54] + w * (i21 * i21 + i11 * i22) - s9_0 * s9_0 - s9_1 * s9_1
            - s9_2 * s9_2 - s9_3 * s9_3 - s9_4 * s9_4 - s9_5 * s9_5 - s9_6 * s9_6 - s9_7 * s9_7
            - s9_8 * s9_8))
    s[o + 0] = s0_0
    s[o + 10], s[o + 11] = s1_0, s1_1
    s[o + 20], s[o + 21], s[o + 22] = s2_0, s2_1, s2_2
    s[o + 30], s[o + 31], s[o + 32], s[o + 33] = s3_0, s3_1, s3_2, s3_3
    s[o + 40], s[o + 41], s[o + 42], s[o + 43], s[o + 44] = s4_0, s4_1, s4_2, s4_3, s4_4
    s[o + 50], s[o + 51], s[o + 52], s[o + 53], s[o + 54] = s5_0, s5_1, s5_2, s5_3, s5_4
    s[o + 55] = s5_5
    s[o + 60], s[o + 61], s[o + 62], s[o + 63], s[o + 64] = s6_0, s6_1, s6_2, s6_3, s6_4
    s[o + 65], s[o + 66] = s6_5, s6_6
    s[o + 70], s[o + 71], s[o + 72], s[o + 73], s[o + 74] = s7_0, s7_1, s7_2, s7_3, s7_4
    s[o + 75], s[o + 76], s[o + 77] = s7_5, s7_6, s7_7
    s[o + 80], s[o + 81], s[o + 82], s[o + 83], s[o + 84] = s8_0, s8_1, s8_2, s8_3, s8_4
    s[o + 85], s[o + 86], s[o + 87], s[o + 88] = s8_5, s8_6, s8_7, s8_8
    s[o + 90], s[o + 91], s[o + 92], s[o + 93], s[o + 94] = s9_0, s9_1, s9_2, s9_3, s9_4
    s[o + 95], s[o + 96], s[o + 97], s[o + 98], s[o + 99] = s9_5, s9_6, s9_7, s9_8, s9_9


@njit(cache=True, inline="always")
def barrier_apply(c, co, s, so, x, xo, out, oo):
    """``out[oo:oo+13] = P_mix x[xo:xo+13]`` with the factor of :func:`barrier_factor`
    (link i's constants at ``c[co:]``, its state at ``s[so:]``; x is read whole before out is
    written): ``b = T^T x``, then the block solve ``z_j = S^-1 (b_j - F b_nu)``, ``z_nu =
    P_nu b_nu - F^T z_j`` (``F``: ``BAR_F``, ``P_nu = E^-1``: ``NAT_P_NU``), then ``out = T
    z``: ``theta_k = j_k`` but for ``theta_4..6 = nu`` and ``theta_10 = j_5 + j_6 - nu_1 -
    nu_2`` (cyclically). Unrolled on scalars in the operations and order of the loops of a
    forward and a backward substitution (``t{a}``: z_j's entry a)."""
    x10, x11, x12 = x[xo + 10], x[xo + 11], x[xo + 12]
    n0, n1, n2 = x[xo + 4] - x11 - x12, x[xo + 5] - x10 - x12, x[xo + 6] - x10 - x11
    f = co + BAR_F
    p = co + NAT_P_NU
    o = so + NAT_LS_CHOL
    s0_0 = s[o + 0]
    s1_0, s1_1 = s[o + 10], s[o + 11]
    s2_0, s2_1, s2_2 = s[o + 20], s[o + 21], s[o + 22]
    s3_0, s3_1, s3_2, s3_3 = s[o + 30], s[o + 31], s[o + 32], s[o + 33]
    s4_0, s4_1, s4_2, s4_3, s4_4 = s[o + 40], s[o + 41], s[o + 42], s[o + 43], s[o + 44]
    s5_0, s5_1, s5_2, s5_3, s5_4 = s[o + 50], s[o + 51], s[o + 52], s[o + 53], s[o + 54]
    s5_5 = s[o + 55]
    s6_0, s6_1, s6_2, s6_3, s6_4 = s[o + 60], s[o + 61], s[o + 62], s[o + 63], s[o + 64]
    s6_5, s6_6 = s[o + 65], s[o + 66]
    s7_0, s7_1, s7_2, s7_3, s7_4 = s[o + 70], s[o + 71], s[o + 72], s[o + 73], s[o + 74]
    s7_5, s7_6, s7_7 = s[o + 75], s[o + 76], s[o + 77]
    s8_0, s8_1, s8_2, s8_3, s8_4 = s[o + 80], s[o + 81], s[o + 82], s[o + 83], s[o + 84]
    s8_5, s8_6, s8_7, s8_8 = s[o + 85], s[o + 86], s[o + 87], s[o + 88]
    s9_0, s9_1, s9_2, s9_3, s9_4 = s[o + 90], s[o + 91], s[o + 92], s[o + 93], s[o + 94]
    s9_5, s9_6, s9_7, s9_8, s9_9 = s[o + 95], s[o + 96], s[o + 97], s[o + 98], s[o + 99]
    # b_j - F b_nu
    t0 = x[xo + 0] - (c[f + 0] * n0 + c[f + 1] * n1 + c[f + 2] * n2)
    t1 = x[xo + 1] - (c[f + 3] * n0 + c[f + 4] * n1 + c[f + 5] * n2)
    t2 = x[xo + 2] - (c[f + 6] * n0 + c[f + 7] * n1 + c[f + 8] * n2)
    t3 = x[xo + 3] - (c[f + 9] * n0 + c[f + 10] * n1 + c[f + 11] * n2)
    t4 = (x11 + x12) - (c[f + 12] * n0 + c[f + 13] * n1 + c[f + 14] * n2)
    t5 = (x10 + x12) - (c[f + 15] * n0 + c[f + 16] * n1 + c[f + 17] * n2)
    t6 = (x10 + x11) - (c[f + 18] * n0 + c[f + 19] * n1 + c[f + 20] * n2)
    t7 = x[xo + 7] - (c[f + 21] * n0 + c[f + 22] * n1 + c[f + 23] * n2)
    t8 = x[xo + 8] - (c[f + 24] * n0 + c[f + 25] * n1 + c[f + 26] * n2)
    t9 = x[xo + 9] - (c[f + 27] * n0 + c[f + 28] * n1 + c[f + 29] * n2)
    # S^-1: forward, then backward substitution
    t0 = t0 * s0_0
    t1 = (t1 - s1_0 * t0) * s1_1
    t2 = (t2 - s2_0 * t0 - s2_1 * t1) * s2_2
    t3 = (t3 - s3_0 * t0 - s3_1 * t1 - s3_2 * t2) * s3_3
    t4 = (t4 - s4_0 * t0 - s4_1 * t1 - s4_2 * t2 - s4_3 * t3) * s4_4
    t5 = (t5 - s5_0 * t0 - s5_1 * t1 - s5_2 * t2 - s5_3 * t3 - s5_4 * t4) * s5_5
    t6 = (t6 - s6_0 * t0 - s6_1 * t1 - s6_2 * t2 - s6_3 * t3 - s6_4 * t4 - s6_5 * t5) * s6_6
    t7 = (t7 - s7_0 * t0 - s7_1 * t1 - s7_2 * t2 - s7_3 * t3 - s7_4 * t4 - s7_5 * t5
          - s7_6 * t6) * s7_7
    t8 = (t8 - s8_0 * t0 - s8_1 * t1 - s8_2 * t2 - s8_3 * t3 - s8_4 * t4 - s8_5 * t5 - s8_6 * t6
          - s8_7 * t7) * s8_8
    t9 = (t9 - s9_0 * t0 - s9_1 * t1 - s9_2 * t2 - s9_3 * t3 - s9_4 * t4 - s9_5 * t5 - s9_6 * t6
          - s9_7 * t7 - s9_8 * t8) * s9_9
    t9 = t9 * s9_9
    t8 = (t8 - s9_8 * t9) * s8_8
    t7 = (t7 - s8_7 * t8 - s9_7 * t9) * s7_7
    t6 = (t6 - s7_6 * t7 - s8_6 * t8 - s9_6 * t9) * s6_6
    t5 = (t5 - s6_5 * t6 - s7_5 * t7 - s8_5 * t8 - s9_5 * t9) * s5_5
    t4 = (t4 - s5_4 * t5 - s6_4 * t6 - s7_4 * t7 - s8_4 * t8 - s9_4 * t9) * s4_4
    t3 = (t3 - s4_3 * t4 - s5_3 * t5 - s6_3 * t6 - s7_3 * t7 - s8_3 * t8 - s9_3 * t9) * s3_3
    m0 = c[p] * n0 + c[p + 1] * n1 + c[p + 2] * n2     # z_nu = P_nu b_nu - F^T z_j
    m1 = c[p + 3] * n0 + c[p + 4] * n1 + c[p + 5] * n2
    m2 = c[p + 6] * n0 + c[p + 7] * n1 + c[p + 8] * n2
    t2 = (t2 - s3_2 * t3 - s4_2 * t4 - s5_2 * t5 - s6_2 * t6 - s7_2 * t7 - s8_2 * t8
          - s9_2 * t9) * s2_2
    t1 = (t1 - s2_1 * t2 - s3_1 * t3 - s4_1 * t4 - s5_1 * t5 - s6_1 * t6 - s7_1 * t7 - s8_1 * t8
          - s9_1 * t9) * s1_1
    t0 = (t0 - s1_0 * t1 - s2_0 * t2 - s3_0 * t3 - s4_0 * t4 - s5_0 * t5 - s6_0 * t6 - s7_0 * t7
          - s8_0 * t8 - s9_0 * t9) * s0_0
    m0 = (m0 - c[f + 0] * t0 - c[f + 3] * t1 - c[f + 6] * t2 - c[f + 9] * t3 - c[f + 12] * t4
          - c[f + 15] * t5 - c[f + 18] * t6 - c[f + 21] * t7 - c[f + 24] * t8 - c[f + 27] * t9)
    m1 = (m1 - c[f + 1] * t0 - c[f + 4] * t1 - c[f + 7] * t2 - c[f + 10] * t3 - c[f + 13] * t4
          - c[f + 16] * t5 - c[f + 19] * t6 - c[f + 22] * t7 - c[f + 25] * t8 - c[f + 28] * t9)
    m2 = (m2 - c[f + 2] * t0 - c[f + 5] * t1 - c[f + 8] * t2 - c[f + 11] * t3 - c[f + 14] * t4
          - c[f + 17] * t5 - c[f + 20] * t6 - c[f + 23] * t7 - c[f + 26] * t8 - c[f + 29] * t9)
    out[oo], out[oo + 1], out[oo + 2], out[oo + 3] = t0, t1, t2, t3
    out[oo + 7], out[oo + 8], out[oo + 9] = t7, t8, t9
    out[oo + 4], out[oo + 5], out[oo + 6] = m0, m1, m2
    out[oo + 10] = t5 + t6 - m1 - m2
    out[oo + 11] = t4 + t6 - m0 - m2
    out[oo + 12] = t4 + t5 - m0 - m1


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
