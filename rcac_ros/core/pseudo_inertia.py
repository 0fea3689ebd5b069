"""Physical consistency of the 13 parameters, the natural adaptation geometry (doc/design.md §8).

A body's standard parameters ``pi`` (mass m, first moment h = m c, inertia I_o about the
frame origin; Pinocchio's order ``[m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``) are
physically consistent exactly when the pseudo-inertia

    J(pi) = [[Sigma, h], [h^T, m]],     Sigma = 1/2 tr(I_o) 1 - I_o = int r r^T dm

is positive definite (Wensing, Kim, Slotine, RA-L 2018). In the paper's 13 parameters
(doc/design.md §2) J is linear and reads

    J(theta) = [[t5 + (-t11 + t12 + t13)/2, t8, t9, t2],
                [t8, t6 + (t11 - t12 + t13)/2, t10, t3],
                [t9, t10, t7 + (t11 + t12 - t13)/2, t4],
                [t2, t3, t4, t1]]                                   (1-based t_k)

and ``theta -> (J, nu)`` with ``nu = (t5, t6, t7)`` is a linear bijection of R^13 onto
(symmetric 4x4) x R^3. ``nu`` is what the 13 add to a body: for a body ``nu = h_k^2 / m``,
and the regressor sees it only through ``t5 + t6 + t7`` (the rank-11 direction).

The natural geometry (doc/design.md §8) replaces the gain ``P`` of eq 24 by

    P_eff(theta_hat): J(dtheta) = k J_hat G(g) J_hat,   dnu = P_nu u_nu(g)

where ``G(g)`` is the symmetric 4x4 with ``tr(G J(dtheta)) + u_nu . dnu = g . dtheta`` for
every dtheta (the gradient g split on the two factors), i.e. ``k`` times the inverse Hessian
of ``-log det J`` on J and a fixed ``P_nu`` on nu; a step is then made consistent by the
retraction of :mod:`rcac_ros.core.retraction`.
Everything here is O(1) per link: 4x4 products and one 4x4 Cholesky factorisation.
"""

import math

import numpy as np
from ._jit import njit

from ._validate import as_array, scalar
from .law_options import BARRIER_C, BARRIER_C_MIN
from rcac_ros.errors import GainError, InputError

#: Pinocchio's order of the standard parameters (``Inertia.toDynamicParameters``).
STANDARD_NAMES = ("m", "hx", "hy", "hz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")

#: d theta / d nu at fixed J (13 x 3): nu_k moves t5+k and takes it off the two other
#: diagonal inertia entries (doc/design.md §8).
NU_BASIS = np.zeros((13, 3))
for _k in range(3):
    NU_BASIS[4 + _k, _k] = 1.0
    for _j in range(3):
        if _j != _k:
            NU_BASIS[10 + _j, _k] = -1.0

#: Default scale of the nominal model when no ``theta_hat0`` is given (doc/design.md §8).
NOMINAL_SCALE = 0.5
#: Smallest eigenvalue of the centre-of-mass second moment of a default start, as a
#: fraction of its trace (a nominal that is not a body is made one, doc/design.md §8).
SECOND_MOMENT_FLOOR = 0.01


#: the natural geometry's metrics (doc/design.md §8): k_i times the log-det Hessian, or the
#: barrier plus the Euclidean quadratic
NATURAL_METRICS = ("log_det", "barrier")


# ---- the linear maps (numba, one link: 13 entries at th[o:o+13]) ---------------------------

@njit(cache=True, inline="always")
def pseudo_inertia_into(th, o, J):
    """``J(theta)`` (4x4) of the 13 parameters ``th[o:o+13]`` into ``J`` (module docstring)."""
    t11, t12, t13 = th[o + 10], th[o + 11], th[o + 12]
    J[0, 0] = th[o + 4] + 0.5 * (-t11 + t12 + t13)
    J[1, 1] = th[o + 5] + 0.5 * (t11 - t12 + t13)
    J[2, 2] = th[o + 6] + 0.5 * (t11 + t12 - t13)
    J[3, 3] = th[o]
    J[0, 1] = J[1, 0] = th[o + 7]
    J[0, 2] = J[2, 0] = th[o + 8]
    J[1, 2] = J[2, 1] = th[o + 9]
    J[0, 3] = J[3, 0] = th[o + 1]
    J[1, 3] = J[3, 1] = th[o + 2]
    J[2, 3] = J[3, 2] = th[o + 3]


@njit(cache=True, inline="always")
def theta_from_pseudo(J, n0, n1, n2, out, o):
    """``out[o:o+13]``: the 13 parameters with pseudo-inertia ``J`` and ``nu = (n0, n1, n2)``."""
    a, b, c = J[0, 0] - n0, J[1, 1] - n1, J[2, 2] - n2      # Sigma_c diagonal
    out[o] = J[3, 3]
    out[o + 1], out[o + 2], out[o + 3] = J[0, 3], J[1, 3], J[2, 3]
    out[o + 4], out[o + 5], out[o + 6] = n0, n1, n2
    out[o + 7], out[o + 8], out[o + 9] = J[0, 1], J[0, 2], J[1, 2]
    out[o + 10], out[o + 11], out[o + 12] = b + c, a + c, a + b


@njit(cache=True, inline="always")
def dual_into(g, o, G):
    """``G(g)`` (4x4) and ``u_nu`` (returned) with ``tr(G J(d)) + u_nu . d_nu = g . d``.

    ``g[o:o+13]`` is a gradient in the 13 parameters (e.g. ``Y^T s``); ``G`` is symmetric.
    """
    g10, g11, g12 = g[o + 10], g[o + 11], g[o + 12]
    G[0, 0] = g11 + g12
    G[1, 1] = g10 + g12
    G[2, 2] = g10 + g11
    G[3, 3] = g[o]
    G[0, 1] = G[1, 0] = 0.5 * g[o + 7]
    G[0, 2] = G[2, 0] = 0.5 * g[o + 8]
    G[1, 2] = G[2, 1] = 0.5 * g[o + 9]
    G[0, 3] = G[3, 0] = 0.5 * g[o + 1]
    G[1, 3] = G[3, 1] = 0.5 * g[o + 2]
    G[2, 3] = G[3, 2] = 0.5 * g[o + 3]
    return g[o + 4] - g11 - g12, g[o + 5] - g10 - g12, g[o + 6] - g10 - g11


@njit(cache=True, inline="always")
def cholesky4(J, L):
    """Lower Cholesky factor of the 4x4 ``J`` into ``L``; False (L partial) if not PD."""
    for j in range(4):
        d = J[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        d = math.sqrt(d)
        L[j, j] = d
        for i in range(j + 1, 4):
            s = J[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
        for i in range(j):
            L[i, j] = 0.0
    return True


@njit(cache=True, inline="always")
def pseudo_entries(th, o):
    """The 10 entries ``(J00, J11, J22, J33, J01, J02, J12, J03, J13, J23)`` of ``J(theta)``
    (:func:`pseudo_inertia_into`, the same operations) as scalars."""
    t11, t12, t13 = th[o + 10], th[o + 11], th[o + 12]
    return (th[o + 4] + 0.5 * (-t11 + t12 + t13), th[o + 5] + 0.5 * (t11 - t12 + t13),
            th[o + 6] + 0.5 * (t11 + t12 - t13), th[o], th[o + 7], th[o + 8], th[o + 9],
            th[o + 1], th[o + 2], th[o + 3])


@njit(cache=True, inline="always")
def theta_from_entries(j00, j11, j22, j33, j01, j02, j12, j03, j13, j23, n0, n1, n2, out, o):
    """:func:`theta_from_pseudo` (the same operations) from J's 10 entries as scalars."""
    a, b, c = j00 - n0, j11 - n1, j22 - n2
    out[o] = j33
    out[o + 1], out[o + 2], out[o + 3] = j03, j13, j23
    out[o + 4], out[o + 5], out[o + 6] = n0, n1, n2
    out[o + 7], out[o + 8], out[o + 9] = j01, j02, j12
    out[o + 10], out[o + 11], out[o + 12] = b + c, a + c, a + b


@njit(cache=True, inline="always")
def cholesky_entries(a00, a11, a22, a33, a01, a02, a12, a03, a13, a23):
    """:func:`cholesky4` (the same operations, the same verdict) of the symmetric 4x4 with
    these 10 entries, unrolled on scalars: ``(ok, l00, l10, l11, l20, l21, l22, l30, l31,
    l32, l33)``, the factor's entries 0 past the first pivot that is not > 0."""
    l00 = l10 = l11 = l20 = l21 = l22 = l30 = l31 = l32 = l33 = 0.0
    ok = False
    d = a00
    if d > 0.0:
        l00 = math.sqrt(d)
        l10, l20, l30 = a01 / l00, a02 / l00, a03 / l00
        d = a11 - l10 * l10
        if d > 0.0:
            l11 = math.sqrt(d)
            l21 = (a12 - l20 * l10) / l11
            l31 = (a13 - l30 * l10) / l11
            d = a22 - l20 * l20 - l21 * l21
            if d > 0.0:
                l22 = math.sqrt(d)
                l32 = (a23 - l30 * l20 - l31 * l21) / l22
                d = a33 - l30 * l30 - l31 * l31 - l32 * l32
                if d > 0.0:
                    l33 = math.sqrt(d)
                    ok = True
    return ok, l00, l10, l11, l20, l21, l22, l30, l31, l32, l33


@njit(cache=True, inline="always")
def positive_definite4(a00, a11, a22, a33, a01, a02, a12, a03, a13, a23):
    """True if the symmetric 4x4 with these 10 entries is positive definite: every pivot of
    its ``L D L^T`` (L unit lower) > 0, the verdict of :func:`cholesky_entries` up to
    rounding (the same elimination without its square roots). Three divisions."""
    if not a00 > 0.0:
        return False
    r0 = 1.0 / a00
    l10, l20, l30 = a01 * r0, a02 * r0, a03 * r0
    d1 = a11 - a01 * l10
    if not d1 > 0.0:
        return False
    r1 = 1.0 / d1
    u21, u31 = a12 - a02 * l10, a13 - a03 * l10
    l21 = u21 * r1
    d2 = a22 - a02 * l20 - u21 * l21
    if not d2 > 0.0:
        return False
    u32 = a23 - a03 * l20 - u31 * l21
    return a33 - a03 * l30 - u31 * (u31 * r1) - u32 * (u32 / d2) > 0.0


@njit(cache=True, inline="always")
def inverse_ldl_entries(j00, j11, j22, j33, j01, j02, j12, j03, j13, j23):
    """``J^-1`` of the symmetric 4x4 with these 10 entries (the order of
    :func:`pseudo_entries`) by ``J = L D L^T`` (L unit lower), ``J^-1 = M^T D^-1 M``,
    ``M = L^-1``: four divisions, no square root. ``(ok, k00, k01, k02, k03, k11, k12, k13,
    k22, k23, k33)``, the upper triangle of the inverse; ``ok``: every pivot > 0 (J positive
    definite, the verdict of :func:`cholesky_entries` up to rounding), else the entries are
    0."""
    k00 = k01 = k02 = k03 = k11 = k12 = k13 = k22 = k23 = k33 = 0.0
    if not j00 > 0.0:
        return False, k00, k01, k02, k03, k11, k12, k13, k22, k23, k33
    r0 = 1.0 / j00
    l10, l20, l30 = j01 * r0, j02 * r0, j03 * r0
    d1 = j11 - j01 * l10
    if not d1 > 0.0:
        return False, k00, k01, k02, k03, k11, k12, k13, k22, k23, k33
    r1 = 1.0 / d1
    u21, u31 = j12 - j02 * l10, j13 - j03 * l10
    l21, l31 = u21 * r1, u31 * r1
    d2 = j22 - j02 * l20 - u21 * l21
    if not d2 > 0.0:
        return False, k00, k01, k02, k03, k11, k12, k13, k22, k23, k33
    r2 = 1.0 / d2
    u32 = j23 - j03 * l20 - u31 * l21
    l32 = u32 * r2
    d3 = j33 - j03 * l30 - u31 * l31 - u32 * l32
    if not d3 > 0.0:
        return False, k00, k01, k02, k03, k11, k12, k13, k22, k23, k33
    r3 = 1.0 / d3
    m10, m21, m32 = -l10, -l21, -l32                  # M = L^-1 (unit lower)
    m20 = -l20 - l21 * m10
    m31 = -l31 - l32 * m21
    m30 = -l30 - l31 * m10 - l32 * m20
    k33 = r3                                          # (M^T D^-1 M)_pq, k >= max(p, q)
    k23, k13, k03 = r3 * m32, r3 * m31, r3 * m30
    a20, a21 = r2 * m20, r2 * m21
    a10 = r1 * m10
    k22 = r2 + m32 * k23
    k12 = a21 + m32 * k13
    k02 = a20 + m32 * k03
    k11 = r1 + m21 * a21 + m31 * k13
    k01 = a10 + m21 * a20 + m31 * k03
    k00 = r0 + m10 * a10 + m20 * a20 + m30 * k03
    return True, k00, k01, k02, k03, k11, k12, k13, k22, k23, k33


@njit(cache=True, inline="always")
def natural_gain_apply(th, o, g, go, out, oo, k, Pnu, po):
    """``out[oo:oo+13] = P_eff(theta_hat) g[go:go+13]`` (module docstring, doc/design.md §8).

    ``th[o:o+13]`` is theta_hat, ``k`` the natural gain, ``Pnu[po:po+9]`` the 3x3 gain on nu
    (row-major). ``g . out = k tr(G J G J) + u_nu^T P_nu u_nu >= 0``: P_eff is symmetric
    positive semi-definite (definite where J is). ``g`` is read whole before ``out`` is
    written (they may share an array). The 4x4 algebra is unrolled on the 10 entries of the
    symmetric matrices and the 16 of
    ``T = G J``, in the operations and order of :func:`pseudo_inertia_into`,
    :func:`dual_into` and ``k J (G J)``.
    """
    j00, j11, j22, j33, j01, j02, j12, j03, j13, j23 = pseudo_entries(th, o)
    h10, h11, h12 = g[go + 10], g[go + 11], g[go + 12]        # dual_into: G(g) and u_nu
    g00, g11, g22, g33 = h11 + h12, h10 + h12, h10 + h11, g[go]
    g01, g02, g12 = 0.5 * g[go + 7], 0.5 * g[go + 8], 0.5 * g[go + 9]
    g03, g13, g23 = 0.5 * g[go + 1], 0.5 * g[go + 2], 0.5 * g[go + 3]
    u0, u1, u2 = g[go + 4] - h11 - h12, g[go + 5] - h10 - h12, g[go + 6] - h10 - h11
    t00 = g00 * j00 + g01 * j01 + g02 * j02 + g03 * j03       # T = G J
    t01 = g00 * j01 + g01 * j11 + g02 * j12 + g03 * j13
    t02 = g00 * j02 + g01 * j12 + g02 * j22 + g03 * j23
    t03 = g00 * j03 + g01 * j13 + g02 * j23 + g03 * j33
    t10 = g01 * j00 + g11 * j01 + g12 * j02 + g13 * j03
    t11 = g01 * j01 + g11 * j11 + g12 * j12 + g13 * j13
    t12 = g01 * j02 + g11 * j12 + g12 * j22 + g13 * j23
    t13 = g01 * j03 + g11 * j13 + g12 * j23 + g13 * j33
    t20 = g02 * j00 + g12 * j01 + g22 * j02 + g23 * j03
    t21 = g02 * j01 + g12 * j11 + g22 * j12 + g23 * j13
    t22 = g02 * j02 + g12 * j12 + g22 * j22 + g23 * j23
    t23 = g02 * j03 + g12 * j13 + g22 * j23 + g23 * j33
    t30 = g03 * j00 + g13 * j01 + g23 * j02 + g33 * j03
    t31 = g03 * j01 + g13 * j11 + g23 * j12 + g33 * j13
    t32 = g03 * j02 + g13 * j12 + g23 * j22 + g33 * j23
    t33 = g03 * j03 + g13 * j13 + g23 * j23 + g33 * j33
    p00 = k * (j00 * t00 + j01 * t10 + j02 * t20 + j03 * t30)  # k J T (symmetric)
    p01 = k * (j00 * t01 + j01 * t11 + j02 * t21 + j03 * t31)
    p02 = k * (j00 * t02 + j01 * t12 + j02 * t22 + j03 * t32)
    p03 = k * (j00 * t03 + j01 * t13 + j02 * t23 + j03 * t33)
    p11 = k * (j01 * t01 + j11 * t11 + j12 * t21 + j13 * t31)
    p12 = k * (j01 * t02 + j11 * t12 + j12 * t22 + j13 * t32)
    p13 = k * (j01 * t03 + j11 * t13 + j12 * t23 + j13 * t33)
    p22 = k * (j02 * t02 + j12 * t12 + j22 * t22 + j23 * t32)
    p23 = k * (j02 * t03 + j12 * t13 + j22 * t23 + j23 * t33)
    p33 = k * (j03 * t03 + j13 * t13 + j23 * t23 + j33 * t33)
    n0 = Pnu[po] * u0 + Pnu[po + 1] * u1 + Pnu[po + 2] * u2
    n1 = Pnu[po + 3] * u0 + Pnu[po + 4] * u1 + Pnu[po + 5] * u2
    n2 = Pnu[po + 6] * u0 + Pnu[po + 7] * u1 + Pnu[po + 8] * u2
    theta_from_entries(p00, p11, p22, p33, p01, p02, p12, p03, p13, p23, n0, n1, n2, out, oo)


@njit(cache=True)
def natural_gains_into(theta, k, Pnu, out):
    """``out[i]`` (169, row-major) = ``P_eff(theta_i)`` for every link (the non-recursive
    law's explicit gains, doc/design.md §8); ``theta`` (n, 13), ``k`` (n,), ``Pnu`` (n, 9)."""
    e = np.zeros(13)
    col = np.empty(13)
    for i in range(theta.shape[0]):
        for c in range(13):
            e[c] = 1.0
            natural_gain_apply(theta[i], 0, e, 0, col, 0, k[i], Pnu[i], 0)
            e[c] = 0.0
            for r in range(13):
                out[i, 13 * r + c] = col[r]


@njit(cache=True)
def barrier_gains_into(theta, kc, P_inv, E, out):
    """``out[i]`` (169, row-major) = ``P_mix(theta_i) = (H(theta_i) / kc_i + P_i^-1)^-1``
    for every link: the barrier metric's explicit gains of the non-recursive law
    (doc/design.md §8). ``theta`` (n, 13), ``kc`` (n,) the products ``c k_i``, ``P_inv``
    (n, 13, 13), ``E`` (13, 4, 4) the pseudo-inertias of the unit parameter vectors; ``H``
    from its trace form ``H_ab = tr(J^-1 E_a J^-1 E_b)``."""
    J = np.empty((4, 4))
    G = np.empty((13, 4, 4))
    M = np.empty((13, 13))
    for i in range(theta.shape[0]):
        pseudo_inertia_into(theta[i], 0, J)
        Ji = np.linalg.inv(J)
        for a in range(13):
            G[a] = Ji @ E[a]
        for a in range(13):
            for b in range(a + 1):
                acc = 0.0
                for p in range(4):
                    for q in range(4):
                        acc += G[a, p, q] * G[b, q, p]
                M[a, b] = acc / kc[i] + P_inv[i, a, b]
                M[b, a] = M[a, b]
        Pm = np.linalg.inv(M)
        for a in range(13):
            for b in range(13):
                out[i, 13 * a + b] = 0.5 * (Pm[a, b] + Pm[b, a])


# ---- Python side: conversions, checks, defaults --------------------------------------------

def pseudo_inertia(theta):
    """``J(theta)`` of 13-parameter sets, shape (..., 4, 4) for ``theta`` (..., 13)."""
    t = np.asarray(theta, dtype=float)
    J = np.empty(t.shape[:-1] + (4, 4))
    J[..., 0, 0] = t[..., 4] + 0.5 * (-t[..., 10] + t[..., 11] + t[..., 12])
    J[..., 1, 1] = t[..., 5] + 0.5 * (t[..., 10] - t[..., 11] + t[..., 12])
    J[..., 2, 2] = t[..., 6] + 0.5 * (t[..., 10] + t[..., 11] - t[..., 12])
    J[..., 3, 3] = t[..., 0]
    for (i, j), k in (((0, 1), 7), ((0, 2), 8), ((1, 2), 9), ((0, 3), 1), ((1, 3), 2),
                      ((2, 3), 3)):
        J[..., i, j] = J[..., j, i] = t[..., k]
    return J


def standard_parameters(theta):
    """The 10 standard parameters ``pi`` (Pinocchio's order, :data:`STANDARD_NAMES`) of the
    13 parameters ``theta`` (..., 13): mass, first moment, inertia about the frame origin."""
    t = np.asarray(theta, dtype=float)
    return np.stack([t[..., 0], t[..., 1], t[..., 2], t[..., 3],
                     t[..., 10] + t[..., 5] + t[..., 6], -t[..., 7],
                     t[..., 11] + t[..., 4] + t[..., 6], -t[..., 8], -t[..., 9],
                     t[..., 12] + t[..., 4] + t[..., 5]], axis=-1)


def theta_from_parts(pi, nu):
    """The 13 parameters with standard parameters ``pi`` (..., 10) and ``nu`` (..., 3)."""
    p = np.asarray(pi, dtype=float)
    nu = np.asarray(nu, dtype=float)
    t = np.empty(np.broadcast_shapes(p.shape[:-1], nu.shape[:-1]) + (13,))
    t[..., 0:4] = p[..., 0:4]
    t[..., 4:7] = nu
    t[..., 7], t[..., 8], t[..., 9] = -p[..., 5], -p[..., 7], -p[..., 8]
    t[..., 10] = p[..., 4] - nu[..., 1] - nu[..., 2]
    t[..., 11] = p[..., 6] - nu[..., 0] - nu[..., 2]
    t[..., 12] = p[..., 9] - nu[..., 0] - nu[..., 1]
    return t


def body_theta(pi):
    """The 13 parameters of the body with standard parameters ``pi`` (``nu = h_k^2 / m``).

    For a body these are eq 13's ``[m, m px, ..., Izz]`` (doc/design.md §2); ``m`` must be > 0.
    """
    p = np.asarray(pi, dtype=float)
    return theta_from_parts(p, p[..., 1:4] ** 2 / p[..., 0:1])


def lambda_min(theta):
    """Smallest eigenvalue of ``J(theta_i)`` per link, shape (...,) for ``theta`` (..., 13).

    > 0 exactly when the link's estimates are a physical body (Wensing, Kim, Slotine 2018).
    """
    return np.linalg.eigvalsh(pseudo_inertia(theta))[..., 0]


def is_body(theta):
    """Per link, whether ``J(theta_i)`` is positive definite (a 4x4 Cholesky factorisation)."""
    J = pseudo_inertia(np.atleast_2d(theta))
    ok = np.empty(J.shape[0], dtype=bool)
    L = np.empty((4, 4))
    for i in range(J.shape[0]):
        ok[i] = bool(np.all(np.isfinite(J[i]))) and cholesky4(J[i], L)
    return ok.reshape(np.shape(theta)[:-1])


def bregman_log_det(theta, theta_hat):
    """``D(J || J_hat) = tr(J J_hat^-1) - log det(J J_hat^-1) - 4`` per link, the Bregman
    divergence of ``-log det`` between the pseudo-inertias of ``theta`` and ``theta_hat``
    (..., 13), both bodies (doc/design.md §8). >= 0, zero exactly when ``J = J_hat``."""
    J = pseudo_inertia(theta)
    L = np.linalg.cholesky(pseudo_inertia(theta_hat))
    X = np.linalg.solve(L, np.swapaxes(np.linalg.solve(L, J), -1, -2))   # L^-1 J L^-T
    logdet = np.linalg.slogdet(X)[1]           # X is positive definite: its sign is +1
    return np.trace(X, axis1=-2, axis2=-1) - logdet - 4.0


def check_body(theta, name="theta_hat0", exc=InputError):
    """Raise ``exc`` with one line naming the first link whose ``theta`` is not a body."""
    ok = np.atleast_1d(is_body(theta))
    if not ok.all():
        i = int(np.argmin(ok))
        lam = float(np.atleast_1d(lambda_min(theta))[i])
        raise exc(f"{name}: link {i + 1} is not a physical body (lambda_min of its "
                  f"pseudo-inertia J = {lam:.3g} <= 0); the natural geometry needs one "
                  f"(doc/design.md §8)")


def nearest_body(theta, floor=SECOND_MOMENT_FLOOR):
    """A body close to ``theta`` (n, 13): same mass and centre of mass, second moment about
    the centre of mass with its eigenvalues raised to at least ``floor`` times its trace.

    A body is returned unchanged (up to ``nu = h^2 / m``) when it already passes; a mass
    <= 0 raises :class:`GainError` (no centre of mass to keep).
    """
    J = pseudo_inertia(np.atleast_2d(theta))
    out = np.empty((J.shape[0], 13))
    for i, Ji in enumerate(J):
        m, h = Ji[3, 3], Ji[:3, 3]
        if not m > 0.0:
            raise GainError(f"theta_0: link {i + 1} has mass {m:.3g} <= 0, no body near it")
        Sc = Ji[:3, :3] - np.outer(h, h) / m             # second moment about the CoM
        w, V = np.linalg.eigh(0.5 * (Sc + Sc.T))
        lo = floor * max(float(np.sum(np.abs(w))), 1e-12 * m)
        if w[0] < lo:
            Sc = (V * np.maximum(w, lo)) @ V.T
        Jn = np.zeros((4, 4))
        Jn[:3, :3] = Sc + np.outer(h, h) / m
        Jn[:3, 3] = Jn[3, :3] = h
        Jn[3, 3] = m
        nu = h ** 2 / m
        theta_from_pseudo(Jn, nu[0], nu[1], nu[2], out[i], 0)
    return out


def default_start(theta_nominal, scale=NOMINAL_SCALE):
    """The natural geometry's default ``theta_hat0``: the nominal model made a body
    (:func:`nearest_body`), then scaled by ``scale`` (mass, first and second moments; the
    centres of mass stay). A scaled body is a body: J scales by ``scale``."""
    return scale * nearest_body(theta_nominal)


def nu_gain(P):
    """``P_nu = (B^T P^-1 B)^-1`` per link for gains ``P`` (n, 13, 13): the Euclidean metric
    restricted to the nu directions at fixed J (``B`` = :data:`NU_BASIS`)."""
    Pinv = np.linalg.inv(P)
    return np.linalg.inv(NU_BASIS.T @ Pinv @ NU_BASIS)


#: the entry (row, column) of J that theta_0 .. theta_9 each set alone: the coordinates ``j``
#: of J in which the barrier metric's gain is factored (doc/design.md §8)
J_SLOTS = ((3, 3), (0, 3), (1, 3), (2, 3), (0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def barrier_blocks(P):
    """The constant blocks of the barrier metric's gain for gains ``P`` (n, 13, 13),
    doc/design.md §8: ``(A P_i A^T)^-1`` (n, 55: its lower triangle, packed by rows) and
    ``F_i = -(A P_i A^T)^-1 A P_i N^T`` (n, 10, 3), with ``A``: theta -> j (J's entries at
    :data:`J_SLOTS`) and ``N``: theta -> nu = theta_4..6. In the coordinates ``(j, nu)`` the
    metric ``P_i^-1`` is ``[[X, C], [C^T, E]]``; the first block is ``X - C E^-1 C^T`` (its
    Schur complement), ``F_i = C E^-1``, and ``E^-1`` is :func:`nu_gain`'s ``P_nu``."""
    A = np.array([[pseudo_inertia(e)[i, j] for e in np.eye(13)] for i, j in J_SLOTS])
    N = np.eye(13)[4:7]
    rows, cols = np.tril_indices(10)
    Q, F = np.empty((len(P), 55)), np.empty((len(P), 10, 3))
    for i, Pi in enumerate(P):
        Qt = np.linalg.inv(A @ Pi @ A.T)
        Q[i] = (0.5 * (Qt + Qt.T))[rows, cols]
        F[i] = -Qt @ (A @ Pi @ N.T)
    return Q, F


def log_det_hessian(theta):
    """The Hessian of ``-log det J(theta)`` in the 13 parameters (13 x 13, rank 10)."""
    J = pseudo_inertia(theta)
    Ji = np.linalg.inv(J)
    basis = [pseudo_inertia(e) for e in np.eye(13)]
    return np.array([[np.trace(Ji @ a @ Ji @ b) for b in basis] for a in basis])


def matched_gain(P, theta_hat0):
    """Default natural gain ``k_i`` per link: the largest k for which the natural law's gain
    at the start nowhere exceeds ``P_i`` on the pseudo-inertia (doc/design.md §8).

    With ``A`` the map theta -> J's 10 entries and ``H`` the Hessian of ``-log det J`` in
    those entries, ``k`` is the smallest eigenvalue of ``H^1/2 A P A^T H^1/2``: then
    ``k H^-1 <= A P A^T`` (the Euclidean law's gain on J), with equality along one direction.
    """
    A = np.array([_entries(pseudo_inertia(e)) for e in np.eye(13)]).T       # 10 x 13
    E = [_unpack(e) for e in np.eye(10)]
    k = np.empty(len(P))
    for i, (Pi, th) in enumerate(zip(P, theta_hat0)):
        Ji = np.linalg.inv(pseudo_inertia(th))
        H = np.array([[np.trace(Ji @ a @ Ji @ b) for b in E] for a in E])
        w, V = np.linalg.eigh(0.5 * (H + H.T))
        Hh = (V * np.sqrt(w)) @ V.T
        k[i] = np.linalg.eigvalsh(Hh @ A @ Pi @ A.T @ Hh)[0]
    return k


_IDX = ((0, 0), (1, 1), (2, 2), (3, 3), (0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3))


def _entries(J):
    return np.array([J[i, j] for i, j in _IDX])


def _unpack(v):
    J = np.zeros((4, 4))
    for x, (i, j) in zip(v, _IDX):
        J[i, j] = J[j, i] = x
    return J


def as_start(theta_hat0, n, name="theta_hat0"):
    """``theta_hat0`` (n, 13) checked to be finite and a body per link, else InputError."""
    th = as_array(theta_hat0, (n, 13), name)
    check_body(th, name)
    return th


# ---- the natural least-squares gain (doc/design.md §8) ---------------------------------------

#: sqrt(2): the weight of an off-diagonal entry of a whitened 4x4 (see :func:`whitened_into`).
_SQRT2 = math.sqrt(2.0)


@njit(cache=True, inline="always")
def inverse_cholesky4(J, L):
    """``L`` <- the inverse of the lower Cholesky factor of the 4x4 ``J`` (lower triangular,
    ``J^-1 = L^T L``); False (L partial) if J is not positive definite."""
    if not cholesky4(J, L):
        return False
    d0, d1, d2, d3 = 1.0 / L[0, 0], 1.0 / L[1, 1], 1.0 / L[2, 2], 1.0 / L[3, 3]
    for j in range(4):                              # in place, column by column
        dj = d0 if j == 0 else d1 if j == 1 else d2 if j == 2 else d3
        for i in range(j + 1, 4):
            acc = L[i, j] * dj
            for m in range(j + 1, i):
                acc += L[i, m] * L[m, j]
            L[i, j] = -acc * (d1 if i == 1 else d2 if i == 2 else d3)
        L[j, j] = dj
    return True


@njit(cache=True, inline="always")
def whitened_into(R, th, o, X, out, oo):
    """``out[oo:oo+10]``: the entries of ``N = R J(th[o:o+13]) R^T`` (``R`` from
    :func:`inverse_cholesky4` of ``J_hat``), the off-diagonal ones times sqrt(2), so that
    ``out_a . out_b = tr(J_hat^-1 J(d_a) J_hat^-1 J(d_b))``: the Hessian of ``-log det J``
    at ``J_hat`` between two directions ``d_a``, ``d_b`` of the 13 parameters. ``X``: 4x4
    scratch (``J(d)`` is linear in d, so ``th`` may be any direction)."""
    pseudo_inertia_into(th, o, X)
    for i in range(3, -1, -1):                      # X <- R X in place, bottom row first
        for j in range(4):                          # (row i reads rows m <= i only)
            acc = 0.0
            for m in range(i + 1):
                acc += R[i, m] * X[m, j]
            X[i, j] = acc
    c = 0
    for i in range(4):                              # N = (R X) R^T, lower triangle
        for j in range(i + 1):
            acc = 0.0
            for m in range(j + 1):
                acc += X[i, m] * R[j, m]
            out[oo + c] = acc if i == j else _SQRT2 * acc
            c += 1


def initial_estimates(model, geometry, theta_hat0):
    """The link estimates a controller starts from (both laws): ``theta_hat0`` checked, by
    default zero (Euclidean) or a body per link (natural: the nominal model made a body,
    doc/design.md §8)."""
    n = model.n
    if geometry == "natural":
        return default_start(model.theta()) if theta_hat0 is None else as_start(theta_hat0, n)
    return np.zeros((n, 13)) if theta_hat0 is None else \
        as_array(theta_hat0, (n, 13), "theta_hat0")


def natural_metric_option(natural_metric, barrier_c, geometry, adaptation="gradient"):
    """Check the natural geometry's metric options (doc/design.md §8): ``(natural_metric,
    c)``, ``c`` None unless ``natural_metric="barrier"`` (then ``barrier_c`` or
    :data:`BARRIER_C`); one-line :class:`GainError` otherwise. ``natural_metric=None`` is
    the default: ``"barrier"`` in the natural geometry with ``adaptation="gradient"``,
    ``"log_det"`` otherwise (natural least squares has its own metric; the Euclidean
    geometry none)."""
    if natural_metric is None:
        natural_metric = "barrier" if geometry == "natural" and adaptation == "gradient" \
            else "log_det"
    if natural_metric not in NATURAL_METRICS:
        raise GainError(f"natural_metric: expected 'log_det' or 'barrier', got "
                        f"{natural_metric!r}")
    if natural_metric == "barrier" and geometry != "natural":
        raise GainError("natural_metric: 'barrier' only with geometry='natural'")
    if natural_metric == "barrier" and adaptation != "gradient":
        raise GainError(f"natural_metric: 'barrier' needs adaptation='gradient', got "
                        f"{adaptation!r} (natural least squares has its own metric, "
                        f"doc/design.md §8)")
    if barrier_c is not None and natural_metric != "barrier":
        raise GainError("barrier_c: only with natural_metric='barrier'")
    if natural_metric != "barrier":
        return natural_metric, None
    c = scalar(BARRIER_C if barrier_c is None else barrier_c, "barrier_c", GainError,
               minimum=0.0, strict=True)
    if c < BARRIER_C_MIN:                           # H / (c k_i) must stay finite
        raise GainError(f"barrier_c: must be >= {BARRIER_C_MIN:g} (the barrier's curvature "
                        f"at the start at most {1 / BARRIER_C_MIN:g} times the quadratic's), "
                        f"got {c:g}")
    return natural_metric, c
