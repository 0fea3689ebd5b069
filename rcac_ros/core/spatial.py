"""Compiled building blocks of the matrix-form Newton-Euler recursion (eqs 9-12, 15).

Motion vectors are ``V = [v; w]`` and force vectors ``F = [f; n]``: linear part
first (doc/design.md §1). Frame ``i`` is reached from frame ``i-1`` by ``p_i``, then
``R_fix_i``, then ``Rz(q_i)``; ``C = iC_{i-1} = (R_fix_i Rz(q_i))^T``.

The packed per-link model row (``RobotModel`` is unpacked once into this layout, its
field ``packed``, see :func:`pack_kinematics`) is ``[p (3), R_fix row-major (9), theta (13),
armature, damping, friction, v_c]`` (the joint terms of doc/design.md §7).

All kernels are scalar code compiled by numba with ``cache=True``. They never
allocate from another dtype than their inputs, so running them with
``NUMBA_DISABLE_JIT=1`` on object arrays counts their arithmetic exactly
(:mod:`rcac_ros.tools.bench.opcount`).
"""

import math

from ._jit import njit
#: the packed model row's columns (:func:`rcac_ros.core.model.pack_kinematics`)
from .model import JA, JD, JF, JV, KIN_COLS, P0, RF0, TH0  # noqa: F401  (re-exported)


@njit(cache=True, inline="always")
def joint_friction_torque(row, qd):
    """``damping qd + friction tanh(qd / v_c)`` of one joint (doc/design.md §7).

    Exactly 0.0 when both terms are zero (the rigid model's arithmetic is then unchanged).
    """
    t = 0.0
    if row[JD] != 0.0:
        t = row[JD] * qd
    if row[JF] != 0.0:
        t += row[JF] * math.tanh(qd / row[JV])
    return t


@njit(cache=True)
def joint_rotation(row, rf, q, C, i):
    """Eq 10's rotation: ``C[i] = (R_fix Rz(q))^T`` as 9 row-major entries.

    ``row`` is the packed model row array, ``rf`` the column where R_fix starts.
    """
    c = math.cos(q)
    s = math.sin(q)
    r00, r01, r02 = row[rf], row[rf + 1], row[rf + 2]
    r10, r11, r12 = row[rf + 3], row[rf + 4], row[rf + 5]
    r20, r21, r22 = row[rf + 6], row[rf + 7], row[rf + 8]
    # rows of C are the columns of R_fix Rz(q)
    C[i, 0] = c * r00 + s * r01
    C[i, 1] = c * r10 + s * r11
    C[i, 2] = c * r20 + s * r21
    C[i, 3] = c * r01 - s * r00
    C[i, 4] = c * r11 - s * r10
    C[i, 5] = c * r21 - s * r20
    C[i, 6] = r02
    C[i, 7] = r12
    C[i, 8] = r22


@njit(cache=True)
def rotate(C, i, x, y, z):
    """``C[i] @ (x, y, z)``."""
    return (C[i, 0] * x + C[i, 1] * y + C[i, 2] * z,
            C[i, 3] * x + C[i, 4] * y + C[i, 5] * z,
            C[i, 6] * x + C[i, 7] * y + C[i, 8] * z)


@njit(cache=True)
def rotate_T(C, i, x, y, z):
    """``C[i]^T @ (x, y, z)``."""
    return (C[i, 0] * x + C[i, 3] * y + C[i, 6] * z,
            C[i, 1] * x + C[i, 4] * y + C[i, 7] * z,
            C[i, 2] * x + C[i, 5] * y + C[i, 8] * z)


@njit(cache=True)
def transform_motion(C, i, px, py, pz, vx, vy, vz, wx, wy, wz):
    """Eq 10: ``iT_{i-1} V = [C (v + w x p); C w]``."""
    ux = vx + wy * pz - wz * py
    uy = vy + wz * px - wx * pz
    uz = vz + wx * py - wy * px
    a, b, c = rotate(C, i, ux, uy, uz)
    d, e, f = rotate(C, i, wx, wy, wz)
    return a, b, c, d, e, f


@njit(cache=True)
def transform_force_T(C, i, px, py, pz, fx, fy, fz, nx, ny, nz):
    """Eq 15's transpose: ``iT_{i-1}^T F = [C^T f; p x (C^T f) + C^T n]``."""
    a, b, c = rotate_T(C, i, fx, fy, fz)
    d, e, f = rotate_T(C, i, nx, ny, nz)
    return a, b, c, d + py * c - pz * b, e + pz * a - px * c, f + px * b - py * a


@njit(cache=True)
def z_cross_rate(qd, x, y):
    """Eq 12's action ``-(z qd)^x`` on the first two components (the third is zero)."""
    return qd * y, -qd * x


@njit(cache=True)
def propagate(C, i, px, py, pz, qd, x, xd, u, ud):
    """Eqs 9 and 11 for any motion vector and its rate: ``(x_i, xdot_i)`` from link i-1's.

    ``x_i = T x + z6 u``, ``xdot_i = T xdot + Tdot x + z6 ud``, with ``Tdot x = -(z qd)^x (T x)``
    (eq 12). ``(u, ud) = (qd, qdd)`` gives V and Vdot; ``(qd_r, qdd_r)`` the reference motion
    of eq 18; ``(0, 0)`` carries joint 1's axis ``a_j`` and ``adot_j`` (doc/design.md §4).
    """
    tvx, tvy, tvz, twx, twy, twz = transform_motion(C, i, px, py, pz,
                                                    x[0], x[1], x[2], x[3], x[4], x[5])
    dvx, dvy, dvz, dwx, dwy, dwz = transform_motion(C, i, px, py, pz,
                                                    xd[0], xd[1], xd[2], xd[3], xd[4], xd[5])
    cvx, cvy = z_cross_rate(qd, tvx, tvy)
    cwx, cwy = z_cross_rate(qd, twx, twy)
    return ((tvx, tvy, tvz, twx, twy, twz + u),
            (dvx + cvx, dvy + cvy, dvz, dwx + cwx, dwy + cwy, dwz + ud))
