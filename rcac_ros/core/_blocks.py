"""Compiled building blocks shared by the recursive law and the Slotine-Li baseline.

Each block is one equation of doc/design.md §3-4 over one link, reading the packed layout of
:mod:`rcac_ros.core._packing`.
"""

import math

import numba
import numpy as np

from ._jit import address_of, njit, unmanaged

from ._packing import CONST_COLS, GAIN_K_D, I_ERR, LAMBDA, S_LINK
from rcac_ros.errors import InputError
from .spatial import P0, RF0, joint_rotation, propagate, rotate, transform_motion

INPUT_NAMES = ("q", "qd", "q_d", "qd_d", "qdd_d")

#: The only signatures the step kernels are compiled for: anything else is a TypeError at
#: dispatch (never a silent recompilation), which the Python entry points convert once.
VEC = "float64[::1]"
#: the recursive law's step kernels': (data, filt, q, qd, q_d, qd_d, qdd_d) -> tau
RCAC_SIGNATURE = f"{VEC}(float64[:, ::1], float64[:, :, ::1], {VEC}, {VEC}, {VEC}, {VEC}, {VEC})"


@njit(cache=True)
def check_vectors(n, a, b, c, d, e):
    """0 if all five vectors have length n and are finite; else 1-5 (length) or 11-15 (NaN/Inf)."""
    vecs = (a, b, c, d, e)
    for k in range(5):
        if vecs[k].shape[0] != n:
            return k + 1
    for k in range(5):
        v = vecs[k]
        for i in range(n):
            if not math.isfinite(v[i]):
                return k + 11
    return 0


@njit(cache=True, inline="always")
def rejects_input(scal, n, q, qd, q_d, qd_d, qdd_d):
    """True, with :func:`check_vectors`' code in ``scal[I_ERR]``, if a step's inputs are not
    five finite vectors of length n (the kernel then returns an empty tau)."""
    err = check_vectors(n, q, qd, q_d, qd_d, qdd_d)
    if err != 0:
        scal[I_ERR] = err
        return True
    return False


@njit(cache=True, inline="always")
def packed_views(data, filt):
    """The recursive law's kernel arguments as views: ``n``, the per-link constants
    ``data[:n, :CONST_COLS]``, the per-link state, the scalars ``data[n]`` and the channels
    ``filt[:, n]`` (layout: :mod:`rcac_ros.core._packing`)."""
    n = data.shape[0] - 1
    return n, data[:n, :CONST_COLS], data[:n, CONST_COLS:], data[n], filt[:, n]


@njit(cache=True, inline="always")
def unmanaged_block(arr, start, shape):
    """Elements ``start ...`` of a C-contiguous ``arr`` as a C-contiguous array of ``shape``
    (``arr.ravel()[start:start + size].reshape(shape)``), without a reference count.

    As :func:`unmanaged`: the block must not outlive ``arr`` (the kernel takes it of an
    array its caller holds, for the length of that call), and ``start`` plus the block's
    size must not exceed ``arr.size`` (not checked).
    """
    return numba.carray(address_of(arr, start), shape)


@njit(cache=True, inline="always")
def unmanaged_views(data, filt):
    """:func:`packed_views`, unmanaged (:func:`unmanaged_block`) and C-contiguous: ``n``, the
    per-link constants, the per-link state, the scalars ``data[n]`` and the channels.

    The per-link blocks are the rows of ``data`` at their first column (constants: 0, state:
    ``CONST_COLS``), each as wide as a whole row, so that their columns are at fixed
    offsets: ``const[i, k]`` is ``data[i, k]`` and ``state[i, k]`` is ``data[i, CONST_COLS +
    k]``; likewise ``chan[c, k]`` is ``filt[c, n, k]``. Only the columns of each block are
    read (those of :mod:`rcac_ros.core._packing`); past them a row runs into the next block
    (the last channel's, past the end of ``filt``), which is never read through it. ``data``
    and ``filt`` must outlive the views (the kernel's arguments, for the length of its call).
    """
    n = data.shape[0] - 1
    width = data.shape[1]
    m, rows, cols = filt.shape[0], filt.shape[1], filt.shape[2]
    return (n, unmanaged_block(data, 0, (n, width)),
            unmanaged_block(data, CONST_COLS, (n, width)),
            unmanaged_block(data, n * width, (width,)),
            unmanaged_block(filt, n * cols, (m, rows * cols)))


if numba.config.DISABLE_JIT:      # the kernels as Python (the operation count): plain views
    def unmanaged(arr):                                                   # noqa: F811
        """:func:`unmanaged` run as Python: ``arr`` itself."""
        return arr

    def unmanaged_block(arr, start, shape):                               # noqa: F811
        """:func:`unmanaged_block` run as Python: a view of ``arr``'s elements."""
        return arr.reshape(-1)[start:start + math.prod(shape)].reshape(shape)

    def unmanaged_views(data, filt):                                      # noqa: F811
        """:func:`unmanaged_views` run as Python: :func:`packed_views`' (the same columns)."""
        return packed_views(data, filt)


def input_error(scal, n, values):
    """The InputError for the code a kernel left in ``scal[I_ERR]``."""
    code = int(scal[I_ERR])
    scal[I_ERR] = 0.0
    name = INPUT_NAMES[(code - 1) % 10]
    if code < 10:
        return InputError(f"{name}: expected length {n}, got {np.shape(values[code - 1])}")
    return InputError(f"{name}: contains NaN or Inf")


@njit(cache=True, inline="always")
def reference_motion(C, i, row, q, qd, q_d, qd_d, qdd_d, V, Vr, Vdr, g):
    """Link i's ``V_i`` (eq 9), ``V_ri``, ``Vdot_ri`` (eq 18) and gravity from link i-1's.

    Writes ``C[i]`` (eq 10's rotation); ``q ... qdd_d`` are joint i's scalars, ``row`` its
    packed constants. Returns ``(V, V_r, Vdot_r, g)`` as tuples.
    """
    joint_rotation(row, RF0, q, C, i)
    px, py, pz = row[P0], row[P0 + 1], row[P0 + 2]
    qdr = qd_d - row[LAMBDA] * (q - q_d)
    qddr = qdd_d - row[LAMBDA] * (qd - qd_d)
    vx, vy, vz, wx, wy, wz = transform_motion(C, i, px, py, pz, V[0], V[1], V[2], V[3], V[4],
                                              V[5])
    Vr, Vdr = propagate(C, i, px, py, pz, qd, Vr, Vdr, qdr, qddr)   # Tdot with the actual qd
    return (vx, vy, vz, wx, wy, wz + qd), Vr, Vdr, rotate(C, i, g[0], g[1], g[2])


@njit(cache=True, inline="always")
def feedback_wrench(const, state, Fs, i, kd_diag, F):
    """Eq 19b's link i terms, added to ``F`` (6, in place): ``Y_ri theta_hat_i + K_Di (V_ri -
    V_i)``, with ``Fs[i] = Y_ri theta_hat_i`` and ``s_i = V_i - V_ri`` in ``state[i]``.

    Indexes the packed arrays at link i (no view of a row: each would cost atomic reference
    counts per link and step).
    """
    for r in range(6):
        acc = Fs[i, r]
        if kd_diag:
            acc -= const[i, GAIN_K_D + 7 * r] * state[i, S_LINK + r]
        else:
            for k in range(6):
                acc -= const[i, GAIN_K_D + 6 * r + k] * state[i, S_LINK + k]
        F[r] += acc


@njit(cache=True)
def cholesky_solve(A, b):
    """Solve ``A x = b`` in place (``b`` becomes x) for symmetric positive definite A."""
    n = A.shape[0]
    for j in range(n):
        d = A[j, j]
        for k in range(j):
            d -= A[j, k] * A[j, k]
        d = np.sqrt(d)
        A[j, j] = d
        for i in range(j + 1, n):
            v = A[i, j]
            for k in range(j):
                v -= A[i, k] * A[j, k]
            A[i, j] = v / d
    for i in range(n):
        v = b[i]
        for k in range(i):
            v -= A[i, k] * b[k]
        b[i] = v / A[i, i]
    for i in range(n - 1, -1, -1):
        v = b[i]
        for k in range(i + 1, n):
            v -= A[k, i] * b[k]
        b[i] = v / A[i, i]
