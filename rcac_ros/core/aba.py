"""O(n) forward dynamics: Featherstone's articulated-body algorithm on the paper's frames.

Per link (``[v; w]`` order, eq 14's ``M_i``):
    forward:   V_i = T V_{i-1} + z6 qd_i,   c_i = Tdot V_{i-1},   p_i = C_i V_i + G_i
    backward:  U_i = IA_i z6,  D_i = z6^T U_i + armature_i,
               u_i = tau_i - tau_f,i - z6^T pA_i     (tau_f: joint friction, doc/design.md §7)
               Ia = IA_i - U_i U_i^T / D_i,  pa = pA_i + Ia c_i + U_i u_i / D_i
               IA_{i-1} += T_i^T Ia T_i,      pA_{i-1} += T_i^T pa
    forward:   a' = T a_{i-1} + c_i,  qdd_i = (u_i - U_i^T a') / D_i,  a_i = a' + z6 qdd_i
"""

import numpy as np
from ._jit import njit

from ._validate import joint_vectors
from .crba import congruence_to_parent, spatial_inertia
from .regressor import link_wrench
from .spatial import JA, P0, RF0, TH0, joint_friction_torque, joint_rotation, \
    transform_force_T, transform_motion, z_cross_rate


@njit(cache=True)
def aba_kernel(kin, g, q, qd, tau):
    """``qdd`` for the packed model ``kin``, base-frame gravity ``g``."""
    n = q.shape[0]
    C = np.empty((n, 9), q.dtype)
    IA = np.empty((n, 6, 6), q.dtype)
    pA = np.empty((n, 6), q.dtype)
    c = np.empty((n, 6), q.dtype)
    U = np.empty((n, 6), q.dtype)
    u = np.empty(n, q.dtype)
    Dv = np.empty(n, q.dtype)
    qdd = np.empty(n, q.dtype)
    Ia = np.empty((1, 6, 6), q.dtype)
    vx = vy = vz = wx = wy = wz = 0.0
    gx, gy, gz = g[0], g[1], g[2]
    for i in range(n):
        row = kin[i]
        joint_rotation(row, RF0, q[i], C, i)
        tvx, tvy, tvz, twx, twy, twz = transform_motion(C, i, row[P0], row[P0 + 1], row[P0 + 2],
                                                        vx, vy, vz, wx, wy, wz)
        c[i, 0], c[i, 1] = z_cross_rate(qd[i], tvx, tvy)
        c[i, 3], c[i, 4] = z_cross_rate(qd[i], twx, twy)
        c[i, 2] = 0.0
        c[i, 5] = 0.0
        vx, vy, vz, wx, wy, wz = tvx, tvy, tvz, twx, twy, twz + qd[i]
        gx, gy, gz = (C[i, 0] * gx + C[i, 1] * gy + C[i, 2] * gz,
                      C[i, 3] * gx + C[i, 4] * gy + C[i, 5] * gz,
                      C[i, 6] * gx + C[i, 7] * gy + C[i, 8] * gz)
        f = link_wrench(row, TH0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, vx, vy, vz, wx, wy, wz,
                        gx, gy, gz)
        for k in range(6):
            pA[i, k] = f[k]
        spatial_inertia(row, TH0, IA, i)
    for i in range(n - 1, -1, -1):
        for k in range(6):
            U[i, k] = IA[i, k, 5]
        D = U[i, 5]
        r = kin[i]
        if r[JA] != 0.0:
            D += r[JA]
        Dv[i] = D
        tf = joint_friction_torque(r, qd[i])
        if tf != 0.0:
            u[i] = (tau[i] - tf) - pA[i, 5]
        else:
            u[i] = tau[i] - pA[i, 5]
        if i > 0:
            pa = np.empty(6, q.dtype)
            for a in range(6):
                for b in range(6):
                    Ia[0, a, b] = IA[i, a, b] - U[i, a] * U[i, b] / D
            for a in range(6):
                acc = pA[i, a] + U[i, a] * u[i] / D
                for b in range(6):
                    acc += Ia[0, a, b] * c[i, b]
                pa[a] = acc
            congruence_to_parent(C, i, r[P0], r[P0 + 1], r[P0 + 2], Ia, 0, IA, i - 1)
            f = transform_force_T(C, i, r[P0], r[P0 + 1], r[P0 + 2], pa[0], pa[1], pa[2],
                                  pa[3], pa[4], pa[5])
            for k in range(6):
                pA[i - 1, k] += f[k]
    ax = ay = az = bx = by = bz = 0.0
    for i in range(n):
        r = kin[i]
        ax, ay, az, bx, by, bz = transform_motion(C, i, r[P0], r[P0 + 1], r[P0 + 2],
                                                  ax, ay, az, bx, by, bz)
        ax += c[i, 0]
        ay += c[i, 1]
        bx += c[i, 3]
        by += c[i, 4]
        qdd[i] = (u[i] - (U[i, 0] * ax + U[i, 1] * ay + U[i, 2] * az + U[i, 3] * bx
                          + U[i, 4] * by + U[i, 5] * bz)) / Dv[i]
        bz += qdd[i]
    return qdd


def forward_dynamics(model, q, qd, tau):
    """Joint accelerations ``qdd = M^-1 (tau - C qd - G - tau_f)`` in O(n) (articulated bodies).

    ``M`` includes the armature and ``tau_f`` the joint friction (doc/design.md §7).

    Raises
    ------
    InputError
        If a vector has the wrong length or holds NaN/Inf.
    """
    q, qd, tau = joint_vectors(model.n, q=q, qd=qd, tau=tau)
    return aba_kernel(model.packed, model.gravity, q, qd, tau)
