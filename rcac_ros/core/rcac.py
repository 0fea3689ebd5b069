"""The recursive composite adaptive controller (eqs 18-24, doc/design.md §3-4), with m channels.

Per control period ``h``, with ``s_i = V_i - V_ri``:

    qd_r = qd_d - Lambda (q - q_d),   qdd_r = qdd_d - Lambda (qd - qd_d)           (eq 18)
    V_ri = T V_r,i-1 + z6 qd_ri
    Vdot_ri = T Vdot_r,i-1 + Tdot V_r,i-1 + z6 qdd_ri         (Tdot with the actual qd_i)
    F_ri = (i+1 T_i)^T F_r,i+1 + Y_ri theta_hat_i + K_Di (V_ri - V_i)              (eq 19b)
    tau_i = z6^T F_ri                                                               (eq 20)
    W_cj, y_c, E_c = sum_j W_cj theta_hat_j - y_c      for each channel c (eqs 21-23, channels.py)
    theta_hat_dot_i = -P_i (Y_ri^T s_i + gamma sum_c W_ci^T E_c)                     (eq 24)
                      - P_i sigma_i (theta_hat_i - theta_0i)          (leakage, optional)

The paper predicts one channel, the filtered torque of joint 1 (``channels=[1]``, the
default). More channels (:mod:`rcac_ros.core.channels`) predict more filtered torques;
``channels="all"`` is the Slotine-Li composite law, computed recursively.

Discretisation (the paper leaves it open): filters exact (zero-order hold on the applied
torque, first-order hold on ``phi``, ``psi``); ``theta_hat`` takes one step of ``h`` after
the torque is computed, explicit Euler in the tracking term ``Y_ri^T s_i``, and in the
prediction-error term either

- ``update="implicit"`` (default): backward Euler, ``(I + h gamma P W^T W) theta+ = r``,
  solved by Woodbury with an m x m Cholesky factorisation, O(m^2 n + m^3); for m = 1
  Sherman-Morrison, O(n). It is stable for any gain and tends to eq 24 as ``h -> 0``;
  with the paper's ``P_i = 100 I`` and ``gamma = 0.1`` the explicit step is unstable at
  2 ms (``h gamma W P W^T`` is far above 2).
- ``update="explicit"``: forward Euler, O(m n).

Options beyond the paper: a least-squares gain with bounded-gain forgetting
(:mod:`rcac_ros.core.least_squares`), a dead zone on ``s`` and on each ``E_c``, the
projection of ``theta_hat`` onto bounds (mass >= 0, an optional box), and leakage toward
nominal estimates ``theta_0`` (:func:`leakage_gradient`). With the defaults the law is the
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
from numba import njit

from ._blocks import (INPUT_NAMES, VEC, check_vectors, cholesky_solve, feedback_wrench,
                      gain_step, input_error, reference_motion)
from ._packing import (ADAPT_GRADIENT, ADAPT_LS, ADAPT_LS_PREDICTION, CH_A, CH_ACTIVE, CH_AD,
                       CH_E, CH_JOINT, CH_Y, CHAN_COLS, CONST_COLS, FILT_COLS, I_ADAPT, I_DZ_E,
                       I_DZ_S, I_E, I_ERR, I_FB0, I_FB1, I_FE, I_FORGET, I_FROZEN, I_G, I_GAMMA,
                       I_H, I_IMPLICIT, I_K, I_KD_DIAG, I_LAM, I_LEAK, I_P_DIAG, I_PROJECT,
                       I_TRACKING, I_Y, KD0, LAM, LEAK_M0, PG0, PHF, PHP, PMAX, POWER, PSF, PSP,
                       QPREV, S0, SQ, TAU, TH, TH0, THI, TLO, UR, WR, Gains, block, new_data)
from ._validate import as_array, joint_values, scalar
from .channels import (axis_terms, channel_codes, filtered_output, parse_channels,
                       power_terms)
from rcac_ros.errors import GainError
from .least_squares import (apply_factored, bounded_gain_forgetting, initial_factor,
                            potter_update)
from .regressor import reference_wrench, regressor_row, regressor_terms
from .spatial import P0, propagate, transform_force_T

RCAC_SIGNATURE = f"{VEC}(float64[:, ::1], float64[:, :, ::1], {VEC}, {VEC}, {VEC}, {VEC}, {VEC})"
UPDATES = ("implicit", "explicit")
AXIS_Z = (0.0, 0.0, 0.0, 0.0, 0.0, 1.0)      #: z6, a joint channel's axis at its joint
AXIS_0 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
ADAPTATIONS = {"gradient": ADAPT_GRADIENT, "least_squares": ADAPT_LS,
               "least_squares_prediction": ADAPT_LS_PREDICTION}


@njit(cache=True, inline="always")
def channel_start(code):
    """The first link (0-based) the channel of ``CH_JOINT`` code ``code`` reaches."""
    return 0 if code == POWER else int(code)


@njit(cache=True, inline="always")
def start_channels(chan, state, scal, q, first):
    """Each ``y_c`` for this step (the filtered applied output), ``E_c`` reset to 0."""
    for c in range(chan.shape[0]):
        chan[c, CH_Y] = filtered_output(chan, c, state, scal, q, first)
        chan[c, CH_E] = 0.0


@njit(cache=True, inline="always")
def predict_link(chan, filt, i, C, row, qd, V, g, st, coef, first, pp):
    """Link i's share of every channel: ``W_ci`` and ``E_c += W_ci theta_hat_i`` (eqs 22-23).

    A joint channel k carries its axis in ``chan[c]``: ``a_k = z6``, ``adot_k = 0``, then
    ``a_j = T_j a_j-1``, ``adot_j = Tdot_j a_j-1 + T_j adot_j-1`` (doc/design.md §4). The
    filters use a first-order hold on the samples and start at ``phi(0)`` and 0, so that E
    is exact from the first step. The channel loop calls no helper taking an array (each
    would cost atomic reference counts per channel and link): it updates them in place.
    ``phi_ci``, ``psi_ci`` go through the scratch ``pp`` (26): the filter loop then reads an
    array, not a 13-tuple at a varying index (a switch per read).
    """
    fe, fb0, fb1, lam = coef
    px, py, pz = row[P0], row[P0 + 1], row[P0 + 2]
    for c in range(chan.shape[0]):
        code = chan[c, CH_JOINT]
        if code == POWER:
            phi, psi = power_terms(V, g)
        elif i < code:
            continue
        else:
            if i == code:
                A, Ad = AXIS_Z, AXIS_0
            else:
                A = (chan[c, CH_A], chan[c, CH_A + 1], chan[c, CH_A + 2], chan[c, CH_A + 3],
                     chan[c, CH_A + 4], chan[c, CH_A + 5])
                Ad = (chan[c, CH_AD], chan[c, CH_AD + 1], chan[c, CH_AD + 2],
                      chan[c, CH_AD + 3], chan[c, CH_AD + 4], chan[c, CH_AD + 5])
                A, Ad = propagate(C, i, px, py, pz, qd, A, Ad, 0.0, 0.0)
            for r in range(6):
                chan[c, CH_A + r] = A[r]
                chan[c, CH_AD + r] = Ad[r]
            phi, psi = axis_terms(A, Ad, V, g)
        (pp[0], pp[1], pp[2], pp[3], pp[4], pp[5], pp[6], pp[7], pp[8], pp[9], pp[10],
         pp[11], pp[12]) = phi
        (pp[13], pp[14], pp[15], pp[16], pp[17], pp[18], pp[19], pp[20], pp[21], pp[22],
         pp[23], pp[24], pp[25]) = psi
        E = chan[c, CH_E]
        for k in range(13):
            ph = pp[k]
            ps = pp[13 + k]
            if first:
                filt[c, i, PHF + k] = ph
                filt[c, i, PSF + k] = 0.0
            else:
                php = filt[c, i, PHP + k]
                psp = filt[c, i, PSP + k]
                filt[c, i, PHF + k] = fe * filt[c, i, PHF + k] + fb0 * php + fb1 * (ph - php)
                filt[c, i, PSF + k] = fe * filt[c, i, PSF + k] + fb0 * psp + fb1 * (ps - psp)
            filt[c, i, PHP + k] = ph
            filt[c, i, PSP + k] = ps
            w = lam * (ph - filt[c, i, PHF + k]) + filt[c, i, PSF + k]
            filt[c, i, WR + k] = w
            E += w * st[TH + k]
        chan[c, CH_E] = E


@njit(cache=True, inline="always")
def close_channels(chan, scal):
    """``E_c -= y_c`` and the dead zone on E: a channel adapts only if ``|E_c| > dz``."""
    dz = scal[I_DZ_E]
    for c in range(chan.shape[0]):
        chan[c, CH_E] -= chan[c, CH_Y]
        chan[c, CH_ACTIVE] = 1.0 if dz <= 0.0 or abs(chan[c, CH_E]) > dz else 0.0
    scal[I_E] = chan[0, CH_E]
    scal[I_Y] = chan[0, CH_Y]


@njit(cache=True, inline="always")
def tracking_active(const, scal, q, qd, q_d, qd_d):
    """The dead zone on s: the tracking term adapts only if ``max |qd - qd_r| > dz``."""
    dz = scal[I_DZ_S]
    if dz <= 0.0:
        return True
    worst = 0.0
    for i in range(q.shape[0]):
        worst = max(worst, abs(qd[i] - (qd_d[i] - const[i, LAM] * (q[i] - q_d[i]))))
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
                grad[k] -= gamma * filt[c, i, WR + k] * y
        else:
            e = chan[c, CH_E]
            for k in range(13):
                grad[k] += gamma * filt[c, i, WR + k] * e


@njit(cache=True, inline="always")
def leakage_gradient(row, st, scal, grad):
    """Add the leakage to ``grad``: ``+ sigma_i (theta_hat_i - theta_0i)`` (module docstring).

    ``sigma_i = sigma_0`` (fixed), or the switching ``sigma_i`` of Ioannou & Sun ch. 8 when
    link i's ``M_0 = row[LEAK_M0] > 0``: zero inside ``||theta_hat_i - theta_0i|| <= M_0``.
    """
    sigma = scal[I_LEAK]
    m0 = row[LEAK_M0]
    if m0 > 0.0:
        d2 = 0.0
        for k in range(13):
            d = st[TH + k] - row[TH0 + k]
            d2 += d * d
        dist = np.sqrt(d2)
        if dist <= m0:
            return
        sigma *= min(dist / m0 - 1.0, 1.0)
    for k in range(13):
        grad[k] += sigma * (st[TH + k] - row[TH0 + k])


@njit(cache=True, inline="always")
def adapt_link(row, st, chan, filt, i, G, scal, tracking, R, grad, Pg, t):
    """Eq 24, step 1, link i: ``R_i = theta_hat_i - h P_i (Y_ri^T s_i + leakage + prediction
    part)``, and ``U_ci = P_i W_ci^T`` for the implicit solve (P: fixed or least squares).
    With ``least_squares_prediction`` the leakage takes the tracking term's fixed ``P_i``."""
    h, gamma = scal[I_H], scal[I_GAMMA]
    implicit = scal[I_IMPLICIT] != 0.0
    mode = scal[I_ADAPT]
    p_diag = scal[I_P_DIAG] != 0.0
    for k in range(13):
        grad[k] = G[i, k] if tracking else 0.0
    if scal[I_LEAK] > 0.0:
        leakage_gradient(row, st, scal, grad)
    if mode == ADAPT_GRADIENT:
        prediction_gradient(chan, filt, i, grad, gamma, implicit)
        gain_step(row, p_diag, st, grad, h, R, i)
    elif mode == ADAPT_LS:
        prediction_gradient(chan, filt, i, grad, gamma, implicit)
        apply_factored(st, SQ, grad, Pg, t)
        for k in range(13):
            R[i, k] = st[TH + k] - h * Pg[k]
    else:                               # fixed P on the tracking term, least squares on E
        gain_step(row, p_diag, st, grad, h, R, i)
        for k in range(13):
            grad[k] = 0.0
        prediction_gradient(chan, filt, i, grad, gamma, implicit)
        apply_factored(st, SQ, grad, Pg, t)
        for k in range(13):
            R[i, k] -= h * Pg[k]
    if not implicit:
        return
    for c in range(chan.shape[0]):
        if chan[c, CH_ACTIVE] == 0.0 or i < channel_start(chan[c, CH_JOINT]):
            continue
        if mode == ADAPT_GRADIENT:              # U_ci = P_i W_ci^T, fixed P_i
            if p_diag:
                for a in range(13):
                    filt[c, i, UR + a] = row[PG0 + 14 * a] * filt[c, i, WR + a]
            else:
                for a in range(13):
                    acc = 0.0
                    for k in range(13):
                        acc += row[PG0 + 13 * a + k] * filt[c, i, WR + k]
                    filt[c, i, UR + a] = acc
        else:
            for k in range(13):
                grad[k] = filt[c, i, WR + k]
            apply_factored(st, SQ, grad, Pg, t)
            for k in range(13):
                filt[c, i, UR + k] = Pg[k]


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
        WR_ = 0.0
        WU = 0.0
        for i in range(c0, n):
            for k in range(13):
                WR_ += filt[c, i, WR + k] * R[i, k]
                WU += filt[c, i, WR + k] * filt[c, i, UR + k]
        kc = scal[I_H] * scal[I_GAMMA] * WR_ / (1.0 + scal[I_H] * scal[I_GAMMA] * WU)
        for i in range(n):
            for k in range(13):
                state[i, TH + k] = R[i, k] if i < c0 else R[i, k] - kc * filt[c, i, UR + k]
        return
    for i in range(n):
        for k in range(13):
            state[i, TH + k] = R[i, k]
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
        while L < na and start[L] <= i:
            L += 1
        for j in range(L):
            c = int(order[j])
            for k in range(13):
                Wt[k, j] = filt[c, i, WR + k]
                Ut[k, j] = filt[c, i, UR + k]
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
        while L < na and start[L] <= i:
            L += 1
        for j in range(L):
            c = int(order[j])
            zc = hg * z[j]
            for k in range(13):
                state[i, TH + k] -= zc * filt[c, i, UR + k]


@njit(cache=True, inline="always")
def update_least_squares(chan, filt, const, state, scal, f, Sf):
    """The least-squares gain of each link: Potter's update with the active channels'
    rows, then bounded-gain forgetting (:mod:`rcac_ros.core.least_squares`)."""
    h = scal[I_H]
    for i in range(state.shape[0]):
        S = state[i, SQ:SQ + 169]
        for c in range(chan.shape[0]):
            if chan[c, CH_ACTIVE] != 0.0 and i >= channel_start(chan[c, CH_JOINT]):
                potter_update(S, filt[c, i, WR:WR + 13], h, f, Sf)
        bounded_gain_forgetting(S, h, scal[I_FORGET], const[i, PMAX])


@njit(cache=True, inline="always")
def project(const, state):
    """Projection: ``theta_hat_i`` clipped to ``[theta_min_i, theta_max_i]``."""
    for i in range(state.shape[0]):
        for k in range(13):
            state[i, TH + k] = min(max(state[i, TH + k], const[i, TLO + k]), const[i, THI + k])


@njit(cache=True, inline="always")
def is_paper_law(chan, scal):
    """True for the paper's law exactly: one channel (joint 1), the fixed gain, implicit
    update, no dead zone, no projection, no leakage, adapting. :func:`paper_step` then runs
    it."""
    return (chan.shape[0] == 1 and chan[0, CH_JOINT] == 0.0 and scal[I_ADAPT] == ADAPT_GRADIENT
            and scal[I_IMPLICIT] != 0.0 and scal[I_DZ_S] <= 0.0 and scal[I_DZ_E] <= 0.0
            and scal[I_PROJECT] == 0.0 and scal[I_FROZEN] == 0.0 and scal[I_LEAK] <= 0.0)


@njit(RCAC_SIGNATURE, cache=True)
def paper_step(data, filt, q, qd, q_d, qd_d, qdd_d):
    """:func:`rcac_step_kernel` for the paper's law (:func:`is_paper_law`), fused in one body.

    The controller calls it directly for that law: one compiled call, as the kernel's.

    The same equations, in the same floating-point order, as the general kernel with
    ``channels=[1]``: joint 1's axis ``a_j`` travels in registers, and each link's blocks
    are computed in place, with no per-link helper taking arrays (each such argument
    costs an atomic reference count in the loop). One allocation besides ``tau``.
    """
    n = data.shape[0] - 1
    const = data[:n, :CONST_COLS]
    state = data[:n, CONST_COLS:]
    scal = data[n]
    chan = filt[:, n]
    err = check_vectors(n, q, qd, q_d, qd_d, qdd_d)
    if err != 0:
        scal[I_ERR] = err
        return np.empty(0, q.dtype)
    work = np.empty(n * 41 + 6, q.dtype)
    C = work[:9 * n].reshape((n, 9))              # eq 10's rotations
    Fs = work[9 * n:15 * n].reshape((n, 6))       # Y_ri theta_hat_i
    G = work[15 * n:28 * n].reshape((n, 13))      # Y_ri^T s_i
    R = work[28 * n:41 * n].reshape((n, 13))      # theta_hat_i - h P_i (...), eq 24 step 1
    F = work[41 * n:41 * n + 6]                   # F_ri during the backward pass
    tau = np.empty(n, q.dtype)
    lam, h, gamma = scal[I_LAM], scal[I_H], scal[I_GAMMA]
    fe, fb0, fb1 = scal[I_FE], scal[I_FB0], scal[I_FB1]
    first = scal[I_K] == 0.0
    kd_diag = scal[I_KD_DIAG] != 0.0
    p_diag = scal[I_P_DIAG] != 0.0
    y = filtered_output(chan, 0, state, scal, q, first)       # y = tau_1^f (eq 22)
    zero = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    V, Vr, Vdr = zero, zero, zero                      # V_i, V_ri, Vdot_ri
    A, Ad = zero, zero                                 # a_j, adot_j (joint 1's axis, frame j)
    g = (scal[I_G], scal[I_G + 1], scal[I_G + 2])
    E = 0.0
    for i in range(n):
        row = data[i]                                  # link i: constants, then state
        qdi = qd[i]
        V, Vr, Vdr, g = reference_motion(C, i, row, q[i], qdi, q_d[i], qd_d[i], qdd_d[i],
                                         V, Vr, Vdr, g)
        vx, vy, vz, wx, wy, wz = V
        rvx, rvy, rvz, rwx, rwy, rwz = Vr
        dvx, dvy, dvz, dwx, dwy, dwz = Vdr
        gx, gy, gz = g
        # a_1 = z6, a_j = T_j a_j-1 ; adot_j = Tdot_j a_j-1 + T_j adot_j-1
        if i == 0:
            A = (0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        else:
            A, Ad = propagate(C, i, row[P0], row[P0 + 1], row[P0 + 2], qdi, A, Ad, 0.0, 0.0)
        svx, svy, svz, swx, swy, swz = vx - rvx, vy - rvy, vz - rvz, wx - rwx, wy - rwy, wz - rwz
        state[i, S0], state[i, S0 + 1], state[i, S0 + 2] = svx, svy, svz
        state[i, S0 + 3], state[i, S0 + 4], state[i, S0 + 5] = swx, swy, swz
        # eq 19b's Y_ri theta_hat_i and eq 24's Y_ri^T s_i, neither forming Y_ri
        f = reference_wrench(row, CONST_COLS + TH, dvx, dvy, dvz, dwx, dwy, dwz,
                             rvx, rvy, rvz, rwx, rwy, rwz, wx, wy, wz, gx, gy, gz)
        for k in range(6):
            Fs[i, k] = f[k]
        gr = regressor_terms(svx, svy, svz, swx, swy, swz, dvx, dvy, dvz, dwx, dwy, dwz,
                             rvx, rvy, rvz, rwx, rwy, rwz, wx, wy, wz, gx, gy, gz)
        for k in range(13):
            G[i, k] = gr[k]
        phi, psi = axis_terms(A, Ad, V, g)                           # eq 22
        for k in range(13):
            ph = phi[k]
            ps = psi[k]
            if first:
                filt[0, i, PHF + k] = ph
                filt[0, i, PSF + k] = 0.0
            else:
                php = filt[0, i, PHP + k]
                psp = filt[0, i, PSP + k]
                filt[0, i, PHF + k] = fe * filt[0, i, PHF + k] + fb0 * php + fb1 * (ph - php)
                filt[0, i, PSF + k] = fe * filt[0, i, PSF + k] + fb0 * psp + fb1 * (ps - psp)
            filt[0, i, PHP + k] = ph
            filt[0, i, PSP + k] = ps
            w = lam * (ph - filt[0, i, PHF + k]) + filt[0, i, PSF + k]     # eq 23
            filt[0, i, WR + k] = w
            E += w * state[i, TH + k]
    E -= y
    chan[0, CH_Y], chan[0, CH_E], chan[0, CH_ACTIVE] = y, E, 1.0
    scal[I_E], scal[I_Y], scal[I_TRACKING] = E, y, 1.0
    for k in range(6):
        F[k] = 0.0
    for i in range(n - 1, -1, -1):
        if i < n - 1:
            F[0], F[1], F[2], F[3], F[4], F[5] = transform_force_T(
                C, i + 1, const[i + 1, P0], const[i + 1, P0 + 1], const[i + 1, P0 + 2],
                F[0], F[1], F[2], F[3], F[4], F[5])
        # eq 19b: + Y_ri theta_hat_i + K_Di (V_ri - V_i), with V_ri - V_i = -s_i
        for r in range(6):
            acc = Fs[i, r]
            if kd_diag:
                acc -= const[i, KD0 + 7 * r] * state[i, S0 + r]
            else:
                for k in range(6):
                    acc -= const[i, KD0 + 6 * r + k] * state[i, S0 + k]
            F[r] += acc
        tau[i] = F[5]                                                        # eq 20
        # eq 24, step 1: R_i = theta_hat_i - h P_i (Y_ri^T s_i - gamma W_i^T y), U_i = P_i W_i^T
        for k in range(13):
            G[i, k] -= gamma * filt[0, i, WR + k] * y
        if p_diag:
            for a in range(13):
                R[i, a] = state[i, TH + a] - h * const[i, PG0 + 14 * a] * G[i, a]
                filt[0, i, UR + a] = const[i, PG0 + 14 * a] * filt[0, i, WR + a]
        else:
            for a in range(13):
                acc_r = 0.0
                acc_u = 0.0
                for c in range(13):
                    acc_r += const[i, PG0 + 13 * a + c] * G[i, c]
                    acc_u += const[i, PG0 + 13 * a + c] * filt[0, i, WR + c]
                R[i, a] = state[i, TH + a] - h * acc_r
                filt[0, i, UR + a] = acc_u
    # eq 24, step 2, implicit (Sherman-Morrison, O(n)):
    # theta_hat+ = R - h gamma U (W R) / (1 + h gamma W U)
    WR_ = 0.0
    WU = 0.0
    for i in range(n):
        for k in range(13):
            WR_ += filt[0, i, WR + k] * R[i, k]
            WU += filt[0, i, WR + k] * filt[0, i, UR + k]
    kc = h * gamma * WR_ / (1.0 + h * gamma * WU)
    for i in range(n):
        for k in range(13):
            state[i, TH + k] = R[i, k] - kc * filt[0, i, UR + k]
        state[i, TAU] = tau[i]
        state[i, QPREV] = q[i]
    scal[I_K] += 1.0
    return tau


@njit(RCAC_SIGNATURE, cache=True)
def rcac_step_kernel(data, filt, q, qd, q_d, qd_d, qdd_d):
    """One control period of eqs 18-24; returns tau (empty on bad input, code in scal[I_ERR]).

    ``data``, ``filt`` and ``chan`` follow the layout of :mod:`rcac_ros.core._packing`.
    """
    n = data.shape[0] - 1
    const = data[:n, :CONST_COLS]
    state = data[:n, CONST_COLS:]
    scal = data[n]
    chan = filt[:, n]
    if is_paper_law(chan, scal):
        return paper_step(data, filt, q, qd, q_d, qd_d, qdd_d)
    err = check_vectors(n, q, qd, q_d, qd_d, qdd_d)
    if err != 0:
        scal[I_ERR] = err
        return np.empty(0, q.dtype)
    m = chan.shape[0]
    work = np.empty(n * 41 + 84 + m * (m + 29), q.dtype)
    C = work[:9 * n].reshape((n, 9))              # eq 10's rotations
    Fs = work[9 * n:15 * n].reshape((n, 6))       # Y_ri theta_hat_i
    G = work[15 * n:28 * n].reshape((n, 13))      # Y_ri^T s_i
    R = work[28 * n:41 * n].reshape((n, 13))      # theta_hat_i - h P_i (...), eq 24 step 1
    grad, Pg, t = work[41 * n + 39:41 * n + 52], work[41 * n + 52:41 * n + 65], \
        work[41 * n + 65:41 * n + 78]
    F = work[41 * n + 78:41 * n + 84]             # F_ri during the backward pass
    pp = work[41 * n:41 * n + 26]                 # phi_ci, psi_ci of predict_link
    o = 41 * n + 84                               # the implicit solve's scratch:
    A = work[o:o + m * m]                         # the m x m system (flat),
    z = work[o + m * m:o + m * (m + 1)]           # its right-hand side,
    order = work[o + m * (m + 1):o + m * (m + 2)]  # the active channels by first link,
    start = work[o + m * (m + 2):o + m * (m + 3)]  # their first links,
    Wt = work[o + m * (m + 3):o + m * (m + 16)].reshape((13, m))  # W_ci, U_ci at link i
    Ut = work[o + m * (m + 16):o + m * (m + 29)].reshape((13, m))  # as columns
    coef = (scal[I_FE], scal[I_FB0], scal[I_FB1], scal[I_LAM])
    tau = np.empty(n, q.dtype)
    first = scal[I_K] == 0.0
    start_channels(chan, state, scal, q, first)
    zero = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    V, Vr, Vdr = zero, zero, zero                      # V_i, V_ri, Vdot_ri
    g = (scal[I_G], scal[I_G + 1], scal[I_G + 2])
    for i in range(n):
        row = const[i]
        st = state[i]
        V, Vr, Vdr, g = reference_motion(C, i, row, q[i], qd[i], q_d[i], qd_d[i], qdd_d[i],
                                         V, Vr, Vdr, g)
        vx, vy, vz, wx, wy, wz = V
        rvx, rvy, rvz, rwx, rwy, rwz = Vr
        dvx, dvy, dvz, dwx, dwy, dwz = Vdr
        gx, gy, gz = g
        st[S0], st[S0 + 1], st[S0 + 2] = vx - rvx, vy - rvy, vz - rvz
        st[S0 + 3], st[S0 + 4], st[S0 + 5] = wx - rwx, wy - rwy, wz - rwz
        # eq 19b's Y_ri theta_hat_i and eq 24's Y_ri^T s_i, neither forming Y_ri
        f = reference_wrench(st, TH, dvx, dvy, dvz, dwx, dwy, dwz, rvx, rvy, rvz, rwx, rwy,
                             rwz, wx, wy, wz, gx, gy, gz)
        for k in range(6):
            Fs[i, k] = f[k]
        regressor_row(G[i], vx - rvx, vy - rvy, vz - rvz, wx - rwx, wy - rwy, wz - rwz,
                      dvx, dvy, dvz, dwx, dwy, dwz, rvx, rvy, rvz, rwx, rwy, rwz,
                      wx, wy, wz, gx, gy, gz)
        predict_link(chan, filt, i, C, row, qd[i], V, g, st, coef, first, pp)
    close_channels(chan, scal)
    frozen = scal[I_FROZEN] != 0.0                 # set_adaptation(False)
    tracking = tracking_active(const, scal, q, qd, q_d, qd_d) and not frozen
    scal[I_TRACKING] = 1.0 if tracking else 0.0
    for k in range(6):
        F[k] = 0.0
    for i in range(n - 1, -1, -1):
        row = const[i]
        st = state[i]
        if i < n - 1:
            r = const[i + 1]
            F[0], F[1], F[2], F[3], F[4], F[5] = transform_force_T(
                C, i + 1, r[P0], r[P0 + 1], r[P0 + 2], F[0], F[1], F[2], F[3], F[4], F[5])
        feedback_wrench(row, Fs[i], st[S0:S0 + 6], scal[I_KD_DIAG] != 0.0, F)   # eq 19b
        tau[i] = F[5]                                                              # eq 20
        if not frozen:
            adapt_link(row, st, chan, filt, i, G, scal, tracking, R, grad, Pg, t)
    if frozen:
        pass
    elif scal[I_IMPLICIT] != 0.0:
        implicit_solve(chan, filt, state, R, A, z, order, start, Wt, Ut, scal)
    else:
        for i in range(n):
            for k in range(13):
                state[i, TH + k] = R[i, k]
    if not frozen and scal[I_ADAPT] != ADAPT_GRADIENT:
        update_least_squares(chan, filt, const, state, scal, grad, Pg)
    if not frozen and scal[I_PROJECT] != 0.0:
        project(const, state)
    for i in range(n):
        state[i, TAU] = tau[i]
        state[i, QPREV] = q[i]
    scal[I_K] += 1.0
    return tau


class RecursiveCompositeController:
    """The recursive composite adaptive controller of eqs 18-24, O(m n) per step.

    Parameters
    ----------
    model : RobotModel
        Kinematics (``p``, ``R_fix``) and gravity; its inertial parameters are *not*
        used: the controller knows only ``theta_hat``.
    K_D : float, (6,), (6, 6) or (n, 6, 6)
        Link feedback gains ``K_Di`` (eq 19), symmetric positive definite.
    Lambda : float, (n,) or diagonal (n, n)
        ``Lambda`` of eq 18, positive (per joint).
    P : float, (13,), (13, 13) or (n, 13, 13)
        Adaptation gains ``P_i`` (eq 24), symmetric positive definite; with least squares,
        their initial value.
    gamma : float
        Weight of the prediction errors (eq 24); ``0`` gives the direct adaptive law.
    lam : float
        Bandwidth ``lambda`` of the filter ``lambda / (p + lambda)``, rad/s (the paper gives none).
    h : float
        Control period, s.
    theta_hat0 : array_like (n, 13), optional
        Initial estimates (default zero, as in the paper).
    channels : int, str or sequence, optional
        The predicted filtered torques (:func:`~rcac_ros.core.channels.parse_channels`):
        ``[1]`` (default, the paper's), ``"all"``, ``"power"``, or e.g. ``[1, 7, "power"]``.
    update : {"implicit", "explicit"}
        Discretisation of the prediction-error term (module docstring).
    adaptation : {"gradient", "least_squares", "least_squares_prediction"}
        ``P_i`` fixed (default), least squares with bounded-gain forgetting on both terms,
        or least squares on the prediction term only (the tracking term keeps ``P``).
    forgetting : float
        ``lambda_0`` of the bounded-gain forgetting, 1/s (least squares).
    P_max : float, optional
        ``k_0``: bound on every ``trace(P_i)`` (default: each link's ``trace(P_i(0))``).
    dead_zone_s, dead_zone_E : float
        No adaptation of the tracking term while ``max_j |qd_j - qd_rj| <= dead_zone_s``, and
        none from channel c while ``|E_c| <= dead_zone_E`` (0: no dead zone).
    theta_bounds : None, "mass" or (theta_min, theta_max)
        Projection after each step: none (default), mass >= 0, or a box (each bound a
        scalar, (13,) or (n, 13); ``-inf``/``inf`` for none), with mass >= 0 too.

    Raises
    ------
    GainError
        On a gain or option of wrong shape or value, naming the field.
    InputError
        On a ``theta_hat0`` of wrong shape or not finite.
    """

    def __init__(self, model, K_D=1e4, Lambda=1.0, P=100.0, gamma=0.1, lam=10.0, h=0.002,
                 theta_hat0=None, channels=(1,), update="implicit", adaptation="gradient",
                 forgetting=0.0, P_max=None, dead_zone_s=0.0, dead_zone_E=0.0,
                 theta_bounds=None, leakage=0.0, leakage_bound=0.0, theta_0=None):
        self.model = model
        n = model.n
        gains = Gains(model, K_D, Lambda, P, gamma, lam, h)
        self.K_D, self.P, self.Lambda = gains.K_D, gains.P, gains.Lambda
        self.gamma, self.lam, self.h = gains.gamma, gains.lam, gains.h
        self.channels = parse_channels(channels, n)
        self._data = new_data(n)
        gains.pack(model, self._data)
        self._const = self._data[:n, :CONST_COLS]
        self._state = self._data[:n, CONST_COLS:]       # views into the one kernel argument
        self._scal = self._data[n]
        self._configure(update, adaptation, forgetting, P_max, dead_zone_s, dead_zone_E,
                        theta_bounds)
        m = len(self.channels)
        self._buf = np.zeros((m, n + 1, FILT_COLS))    # the kernel's second argument:
        self._filt = self._buf[:, :n]                  # filt[c, :n], and chan as row n
        self._chan = self._buf[:, n, :CHAN_COLS]
        self._chan[:, CH_JOINT] = channel_codes(self.channels)
        self.adapting = True
        self.reset(theta_hat0)
        self._leakage(leakage, leakage_bound, theta_hat0 if theta_0 is None else theta_0)
        self._choose_kernel()               # after every scalar the choice reads

    def _leakage(self, leakage, leakage_bound, theta_0):
        self.leakage = scalar(leakage, "leakage", GainError, minimum=0.0)
        self.leakage_bound = joint_values(leakage_bound, self.n, "leakage_bound", GainError)
        if np.any(self.leakage_bound < 0.0):
            raise GainError("leakage_bound: must be >= 0")
        self.theta_0 = np.zeros((self.n, 13)) if theta_0 is None else \
            as_array(theta_0, (self.n, 13), "theta_0", GainError)
        if self.adaptation == "least_squares":
            top = float(self._const[:, PMAX].max())
        else:
            top = float(np.linalg.eigvalsh(self.P).max())
        if self.h * self.leakage * top >= 1.0:
            raise GainError(f"leakage: h * leakage * lambda_max(P) = "
                            f"{self.h * self.leakage * top:.3g}, must be < 1 (explicit Euler)")
        self._const[:, block("theta_0")] = self.theta_0
        self._scal[I_LEAK] = self.leakage
        self._const[:, LEAK_M0] = self.leakage_bound

    def _choose_kernel(self):
        """The compiled step: :func:`paper_step` for the paper's law (saves the dispatch
        through :func:`rcac_step_kernel`), else the general kernel."""
        self._kernel = paper_step if is_paper_law(self._chan, self._scal) else \
            rcac_step_kernel

    def _configure(self, update, adaptation, forgetting, P_max, dead_zone_s, dead_zone_E,
                   theta_bounds):
        if update not in UPDATES:
            raise GainError(f"update: expected 'implicit' or 'explicit', got {update!r}")
        if adaptation not in ADAPTATIONS:
            raise GainError(f"adaptation: expected one of {', '.join(ADAPTATIONS)}, "
                            f"got {adaptation!r}")
        self.update, self.adaptation = update, adaptation
        scal = self._scal
        scal[I_IMPLICIT] = 1.0 if update == "implicit" else 0.0
        scal[I_ADAPT] = ADAPTATIONS[adaptation]
        scal[I_FORGET] = scalar(forgetting, "forgetting", GainError, minimum=0.0)
        self._const[:, PMAX] = np.trace(self.P, axis1=1, axis2=2) if P_max is None else \
            scalar(P_max, "P_max", GainError, minimum=0.0, strict=True)
        scal[I_DZ_S] = scalar(dead_zone_s, "dead_zone_s", GainError, minimum=0.0)
        scal[I_DZ_E] = scalar(dead_zone_E, "dead_zone_E", GainError, minimum=0.0)
        self.theta_min, self.theta_max = self._bounds(theta_bounds)
        if self.theta_min is not None:
            self._const[:, block("theta_lo")] = self.theta_min
            self._const[:, block("theta_hi")] = self.theta_max
            scal[I_PROJECT] = 1.0

    def _bounds(self, theta_bounds):
        n = self.n
        if theta_bounds is None:
            return None, None
        if isinstance(theta_bounds, str):
            if theta_bounds != "mass":
                raise GainError(f"theta_bounds: expected None, 'mass' or (theta_min, "
                                f"theta_max), got {theta_bounds!r}")
            lo, hi = np.full((n, 13), -np.inf), np.full((n, 13), np.inf)
        else:
            try:
                lo, hi = theta_bounds
            except (TypeError, ValueError):
                raise GainError("theta_bounds: expected None, 'mass' or (theta_min, "
                                "theta_max)") from None
            lo = self._bound(lo, "theta_min")
            hi = self._bound(hi, "theta_max")
            if np.any(lo > hi):
                raise GainError("theta_bounds: theta_min > theta_max somewhere")
        lo[:, 0] = np.maximum(lo[:, 0], 0.0)          # mass >= 0
        if np.any(hi[:, 0] < 0.0):
            raise GainError("theta_bounds: theta_max of a mass is < 0")
        return lo, hi

    def _bound(self, value, name):
        try:
            arr = np.broadcast_to(np.asarray(value, dtype=float), (self.n, 13)).copy()
        except (TypeError, ValueError):
            raise GainError(f"{name}: expected a scalar, (13,) or ({self.n}, 13) values") \
                from None
        if np.any(np.isnan(arr)):
            raise GainError(f"{name}: contains NaN")
        return arr

    @property
    def n(self):
        """Number of joints."""
        return self.model.n

    @property
    def m(self):
        """Number of prediction channels."""
        return len(self.channels)

    def reset(self, theta_hat0=None):
        """Restart: estimates to ``theta_hat0`` (default 0), filters, gains and step count."""
        th = np.zeros((self.n, 13)) if theta_hat0 is None else \
            as_array(theta_hat0, (self.n, 13), "theta_hat0")
        self._state[:] = 0.0
        self._state[:, TH:TH + 13] = th
        self._state[:, SQ:SQ + 169] = initial_factor(self.P)
        self._filt[:] = 0.0
        self._chan[:, CH_Y:] = 0.0
        self._scal[[I_K, I_ERR, I_E, I_Y]] = 0.0

    def step(self, q, qd, q_d, qd_d, qdd_d):
        """One control period: returns the joint torques ``tau`` (eq 20) and adapts (eq 24).

        Parameters
        ----------
        q, qd : array_like, shape (n,)
            Measured joint positions and velocities.
        q_d, qd_d, qdd_d : array_like, shape (n,)
            Desired position, velocity and acceleration.

        Returns
        -------
        ndarray, shape (n,)

        Raises
        ------
        InputError
            If a vector has the wrong length or holds NaN/Inf (the state is left untouched).
        """
        try:
            tau = self._kernel(self._data, self._buf, q, qd, q_d, qd_d, qdd_d)
        except TypeError:  # not float64 1-D contiguous arrays: convert once, then retry
            values = (q, qd, q_d, qd_d, qdd_d)
            args = [as_array(v, (None,), k) for k, v in zip(INPUT_NAMES, values)]
            tau = self._kernel(self._data, self._buf, *args)
        if tau.shape[0] == 0:
            raise input_error(self._scal, self.n, (q, qd, q_d, qd_d, qdd_d))
        return tau

    def set_adaptation(self, enabled):
        """Freeze (``False``) or resume (``True``) the adaptation of eq 24, keeping ``theta_hat``.

        Frozen, ``theta_hat`` (and a least-squares gain) stay where they are, the torque of
        eqs 19-20 uses them, and the filters and ``E`` keep running (``E`` then measures the
        frozen estimates).
        """
        self._scal[I_FROZEN] = 0.0 if enabled else 1.0
        self.adapting = bool(enabled)
        self._choose_kernel()

    def set_applied_torque(self, tau):
        """Tell the filters (``y_c``, eq 22) the torque really applied after the last step.

        By default ``y`` filters the torque :meth:`step` returned. When the arm receives
        another one (clipped to an effort limit, or a safe effort), pass it here, or the
        prediction errors ``E`` compare the model with a torque the arm never felt.

        Raises
        ------
        InputError
            If ``tau`` has the wrong length or holds NaN/Inf.
        """
        self._state[:, TAU] = as_array(tau, (self.n,), "tau")

    def restart_filters(self):
        """Restart the filters of eqs 21-24 at the next step, keeping ``theta_hat``.

        For a gap in the measurements (a watchdog trip): the filters start again as at
        t = 0 (``phi^f = phi``, ``psi^f = 0``, ``y = 0``), so ``E`` is exact from there on.
        """
        self._scal[I_K] = 0.0

    @property
    def theta_hat(self):
        """Current estimates ``theta_hat``, shape (n, 13) (a copy)."""
        return self._state[:, TH:TH + 13].copy()

    @property
    def E(self):
        """Prediction errors ``E_c = sum_j W_cj theta_hat_j - y_c`` of the last step, (m,)."""
        return self._chan[:, CH_E].copy()

    @property
    def y(self):
        """Filtered applied outputs ``y_c`` (e.g. ``tau_1^f``) at the last step, (m,)."""
        return self._chan[:, CH_Y].copy()

    @property
    def link_velocity_error(self):
        """``s_i = V_i - V_ri`` of the last step, shape (n, 6) (a copy)."""
        return self._state[:, S0:S0 + 6].copy()

    @property
    def W(self):
        """The filtered regressor rows ``W_cj`` of the last step, (m, n, 13) (a copy)."""
        return self._filt[:, :, WR:WR + 13].copy()

    @property
    def gain(self):
        """The adaptation gain ``P_i`` in use, (n, 13, 13): fixed, or least squares."""
        if self.adaptation == "gradient":
            return self.P.copy()
        S = self._state[:, SQ:SQ + 169].reshape(self.n, 13, 13)
        return S @ S.transpose(0, 2, 1)

    @property
    def adapted(self):
        """Whether the tracking term and each channel adapted at the last step (dead zones)."""
        return bool(self._scal[I_TRACKING]), self._chan[:, CH_ACTIVE] != 0.0

    def lyapunov(self, theta):
        """Eqs 25-26: ``sum_i (s_i^T M_i s_i + theta_tilde_i^T P_i^-1 theta_tilde_i) / 2``.

        Uses the link velocity errors of the last step and the true parameters ``theta`` (n, 13).
        """
        from .regressor import link_matrices
        theta = as_array(theta, (self.n, 13), "theta")
        s = self.link_velocity_error
        tt = self.theta_hat - theta
        P = self.gain
        total = 0.0
        for i in range(self.n):
            M = link_matrices(theta[i], np.zeros(3))[0]
            total += 0.5 * s[i] @ M @ s[i] + 0.5 * tt[i] @ np.linalg.solve(P[i], tt[i])
        return float(total)
