"""Inverse dynamics by the matrix-form recursive Newton-Euler algorithm (eqs 9, 11, 15, 16)."""

import numpy as np
from ._jit import njit

from ._validate import joint_vectors
from .regressor import link_wrench
from .spatial import JA, P0, RF0, TH0, joint_friction_torque, joint_rotation, propagate, \
    rotate, transform_force_T


@njit(cache=True)
def rnea_kernel(kin, g, q, qd, qdd):
    """tau for the packed model ``kin`` (rows ``[p, R_fix, theta]``) and gravity ``g`` (base).

    Forward (i = 1..n):  V_i = T V_{i-1} + z6 qd_i                       (eq 9)
                         Vdot_i = T Vdot_{i-1} + Tdot V_{i-1} + z6 qdd_i   (eq 11)
                         F*_i = M_i Vdot_i + C_i V_i + G_i                 (eq 13)
    Backward (i = n..1): F_i = (i+1 T_i)^T F_{i+1} + F*_i,  tau_i = z6^T F_i   (eqs 15, 16)
    Joint terms (doc/design.md §7): tau_i += armature_i qdd_i + damping_i qd_i
                                             + friction_i tanh(qd_i / v_c)
    """
    n = q.shape[0]
    C = np.empty((n, 9), q.dtype)
    Fs = np.empty((n, 6), q.dtype)
    tau = np.empty(n, q.dtype)
    V = Vd = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    gx, gy, gz = g[0], g[1], g[2]
    for i in range(n):
        row = kin[i]
        joint_rotation(row, RF0, q[i], C, i)
        V, Vd = propagate(C, i, row[P0], row[P0 + 1], row[P0 + 2], qd[i], V, Vd, qd[i], qdd[i])
        vx, vy, vz, wx, wy, wz = V
        ax, ay, az, bx, by, bz = Vd
        gx, gy, gz = rotate(C, i, gx, gy, gz)
        f = link_wrench(row, TH0, ax, ay, az, bx, by, bz, vx, vy, vz, wx, wy, wz, gx, gy, gz)
        for k in range(6):
            Fs[i, k] = f[k]
    fx = fy = fz = nx = ny = nz = 0.0
    for i in range(n - 1, -1, -1):
        if i < n - 1:
            r = kin[i + 1]
            fx, fy, fz, nx, ny, nz = transform_force_T(C, i + 1, r[P0], r[P0 + 1], r[P0 + 2],
                                                       fx, fy, fz, nx, ny, nz)
        fx, fy, fz = fx + Fs[i, 0], fy + Fs[i, 1], fz + Fs[i, 2]
        nx, ny, nz = nx + Fs[i, 3], ny + Fs[i, 4], nz + Fs[i, 5]
        tau[i] = nz
        r = kin[i]
        if r[JA] != 0.0:
            tau[i] += r[JA] * qdd[i]
        tf = joint_friction_torque(r, qd[i])
        if tf != 0.0:
            tau[i] += tf
    return tau


def inverse_dynamics(model, q, qd, qdd):
    """Joint torques ``tau = M(q) qdd + C(q, qd) qd + G(q) + tau_f`` by the paper's recursion.

    ``M`` includes the armature on its diagonal and ``tau_f`` is the joint friction,
    ``damping qd + friction tanh(qd / v_c)`` (doc/design.md §7).

    Parameters
    ----------
    model : RobotModel
    q, qd, qdd : array_like, shape (n,)

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    InputError
        If a vector has the wrong length or holds NaN/Inf.
    """
    q, qd, qdd = joint_vectors(model.n, q=q, qd=qd, qdd=qdd)
    return rnea_kernel(model.packed, model.gravity, q, qd, qdd)
