"""The retraction of the natural geometry (doc/design.md §8): a step made physically consistent.

A step ``Delta = J(theta_lin - theta_hat)`` of a link's pseudo-inertia
(:mod:`rcac_ros.core.pseudo_inertia`) is made consistent by

    J+ = J_hat + a Delta + a^2/2 Delta J_hat^-1 Delta = L (I + a Z + a^2 Z^2 / 2) L^T,
    Z = L^-1 Delta L^-T,  J_hat = L L^T,  a = min(1, 1 / ||Z||_F)

positive definite for any Delta (eigenvalues of ``I + aZ + a^2 Z^2/2`` lie in [1/2, 5/2]),
with a numerical floor ``lambda_min(J+) >= FLOOR tr(J+)`` (:func:`retract`); with the
metric ``"barrier"`` the Euclidean step is shortened instead (:func:`retract_short`).
O(1) per link: 4x4 products and ``J_hat^-1`` from its ``L D L^T`` (no square root); the
floor's Cholesky factorisation only past :data:`COND_SHORTCUT`.
"""

import math

from ._jit import njit
from .pseudo_inertia import (cholesky_entries, inverse_ldl_entries, positive_definite4,
                             pseudo_entries, theta_from_entries)


#: Numerical floor of the retraction: lambda_min(J) >= FLOOR tr(J) after every step, far
#: above the rounding of a 4x4 factorisation and far below any real body's ratio.
FLOOR = 1e-12


#: Numerical guard on nu: |nu_k| <= NU_RATIO tr(J), so that the 13 stored parameters keep
#: J's digits (a body has 0 <= nu_k = h_k^2 / m <= Sigma_kk <= tr(J)).
NU_RATIO = 100.0


#: Most halvings of a step that would cross the floor (2^-30: the step is then kept out).
HALVINGS = 30


#: A step with tr(J+) tr(J_hat^-1) at most this skips the floor's factorisation on its first
#: try: it provably passes (it can fail only beyond 1 / (2 FLOOR) = 5e11, :func:`retract`).
COND_SHORTCUT = 1e9


@njit(cache=True, inline="always")
def step_entries(old, oo, new, on):
    """The step ``old -> new`` of a retraction: J_hat's 10 entries, Delta's 10 (``J(new) -
    J_hat``, in the order of :func:`pseudo_entries`) and new's nu."""
    j00, j11, j22, j33, j01, j02, j12, j03, j13, j23 = pseudo_entries(old, oo)
    e00, e11, e22, e33, e01, e02, e12, e03, e13, e23 = pseudo_entries(new, on)
    return (j00, j11, j22, j33, j01, j02, j12, j03, j13, j23,
            e00 - j00, e11 - j11, e22 - j22, e33 - j33, e01 - j01, e02 - j02, e12 - j12,
            e03 - j03, e13 - j13, e23 - j23, new[on + 4], new[on + 5], new[on + 6])


@njit(cache=True, inline="always")
def retract(old, oo, new, on):
    """Make the step ``old -> new`` (13 parameters each) consistent, in place in ``new``.

    ``J_hat = J(old)`` must be positive definite. With ``Delta = J(new) - J_hat``, ``new``
    becomes the parameters of ``J_hat + a Delta + a^2/2 Delta J_hat^-1 Delta`` (its nu
    unchanged), ``a = min(1, 1/||Z||_F)``, ``Z = L^-1 Delta L^-T`` (module docstring).
    Returns ``a`` (1: the step was not shortened). ``old`` and ``new`` may share an array.
    The 4x4 algebra is unrolled on the 10 entries of each symmetric matrix (J_hat, Delta,
    J_hat^-1, Delta J_hat^-1 Delta, the trial J+) and the 16 of ``J_hat^-1 Delta``, in
    registers; ``J_hat^-1`` comes from J_hat's own ``L D L^T`` (L unit lower, not the
    Cholesky factor of Z; four divisions, no square root,
    :func:`~rcac_ros.core.pseudo_inertia.inverse_ldl_entries`), and ``||Z||_F^2 =
    tr((J_hat^-1 Delta)^2)`` needs no factor of its own.

    Floating point: ``a`` is halved (at most :data:`HALVINGS` times) until ``J+ - FLOOR
    tr(J+) 1`` passes a Cholesky factorisation, so every stored J stays clear of rounding
    (:data:`FLOOR`); if none passes, or ``J_hat`` itself is not positive definite, J is kept
    (``a = 0``) and only nu moves; a step that is not finite is not taken at all. ``nu`` is
    clipped to ``|nu_k| <= NU_RATIO tr(J+)`` (:data:`NU_RATIO`).
    """
    (j00, j11, j22, j33, j01, j02, j12, j03, j13, j23, d00, d11, d22, d33, d01, d02, d12,
     d03, d13, d23, n0, n1, n2) = step_entries(old, oo, new, on)
    ok, k00, k01, k02, k03, k11, k12, k13, k22, k23, k33 = inverse_ldl_entries(  # J_hat^-1
        j00, j11, j22, j33, j01, j02, j12, j03, j13, j23)
    if not ok:                                     # never, from a checked start
        theta_from_entries(j00, j11, j22, j33, j01, j02, j12, j03, j13, j23, n0, n1, n2,
                           new, on)
        return 0.0
    tr_inv = k00 + k11 + k22 + k33                # >= 1 / lambda_min(J_hat)
    # J_hat^-1 Delta
    m00 = k00 * d00 + k01 * d01 + k02 * d02 + k03 * d03
    m01 = k00 * d01 + k01 * d11 + k02 * d12 + k03 * d13
    m02 = k00 * d02 + k01 * d12 + k02 * d22 + k03 * d23
    m03 = k00 * d03 + k01 * d13 + k02 * d23 + k03 * d33
    m10 = k01 * d00 + k11 * d01 + k12 * d02 + k13 * d03
    m11 = k01 * d01 + k11 * d11 + k12 * d12 + k13 * d13
    m12 = k01 * d02 + k11 * d12 + k12 * d22 + k13 * d23
    m13 = k01 * d03 + k11 * d13 + k12 * d23 + k13 * d33
    m20 = k02 * d00 + k12 * d01 + k22 * d02 + k23 * d03
    m21 = k02 * d01 + k12 * d11 + k22 * d12 + k23 * d13
    m22 = k02 * d02 + k12 * d12 + k22 * d22 + k23 * d23
    m23 = k02 * d03 + k12 * d13 + k22 * d23 + k23 * d33
    m30 = k03 * d00 + k13 * d01 + k23 * d02 + k33 * d03
    m31 = k03 * d01 + k13 * d11 + k23 * d12 + k33 * d13
    m32 = k03 * d02 + k13 * d12 + k23 * d22 + k33 * d23
    m33 = k03 * d03 + k13 * d13 + k23 * d23 + k33 * d33
    z2 = (0.0 + m00 * m00 + m01 * m10 + m02 * m20 + m03 * m30      # ||Z||_F^2 = tr((J^-1 D)^2)
          + m10 * m01 + m11 * m11 + m12 * m21 + m13 * m31
          + m20 * m02 + m21 * m12 + m22 * m22 + m23 * m32
          + m30 * m03 + m31 * m13 + m32 * m23 + m33 * m33)
    if not (math.isfinite(z2) and math.isfinite(n0 + n1 + n2)):
        for c in range(13):                         # a step that is not finite: no step
            new[on + c] = old[oo + c]
        return 0.0
    # Q = Delta J_hat^-1 Delta (symmetric)
    q00 = d00 * m00 + d01 * m10 + d02 * m20 + d03 * m30
    q01 = d00 * m01 + d01 * m11 + d02 * m21 + d03 * m31
    q02 = d00 * m02 + d01 * m12 + d02 * m22 + d03 * m32
    q03 = d00 * m03 + d01 * m13 + d02 * m23 + d03 * m33
    q11 = d01 * m01 + d11 * m11 + d12 * m21 + d13 * m31
    q12 = d01 * m02 + d11 * m12 + d12 * m22 + d13 * m32
    q13 = d01 * m03 + d11 * m13 + d12 * m23 + d13 * m33
    q22 = d02 * m02 + d12 * m12 + d22 * m22 + d23 * m32
    q23 = d02 * m03 + d12 * m13 + d22 * m23 + d23 * m33
    q33 = d03 * m03 + d13 * m13 + d23 * m23 + d33 * m33
    a = 1.0 if z2 <= 1.0 else 1.0 / math.sqrt(z2)
    for h in range(HALVINGS):
        half = 0.5 * a * a                          # J+ = J_hat + a Delta + a^2/2 Q
        c00, c11 = j00 + a * d00 + half * q00, j11 + a * d11 + half * q11
        c22, c33 = j22 + a * d22 + half * q22, j33 + a * d33 + half * q33
        tr = 0.0 + c00 + c11 + c22 + c33
        # the numerical floor (module docstring). Shortcut: lambda_min(J+) >= (1 - r + r^2/2)
        # lambda_min(J) >= lambda_min(J) / 2 (r = a ||Z||_F <= 1) and lambda_min(J) >= 1 /
        # tr(J^-1), so J+ clears the floor when tr(J+) tr(J^-1) < 1 / (2 FLOOR) = 5e11; at
        # most COND_SHORTCUT (500x under that, J+'s margin far above the rounding of this
        # step) the factorisation would pass: it is skipped.
        if h == 0 and tr * tr_inv <= COND_SHORTCUT:
            break
        f = FLOOR * tr
        if cholesky_entries(c00 - f, c11 - f, c22 - f, c33 - f,
                            j01 + a * d01 + half * q01, j02 + a * d02 + half * q02,
                            j12 + a * d12 + half * q12, j03 + a * d03 + half * q03,
                            j13 + a * d13 + half * q13, j23 + a * d23 + half * q23)[0]:
            break
        a *= 0.5
    else:
        a = 0.0                                     # keep J_hat (it passed before)
    if a > 0.0:
        j00, j11, j22, j33 = c00, c11, c22, c33
        j01, j02, j12 = j01 + a * d01 + half * q01, j02 + a * d02 + half * q02, \
            j12 + a * d12 + half * q12
        j03, j13, j23 = j03 + a * d03 + half * q03, j13 + a * d13 + half * q13, \
            j23 + a * d23 + half * q23
    bound = NU_RATIO * (j00 + j11 + j22 + j33)
    theta_from_entries(j00, j11, j22, j33, j01, j02, j12, j03, j13, j23,
                       min(max(n0, -bound), bound), min(max(n1, -bound), bound),
                       min(max(n2, -bound), bound), new, on)
    return a


@njit(cache=True, inline="always")
def retract_short(old, oo, new, on):
    """The barrier metric's retraction: the Euclidean step ``old -> new``, shortened.

    ``J+ = J_hat + a Delta`` with ``a`` the largest of 1, 1/2, 1/4, ... (at most
    :data:`HALVINGS` halvings) for which ``J+ - FLOOR tr(J+) 1 - 1/2 J_hat`` is positive
    definite (the pivots of its ``L D L^T``,
    :func:`~rcac_ros.core.pseudo_inertia.positive_definite4`): no direction of ``J_hat``
    loses more than half of itself in a step, and J+ clears the floor. One 4x4
    factorisation (three divisions) when the step is kept whole.
    ``J_hat = J(old)`` must be positive definite; a step that is not finite, or that no
    halving makes pass, is not taken (``a = 0``: J kept, nu moves). ``nu`` is clipped as
    in :func:`retract`. Returns ``a``.
    """
    (j00, j11, j22, j33, j01, j02, j12, j03, j13, j23, d00, d11, d22, d33, d01, d02, d12,
     d03, d13, d23, n0, n1, n2) = step_entries(old, oo, new, on)
    a = 1.0
    if not math.isfinite(d00 + d11 + d22 + d33 + d01 + d02 + d12 + d03 + d13 + d23
                         + n0 + n1 + n2):
        for c in range(13):                         # a step that is not finite: no step
            new[on + c] = old[oo + c]
        return 0.0
    for h in range(HALVINGS):
        f = FLOOR * (j00 + j11 + j22 + j33 + a * (d00 + d11 + d22 + d33))
        if positive_definite4(0.5 * j00 + a * d00 - f, 0.5 * j11 + a * d11 - f,
                              0.5 * j22 + a * d22 - f, 0.5 * j33 + a * d33 - f,
                              0.5 * j01 + a * d01, 0.5 * j02 + a * d02, 0.5 * j12 + a * d12,
                              0.5 * j03 + a * d03, 0.5 * j13 + a * d13, 0.5 * j23 + a * d23):
            break
        a *= 0.5
    else:
        a = 0.0                                     # keep J_hat
    j00, j11, j22, j33 = j00 + a * d00, j11 + a * d11, j22 + a * d22, j33 + a * d33
    j01, j02, j12 = j01 + a * d01, j02 + a * d02, j12 + a * d12
    j03, j13, j23 = j03 + a * d03, j13 + a * d13, j23 + a * d23
    bound = NU_RATIO * (j00 + j11 + j22 + j33)
    theta_from_entries(j00, j11, j22, j33, j01, j02, j12, j03, j13, j23,
                       min(max(n0, -bound), bound), min(max(n1, -bound), bound),
                       min(max(n2, -bound), bound), new, on)
    return a


@njit(cache=True)
def retract_rows(prev, theta, short):
    """Every link's step ``prev[i] -> theta[i]`` made consistent in place, by :func:`retract`
    or, with ``short`` (the metric ``"barrier"``), by :func:`retract_short`; the smallest
    step length."""
    a_min = 1.0
    for i in range(theta.shape[0]):
        if short:
            a = retract_short(prev[i], 0, theta[i], 0)
        else:
            a = retract(prev[i], 0, theta[i], 0)
        a_min = min(a_min, a)
    return a_min
