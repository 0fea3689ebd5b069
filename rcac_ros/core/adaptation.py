"""The adaptation step of the recursive composite law: eq 24 over one control period.

    theta_hat_dot_i = -P_i (Y_ri^T s_i + gamma sum_c W_ci^T E_c)                     (eq 24)
                      - P_i sigma_i (theta_hat_i - theta_0i)          (leakage, optional)

Discretisation (the paper leaves it open): ``theta_hat`` takes one step of ``h`` after
the torque is computed, explicit Euler in the tracking term ``Y_ri^T s_i``, and in the
prediction-error term either

- ``update="implicit"`` (default): backward Euler, ``(I + h gamma P W^T W) theta+ = r``,
  solved by Woodbury with an m x m Cholesky factorisation, O(m^2 n + m^3); for m = 1
  Sherman-Morrison, O(n) (:func:`implicit_solve`). It is stable for any gain and tends to
  eq 24 as ``h -> 0``; with the paper's ``P_i = 100 I`` and ``gamma = 0.1`` the explicit
  step is unstable at 2 ms (``h gamma W P W^T`` is far above 2).
- ``update="explicit"``: forward Euler, O(m n).

Step 1 (:func:`adapt_link`, during the backward pass) forms, link by link,
``R_i = theta_hat_i - h P_i (gradient)`` and ``U_ci = P_i W_ci^T``; step 2
(:func:`implicit_solve`) solves for ``theta_hat+``; then the least-squares gain is updated
(:func:`update_least_squares`) and ``theta_hat`` projected (:func:`project`).

Options beyond the paper: a least-squares gain with bounded-gain forgetting
(:mod:`rcac_ros.core.least_squares`), a dead zone on ``s`` (:func:`tracking_active`) and
on each ``E_c`` (:func:`rcac_ros.core.channels.close_channels`), the projection of
``theta_hat`` onto bounds (mass >= 0, an optional box), and leakage toward nominal
estimates ``theta_0`` (:func:`leakage_gradient`). With the defaults the law is the
paper's, to the last bit. ``gamma = 0`` is the direct adaptive controller.

Leakage (Ioannou & Kokotovic 1983; Ioannou & Sun, "Robust Adaptive Control", 1996, ch. 8):
with ``sigma_i = sigma_0`` (``leakage_bound = 0``) it is the fixed sigma-modification,
which bounds ``theta_hat`` for any bounded disturbance but biases the ideal law; the
switching sigma-modification (``leakage_bound = M_0 > 0``) leaks only outside the ball
``||theta_hat_i - theta_0i|| <= M_0``, per link:

    sigma_i = 0                                    if ||theta_hat_i - theta_0i|| <= M_0
            = sigma_0 (||theta_hat_i - theta_0i|| / M_0 - 1)   if M_0 < ... <= 2 M_0
            = sigma_0                              beyond 2 M_0

so the law is the ideal one while the estimates stay inside (pick ``M_0 >=
||theta_i - theta_0i||``, a bound the user declares). The leakage is an explicit Euler term:
with no other input ``theta_hat_i - theta_0i`` is multiplied by ``I - h sigma_i P_i`` each
step, which needs ``h sigma_0 lambda_max(P_i) < 1`` (checked).
"""

import numpy as np

from ._jit import njit

from ._packing import (ADAPT_GRADIENT, ADAPT_LS, ADAPT_LS_PREDICTION, CH_ACTIVE, CH_E, CH_JOINT,
                       CH_Y, GAIN_P, I_ADAPT, I_BARRIER_C, I_DZ_S, I_FORGET, I_GAMMA, I_H,
                       I_IMPLICIT, I_LEAK, I_NATURAL, I_P_DIAG, LAMBDA, LEAK_M0, NAT_K, P_FACTOR,
                       THETA_0, THETA_HAT, THETA_MAX, THETA_MIN, THETA_PREV, TRACE_MAX, U_ROW,
                       W_ROW)
from ._blocks import cholesky_solve
from .channels import channel_start
from .least_squares import apply_factored, bounded_gain_forgetting, potter_update
from .natural_step import BARRIER, LOG_DET, NATURAL_LS, natural_gain_row, natural_gain_step


@njit(cache=True, inline="always")
def tracking_active(const, scal, q, qd, q_d, qd_d):
    """The dead zone on s: the tracking term adapts only if ``max |qd - qd_r| > dz``."""
    dz = scal[I_DZ_S]
    if dz <= 0.0:
        return True
    worst = 0.0
    for i in range(q.shape[0]):
        worst = max(worst, abs(qd[i] - (qd_d[i] - const[i, LAMBDA] * (q[i] - q_d[i]))))
    return worst > dz


@njit(cache=True, inline="always")
def prediction_gradient(chan, filt, i, grad, gamma, implicit):
    """Add the prediction term to ``grad``: ``- gamma W_ci^T y_c`` (implicit: the rest is
    solved) or ``+ gamma W_ci^T E_c`` (explicit), over the active channels."""
    for c in range(chan.shape[0]):
        if chan[c, CH_ACTIVE] == 0.0 or i < channel_start(chan[c, CH_JOINT]):
            continue
        if implicit:
            y = chan[c, CH_Y]
            for k in range(13):
                grad[k] -= gamma * filt[c, i, W_ROW + k] * y
        else:
            e = chan[c, CH_E]
            for k in range(13):
                grad[k] += gamma * filt[c, i, W_ROW + k] * e


@njit(cache=True, inline="always")
def leakage_gradient(const, state, i, scal, grad):
    """Add the leakage to ``grad``: ``+ sigma_i (theta_hat_i - theta_0i)`` (module docstring).

    ``sigma_i = sigma_0`` (fixed), or the switching ``sigma_i`` of Ioannou & Sun ch. 8 when
    link i's ``M_0 = const[i, LEAK_M0] > 0``: zero inside ``||theta_hat_i - theta_0i|| <=
    M_0``.
    """
    sigma = scal[I_LEAK]
    m0 = const[i, LEAK_M0]
    if m0 > 0.0:
        d2 = 0.0
        for k in range(13):
            d = state[i, THETA_HAT + k] - const[i, THETA_0 + k]
            d2 += d * d
        dist = np.sqrt(d2)
        if dist <= m0:
            return
        sigma *= min(dist / m0 - 1.0, 1.0)
    for k in range(13):
        grad[k] += sigma * (state[i, THETA_HAT + k] - const[i, THETA_0 + k])


@njit(cache=True, inline="always")
def gain_step(const, p_diag, state, grad, h, R, i):
    """``R_i = theta_hat_i - h P_i grad`` with the fixed gain ``P_i`` (eq 24, explicit part).

    ``const``, ``state``: the links' packed constants and state (link i in row i).
    """
    if p_diag:
        for a in range(13):
            R[i, a] = state[i, THETA_HAT + a] - h * const[i, GAIN_P + 14 * a] * grad[a]
    else:
        for a in range(13):
            acc = 0.0
            for c in range(13):
                acc += const[i, GAIN_P + 13 * a + c] * grad[c]
            R[i, a] = state[i, THETA_HAT + a] - h * acc


@njit(cache=True, inline="always")
def adapt_link(const, state, chan, filt, i, G, scal, tracking, R, grad, Pg, t, M4):
    """Eq 24, step 1, link i: ``R_i = theta_hat_i - h P_i (Y_ri^T s_i + leakage + prediction
    part)``, and ``U_ci = P_i W_ci^T`` for the implicit solve (P: fixed or least squares).
    With ``least_squares_prediction`` the leakage takes the tracking term's fixed ``P_i``.

    Natural geometry (doc/design.md §8): the fixed ``P_i`` becomes ``P_eff(theta_hat_i)``
    (``M4``: four 4x4 scratch matrices), and ``theta_hat_i`` is kept for the retraction;
    with least squares the gain is ``(H(theta_hat_i) / k_i + Gamma_i)^-1``
    (:func:`~rcac_ros.core.natural_step.natural_ls_factor`); with the metric ``"barrier"``
    (``scal[I_BARRIER_C] = c > 0``) it is ``P_mix = (H(theta_hat_i) / (c k_i) + P_i^-1)^-1``,
    factored on J's 10 entries with nu eliminated
    (:func:`~rcac_ros.core.natural_step.barrier_factor`).

    ``const``, ``state``: the links' packed constants and state, indexed at link i (views of
    row i only where a helper needs them, off the default law's path).
    """
    h, gamma = scal[I_H], scal[I_GAMMA]
    implicit = scal[I_IMPLICIT] != 0.0
    mode = scal[I_ADAPT]
    p_diag = scal[I_P_DIAG] != 0.0
    natural = scal[I_NATURAL] != 0.0
    metric = NATURAL_LS if mode == ADAPT_LS else BARRIER if scal[I_BARRIER_C] > 0.0 \
        else LOG_DET
    for k in range(13):
        grad[k] = G[i, k] if tracking else 0.0
    if natural:
        for k in range(13):
            state[i, THETA_PREV + k] = state[i, THETA_HAT + k]
    if scal[I_LEAK] > 0.0:
        leakage_gradient(const, state, i, scal, grad)
    if mode != ADAPT_LS_PREDICTION:
        prediction_gradient(chan, filt, i, grad, gamma, implicit)
    if natural:     # (H / k_i + Gamma_i)^-1, (H / (c k_i) + P_i^-1)^-1 or k_i H^-1, P_nu
        row, st = const[i], state[i]
        k_metric = row[NAT_K] if mode == ADAPT_LS else scal[I_BARRIER_C] * row[NAT_K]
        natural_gain_step(row, st, metric, k_metric, grad, h, R, i, Pg, t, M4)
    elif mode == ADAPT_GRADIENT:
        gain_step(const, p_diag, state, grad, h, R, i)
    elif mode == ADAPT_LS:
        apply_factored(state[i], P_FACTOR, grad, Pg, t)
        for k in range(13):
            R[i, k] = state[i, THETA_HAT + k] - h * Pg[k]
    else:                               # fixed P on the tracking term, least squares on E
        gain_step(const, p_diag, state, grad, h, R, i)
        for k in range(13):
            grad[k] = 0.0
        prediction_gradient(chan, filt, i, grad, gamma, implicit)
        apply_factored(state[i], P_FACTOR, grad, Pg, t)
        for k in range(13):
            R[i, k] -= h * Pg[k]
    if not implicit:
        return
    for c in range(chan.shape[0]):
        if chan[c, CH_ACTIVE] == 0.0 or i < channel_start(chan[c, CH_JOINT]):
            continue
        if natural:                             # U_ci = P_eff(theta_hat_i) W_ci^T
            natural_gain_row(const[i], state[i], metric, filt[c, i], t)
        elif mode == ADAPT_GRADIENT:            # U_ci = P_i W_ci^T, fixed P_i
            if p_diag:
                for a in range(13):
                    filt[c, i, U_ROW + a] = const[i, GAIN_P + 14 * a] * filt[c, i, W_ROW + a]
            else:
                for a in range(13):
                    acc = 0.0
                    for k in range(13):
                        acc += const[i, GAIN_P + 13 * a + k] * filt[c, i, W_ROW + k]
                    filt[c, i, U_ROW + a] = acc
        else:
            for k in range(13):
                grad[k] = filt[c, i, W_ROW + k]
            apply_factored(state[i], P_FACTOR, grad, Pg, t)
            for k in range(13):
                filt[c, i, U_ROW + k] = Pg[k]


@njit(cache=True, inline="always")
def sorted_active(chan, order, start):
    """The active channels in ``order[:na]``, sorted by their first link (``start[:na]``).

    Insertion sort, stable: O(m) for channels already in order (``"all"``). At link i the
    channels that reach it are then a prefix of ``order``. Returns ``na``.
    """
    na = 0
    for c in range(chan.shape[0]):
        if chan[c, CH_ACTIVE] == 0.0:
            continue
        s = channel_start(chan[c, CH_JOINT])
        j = na
        while j > 0 and start[j - 1] > s:
            order[j] = order[j - 1]
            start[j] = start[j - 1]
            j -= 1
        order[j] = c
        start[j] = s
        na += 1
    return na


@njit(cache=True, inline="always")
def reaching(start, na, i, L):
    """How many sorted channels reach link i: they are a prefix of :func:`sorted_active`'s
    order; ``L``, the count at link i-1, only grows (``start[:na]``: their first links)."""
    while L < na and start[L] <= i:
        L += 1
    return L


@njit(cache=True, inline="always")
def implicit_solve(chan, filt, state, R, A, z, order, start, Wt, Ut, scal):
    """Eq 24, step 2: ``(I + h gamma U W) theta+ = R`` by Woodbury over the active channels.

    ``theta+ = R - h gamma U (I + h gamma W U)^-1 W R``; for one channel Sherman-Morrison.
    ``A`` (m * m), ``z``, ``order``, ``start`` (m) and ``Wt``, ``Ut`` (13, m) are scratch.
    """
    n, m = R.shape[0], chan.shape[0]
    hg = scal[I_H] * scal[I_GAMMA]
    na = 0
    c = 0
    for a in range(m):
        if chan[a, CH_ACTIVE] != 0.0:
            na += 1
            c = a
    if na == 1:
        c0 = channel_start(chan[c, CH_JOINT])
        w_dot_r = 0.0
        w_dot_u = 0.0
        for i in range(c0, n):
            for k in range(13):
                w_dot_r += filt[c, i, W_ROW + k] * R[i, k]
                w_dot_u += filt[c, i, W_ROW + k] * filt[c, i, U_ROW + k]
        kc = scal[I_H] * scal[I_GAMMA] * w_dot_r / (1.0 + scal[I_H] * scal[I_GAMMA] * w_dot_u)
        for i in range(n):
            for k in range(13):
                state[i, THETA_HAT + k] = (R[i, k] if i < c0
                                           else R[i, k] - kc * filt[c, i, U_ROW + k])
        return
    for i in range(n):
        for k in range(13):
            state[i, THETA_HAT + k] = R[i, k]
    if na == 0:
        return
    na = sorted_active(chan, order, start)
    # A = sum_i W_i U_i^T and z = sum_i W_i R_i, link by link, in the sorted order of the
    # channels: the L channels that reach link i are the first L. Their rows W_i, U_i are
    # gathered as columns of Wt, Ut (13 x L), so that the rank-13 update of A's lower
    # triangle (A is symmetric; the Cholesky factorisation reads no more) runs its
    # innermost loop over contiguous channels (SIMD).
    Aa = A[:na * na].reshape((na, na))
    for a in range(na):
        z[a] = 0.0
        for b in range(a + 1):
            Aa[a, b] = 0.0
    L = 0
    for i in range(n):
        L = reaching(start, na, i, L)
        for j in range(L):
            c = int(order[j])
            for k in range(13):
                Wt[k, j] = filt[c, i, W_ROW + k]
                Ut[k, j] = filt[c, i, U_ROW + k]
        for k in range(13):
            r = R[i, k]
            for j in range(L):
                z[j] += Wt[k, j] * r
        for a in range(L):
            w0, w1, w2, w3, w4, w5, w6 = Wt[0, a], Wt[1, a], Wt[2, a], Wt[3, a], Wt[4, a], \
                Wt[5, a], Wt[6, a]
            w7, w8, w9, w10, w11, w12 = Wt[7, a], Wt[8, a], Wt[9, a], Wt[10, a], Wt[11, a], \
                Wt[12, a]
            for b in range(a + 1):
                Aa[a, b] += (w0 * Ut[0, b] + w1 * Ut[1, b] + w2 * Ut[2, b] + w3 * Ut[3, b]
                             + w4 * Ut[4, b] + w5 * Ut[5, b] + w6 * Ut[6, b] + w7 * Ut[7, b]
                             + w8 * Ut[8, b] + w9 * Ut[9, b] + w10 * Ut[10, b]
                             + w11 * Ut[11, b] + w12 * Ut[12, b])
    for a in range(na):
        for b in range(a + 1):
            Aa[a, b] *= hg
        Aa[a, a] += 1.0
    zz = z[:na]
    cholesky_solve(Aa, zz)
    # theta+_i = R_i - h gamma sum_c z_c U_ci
    L = 0
    for i in range(n):
        L = reaching(start, na, i, L)
        for j in range(L):
            c = int(order[j])
            zc = hg * z[j]
            for k in range(13):
                state[i, THETA_HAT + k] -= zc * filt[c, i, U_ROW + k]


@njit(cache=True, inline="always")
def update_least_squares(chan, filt, const, state, scal, f, Sf):
    """The least-squares gain of each link: Potter's update with the active channels'
    rows, then bounded-gain forgetting (:mod:`rcac_ros.core.least_squares`)."""
    h = scal[I_H]
    for i in range(state.shape[0]):
        S = state[i, P_FACTOR:P_FACTOR + 169]
        for c in range(chan.shape[0]):
            if chan[c, CH_ACTIVE] != 0.0 and i >= channel_start(chan[c, CH_JOINT]):
                potter_update(S, filt[c, i, W_ROW:W_ROW + 13], h, f, Sf)
        bounded_gain_forgetting(S, h, scal[I_FORGET], const[i, TRACE_MAX])


@njit(cache=True, inline="always")
def project(const, state):
    """Projection: ``theta_hat_i`` clipped to ``[theta_min_i, theta_max_i]``."""
    for i in range(state.shape[0]):
        for k in range(13):
            state[i, THETA_HAT + k] = min(max(state[i, THETA_HAT + k], const[i, THETA_MIN + k]),
                                          const[i, THETA_MAX + k])
