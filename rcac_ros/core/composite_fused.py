"""The fused step kernels of the recursive composite law: the paper's law in one loop body.

:func:`paper_step` is the paper's law (:func:`is_paper_law`: one channel, joint 1, the fixed
gain, the implicit update) fused in one loop body, bit for bit the results of the general
kernel of :mod:`rcac_ros.core.composite_kernels` (test/core/test_channels.py); it is the
speed (doc/tools.md, ``rcac bench``). :func:`paper_friction_step` is the same body with the
joint terms (doc/design.md §7), :func:`paper_natural_step` in the natural geometry
(doc/design.md §8). A module of its own so that it compiles apart from the general kernel:
``python -m rcac_ros.tools.warm`` compiles the two in two processes at a time.

All read and write the packed arrays of :mod:`rcac_ros.core._packing`; the controller
(:class:`~rcac_ros.core.composite.RecursiveCompositeController`) chooses one.
"""

import math

import numpy as np
from ._jit import kernel, njit

from ._blocks import RCAC_SIGNATURE, feedback_wrench, packed_views, reference_motion, \
    rejects_input
from ._packing import (ADAPT_GRADIENT, CH_ACTIVE, CH_E, CH_JOINT, CH_Y, CONST_COLS, GAIN_P,
                       I_ADAPT, I_DZ_E, I_DZ_S, I_E, I_FB0, I_FB1, I_FE, I_FROZEN, I_G, I_GAMMA,
                       I_H, I_HOLD, I_IMPLICIT, I_JOINT_LS, I_K, I_KD_DIAG, I_LAM, I_LEAK,
                       I_NATURAL, I_PROJECT, I_P_DIAG, I_TRACKING, I_Y, LAMBDA, PHI_F, PHI_PREV,
                       PSI_F, PSI_PREV, Q_PREV, S_LINK, TAU, THETA_HAT, U_ROW, W_ROW)
from .natural_step import (LANES, RETRACT_ROWS, lane_update, natural_gain_rows,
                           retract_lanes)
from .channels import axis_terms, filter_step, filtered_output
from .joint_friction import (F_GAIN, F_HAT, F_R, F_SQ, F_VC, F_Y, FOLLOW_TIME, FRICTION_SIGNATURE,
                             JPHI_F, JPHI_PREV, JPSI_F, JPSI_PREV, JU, JW, rotor)
from .regressor import reference_wrench, regressor_terms
from .spatial import P0, propagate, transform_force_T


def paper_options(chan, scal):
    """The paper's law's options, whatever the geometry: one channel (joint 1), the fixed
    gain, implicit update, no dead zone, no projection, no leakage; adapting or frozen
    (``set_adaptation``: the same kernel, so that a freeze never needs another one).
    Plain Python, as the two below: the controller chooses its kernel with them, and
    choosing compiles nothing."""
    return (chan.shape[0] == 1 and chan[0, CH_JOINT] == 0.0 and scal[I_ADAPT] == ADAPT_GRADIENT
            and scal[I_IMPLICIT] != 0.0 and scal[I_DZ_S] <= 0.0 and scal[I_DZ_E] <= 0.0
            and scal[I_PROJECT] == 0.0 and scal[I_LEAK] <= 0.0 and scal[I_JOINT_LS] == 0.0
            and scal[I_HOLD] == 0.0)


def is_paper_law(chan, scal):
    """True for the paper's law exactly: :func:`paper_options` and the Euclidean geometry.
    The controller then runs :func:`paper_step` or :func:`paper_friction_step`."""
    return paper_options(chan, scal) and scal[I_NATURAL] == 0.0


def is_paper_natural_law(chan, scal):
    """True for the paper's law in the natural geometry (doc/design.md §8, either metric):
    :func:`paper_options` and ``geometry="natural"``. Without the joint terms the controller
    then runs :func:`paper_natural_step`."""
    return paper_options(chan, scal) and scal[I_NATURAL] != 0.0


@njit(inline="always")
def paper_law(data, filt, jdata, jfilt, joint, natural, q, qd, q_d, qd_d, qdd_d):
    """The one body of :func:`paper_step`, :func:`paper_friction_step` and
    :func:`paper_natural_step`: the paper's law (:func:`paper_options`) fused in one loop,
    with joint i's terms of doc/design.md §7 (``jdata``, ``jfilt``) when ``joint`` is true,
    else without them (``jdata``, ``jfilt`` unread), and in the natural geometry of
    doc/design.md §8 when ``natural`` is true (the gain ``P_eff(theta_hat_i)`` of either
    metric in eq 24's step 1, then the retraction; ``joint`` is then false). Inlined into
    each entry, which passes ``joint`` and ``natural`` as constants: numba prunes the
    branches they rule out before typing, so each entry compiles only its own law (the
    default law's kernel compiles without the joint terms' and the natural geometry's code)
    and runs without a call.

    The same equations, in the same floating-point order, as the general kernels with
    ``channels=[1]``: joint 1's axis ``a_j`` travels in registers, and each link's blocks
    are computed in place, with no per-link helper taking arrays (each such argument
    costs an atomic reference count in the loop). One allocation besides ``tau``.

    Joint 1's channel sees joint 1's terms only, so they join the Sherman-Morrison solve
    at link 1; every other joint's terms adapt from the tracking term alone.
    """
    n, const, state, scal, chan = packed_views(data, filt)
    if rejects_input(scal, n, q, qd, q_d, qd_d, qdd_d):
        return np.empty(0, q.dtype)
    # natural: P_eff G_i, or the barrier metric's retraction lanes (retract_lanes)
    work = np.empty(n * 41 + 6 + (RETRACT_ROWS * LANES if natural else 13), q.dtype)
    C = work[:9 * n].reshape((n, 9))              # eq 10's rotations
    Fs = work[9 * n:15 * n].reshape((n, 6))       # Y_ri theta_hat_i
    G = work[15 * n:28 * n].reshape((n, 13))      # Y_ri^T s_i
    R = work[28 * n:41 * n].reshape((n, 13))      # theta_hat_i - h P_i (...), eq 24 step 1
    F = work[41 * n:41 * n + 6]                   # F_ri during the backward pass
    Pg = work[41 * n + 6:]                        # natural: P_eff G_i (13), lanes
    tau = np.empty(n, q.dtype)
    lam, h, gamma = scal[I_LAM], scal[I_H], scal[I_GAMMA]
    fe, fb0, fb1 = scal[I_FE], scal[I_FB0], scal[I_FB1]
    first = scal[I_K] == 0.0
    frozen = scal[I_FROZEN] != 0.0                 # set_adaptation(False): tau and filters only
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
    scal[I_E], scal[I_Y], scal[I_TRACKING] = E, y, 0.0 if frozen else 1.0
    for k in range(6):
        F[k] = 0.0
    for i in range(n - 1, -1, -1):
        if i < n - 1:
            F[0], F[1], F[2], F[3], F[4], F[5] = transform_force_T(
                C, i + 1, const[i + 1, P0], const[i + 1, P0 + 1], const[i + 1, P0 + 2],
                F[0], F[1], F[2], F[3], F[4], F[5])
        feedback_wrench(const, state, Fs, i, kd_diag, F)    # eq 19b
        if joint:
            jrow = jdata[i]
            k_q = rotor(jrow, False, min(1.0, h / FOLLOW_TIME))     # doc/design.md §7
            tau[i] = F[5] + (jrow[F_Y] * jrow[F_HAT] + jrow[F_Y + 1] * jrow[F_HAT + 1]
                             + jrow[F_Y + 2] * jrow[F_HAT + 2]) - k_q * jrow[F_SQ]  # eq 20
        else:
            tau[i] = F[5]                                                    # eq 20
        if frozen:
            continue
        if joint:
            for k in range(3):       # eq 24, step 1, joint i's terms
                gk = jrow[F_Y + k] * jrow[F_SQ]
                if i == 0:
                    gk -= gamma * jfilt[0, 0, JW + k] * y
                    jfilt[0, 0, JU + k] = jrow[F_GAIN + k] * jfilt[0, 0, JW + k]
                jrow[F_R + k] = jrow[F_HAT + k] - h * jrow[F_GAIN + k] * gk
        # eq 24, step 1: R_i = theta_hat_i - h P_i (Y_ri^T s_i - gamma W_i^T y), U_i = P_i W_i^T
        for k in range(13):
            G[i, k] -= gamma * filt[0, i, W_ROW + k] * y
        if natural:                  # P_eff(theta_hat_i): natural_gain_rows, after the loop
            continue
        if p_diag:
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
    if frozen:
        for i in range(n):
            state[i, TAU] = tau[i]
            state[i, Q_PREV] = q[i]
        scal[I_K] += 1.0
        return tau
    lanes = False
    if natural:      # eq 24, step 1 with P_eff(theta_hat_i) (doc/design.md §8), one call
        lanes = natural_gain_rows(data, filt, G, R, Pg)
    if natural and lanes:           # step 2 from the barrier's lane buffers: the same numbers
        lane_update(data, filt, h, gamma)
        for i in range(n):
            state[i, TAU] = tau[i]
            state[i, Q_PREV] = q[i]
    else:
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
        retract_lanes(data, Pg)                       # doc/design.md §8
    scal[I_K] += 1.0
    return tau


@kernel(RCAC_SIGNATURE)
def paper_step(data, filt, q, qd, q_d, qd_d, qdd_d):
    """:func:`rcac_step_kernel` for the paper's law (:func:`is_paper_law`): :func:`paper_law`
    without the joint terms, bit for bit the general kernel's results."""
    return paper_law(data, filt, data, filt, False, False, q, qd, q_d, qd_d, qdd_d)


@kernel(RCAC_SIGNATURE)
def paper_natural_step(data, filt, q, qd, q_d, qd_d, qdd_d):
    """:func:`rcac_step_kernel` for the paper's law in the natural geometry
    (:func:`is_paper_natural_law`, doc/design.md §8): :func:`paper_law` with the natural
    gain and the retraction, bit for bit the general kernel's results."""
    return paper_law(data, filt, data, filt, False, True, q, qd, q_d, qd_d, qdd_d)


@kernel(FRICTION_SIGNATURE)
def paper_friction_step(data, filt, jdata, jfilt, q, qd, q_d, qd_d, qdd_d):
    """:func:`friction_step_kernel` for the paper's law
    (:func:`is_paper_law`): :func:`paper_law` with the joint terms (doc/design.md §7)."""
    return paper_law(data, filt, jdata, jfilt, True, False, q, qd, q_d, qd_d, qdd_d)
