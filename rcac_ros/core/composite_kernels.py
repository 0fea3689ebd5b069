"""The general step kernels of the recursive composite law: one control period of eqs 18-24.

- :func:`rcac_step_kernel`: any channels (:mod:`rcac_ros.core.channels`), any option of the
  adaptation step (:mod:`rcac_ros.core.adaptation`), either geometry;
- :func:`friction_step_kernel`: the same body (:func:`general_law`) with the joint terms
  (doc/design.md §7) switched on by a flag.

The paper's law also runs a fused body, bit for bit the same results and faster
(:mod:`rcac_ros.core.composite_fused`). All read and write the packed arrays of
:mod:`rcac_ros.core._packing`; the controller
(:class:`~rcac_ros.core.composite.RecursiveCompositeController`) chooses one.
"""

import math

import numpy as np
from ._jit import kernel, njit

from ._blocks import RCAC_SIGNATURE, VEC, feedback_wrench, reference_motion, \
    rejects_input, unmanaged, unmanaged_block, unmanaged_views
from ._packing import (ADAPT_GRADIENT, CONST_COLS, I_ADAPT, I_FE, I_FB0, I_FB1, I_FROZEN, I_G,
                       I_H, I_HOLD, I_IMPLICIT, I_JOINT_LS, I_K, I_KD_DIAG, I_LAM, I_NATURAL,
                       I_PROJECT, I_RETRACT_MIN, I_TRACKING, LAMBDA, Q_PREV, S_LINK, TAU, TAU_FF,
                       THETA_HAT)
from .adaptation import adapt_link, implicit_solve, project, tracking_active, update_least_squares
from .natural_step import retract_links
from .channels import close_channels, predict_link, start_channels
from .joint_friction import (F_CAP, F_GAIN, F_HAT, F_K, F_PREV, F_R, F_SQ, F_VC, F_Y,
                             FOLLOW_TIME, FRICTION_SIGNATURE, adapt_joint, follow_gain,
                             implicit_solve_joint, predict_joint, retract_term, rotor,
                             term_gain, update_joint_least_squares)
from .regressor import reference_wrench, regressor_terms
from .spatial import P0, transform_force_T

#: general_law's: rcac_step_kernel passes data, filt as jdata, jfilt (same types)
GENERAL_SIGNATURE = (f"{VEC}(float64[:, ::1], float64[:, :, ::1], float64[:, ::1], "
                     f"float64[:, :, ::1], boolean, {VEC}, {VEC}, {VEC}, {VEC}, {VEC}, {VEC})")


@njit(cache=True, inline="always")
def scratch(data, filt, joint):
    """:func:`general_law`'s scratch for the law of ``data``, ``filt``: with n links and m
    channels, ``41 n + 148`` and, for the implicit solve, ``m (m + 2)`` with the joint terms,
    else ``m (m + 29)``."""
    n, m = data.shape[0] - 1, filt.shape[0]
    return np.empty(n * 41 + 148 + m * (m + (2 if joint else 29)), data.dtype)


@kernel(GENERAL_SIGNATURE)
def general_law(data, filt, jdata, jfilt, joint, work, q, qd, q_d, qd_d, qdd_d):
    """The one body of :func:`rcac_step_kernel` and :func:`friction_step_kernel`: one control
    period of eqs 18-24, any channels, any option of the adaptation step, with joint i's
    terms of doc/design.md §7 (``jdata``, ``jfilt``) when ``joint`` is true, else without
    them (``jdata``, ``jfilt`` unread). ``work``: :func:`scratch`'s. Returns tau (empty on
    bad input, code in scal[I_ERR]).

    Compiled once, with ``joint`` a run-time flag (``GENERAL_SIGNATURE``), and called, not
    inlined, by both entries: inlined into each with ``joint`` a constant, the body compiles
    twice for no measurable gain per step.

    Every array it reads or writes, and every view of one, is unmanaged
    (:func:`~rcac_ros.core._blocks.unmanaged`, :func:`~rcac_ros.core._blocks.unmanaged_views`:
    C-contiguous rows, so that each column is at a fixed offset): the links' and channels'
    helpers, inlined at every link, then count no references. All are arguments, held by
    the entry for the length of the call; ``tau`` alone is allocated here.
    """
    data, filt = unmanaged(data), unmanaged(filt)
    jdata, jfilt = unmanaged(jdata), unmanaged(jfilt)
    q, qd, q_d, qd_d, qdd_d = unmanaged(q), unmanaged(qd), unmanaged(q_d), unmanaged(qd_d), \
        unmanaged(qdd_d)
    n, const, state, scal, chan = unmanaged_views(data, filt)
    if rejects_input(scal, n, q, qd, q_d, qd_d, qdd_d):
        return np.empty(0, q.dtype)
    m = chan.shape[0]
    C = unmanaged_block(work, 0, (n, 9))             # eq 10's rotations
    Fs = unmanaged_block(work, 9 * n, (n, 6))        # Y_ri theta_hat_i
    G = unmanaged_block(work, 15 * n, (n, 13))       # Y_ri^T s_i
    R = unmanaged_block(work, 28 * n, (n, 13))       # theta_hat_i - h P_i (...), eq 24 step 1
    pp = unmanaged_block(work, 41 * n, (26,))        # phi_ci, psi_ci of predict_link
    grad = unmanaged_block(work, 41 * n + 39, (13,))
    Pg = unmanaged_block(work, 41 * n + 52, (13,))
    t = unmanaged_block(work, 41 * n + 65, (13,))
    F = unmanaged_block(work, 41 * n + 78, (6,))     # F_ri during the backward pass
    M4 = unmanaged_block(work, 41 * n + 84, (4, 4, 4))   # natural geometry's 4x4s
    o = 41 * n + 148                                 # the implicit solve's scratch:
    A = unmanaged_block(work, o, (m * m,))           # the m x m system (flat),
    z = unmanaged_block(work, o + m * m, (m,))       # its right-hand side,
    order = unmanaged_block(work, o + m * (m + 1), (m,))  # the active channels (by first link)
    coef = (scal[I_FE], scal[I_FB0], scal[I_FB1], scal[I_LAM])
    tau = np.empty(n, q.dtype)
    first = scal[I_K] == 0.0
    start_channels(chan, state, scal, q, first)
    zero = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    V, Vr, Vdr = zero, zero, zero                      # V_i, V_ri, Vdot_ri
    g = (scal[I_G], scal[I_G + 1], scal[I_G + 2])
    for i in range(n):
        row = data[i]                                  # link i: constants, then state
        V, Vr, Vdr, g = reference_motion(C, i, row, q[i], qd[i], q_d[i], qd_d[i], qdd_d[i],
                                         V, Vr, Vdr, g)
        vx, vy, vz, wx, wy, wz = V
        rvx, rvy, rvz, rwx, rwy, rwz = Vr
        dvx, dvy, dvz, dwx, dwy, dwz = Vdr
        gx, gy, gz = g
        state[i, S_LINK], state[i, S_LINK + 1], state[i, S_LINK + 2] = \
            vx - rvx, vy - rvy, vz - rvz
        state[i, S_LINK + 3], state[i, S_LINK + 4], state[i, S_LINK + 5] = \
            wx - rwx, wy - rwy, wz - rwz
        # eq 19b's Y_ri theta_hat_i and eq 24's Y_ri^T s_i, neither forming Y_ri
        f = reference_wrench(row, CONST_COLS + THETA_HAT, dvx, dvy, dvz, dwx, dwy, dwz, rvx, rvy,
                             rvz, rwx, rwy, rwz, wx, wy, wz, gx, gy, gz)
        for k in range(6):
            Fs[i, k] = f[k]
        y = regressor_terms(vx - rvx, vy - rvy, vz - rvz, wx - rwx, wy - rwy, wz - rwz,
                            dvx, dvy, dvz, dwx, dwy, dwz, rvx, rvy, rvz, rwx, rwy, rwz,
                            wx, wy, wz, gx, gy, gz)
        for k in range(13):
            G[i, k] = y[k]
        predict_link(chan, filt, i, C, (row[P0], row[P0 + 1], row[P0 + 2]), qd[i], V, g, state,
                     coef, first, pp)
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
    kd_diag = scal[I_KD_DIAG] != 0.0
    tracking = tracking_active(const, scal, q, qd, q_d, qd_d) and not frozen
    scal[I_TRACKING] = 1.0 if tracking else 0.0
    for k in range(6):
        F[k] = 0.0
    hold = scal[I_HOLD] != 0.0
    ff = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)               # hold: the model's wrench alone
    for i in range(n - 1, -1, -1):
        if i < n - 1:
            F[0], F[1], F[2], F[3], F[4], F[5] = transform_force_T(
                C, i + 1, const[i + 1, P0], const[i + 1, P0 + 1], const[i + 1, P0 + 2], F[0],
                F[1], F[2], F[3], F[4], F[5])
        feedback_wrench(const, state, Fs, i, kd_diag, F)                    # eq 19b
        if hold:
            if i < n - 1:
                ff = transform_force_T(C, i + 1, const[i + 1, P0], const[i + 1, P0 + 1],
                                       const[i + 1, P0 + 2], *ff)
            ff = (ff[0] + Fs[i, 0], ff[1] + Fs[i, 1], ff[2] + Fs[i, 2], ff[3] + Fs[i, 3],
                  ff[4] + Fs[i, 4], ff[5] + Fs[i, 5])
        if not frozen:
            adapt_link(const, state, chan, filt, i, G, scal, tracking, R, grad, Pg, t, M4)
        if joint:
            jrow = jdata[i]
            follow = min(1.0, scal[I_H] / FOLLOW_TIME)   # doc/design.md §7, the rotor
            k_q = rotor(jrow, scal[I_NATURAL] != 0.0, follow)
            joint_model = (jrow[F_Y] * jrow[F_HAT] + jrow[F_Y + 1] * jrow[F_HAT + 1]
                           + jrow[F_Y + 2] * jrow[F_HAT + 2])             # Y_f,i theta_f_hat_i
            tau[i] = F[5] + joint_model - k_q * jrow[F_SQ]                          # eq 20
            if not frozen:
                if scal[I_NATURAL] != 0.0:        # doc/design.md §8: min(k_f x^2, P_f)
                    a = follow
                    for k in range(3):
                        x = jrow[F_HAT + k]
                        jrow[F_PREV + k] = x
                        jrow[F_K + k] = follow_gain(jrow[F_K + k], jrow[F_CAP + k], x, a)
                        jrow[F_GAIN + k] = term_gain(jrow[F_K + k], jrow[F_CAP + k], x)
                adapt_joint(chan, jfilt, i, jrow, scal, tracking)
        else:
            tau[i] = F[5]                                                          # eq 20
        if hold:                                # doc/design.md §6, "The hold"
            model = ff[5] + joint_model if joint else ff[5]
            if not first:
                tau[i] += 0.5 * (model - state[i, TAU_FF])
            state[i, TAU_FF] = model
    if frozen:
        pass
    elif scal[I_IMPLICIT] != 0.0:
        if joint:
            implicit_solve_joint(chan, filt, state, R, jfilt, jdata, A, z, order, scal)
        else:
            start = unmanaged_block(work, o + m * (m + 2), (m,))  # their first links,
            Wt = unmanaged_block(work, o + m * (m + 3), (13, m))    # W_ci, U_ci at
            Ut = unmanaged_block(work, o + m * (m + 16), (13, m))   # link i, columns
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
    if joint and not frozen and scal[I_JOINT_LS] != 0.0:
        update_joint_least_squares(chan, jfilt, jdata, scal, grad)     # doc/design.md §7
    if not frozen and scal[I_PROJECT] != 0.0:
        project(const, state)
        if joint:
            for i in range(n):
                for k in range(3):
                    jdata[i, F_HAT + k] = max(jdata[i, F_HAT + k], 0.0)
    if not frozen and scal[I_NATURAL] != 0.0:
        retract_links(data)                           # doc/design.md §8
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


@kernel(RCAC_SIGNATURE, calls=(general_law,))
def rcac_step_kernel(data, filt, q, qd, q_d, qd_d, qdd_d):
    """One control period of eqs 18-24; returns tau (empty on bad input, code in scal[I_ERR]).

    ``data``, ``filt`` and ``chan`` follow the layout of :mod:`rcac_ros.core._packing`:
    :func:`general_law` without the joint terms.
    """
    return general_law(data, filt, data, filt, False, scratch(data, filt, False), q, qd, q_d,
                       qd_d, qdd_d)


@kernel(FRICTION_SIGNATURE, calls=(general_law,))
def friction_step_kernel(data, filt, jdata, jfilt, q, qd, q_d, qd_d, qdd_d):
    """One control period of the law with joint terms (doc/design.md §7); returns tau.

    ``data``, ``filt`` as :func:`rcac_step_kernel`'s; ``jdata`` (n, JOINT_COLS) and
    ``jfilt`` (m, n, JFILT_COLS) of :mod:`rcac_ros.core.joint_friction` hold the joint
    terms: :func:`general_law` with them. Empty on bad input (code in ``scal[I_ERR]``).
    """
    return general_law(data, filt, jdata, jfilt, True, scratch(data, filt, True), q, qd, q_d,
                       qd_d, qdd_d)
