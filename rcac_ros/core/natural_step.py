"""The natural geometry's adaptation step (doc/design.md §8): eq 24's step 1 with the gain
``P_eff(theta_hat_i)`` of the chosen metric, and the retraction after the step.

- :func:`natural_gain_step`, :func:`natural_gain_row`: ``R_i = theta_hat_i - h P_eff g`` and
  ``U_ci = P_eff W_ci^T`` for link i, with the log-det metric, natural least squares
  (:func:`natural_ls_factor`) or the barrier metric (:func:`barrier_factor`);
- :func:`natural_gain_rows`: the same for every link of the paper's law (the fused kernel),
  with the barrier metric :data:`LANES` links side by side (:func:`barrier_lanes`);
- :func:`retract_links`: every link's step made consistent (:mod:`rcac_ros.core.retraction`);
  :func:`retract_lanes` the same in the fused law, the barrier metric's whole steps tried
  :data:`LANES` links side by side (:func:`short_lanes`).

These are compiled once and called, not inlined, by the kernels of every law that has the
natural geometry (compile time; a call per link costs nothing measurable per step).
"""

import numpy as np

from ._blocks import unmanaged_block
from ._jit import njit
from ._packing import (BAR_F, BAR_Q, CONST_COLS, FILT_COLS, I_BARRIER_C, I_H, I_RETRACT_MIN,
                       LINK_COLS, NAT_K, NAT_LS_CHOL, NAT_LS_N, NAT_P_NU, P_FACTOR, THETA_HAT,
                       THETA_PREV, U_ROW, W_ROW)
from .pseudo_inertia import (inverse_cholesky4, inverse_ldl_entries, natural_gain_apply,
                             positive_definite4, pseudo_entries, pseudo_inertia_into,
                             whitened_into)
from .retraction import FLOOR, NU_RATIO, retract, retract_short


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
    instances do not compile it (compile time). Returns True if the barrier metric's lane
    buffers were used (:func:`barrier_rows`): then ``R``, ``U`` are left there and
    :func:`lane_update` takes the step, keeping ``theta_hat_i`` itself."""
    n = data.shape[0] - 1
    d = data.reshape(data.size)
    fl = filt.reshape(filt.size)
    g = G.reshape(G.size)
    h = d[n * LINK_COLS + I_H]
    c = d[n * LINK_COLS + I_BARRIER_C]
    if c > 0.0:         # the barrier's (H / (c k_i) + P_i^-1)^-1 on G_i and W_i
        base = (n + 1) * FILT_COLS               # channel 0's lane buffers, past its rows
        size = (n + LANES - 1) // LANES * LANE_ROWS * LANES
        if filt.shape[1] * FILT_COLS >= base + size:
            barrier_rows(d, fl, g, n, base)
            return True
    for i in range(n):  # k_i H^-1 and P_nu, or the barrier's gain link by link
        co = i * LINK_COLS                      # link i's constants, then its state
        so = co + CONST_COLS
        fo = i * FILT_COLS                      # channel 0, link i
        for k in range(13):
            d[so + THETA_PREV + k] = d[so + THETA_HAT + k]
        k_i = d[co + NAT_K]
        if c > 0.0:
            barrier_factor(d, co, d, so, c * k_i)
            barrier_apply(d, co, d, so, g, 13 * i, Pg, 0)
            barrier_apply(d, co, d, so, fl, fo + W_ROW, fl, fo + U_ROW)
        else:
            natural_gain_apply(d, so + THETA_HAT, g, 13 * i, Pg, 0, k_i, d, co + NAT_P_NU)
            natural_gain_apply(d, so + THETA_HAT, fl, fo + W_ROW, fl, fo + U_ROW, k_i, d,
                               co + NAT_P_NU)
        for k in range(13):
            R[i, k] = d[so + THETA_HAT + k] - h * Pg[k]
    return False


@njit(cache=True, inline="always")
def barrier_rows(d, fl, g, n, base):
    """:func:`natural_gain_rows` with the barrier metric: the links, :data:`LANES` at a
    time, in their lane buffer (one per group, from ``fl[base]`` on, its constant rows
    filled by :func:`lane_constants`; a view without a reference count): J's entries,
    ``G_i`` and ``W_i`` copied in (the lanes past the last link repeat it), and ``P_mix
    G_i``, ``P_mix W_i`` left there by :func:`barrier_lanes` for :func:`lane_update`;
    ``d``, ``fl``, ``g``: the flat views of ``data``, ``filt``, ``G``."""
    for g0 in range(0, n, LANES):
        m = min(LANES, n - g0)
        X = unmanaged_block(fl, base + g0 * LANE_ROWS, (LANE_ROWS * LANES,))
        for l in range(LANES):
            i = g0 + min(l, m - 1)
            so = i * LINK_COLS + CONST_COLS
            fo = i * FILT_COLS
            j00, j11, j22, j33, j01, j02, j12, j03, j13, j23 = pseudo_entries(d, so + THETA_HAT)
            X[l], X[LANES + l], X[2 * LANES + l], X[3 * LANES + l] = j00, j11, j22, j33
            X[4 * LANES + l], X[5 * LANES + l], X[6 * LANES + l] = j01, j02, j12
            X[7 * LANES + l], X[8 * LANES + l], X[9 * LANES + l] = j03, j13, j23
            for k in range(13):
                X[LANES * (L_G + k) + l] = g[13 * i + k]
                X[LANES * (L_W + k) + l] = fl[fo + W_ROW + k]
        barrier_lanes(X)


@njit(cache=True)
def lane_update(data, filt, h, gamma):
    """Eq 24, step 2 of the paper's law (§6's implicit solve, Sherman-Morrison) after
    :func:`natural_gain_rows` left ``P_mix G_i`` and ``U_i = P_mix W_i^T`` in the barrier's
    lane buffers: ``R_i = theta_hat_i - h P_mix G_i``, ``kc = h gamma W R / (1 + h gamma W
    U)``, ``theta_hat_i`` kept for the retraction and ``theta_hat_i = R_i - kc U_i``: the
    fused kernel's operations in its order, so its numbers, without writing R and U."""
    n = data.shape[0] - 1
    d = data.reshape(data.size)
    fl = filt.reshape(filt.size)
    base = (n + 1) * FILT_COLS
    w_dot_r = 0.0
    w_dot_u = 0.0
    for i in range(n):
        x = base + i // LANES * LANE_ROWS * LANES + i % LANES      # link i's lane
        so = i * LINK_COLS + CONST_COLS
        fo = i * FILT_COLS + W_ROW
        for k in range(13):
            r = d[so + THETA_HAT + k] - h * fl[x + LANES * (L_PG + k)]
            w_dot_r += fl[fo + k] * r
            w_dot_u += fl[fo + k] * fl[x + LANES * (L_U + k)]
    kc = h * gamma * w_dot_r / (1.0 + h * gamma * w_dot_u)
    for i in range(n):
        x = base + i // LANES * LANE_ROWS * LANES + i % LANES
        so = i * LINK_COLS + CONST_COLS
        for k in range(13):
            t = d[so + THETA_HAT + k]
            d[so + THETA_PREV + k] = t
            d[so + THETA_HAT + k] = (t - h * fl[x + LANES * (L_PG + k)]) \
                - kc * fl[x + LANES * (L_U + k)]


def lane_constants(const, c):
    """The lane buffers of :func:`barrier_lanes` for links with the constants ``const``
    (n, CONST_COLS) and ``c`` (doc/design.md §8), one per :data:`LANES` links, flat: the
    constant rows (``c k_i`` at :data:`L_CK`, ``(A P_i A^T)^-1``, ``F_i``, ``P_nu,i``)
    filled, the lanes past the last link repeating it, the others 0. The fused law keeps
    them past channel 0's rows of its second argument (:func:`natural_gain_rows`)."""
    n = const.shape[0]
    out = np.zeros(((n + LANES - 1) // LANES, LANE_ROWS, LANES))
    for g in range(out.shape[0]):
        for l in range(LANES):
            i = min(g * LANES + l, n - 1)
            out[g, L_CK, l] = c * const[i, NAT_K]
            out[g, L_Q:L_Q + 55, l] = const[i, BAR_Q:BAR_Q + 55]
            out[g, L_F:L_F + 30, l] = const[i, BAR_F:BAR_F + 30]
            out[g, L_P_NU:L_P_NU + 9, l] = const[i, NAT_P_NU:NAT_P_NU + 9]
    return out.reshape(-1)


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


#: the rows of the shortened retraction's lane buffer (:func:`short_lanes`): J_hat's 10
#: entries, ``J(theta_lin)``'s 10 and its nu (3), then the whole step's 13 parameters and
#: whether it passed (1 or 0)
R_J, R_E, R_NU, R_OUT, R_WHOLE = 0, 10, 20, 23, 36
RETRACT_ROWS = 37


@njit(cache=True, error_model="numpy")
def short_lanes(X):
    """The first try of :func:`~rcac_ros.core.retraction.retract_short` (the whole step, ``a
    = 1``) for :data:`LANES` links side by side in the lane buffer ``X`` (rows :data:`R_J`
    ..., row r of lane l at ``X[LANES r + l]``): its result and whether it passed (the
    step finite and ``J+ - FLOOR tr(J+) 1 - J_hat / 2`` positive definite), in the same
    operations, so the same numbers; a lane that did not pass is left to
    :func:`~rcac_ros.core.retraction.retract_short` itself (:func:`retract_lanes`). The
    compiler runs the lanes in one vector (numpy's error model: no division checks)."""
    for l in range(X.size // RETRACT_ROWS):
        j00, j11, j22, j33 = X[l], X[LANES + l], X[2 * LANES + l], X[3 * LANES + l]
        j01, j02, j12 = X[4 * LANES + l], X[5 * LANES + l], X[6 * LANES + l]
        j03, j13, j23 = X[7 * LANES + l], X[8 * LANES + l], X[9 * LANES + l]
        e = LANES * R_E + l
        d00, d11 = X[e] - j00, X[e + LANES] - j11
        d22, d33 = X[e + 2 * LANES] - j22, X[e + 3 * LANES] - j33
        d01, d02, d12 = X[e + 4 * LANES] - j01, X[e + 5 * LANES] - j02, X[e + 6 * LANES] - j12
        d03, d13, d23 = X[e + 7 * LANES] - j03, X[e + 8 * LANES] - j13, X[e + 9 * LANES] - j23
        n0, n1, n2 = X[LANES * R_NU + l], X[LANES * (R_NU + 1) + l], X[LANES * (R_NU + 2) + l]
        total = d00 + d11 + d22 + d33 + d01 + d02 + d12 + d03 + d13 + d23 + n0 + n1 + n2
        a = 1.0
        f = FLOOR * (j00 + j11 + j22 + j33 + a * (d00 + d11 + d22 + d33))
        whole = positive_definite4(0.5 * j00 + a * d00 - f, 0.5 * j11 + a * d11 - f,
                                   0.5 * j22 + a * d22 - f, 0.5 * j33 + a * d33 - f,
                                   0.5 * j01 + a * d01, 0.5 * j02 + a * d02,
                                   0.5 * j12 + a * d12, 0.5 * j03 + a * d03,
                                   0.5 * j13 + a * d13, 0.5 * j23 + a * d23)
        whole = whole & (total - total == 0.0)          # the step is finite
        j00, j11, j22, j33 = j00 + a * d00, j11 + a * d11, j22 + a * d22, j33 + a * d33
        j01, j02, j12 = j01 + a * d01, j02 + a * d02, j12 + a * d12
        j03, j13, j23 = j03 + a * d03, j13 + a * d13, j23 + a * d23
        bound = NU_RATIO * (j00 + j11 + j22 + j33)
        n0 = min(max(n0, -bound), bound)
        n1 = min(max(n1, -bound), bound)
        n2 = min(max(n2, -bound), bound)
        a0, a1, a2 = j00 - n0, j11 - n1, j22 - n2       # theta_from_entries, lane by lane
        o = LANES * R_OUT + l
        X[o], X[o + LANES], X[o + 2 * LANES], X[o + 3 * LANES] = j33, j03, j13, j23
        X[o + 4 * LANES], X[o + 5 * LANES], X[o + 6 * LANES] = n0, n1, n2
        X[o + 7 * LANES], X[o + 8 * LANES], X[o + 9 * LANES] = j01, j02, j12
        X[o + 10 * LANES], X[o + 11 * LANES], X[o + 12 * LANES] = a1 + a2, a0 + a2, a0 + a1
        X[LANES * R_WHOLE + l] = 1.0 if whole else 0.0


@njit(cache=True, inline="always")
def lane_entries(X, e, d, o):
    """J's 10 entries of the estimates at ``d[o:o + 13]`` into lane rows 0-9 from ``X[e]``
    (``X[e + k LANES]``, the order of :func:`~rcac_ros.core.pseudo_inertia.pseudo_entries`)."""
    j00, j11, j22, j33, j01, j02, j12, j03, j13, j23 = pseudo_entries(d, o)
    X[e], X[e + LANES], X[e + 2 * LANES], X[e + 3 * LANES] = j00, j11, j22, j33
    X[e + 4 * LANES], X[e + 5 * LANES], X[e + 6 * LANES] = j01, j02, j12
    X[e + 7 * LANES], X[e + 8 * LANES], X[e + 9 * LANES] = j03, j13, j23


@njit(cache=True)
def retract_lanes(data, X):
    """:func:`retract_links` in the fused law: with the metric ``"barrier"`` the whole
    steps of :data:`LANES` links at a time tried side by side (:func:`short_lanes`, ``X``
    its lane buffer, at least :data:`RETRACT_ROWS` x :data:`LANES`), a link whose whole
    step does not pass by :func:`~rcac_ros.core.retraction.retract_short` itself: the
    results of :func:`retract_links`, bit for bit."""
    n = data.shape[0] - 1
    d = data.reshape(data.size)
    if not d[n * LINK_COLS + I_BARRIER_C] > 0.0:
        retract_links(data)
        return
    a_min = 1.0
    for g0 in range(0, n, LANES):
        m = min(LANES, n - g0)
        for l in range(LANES):
            so = (g0 + min(l, m - 1)) * LINK_COLS + CONST_COLS
            lane_entries(X, l, d, so + THETA_PREV)
            lane_entries(X, LANES * R_E + l, d, so + THETA_HAT)
            for k in range(3):
                X[LANES * (R_NU + k) + l] = d[so + THETA_HAT + 4 + k]
        short_lanes(unmanaged_block(X, 0, (RETRACT_ROWS * LANES,)))
        for l in range(m):
            so = (g0 + l) * LINK_COLS + CONST_COLS
            if X[LANES * R_WHOLE + l] != 0.0:
                for k in range(13):
                    d[so + THETA_HAT + k] = X[LANES * (R_OUT + k) + l]
            else:
                a_min = min(a_min, retract_short(d, so + THETA_PREV, d, so + THETA_HAT))
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


@njit(cache=True, inline="always")
def ldl_factor(c, q, cs, ck, j00, j11, j22, j33, j01, j02, j12, j03, j13, j23):
    """The factor of :func:`barrier_factor` for one link: ``S = H_J / (c k) + (A P A^T)^-1 =
    L D L^T`` (L unit lower) from J's 10 entries (the order of
    :func:`~rcac_ros.core.pseudo_inertia.pseudo_entries`), ``ck = c k``, and ``(A P
    A^T)^-1``'s 55 entries (lower, by rows) at ``c[q + cs * k]`` (``cs``: 1 in a link's
    own row, :data:`LANES` in the lane buffer of :func:`barrier_lanes`). Returns L's
    entries and ``D^-1``'s by rows, ``(r0, l1_0, r1, l2_0, l2_1, r2, ...)``: ``l{a}_{b}`` is
    L's (a, b), ``r{a} = 1 / d_a``. Unrolled on scalars in the operations and order of its
    loops: ``u{a}_{b} = S_ab - sum_m u{a}_m l{b}_m`` is ``l{a}_{b} d_b``, ``d_a = S_aa -
    sum_m u{a}_m l{a}_m``; ``i{p}{q}``: ``J^-1``'s (p, q), p >= q (0 if J is not positive
    definite: ``H_J`` left out)."""
    ok, i00, i10, i20, i30, i11, i21, i31, i22, i32, i33 = inverse_ldl_entries(
        j00, j11, j22, j33, j01, j02, j12, j03, j13, j23)
    w = 2.0 / ck if ok else 0.0
    wh, wq = 0.5 * w, 0.25 * w          # w w_p w_q (exact: powers of 2)
    r0 = 1.0 / (c[q] + wq * (i33 * i33 + i33 * i33))
    u1_0 = c[q + cs * 1] + wh * (i30 * i33 + i30 * i33)
    l1_0 = u1_0 * r0
    r1 = 1.0 / (c[q + cs * 2] + w * (i30 * i30 + i00 * i33) - u1_0 * l1_0)
    u2_0 = c[q + cs * 3] + wh * (i31 * i33 + i31 * i33)
    l2_0 = u2_0 * r0
    u2_1 = c[q + cs * 4] + w * (i31 * i30 + i10 * i33) - u2_0 * l1_0
    l2_1 = u2_1 * r1
    r2 = 1.0 / (c[q + cs * 5] + w * (i31 * i31 + i11 * i33) - u2_0 * l2_0 - u2_1 * l2_1)
    u3_0 = c[q + cs * 6] + wh * (i32 * i33 + i32 * i33)
    l3_0 = u3_0 * r0
    u3_1 = c[q + cs * 7] + w * (i32 * i30 + i20 * i33) - u3_0 * l1_0
    l3_1 = u3_1 * r1
    u3_2 = c[q + cs * 8] + w * (i32 * i31 + i21 * i33) - u3_0 * l2_0 - u3_1 * l2_1
    l3_2 = u3_2 * r2
    r3 = 1.0 / (c[q + cs * 9] + w * (i32 * i32 + i22 * i33) - u3_0 * l3_0 - u3_1 * l3_1
                - u3_2 * l3_2)
    u4_0 = c[q + cs * 10] + wq * (i30 * i30 + i30 * i30)
    l4_0 = u4_0 * r0
    u4_1 = c[q + cs * 11] + wh * (i30 * i00 + i00 * i30) - u4_0 * l1_0
    l4_1 = u4_1 * r1
    u4_2 = c[q + cs * 12] + wh * (i30 * i10 + i10 * i30) - u4_0 * l2_0 - u4_1 * l2_1
    l4_2 = u4_2 * r2
    u4_3 = c[q + cs * 13] + wh * (i30 * i20 + i20 * i30) - u4_0 * l3_0 - u4_1 * l3_1 - u4_2 * l3_2
    l4_3 = u4_3 * r3
    r4 = 1.0 / (c[q + cs * 14] + wq * (i00 * i00 + i00 * i00) - u4_0 * l4_0 - u4_1 * l4_1
                - u4_2 * l4_2 - u4_3 * l4_3)
    u5_0 = c[q + cs * 15] + wq * (i31 * i31 + i31 * i31)
    l5_0 = u5_0 * r0
    u5_1 = c[q + cs * 16] + wh * (i31 * i10 + i10 * i31) - u5_0 * l1_0
    l5_1 = u5_1 * r1
    u5_2 = c[q + cs * 17] + wh * (i31 * i11 + i11 * i31) - u5_0 * l2_0 - u5_1 * l2_1
    l5_2 = u5_2 * r2
    u5_3 = c[q + cs * 18] + wh * (i31 * i21 + i21 * i31) - u5_0 * l3_0 - u5_1 * l3_1 - u5_2 * l3_2
    l5_3 = u5_3 * r3
    u5_4 = (c[q + cs * 19] + wq * (i10 * i10 + i10 * i10) - u5_0 * l4_0 - u5_1 * l4_1 - u5_2 * l4_2
            - u5_3 * l4_3)
    l5_4 = u5_4 * r4
    r5 = 1.0 / (c[q + cs * 20] + wq * (i11 * i11 + i11 * i11) - u5_0 * l5_0 - u5_1 * l5_1
                - u5_2 * l5_2 - u5_3 * l5_3 - u5_4 * l5_4)
    u6_0 = c[q + cs * 21] + wq * (i32 * i32 + i32 * i32)
    l6_0 = u6_0 * r0
    u6_1 = c[q + cs * 22] + wh * (i32 * i20 + i20 * i32) - u6_0 * l1_0
    l6_1 = u6_1 * r1
    u6_2 = c[q + cs * 23] + wh * (i32 * i21 + i21 * i32) - u6_0 * l2_0 - u6_1 * l2_1
    l6_2 = u6_2 * r2
    u6_3 = c[q + cs * 24] + wh * (i32 * i22 + i22 * i32) - u6_0 * l3_0 - u6_1 * l3_1 - u6_2 * l3_2
    l6_3 = u6_3 * r3
    u6_4 = (c[q + cs * 25] + wq * (i20 * i20 + i20 * i20) - u6_0 * l4_0 - u6_1 * l4_1 - u6_2 * l4_2
            - u6_3 * l4_3)
    l6_4 = u6_4 * r4
    u6_5 = (c[q + cs * 26] + wq * (i21 * i21 + i21 * i21) - u6_0 * l5_0 - u6_1 * l5_1 - u6_2 * l5_2
            - u6_3 * l5_3 - u6_4 * l5_4)
    l6_5 = u6_5 * r5
    r6 = 1.0 / (c[q + cs * 27] + wq * (i22 * i22 + i22 * i22) - u6_0 * l6_0 - u6_1 * l6_1
                - u6_2 * l6_2 - u6_3 * l6_3 - u6_4 * l6_4 - u6_5 * l6_5)
    u7_0 = c[q + cs * 28] + wh * (i30 * i31 + i30 * i31)
    l7_0 = u7_0 * r0
    u7_1 = c[q + cs * 29] + w * (i30 * i10 + i00 * i31) - u7_0 * l1_0
    l7_1 = u7_1 * r1
    u7_2 = c[q + cs * 30] + w * (i30 * i11 + i10 * i31) - u7_0 * l2_0 - u7_1 * l2_1
    l7_2 = u7_2 * r2
    u7_3 = c[q + cs * 31] + w * (i30 * i21 + i20 * i31) - u7_0 * l3_0 - u7_1 * l3_1 - u7_2 * l3_2
    l7_3 = u7_3 * r3
    u7_4 = (c[q + cs * 32] + wh * (i00 * i10 + i00 * i10) - u7_0 * l4_0 - u7_1 * l4_1 - u7_2 * l4_2
            - u7_3 * l4_3)
    l7_4 = u7_4 * r4
    u7_5 = (c[q + cs * 33] + wh * (i10 * i11 + i10 * i11) - u7_0 * l5_0 - u7_1 * l5_1 - u7_2 * l5_2
            - u7_3 * l5_3 - u7_4 * l5_4)
    l7_5 = u7_5 * r5
    u7_6 = (c[q + cs * 34] + wh * (i20 * i21 + i20 * i21) - u7_0 * l6_0 - u7_1 * l6_1 - u7_2 * l6_2
            - u7_3 * l6_3 - u7_4 * l6_4 - u7_5 * l6_5)
    l7_6 = u7_6 * r6
    r7 = 1.0 / (c[q + cs * 35] + w * (i10 * i10 + i00 * i11) - u7_0 * l7_0 - u7_1 * l7_1
                - u7_2 * l7_2 - u7_3 * l7_3 - u7_4 * l7_4 - u7_5 * l7_5 - u7_6 * l7_6)
    u8_0 = c[q + cs * 36] + wh * (i30 * i32 + i30 * i32)
    l8_0 = u8_0 * r0
    u8_1 = c[q + cs * 37] + w * (i30 * i20 + i00 * i32) - u8_0 * l1_0
    l8_1 = u8_1 * r1
    u8_2 = c[q + cs * 38] + w * (i30 * i21 + i10 * i32) - u8_0 * l2_0 - u8_1 * l2_1
    l8_2 = u8_2 * r2
    u8_3 = c[q + cs * 39] + w * (i30 * i22 + i20 * i32) - u8_0 * l3_0 - u8_1 * l3_1 - u8_2 * l3_2
    l8_3 = u8_3 * r3
    u8_4 = (c[q + cs * 40] + wh * (i00 * i20 + i00 * i20) - u8_0 * l4_0 - u8_1 * l4_1 - u8_2 * l4_2
            - u8_3 * l4_3)
    l8_4 = u8_4 * r4
    u8_5 = (c[q + cs * 41] + wh * (i10 * i21 + i10 * i21) - u8_0 * l5_0 - u8_1 * l5_1 - u8_2 * l5_2
            - u8_3 * l5_3 - u8_4 * l5_4)
    l8_5 = u8_5 * r5
    u8_6 = (c[q + cs * 42] + wh * (i20 * i22 + i20 * i22) - u8_0 * l6_0 - u8_1 * l6_1 - u8_2 * l6_2
            - u8_3 * l6_3 - u8_4 * l6_4 - u8_5 * l6_5)
    l8_6 = u8_6 * r6
    u8_7 = (c[q + cs * 43] + w * (i10 * i20 + i00 * i21) - u8_0 * l7_0 - u8_1 * l7_1 - u8_2 * l7_2
            - u8_3 * l7_3 - u8_4 * l7_4 - u8_5 * l7_5 - u8_6 * l7_6)
    l8_7 = u8_7 * r7
    r8 = 1.0 / (c[q + cs * 44] + w * (i20 * i20 + i00 * i22) - u8_0 * l8_0 - u8_1 * l8_1
                - u8_2 * l8_2 - u8_3 * l8_3 - u8_4 * l8_4 - u8_5 * l8_5 - u8_6 * l8_6
                - u8_7 * l8_7)
    u9_0 = c[q + cs * 45] + wh * (i31 * i32 + i31 * i32)
    l9_0 = u9_0 * r0
    u9_1 = c[q + cs * 46] + w * (i31 * i20 + i10 * i32) - u9_0 * l1_0
    l9_1 = u9_1 * r1
    u9_2 = c[q + cs * 47] + w * (i31 * i21 + i11 * i32) - u9_0 * l2_0 - u9_1 * l2_1
    l9_2 = u9_2 * r2
    u9_3 = c[q + cs * 48] + w * (i31 * i22 + i21 * i32) - u9_0 * l3_0 - u9_1 * l3_1 - u9_2 * l3_2
    l9_3 = u9_3 * r3
    u9_4 = (c[q + cs * 49] + wh * (i10 * i20 + i10 * i20) - u9_0 * l4_0 - u9_1 * l4_1 - u9_2 * l4_2
            - u9_3 * l4_3)
    l9_4 = u9_4 * r4
    u9_5 = (c[q + cs * 50] + wh * (i11 * i21 + i11 * i21) - u9_0 * l5_0 - u9_1 * l5_1 - u9_2 * l5_2
            - u9_3 * l5_3 - u9_4 * l5_4)
    l9_5 = u9_5 * r5
    u9_6 = (c[q + cs * 51] + wh * (i21 * i22 + i21 * i22) - u9_0 * l6_0 - u9_1 * l6_1 - u9_2 * l6_2
            - u9_3 * l6_3 - u9_4 * l6_4 - u9_5 * l6_5)
    l9_6 = u9_6 * r6
    u9_7 = (c[q + cs * 52] + w * (i11 * i20 + i10 * i21) - u9_0 * l7_0 - u9_1 * l7_1 - u9_2 * l7_2
            - u9_3 * l7_3 - u9_4 * l7_4 - u9_5 * l7_5 - u9_6 * l7_6)
    l9_7 = u9_7 * r7
    u9_8 = (c[q + cs * 53] + w * (i21 * i20 + i10 * i22) - u9_0 * l8_0 - u9_1 * l8_1 - u9_2 * l8_2
            - u9_3 * l8_3 - u9_4 * l8_4 - u9_5 * l8_5 - u9_6 * l8_6 - u9_7 * l8_7)
    l9_8 = u9_8 * r8
    r9 = 1.0 / (c[q + cs * 54] + w * (i21 * i21 + i11 * i22) - u9_0 * l9_0 - u9_1 * l9_1
                - u9_2 * l9_2 - u9_3 * l9_3 - u9_4 * l9_4 - u9_5 * l9_5 - u9_6 * l9_6 - u9_7 * l9_7
                - u9_8 * l9_8)
    return (
        r0, l1_0, r1, l2_0, l2_1, r2, l3_0, l3_1, l3_2, r3, l4_0, l4_1, l4_2, l4_3, r4, l5_0,
        l5_1, l5_2, l5_3, l5_4, r5, l6_0, l6_1, l6_2, l6_3, l6_4, l6_5, r6, l7_0, l7_1, l7_2,
        l7_3, l7_4, l7_5, l7_6, r7, l8_0, l8_1, l8_2, l8_3, l8_4, l8_5, l8_6, l8_7, r8, l9_0,
        l9_1, l9_2, l9_3, l9_4, l9_5, l9_6, l9_7, l9_8, r9)


@njit(cache=True)
def barrier_factor(c, co, s, so, ck):
    """The barrier metric's gain of link i (doc/design.md §8), factored: with ``theta =
    T (j, nu)`` (j: J's entries at :data:`~rcac_ros.core.pseudo_inertia.J_SLOTS`), ``P_mix
    = (H / (c k) + P^-1)^-1 = T M^-1 T^T`` and ``M = [[H_J / (c k) + X, C], [C^T, E]]``,
    ``H_J`` the Hessian of ``-log det J`` in j; eliminating nu leaves the 10x10

        S = H_J / (c k) + (A P A^T)^-1     (``BAR_Q``, constant: X - C E^-1 C^T)

    whose factor ``S = L D L^T`` (L unit lower, :func:`ldl_factor`) goes to ``s[so +
    NAT_LS_CHOL:]`` (10x10, row-major: L below the diagonal, ``D^-1`` on it). ``H_J``'s
    entries are ``tr(J^-1 E_p J^-1 E_q) = 2 w_p w_q (Ji_il Ji_jk + Ji_ik Ji_jl)`` between
    the unit symmetric 4x4s ``E_p`` (entries (i, j) and (j, i); ``w = 1/2`` on the
    diagonal). ``S >= (A P A^T)^-1 > 0``: every pivot is > 0. If ``theta_hat_i`` is not a
    body (never: it is one after every step) ``H_J`` is left out and the gain is ``P``.

    Link i's constants are ``c[co:co + CONST_COLS]``, its state ``s[so:so + STATE_COLS]``
    (a flat view of the packed array, or a row and 0); ``ck``: ``c k_i``. O(1), fourteen
    divisions and no square root: ``J^-1`` from J's own ``L D L^T``
    (:func:`~rcac_ros.core.pseudo_inertia.inverse_ldl_entries`), 55 entries and one 10x10
    ``L D L^T``. Not inlined (compile time)."""
    j00, j11, j22, j33, j01, j02, j12, j03, j13, j23 = pseudo_entries(s, so + THETA_HAT)
    fac = ldl_factor(c, co + BAR_Q, 1, ck, j00, j11, j22, j33, j01, j02, j12, j03, j13, j23)
    o = so + NAT_LS_CHOL
    (
        r0, l1_0, r1, l2_0, l2_1, r2, l3_0, l3_1, l3_2, r3, l4_0, l4_1, l4_2, l4_3, r4, l5_0,
        l5_1, l5_2, l5_3, l5_4, r5, l6_0, l6_1, l6_2, l6_3, l6_4, l6_5, r6, l7_0, l7_1, l7_2,
        l7_3, l7_4, l7_5, l7_6, r7, l8_0, l8_1, l8_2, l8_3, l8_4, l8_5, l8_6, l8_7, r8, l9_0,
        l9_1, l9_2, l9_3, l9_4, l9_5, l9_6, l9_7, l9_8, r9) = fac
    s[o] = r0
    s[o + 10] = l1_0
    s[o + 11] = r1
    s[o + 20] = l2_0
    s[o + 21] = l2_1
    s[o + 22] = r2
    s[o + 30] = l3_0
    s[o + 31] = l3_1
    s[o + 32] = l3_2
    s[o + 33] = r3
    s[o + 40] = l4_0
    s[o + 41] = l4_1
    s[o + 42] = l4_2
    s[o + 43] = l4_3
    s[o + 44] = r4
    s[o + 50] = l5_0
    s[o + 51] = l5_1
    s[o + 52] = l5_2
    s[o + 53] = l5_3
    s[o + 54] = l5_4
    s[o + 55] = r5
    s[o + 60] = l6_0
    s[o + 61] = l6_1
    s[o + 62] = l6_2
    s[o + 63] = l6_3
    s[o + 64] = l6_4
    s[o + 65] = l6_5
    s[o + 66] = r6
    s[o + 70] = l7_0
    s[o + 71] = l7_1
    s[o + 72] = l7_2
    s[o + 73] = l7_3
    s[o + 74] = l7_4
    s[o + 75] = l7_5
    s[o + 76] = l7_6
    s[o + 77] = r7
    s[o + 80] = l8_0
    s[o + 81] = l8_1
    s[o + 82] = l8_2
    s[o + 83] = l8_3
    s[o + 84] = l8_4
    s[o + 85] = l8_5
    s[o + 86] = l8_6
    s[o + 87] = l8_7
    s[o + 88] = r8
    s[o + 90] = l9_0
    s[o + 91] = l9_1
    s[o + 92] = l9_2
    s[o + 93] = l9_3
    s[o + 94] = l9_4
    s[o + 95] = l9_5
    s[o + 96] = l9_6
    s[o + 97] = l9_7
    s[o + 98] = l9_8
    s[o + 99] = r9


@njit(cache=True, inline="always")
def ldl_solve(fac, c, f, p, cs, x, xo, xs):
    """``P_mix x`` for one link (13 entries, returned), x's at ``x[xo + xs * k]``, with the
    factor ``fac`` of :func:`ldl_factor`, ``F`` (10 x 3) at ``c[f + cs * k]`` and ``P_nu``
    (3 x 3) at ``c[p + cs * k]``: ``b = T^T x``, then the block solve ``z_j = S^-1 (b_j - F
    b_nu)``, ``z_nu = P_nu b_nu - F^T z_j``, then ``T z``: ``theta_k = j_k`` but for
    ``theta_4..6 = nu`` and ``theta_10 = j_5 + j_6 - nu_1 - nu_2`` (cyclically). Unrolled
    on scalars in the operations and order of the loops of a forward and a backward
    substitution (``t{a}``: z_j's entry a)."""
    (
        r0, l1_0, r1, l2_0, l2_1, r2, l3_0, l3_1, l3_2, r3, l4_0, l4_1, l4_2, l4_3, r4, l5_0,
        l5_1, l5_2, l5_3, l5_4, r5, l6_0, l6_1, l6_2, l6_3, l6_4, l6_5, r6, l7_0, l7_1, l7_2,
        l7_3, l7_4, l7_5, l7_6, r7, l8_0, l8_1, l8_2, l8_3, l8_4, l8_5, l8_6, l8_7, r8, l9_0,
        l9_1, l9_2, l9_3, l9_4, l9_5, l9_6, l9_7, l9_8, r9) = fac
    x10, x11, x12 = x[xo + xs * 10], x[xo + xs * 11], x[xo + xs * 12]
    n0 = x[xo + xs * 4] - x11 - x12
    n1 = x[xo + xs * 5] - x10 - x12
    n2 = x[xo + xs * 6] - x10 - x11
    # b_j - F b_nu
    t0 = x[xo] - (c[f] * n0 + c[f + cs * 1] * n1 + c[f + cs * 2] * n2)
    t1 = x[xo + xs * 1] - (c[f + cs * 3] * n0 + c[f + cs * 4] * n1 + c[f + cs * 5] * n2)
    t2 = x[xo + xs * 2] - (c[f + cs * 6] * n0 + c[f + cs * 7] * n1 + c[f + cs * 8] * n2)
    t3 = x[xo + xs * 3] - (c[f + cs * 9] * n0 + c[f + cs * 10] * n1 + c[f + cs * 11] * n2)
    t4 = (x11 + x12) - (c[f + cs * 12] * n0 + c[f + cs * 13] * n1 + c[f + cs * 14] * n2)
    t5 = (x10 + x12) - (c[f + cs * 15] * n0 + c[f + cs * 16] * n1 + c[f + cs * 17] * n2)
    t6 = (x10 + x11) - (c[f + cs * 18] * n0 + c[f + cs * 19] * n1 + c[f + cs * 20] * n2)
    t7 = x[xo + xs * 7] - (c[f + cs * 21] * n0 + c[f + cs * 22] * n1 + c[f + cs * 23] * n2)
    t8 = x[xo + xs * 8] - (c[f + cs * 24] * n0 + c[f + cs * 25] * n1 + c[f + cs * 26] * n2)
    t9 = x[xo + xs * 9] - (c[f + cs * 27] * n0 + c[f + cs * 28] * n1 + c[f + cs * 29] * n2)
    # S^-1 = L^-T D^-1 L^-1: forward substitution, D^-1, backward substitution
    t1 = t1 - l1_0 * t0
    t2 = t2 - l2_0 * t0 - l2_1 * t1
    t3 = t3 - l3_0 * t0 - l3_1 * t1 - l3_2 * t2
    t4 = t4 - l4_0 * t0 - l4_1 * t1 - l4_2 * t2 - l4_3 * t3
    t5 = t5 - l5_0 * t0 - l5_1 * t1 - l5_2 * t2 - l5_3 * t3 - l5_4 * t4
    t6 = t6 - l6_0 * t0 - l6_1 * t1 - l6_2 * t2 - l6_3 * t3 - l6_4 * t4 - l6_5 * t5
    t7 = t7 - l7_0 * t0 - l7_1 * t1 - l7_2 * t2 - l7_3 * t3 - l7_4 * t4 - l7_5 * t5 - l7_6 * t6
    t8 = (t8 - l8_0 * t0 - l8_1 * t1 - l8_2 * t2 - l8_3 * t3 - l8_4 * t4 - l8_5 * t5 - l8_6 * t6
          - l8_7 * t7)
    t9 = (t9 - l9_0 * t0 - l9_1 * t1 - l9_2 * t2 - l9_3 * t3 - l9_4 * t4 - l9_5 * t5 - l9_6 * t6
          - l9_7 * t7 - l9_8 * t8)
    t0 = t0 * r0
    t1 = t1 * r1
    t2 = t2 * r2
    t3 = t3 * r3
    t4 = t4 * r4
    t5 = t5 * r5
    t6 = t6 * r6
    t7 = t7 * r7
    t8 = t8 * r8
    t9 = t9 * r9
    m0 = c[p] * n0 + c[p + cs * 1] * n1 + c[p + cs * 2] * n2  # z_nu = P_nu b_nu - F^T z_j
    m1 = c[p + cs * 3] * n0 + c[p + cs * 4] * n1 + c[p + cs * 5] * n2
    m2 = c[p + cs * 6] * n0 + c[p + cs * 7] * n1 + c[p + cs * 8] * n2
    t8 = t8 - l9_8 * t9
    t7 = t7 - l8_7 * t8 - l9_7 * t9
    t6 = t6 - l7_6 * t7 - l8_6 * t8 - l9_6 * t9
    t5 = t5 - l6_5 * t6 - l7_5 * t7 - l8_5 * t8 - l9_5 * t9
    t4 = t4 - l5_4 * t5 - l6_4 * t6 - l7_4 * t7 - l8_4 * t8 - l9_4 * t9
    t3 = t3 - l4_3 * t4 - l5_3 * t5 - l6_3 * t6 - l7_3 * t7 - l8_3 * t8 - l9_3 * t9
    t2 = t2 - l3_2 * t3 - l4_2 * t4 - l5_2 * t5 - l6_2 * t6 - l7_2 * t7 - l8_2 * t8 - l9_2 * t9
    t1 = (t1 - l2_1 * t2 - l3_1 * t3 - l4_1 * t4 - l5_1 * t5 - l6_1 * t6 - l7_1 * t7 - l8_1 * t8
          - l9_1 * t9)
    t0 = (t0 - l1_0 * t1 - l2_0 * t2 - l3_0 * t3 - l4_0 * t4 - l5_0 * t5 - l6_0 * t6 - l7_0 * t7
          - l8_0 * t8 - l9_0 * t9)
    m0 = (m0 - c[f] * t0 - c[f + cs * 3] * t1 - c[f + cs * 6] * t2 - c[f + cs * 9] * t3
          - c[f + cs * 12] * t4 - c[f + cs * 15] * t5 - c[f + cs * 18] * t6 - c[f + cs * 21] * t7
          - c[f + cs * 24] * t8 - c[f + cs * 27] * t9)
    m1 = (m1 - c[f + cs * 1] * t0 - c[f + cs * 4] * t1 - c[f + cs * 7] * t2 - c[f + cs * 10] * t3
          - c[f + cs * 13] * t4 - c[f + cs * 16] * t5 - c[f + cs * 19] * t6 - c[f + cs * 22] * t7
          - c[f + cs * 25] * t8 - c[f + cs * 28] * t9)
    m2 = (m2 - c[f + cs * 2] * t0 - c[f + cs * 5] * t1 - c[f + cs * 8] * t2 - c[f + cs * 11] * t3
          - c[f + cs * 14] * t4 - c[f + cs * 17] * t5 - c[f + cs * 20] * t6 - c[f + cs * 23] * t7
          - c[f + cs * 26] * t8 - c[f + cs * 29] * t9)
    return (t0, t1, t2, t3, m0, m1, m2, t7, t8, t9, t5 + t6 - m1 - m2, t4 + t6 - m0 - m2,
            t4 + t5 - m0 - m1)


@njit(cache=True, inline="always")
def barrier_apply(c, co, s, so, x, xo, out, oo):
    """``out[oo:oo+13] = P_mix x[xo:xo+13]`` with the factor of :func:`barrier_factor`
    (:func:`ldl_solve`; link i's constants at ``c[co:]``: ``F = BAR_F``, ``P_nu = E^-1 =
    NAT_P_NU``, its state at ``s[so:]``; x is read whole before out is written)."""
    o = so + NAT_LS_CHOL
    fac = (
        s[o], s[o + 10], s[o + 11], s[o + 20], s[o + 21], s[o + 22], s[o + 30], s[o + 31],
        s[o + 32], s[o + 33], s[o + 40], s[o + 41], s[o + 42], s[o + 43], s[o + 44], s[o + 50],
        s[o + 51], s[o + 52], s[o + 53], s[o + 54], s[o + 55], s[o + 60], s[o + 61], s[o + 62],
        s[o + 63], s[o + 64], s[o + 65], s[o + 66], s[o + 70], s[o + 71], s[o + 72], s[o + 73],
        s[o + 74], s[o + 75], s[o + 76], s[o + 77], s[o + 80], s[o + 81], s[o + 82], s[o + 83],
        s[o + 84], s[o + 85], s[o + 86], s[o + 87], s[o + 88], s[o + 90], s[o + 91], s[o + 92],
        s[o + 93], s[o + 94], s[o + 95], s[o + 96], s[o + 97], s[o + 98], s[o + 99])
    (out[oo], out[oo + 1], out[oo + 2], out[oo + 3], out[oo + 4], out[oo + 5], out[oo + 6],
     out[oo + 7], out[oo + 8], out[oo + 9], out[oo + 10], out[oo + 11], out[oo + 12]) = \
        ldl_solve(fac, c, co + BAR_F, co + NAT_P_NU, 1, x, xo, 1)


#: links side by side in :func:`barrier_lanes` (row r of lane l at ``X[LANES r + l]``)
LANES = 8
#: the rows of the lane buffer: J's 10 entries, ``c k``, ``(A P A^T)^-1`` (55), ``F`` (30),
#: ``P_nu`` (9), ``G_i`` and ``W_i`` (13 each), ``P_mix G_i`` and ``P_mix W_i`` (13 each)
L_J, L_CK, L_Q, L_F, L_P_NU, L_G, L_W, L_PG, L_U = 0, 10, 11, 66, 96, 105, 118, 131, 144
LANE_ROWS = 157


@njit(cache=True, error_model="numpy")
def barrier_lanes(X):
    """:func:`barrier_factor` and :func:`barrier_apply` on ``G_i`` and ``W_i`` for
    :data:`LANES` links side by side in the lane buffer ``X`` (rows of :data:`L_J` ...,
    :data:`LANE_ROWS` x :data:`LANES`, row r of lane l at ``X[LANES r + l]``), into the
    rows :data:`L_PG` and :data:`L_U`: the same operations (:func:`ldl_factor`,
    :func:`ldl_solve`), so the same results, bit for bit; the compiler runs the lanes in
    one vector (numpy's error model: no division checks, the pivots are > 0). Factored
    twice, once per right-hand side: the compiler vectorises a loop with 13 stores, not one
    with 26 (nor the factor's 55)."""
    for l in range(X.size // LANE_ROWS):
        fac = ldl_factor(X, LANES * L_Q + l, LANES, X[LANES * L_CK + l], X[l], X[LANES + l],
                         X[2 * LANES + l], X[3 * LANES + l], X[4 * LANES + l],
                         X[5 * LANES + l], X[6 * LANES + l], X[7 * LANES + l],
                         X[8 * LANES + l], X[9 * LANES + l])
        zg = ldl_solve(fac, X, LANES * L_F + l, LANES * L_P_NU + l, LANES, X, LANES * L_G + l,
                       LANES)
        (
            X[LANES * (L_PG + 0) + l], X[LANES * (L_PG + 1) + l], X[LANES * (L_PG + 2) + l],
            X[LANES * (L_PG + 3) + l], X[LANES * (L_PG + 4) + l], X[LANES * (L_PG + 5) + l],
            X[LANES * (L_PG + 6) + l], X[LANES * (L_PG + 7) + l], X[LANES * (L_PG + 8) + l],
            X[LANES * (L_PG + 9) + l], X[LANES * (L_PG + 10) + l], X[LANES * (L_PG + 11) + l],
            X[LANES * (L_PG + 12) + l]) = zg
    for l in range(X.size // LANE_ROWS):
        fac = ldl_factor(X, LANES * L_Q + l, LANES, X[LANES * L_CK + l], X[l], X[LANES + l],
                         X[2 * LANES + l], X[3 * LANES + l], X[4 * LANES + l],
                         X[5 * LANES + l], X[6 * LANES + l], X[7 * LANES + l],
                         X[8 * LANES + l], X[9 * LANES + l])
        zw = ldl_solve(fac, X, LANES * L_F + l, LANES * L_P_NU + l, LANES, X, LANES * L_W + l,
                       LANES)
        (
            X[LANES * (L_U + 0) + l], X[LANES * (L_U + 1) + l], X[LANES * (L_U + 2) + l],
            X[LANES * (L_U + 3) + l], X[LANES * (L_U + 4) + l], X[LANES * (L_U + 5) + l],
            X[LANES * (L_U + 6) + l], X[LANES * (L_U + 7) + l], X[LANES * (L_U + 8) + l],
            X[LANES * (L_U + 9) + l], X[LANES * (L_U + 10) + l], X[LANES * (L_U + 11) + l],
            X[LANES * (L_U + 12) + l]) = zw


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
