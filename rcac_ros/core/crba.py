"""Joint-space mass matrix by the composite-rigid-body algorithm on the paper's frames."""

import numpy as np
from ._jit import njit

from ._validate import joint_vectors
from .spatial import JA, P0, RF0, TH0, joint_rotation, transform_force_T


@njit(cache=True)
def spatial_inertia(row, o, M, k):
    """Eq 14's ``M = [[m I, -m P], [m P, I_o]]`` of one link into ``M[k]`` from ``row[o:o+13]``."""
    m = row[o]
    hx, hy, hz = row[o + 1], row[o + 2], row[o + 3]
    t5, t6, t7 = row[o + 4], row[o + 5], row[o + 6]
    for r in range(6):
        for c in range(6):
            M[k, r, c] = 0.0
    M[k, 0, 0] = m
    M[k, 1, 1] = m
    M[k, 2, 2] = m
    # -m P = -h^x (top right), m P = h^x (bottom left)
    M[k, 0, 4] = hz
    M[k, 0, 5] = -hy
    M[k, 1, 3] = -hz
    M[k, 1, 5] = hx
    M[k, 2, 3] = hy
    M[k, 2, 4] = -hx
    M[k, 4, 0] = hz
    M[k, 5, 0] = -hy
    M[k, 3, 1] = -hz
    M[k, 5, 1] = hx
    M[k, 3, 2] = hy
    M[k, 4, 2] = -hx
    M[k, 3, 3] = row[o + 10] + t6 + t7
    M[k, 4, 4] = row[o + 11] + t5 + t7
    M[k, 5, 5] = row[o + 12] + t5 + t6
    M[k, 3, 4] = M[k, 4, 3] = -row[o + 7]
    M[k, 3, 5] = M[k, 5, 3] = -row[o + 8]
    M[k, 4, 5] = M[k, 5, 4] = -row[o + 9]


@njit(cache=True)
def congruence_to_parent(C, i, px, py, pz, A, k, B, j):
    """``B[j] += T_i^T A[k] T_i``: a spatial inertia of frame i seen from frame i-1 (eq 10)."""
    # X = A T (columns of T are motion vectors: T e_c); then T^T X column by column.
    X = np.empty((6, 6), A.dtype)
    for r in range(6):
        # row r of A times T: (A T)[r, :] = (T^T A[r, :]^T)^T, a force-transform of the row
        a = transform_force_T(C, i, px, py, pz, A[k, r, 0], A[k, r, 1], A[k, r, 2],
                              A[k, r, 3], A[k, r, 4], A[k, r, 5])
        for c in range(6):
            X[r, c] = a[c]
    for c in range(6):
        b = transform_force_T(C, i, px, py, pz, X[0, c], X[1, c], X[2, c], X[3, c], X[4, c],
                              X[5, c])
        for r in range(6):
            B[j, r, c] += b[r]


@njit(cache=True)
def crba_kernel(kin, q):
    """``M(q)``: composite inertias ``Ic_{i-1} += T_i^T Ic_i T_i``, then column i by ``jT_i^T``.

    ``M_ij = z6^T (jT_i)^T Ic_i z6`` for j <= i, plus the armature on the diagonal
    (doc/design.md §7).
    """
    n = q.shape[0]
    C = np.empty((n, 9), q.dtype)
    Ic = np.empty((n, 6, 6), q.dtype)
    H = np.zeros((n, n), q.dtype)
    for i in range(n):
        joint_rotation(kin[i], RF0, q[i], C, i)
        spatial_inertia(kin[i], TH0, Ic, i)
    for i in range(n - 1, 0, -1):
        r = kin[i]
        congruence_to_parent(C, i, r[P0], r[P0 + 1], r[P0 + 2], Ic, i, Ic, i - 1)
    for i in range(n):
        f = (Ic[i, 0, 5], Ic[i, 1, 5], Ic[i, 2, 5], Ic[i, 3, 5], Ic[i, 4, 5], Ic[i, 5, 5])
        H[i, i] = f[5]
        if kin[i, JA] != 0.0:
            H[i, i] += kin[i, JA]
        for j in range(i, 0, -1):
            r = kin[j]
            f = transform_force_T(C, j, r[P0], r[P0 + 1], r[P0 + 2], f[0], f[1], f[2], f[3],
                                  f[4], f[5])
            H[i, j - 1] = f[5]
            H[j - 1, i] = f[5]
    return H


def mass_matrix(model, q):
    """The joint-space inertia matrix ``M(q)``, shape (n, n), symmetric positive definite.

    The armature of each joint is on the diagonal (doc/design.md §7).

    Raises
    ------
    InputError
        If ``q`` has the wrong length or holds NaN/Inf.
    """
    (q,) = joint_vectors(model.n, q=q)
    return crba_kernel(model.packed, q)
