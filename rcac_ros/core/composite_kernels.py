"""The step kernels of the recursive composite law: one control period of eqs 18-24.

Two compiled bodies of one law, tested against each other bit for bit
(test/core/test_channels.py):

- :func:`rcac_step_kernel`, the general one: any channels (:mod:`rcac_ros.core.channels`),
  any option of the adaptation step (:mod:`rcac_ros.core.adaptation`);
- :func:`paper_step`, the paper's law (:func:`is_paper_law`) fused in one loop body: one
  channel (joint 1), the fixed gain, the implicit update. It is the speed (doc/tools.md,
  ``rcac bench``). :func:`paper_natural_step` is the same body in the natural geometry
  (doc/design.md §8).

With the joint terms (doc/design.md §7) the general kernel is
:func:`friction_step_kernel`, the same body as :func:`rcac_step_kernel`
(:func:`general_law`), and the fused one :func:`paper_friction_step`, the same loop body
as :func:`paper_step` (:func:`paper_law`): each with its joint terms switched on by a
constant.

All read and write the packed arrays of :mod:`rcac_ros.core._packing`; the controller
(:class:`~rcac_ros.core.composite.RecursiveCompositeController`) chooses one.
"""

import math

import numpy as np
from numba import njit

from ._blocks import VEC, check_vectors, feedback_wrench, reference_motion
from ._packing import (ADAPT_GRADIENT, CH_ACTIVE, CH_E, CH_JOINT, CH_Y, CONST_COLS, GAIN_K_D,
                       GAIN_P, I_ADAPT, I_DZ_E, I_DZ_S, I_E, I_ERR, I_FB0, I_FB1, I_FE, I_FROZEN,
                       I_BARRIER_C, I_G, I_GAMMA, I_H, I_IMPLICIT, I_K, I_KD_DIAG, I_LAM, I_LEAK,
                       I_NATURAL, I_PROJECT, I_P_DIAG, I_RETRACT_MIN, I_TRACKING, I_Y, LAMBDA,
                       NAT_K, NAT_P_NU, PHI_F, PHI_PREV, PSI_F, PSI_PREV, Q_PREV, S_LINK, TAU,
                       THETA_HAT, THETA_PREV, U_ROW, W_ROW)
from .adaptation import (adapt_link, diagonal_factor, implicit_solve, natural_ls_apply,
                         natural_ls_factor, project, retract_links, tracking_active,
                         update_least_squares)
from .channels import (axis_terms, close_channels, filter_step, filtered_output, predict_link,
                       start_channels)
from .joint_friction import (F_CAP, F_GAIN, F_HAT, F_K, F_PREV, F_R, F_SQ, F_VC, F_Y,
                             FRICTION_SIGNATURE, JPHI_F, JPHI_PREV, JPSI_F, JPSI_PREV, JU, JW,
                             adapt_joint, implicit_solve_joint, predict_joint, retract_term,
                             term_gain)
from .pseudo_inertia import natural_gain_apply
from .regressor import reference_wrench, regressor_row, regressor_terms
from .spatial import P0, propagate, transform_force_T

RCAC_SIGNATURE = f"{VEC}(float64[:, ::1], float64[:, :, ::1], {VEC}, {VEC}, {VEC}, {VEC}, {VEC})"
#: general_law's: rcac_step_kernel passes data, filt as jdata, jfilt (same types)
GENERAL_SIGNATURE = (f"{VEC}(float64[:, ::1], float64[:, :, ::1], float64[:, ::1], "
                     f"float64[:, :, ::1], boolean, {VEC}, {VEC}, {VEC}, {VEC}, {VEC})")


@njit(cache=True, inline="always")
def paper_options(chan, scal):
    """The paper's law's options, whatever the geometry: one channel (joint 1), the fixed
    gain, implicit update, no dead zone, no projection, no leakage, adapting."""
    return (chan.shape[0] == 1 and chan[0, CH_JOINT] == 0.0 and scal[I_ADAPT] == ADAPT_GRADIENT
            and scal[I_IMPLICIT] != 0.0 and scal[I_DZ_S] <= 0.0 and scal[I_DZ_E] <= 0.0
            and scal[I_PROJECT] == 0.0 and scal[I_FROZEN] == 0.0 and scal[I_LEAK] <= 0.0)


@njit(cache=True, inline="always")
def is_paper_law(chan, scal):
    """True for the paper's law exactly: :func:`paper_options` and the Euclidean geometry.
    The controller then runs :func:`paper_step` or :func:`paper_friction_step`."""
    return paper_options(chan, scal) and scal[I_NATURAL] == 0.0


@njit(cache=True, inline="always")
def is_paper_natural_law(chan, scal):
    """True for the paper's law in the natural geometry (doc/design.md §8, either metric):
    :func:`paper_options` and ``geometry="natural"``. Without the joint terms the controller
    then runs :func:`paper_natural_step`."""
    return paper_options(chan, scal) and scal[I_NATURAL] != 0.0


@njit(cache=True, inline="always")
def paper_law(data, filt, jdata, jfilt, joint, natural, q, qd, q_d, qd_d, qdd_d):
    """The one body of :func:`paper_step`, :func:`paper_friction_step` and
    :func:`paper_natural_step`: the paper's law (:func:`paper_options`) fused in one loop,
    with joint i's terms of doc/design.md §7 (``jdata``, ``jfilt``) when ``joint`` is true,
    else without them (``jdata``, ``jfilt`` unread), and in the natural geometry of
    doc/design.md §8 when ``natural`` is true (the gain ``P_eff(theta_hat_i)`` of either
    metric in eq 24's step 1, then the retraction; ``joint`` is then false). Each caller
    passes ``joint`` and ``natural`` as constants, so the compiler keeps one branch.

    The same equations, in the same floating-point order, as the general kernels with
    ``channels=[1]``: joint 1's axis ``a_j`` travels in registers, and each link's blocks
    are computed in place, with no per-link helper taking arrays (each such argument
    costs an atomic reference count in the loop). One allocation besides ``tau``.

    Joint 1's channel sees joint 1's terms only, so they join the Sherman-Morrison solve
    at link 1; every other joint's terms adapt from the tracking term alone.
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
    work = np.empty(n * 41 + 96, q.dtype)
    C = work[:9 * n].reshape((n, 9))              # eq 10's rotations
    Fs = work[9 * n:15 * n].reshape((n, 6))       # Y_ri theta_hat_i
    G = work[15 * n:28 * n].reshape((n, 13))      # Y_ri^T s_i
    R = work[28 * n:41 * n].reshape((n, 13))      # theta_hat_i - h P_i (...), eq 24 step 1
    F = work[41 * n:41 * n + 6]                   # F_ri during the backward pass
    Pg, t = work[41 * n + 6:41 * n + 19], work[41 * n + 19:41 * n + 32]   # natural: gain
    M4 = work[41 * n + 32:41 * n + 96].reshape((4, 4, 4))   # natural: 4x4 scratch
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
        if joint:                    # joint i's terms: Y_f,i and s_qi (eq 18's qd_ri, qdd_ri)
            jrow = jdata[i]
            qdr = qd_d[i] - row[LAMBDA] * (q[i] - q_d[i])
            sig = math.tanh(qdi / jrow[F_VC])
            jrow[F_Y] = qdd_d[i] - row[LAMBDA] * (qdi - qd_d[i])
            jrow[F_Y + 1] = qdr
            jrow[F_Y + 2] = sig
            jrow[F_SQ] = qdi - qdr
            if i == 0:                           # joint 1's terms in joint 1's channel
                for k in range(3):
                    ph = qdi if k == 0 else 0.0
                    ps = 0.0 if k == 0 else (qdi if k == 1 else sig)
                    jfilt[0, 0, JPHI_F + k], jfilt[0, 0, JPSI_F + k], w = filter_step(
                        first, jfilt[0, 0, JPHI_F + k], jfilt[0, 0, JPSI_F + k],
                        jfilt[0, 0, JPHI_PREV + k], jfilt[0, 0, JPSI_PREV + k], ph, ps, fe,
                        fb0, fb1, lam)
                    jfilt[0, 0, JPHI_PREV + k] = ph
                    jfilt[0, 0, JPSI_PREV + k] = ps
                    jfilt[0, 0, JW + k] = w
                    E += w * jrow[F_HAT + k]
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
        state[i, S_LINK], state[i, S_LINK + 1], state[i, S_LINK + 2] = svx, svy, svz
        state[i, S_LINK + 3], state[i, S_LINK + 4], state[i, S_LINK + 5] = swx, swy, swz
        # eq 19b's Y_ri theta_hat_i and eq 24's Y_ri^T s_i, neither forming Y_ri
        f = reference_wrench(row, CONST_COLS + THETA_HAT, dvx, dvy, dvz, dwx, dwy, dwz,
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
            filt[0, i, PHI_F + k], filt[0, i, PSI_F + k], w = filter_step(       # eq 22-23
                first, filt[0, i, PHI_F + k], filt[0, i, PSI_F + k], filt[0, i, PHI_PREV + k],
                filt[0, i, PSI_PREV + k], ph, ps, fe, fb0, fb1, lam)
            filt[0, i, PHI_PREV + k] = ph
            filt[0, i, PSI_PREV + k] = ps
            filt[0, i, W_ROW + k] = w
            E += w * state[i, THETA_HAT + k]
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
                acc -= const[i, GAIN_K_D + 7 * r] * state[i, S_LINK + r]
            else:
                for k in range(6):
                    acc -= const[i, GAIN_K_D + 6 * r + k] * state[i, S_LINK + k]
            F[r] += acc
        if joint:
            jrow = jdata[i]
            tau[i] = F[5] + (jrow[F_Y] * jrow[F_HAT] + jrow[F_Y + 1] * jrow[F_HAT + 1]
                             + jrow[F_Y + 2] * jrow[F_HAT + 2])             # eq 20
            for k in range(3):       # eq 24, step 1, joint i's terms
                gk = jrow[F_Y + k] * jrow[F_SQ]
                if i == 0:
                    gk -= gamma * jfilt[0, 0, JW + k] * y
                    jfilt[0, 0, JU + k] = jrow[F_GAIN + k] * jfilt[0, 0, JW + k]
                jrow[F_R + k] = jrow[F_HAT + k] - h * jrow[F_GAIN + k] * gk
        else:
            tau[i] = F[5]                                                    # eq 20
        # eq 24, step 1: R_i = theta_hat_i - h P_i (Y_ri^T s_i - gamma W_i^T y), U_i = P_i W_i^T
        for k in range(13):
            G[i, k] -= gamma * filt[0, i, W_ROW + k] * y
        if natural:                  # P_eff(theta_hat_i) of adapt_link, doc/design.md §8
            st = state[i]
            crow = const[i]
            for k in range(13):
                st[THETA_PREV + k] = st[THETA_HAT + k]
            if scal[I_BARRIER_C] > 0.0:           # (H / (c k_i) + P_i^-1)^-1, factored
                if p_diag:
                    diagonal_factor(st, scal[I_BARRIER_C] * crow[NAT_K], M4)
                else:
                    natural_ls_factor(st, scal[I_BARRIER_C] * crow[NAT_K], Pg, M4)
                natural_ls_apply(st, G[i], 0, Pg, 0, t, p_diag)
                for k in range(13):
                    R[i, k] = st[THETA_HAT + k] - h * Pg[k]
                natural_ls_apply(st, filt[0, i], W_ROW, filt[0, i], U_ROW, t, p_diag)
            else:                                 # k_i (Hessian of -log det)^-1, P_nu
                natural_gain_apply(st, THETA_HAT, G[i], 0, Pg, 0, crow[NAT_K], crow, NAT_P_NU)
                for k in range(13):
                    R[i, k] = st[THETA_HAT + k] - h * Pg[k]
                natural_gain_apply(st, THETA_HAT, filt[0, i], W_ROW, filt[0, i], U_ROW,
                                   crow[NAT_K], crow, NAT_P_NU)
        elif p_diag:
            for a in range(13):
                R[i, a] = state[i, THETA_HAT + a] - h * const[i, GAIN_P + 14 * a] * G[i, a]
                filt[0, i, U_ROW + a] = const[i, GAIN_P + 14 * a] * filt[0, i, W_ROW + a]
        else:
            for a in range(13):
                acc_r = 0.0
                acc_u = 0.0
                for c in range(13):
                    acc_r += const[i, GAIN_P + 13 * a + c] * G[i, c]
                    acc_u += const[i, GAIN_P + 13 * a + c] * filt[0, i, W_ROW + c]
                R[i, a] = state[i, THETA_HAT + a] - h * acc_r
                filt[0, i, U_ROW + a] = acc_u
    # eq 24, step 2, implicit (Sherman-Morrison, O(n)):
    # theta_hat+ = R - h gamma U (W R) / (1 + h gamma W U)
    w_dot_r = 0.0
    w_dot_u = 0.0
    for i in range(n):
        for k in range(13):
            w_dot_r += filt[0, i, W_ROW + k] * R[i, k]
            w_dot_u += filt[0, i, W_ROW + k] * filt[0, i, U_ROW + k]
    if joint:
        for k in range(3):
            w_dot_r += jfilt[0, 0, JW + k] * jdata[0, F_R + k]
            w_dot_u += jfilt[0, 0, JW + k] * jfilt[0, 0, JU + k]
    kc = h * gamma * w_dot_r / (1.0 + h * gamma * w_dot_u)
    if joint:
        for i in range(n):
            for k in range(3):
                jdata[i, F_HAT + k] = jdata[i, F_R + k]
        for k in range(3):
            jdata[0, F_HAT + k] -= kc * jfilt[0, 0, JU + k]
    for i in range(n):
        for k in range(13):
            state[i, THETA_HAT + k] = R[i, k] - kc * filt[0, i, U_ROW + k]
        state[i, TAU] = tau[i]
        state[i, Q_PREV] = q[i]
    if natural:
        retract_links(state, scal)                    # doc/design.md §8
    scal[I_K] += 1.0
    return tau


@njit(RCAC_SIGNATURE, cache=True)
def paper_step(data, filt, q, qd, q_d, qd_d, qdd_d):
    """:func:`rcac_step_kernel` for the paper's law (:func:`is_paper_law`): :func:`paper_law`
    without the joint terms, bit for bit the general kernel's results."""
    return paper_law(data, filt, data, filt, False, False, q, qd, q_d, qd_d, qdd_d)


@njit(RCAC_SIGNATURE, cache=True)
def paper_natural_step(data, filt, q, qd, q_d, qd_d, qdd_d):
    """:func:`rcac_step_kernel` for the paper's law in the natural geometry
    (:func:`is_paper_natural_law`, doc/design.md §8): :func:`paper_law` with the natural
    gain and the retraction, bit for bit the general kernel's results."""
    return paper_law(data, filt, data, filt, False, True, q, qd, q_d, qd_d, qdd_d)


@njit(FRICTION_SIGNATURE, cache=True)
def paper_friction_step(data, filt, jdata, jfilt, q, qd, q_d, qd_d, qdd_d):
    """:func:`friction_step_kernel` for the paper's law
    (:func:`is_paper_law`): :func:`paper_law` with the joint terms (doc/design.md §7)."""
    return paper_law(data, filt, jdata, jfilt, True, False, q, qd, q_d, qd_d, qdd_d)


@njit(GENERAL_SIGNATURE, cache=True)
def general_law(data, filt, jdata, jfilt, joint, q, qd, q_d, qd_d, qdd_d):
    """The one body of :func:`rcac_step_kernel` and :func:`friction_step_kernel`: one control
    period of eqs 18-24, any channels, any option of the adaptation step, with joint i's
    terms of doc/design.md §7 (``jdata``, ``jfilt``) when ``joint`` is true, else without
    them (``jdata``, ``jfilt`` unread). Returns tau (empty on bad input, code in scal[I_ERR]).

    Compiled once, eagerly, with ``joint`` a run-time flag (``GENERAL_SIGNATURE``), and
    called, not inlined, by both entries: inlining it into each, with ``joint`` a constant,
    compiled the body twice and tripled the cold compile (about 200 s against 75 s on the
    2-core VM) for no gain per step beyond the noise (same-process A/B, new over old,
    1.01-1.09 for the general laws, 1.08 for the unchanged fused kernel).
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
    m = chan.shape[0]
    # the implicit solve's scratch: with the joint terms, 2 + m, else 29 + m per channel
    work = np.empty(n * 41 + 148 + m * (m + (2 if joint else 29)), q.dtype)
    C = work[:9 * n].reshape((n, 9))              # eq 10's rotations
    Fs = work[9 * n:15 * n].reshape((n, 6))       # Y_ri theta_hat_i
    G = work[15 * n:28 * n].reshape((n, 13))      # Y_ri^T s_i
    R = work[28 * n:41 * n].reshape((n, 13))      # theta_hat_i - h P_i (...), eq 24 step 1
    grad, Pg, t = work[41 * n + 39:41 * n + 52], work[41 * n + 52:41 * n + 65], \
        work[41 * n + 65:41 * n + 78]
    F = work[41 * n + 78:41 * n + 84]             # F_ri during the backward pass
    pp = work[41 * n:41 * n + 26]                 # phi_ci, psi_ci of predict_link
    M4 = work[41 * n + 84:41 * n + 148].reshape((4, 4, 4))   # natural geometry's 4x4s
    o = 41 * n + 148                              # the implicit solve's scratch:
    A = work[o:o + m * m]                         # the m x m system (flat),
    z = work[o + m * m:o + m * (m + 1)]           # its right-hand side,
    order = work[o + m * (m + 1):o + m * (m + 2)]  # the active channels (by first link)
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
        st[S_LINK], st[S_LINK + 1], st[S_LINK + 2] = vx - rvx, vy - rvy, vz - rvz
        st[S_LINK + 3], st[S_LINK + 4], st[S_LINK + 5] = wx - rwx, wy - rwy, wz - rwz
        # eq 19b's Y_ri theta_hat_i and eq 24's Y_ri^T s_i, neither forming Y_ri
        f = reference_wrench(st, THETA_HAT, dvx, dvy, dvz, dwx, dwy, dwz, rvx, rvy, rvz, rwx, rwy,
                             rwz, wx, wy, wz, gx, gy, gz)
        for k in range(6):
            Fs[i, k] = f[k]
        regressor_row(G[i], vx - rvx, vy - rvy, vz - rvz, wx - rwx, wy - rwy, wz - rwz,
                      dvx, dvy, dvz, dwx, dwy, dwz, rvx, rvy, rvz, rwx, rwy, rwz,
                      wx, wy, wz, gx, gy, gz)
        predict_link(chan, filt, i, C, row, qd[i], V, g, st, coef, first, pp)
        if joint:    # joint i's terms: Y_f,i and s_qi (eq 18's qd_ri, qdd_ri), its share
            jrow = jdata[i]
            qdr = qd_d[i] - row[LAMBDA] * (q[i] - q_d[i])
            sig = math.tanh(qd[i] / jrow[F_VC])
            jrow[F_Y] = qdd_d[i] - row[LAMBDA] * (qd[i] - qd_d[i])
            jrow[F_Y + 1] = qdr
            jrow[F_Y + 2] = sig
            jrow[F_SQ] = qd[i] - qdr
            predict_joint(chan, jfilt, i, qd[i], sig, jrow, coef, first)
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
        feedback_wrench(row, Fs[i], st[S_LINK:S_LINK + 6], scal[I_KD_DIAG] != 0.0, F)   # eq 19b
        if not frozen:
            adapt_link(row, st, chan, filt, i, G, scal, tracking, R, grad, Pg, t, M4)
        if joint:
            jrow = jdata[i]
            tau[i] = F[5] + (jrow[F_Y] * jrow[F_HAT] + jrow[F_Y + 1] * jrow[F_HAT + 1]
                             + jrow[F_Y + 2] * jrow[F_HAT + 2])                    # eq 20
            if not frozen:
                if scal[I_NATURAL] != 0.0:        # doc/design.md §8: min(k_f x^2, P_f)
                    for k in range(3):
                        x = jrow[F_HAT + k]
                        jrow[F_PREV + k] = x
                        jrow[F_GAIN + k] = term_gain(jrow[F_K + k], jrow[F_CAP + k], x)
                adapt_joint(chan, jfilt, i, jrow, scal, tracking)
        else:
            tau[i] = F[5]                                                          # eq 20
    if frozen:
        pass
    elif scal[I_IMPLICIT] != 0.0:
        if joint:
            implicit_solve_joint(chan, filt, state, R, jfilt, jdata, A, z, order, scal)
        else:
            start = work[o + m * (m + 2):o + m * (m + 3)]  # their first links,
            Wt = work[o + m * (m + 3):o + m * (m + 16)].reshape((13, m))  # W_ci, U_ci at
            Ut = work[o + m * (m + 16):o + m * (m + 29)].reshape((13, m))  # link i, columns
            implicit_solve(chan, filt, state, R, A, z, order, start, Wt, Ut, scal)
    else:
        for i in range(n):
            for k in range(13):
                state[i, THETA_HAT + k] = R[i, k]
            if joint:
                for k in range(3):
                    jdata[i, F_HAT + k] = jdata[i, F_R + k]
    if not frozen and scal[I_ADAPT] != ADAPT_GRADIENT:
        update_least_squares(chan, filt, const, state, scal, grad, Pg)
    if not frozen and scal[I_PROJECT] != 0.0:
        project(const, state)
        if joint:
            for i in range(n):
                for k in range(3):
                    jdata[i, F_HAT + k] = max(jdata[i, F_HAT + k], 0.0)
    if not frozen and scal[I_NATURAL] != 0.0:
        retract_links(state, scal)                    # doc/design.md §8
        if joint:
            a_min = scal[I_RETRACT_MIN]
            for i in range(n):
                for k in range(3):
                    a_min = min(a_min, retract_term(jdata[i], F_PREV + k, F_HAT + k))
            scal[I_RETRACT_MIN] = a_min
    for i in range(n):
        state[i, TAU] = tau[i]
        state[i, Q_PREV] = q[i]
    scal[I_K] += 1.0
    return tau


@njit(RCAC_SIGNATURE, cache=True)
def rcac_step_kernel(data, filt, q, qd, q_d, qd_d, qdd_d):
    """One control period of eqs 18-24; returns tau (empty on bad input, code in scal[I_ERR]).

    ``data``, ``filt`` and ``chan`` follow the layout of :mod:`rcac_ros.core._packing`:
    :func:`general_law` without the joint terms.
    """
    return general_law(data, filt, data, filt, False, q, qd, q_d, qd_d, qdd_d)


@njit(FRICTION_SIGNATURE, cache=True)
def friction_step_kernel(data, filt, jdata, jfilt, q, qd, q_d, qd_d, qdd_d):
    """One control period of the law with joint terms (doc/design.md §7); returns tau.

    ``data``, ``filt`` as :func:`rcac_step_kernel`'s; ``jdata`` (n, JOINT_COLS) and
    ``jfilt`` (m, n, JFILT_COLS) of :mod:`rcac_ros.core.joint_friction` hold the joint
    terms: :func:`general_law` with them. Empty on bad input (code in ``scal[I_ERR]``).
    """
    return general_law(data, filt, jdata, jfilt, True, q, qd, q_d, qd_d, qdd_d)
