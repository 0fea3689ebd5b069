"""Least-squares adaptation gain with bounded-gain forgetting (Slotine and Li, Automatica 1989).

Per link, the gain ``P_i`` of eq 24 evolves as

    d/dt P_i^-1 = -lambda_f(t) P_i^-1 + W_i^T W_i,     lambda_f = lambda_0 (1 - ||P_i|| / k_0)

(``W_i``: the m rows ``W_ci`` of the prediction channels), so that ``||P_i|| <= k_0``.

Square-root form. The controller keeps a factor ``S_i`` with ``P_i = S_i S_i^T``. One step:

1. information update ``P'^-1 = P^-1 + h W_i^T W_i``, one channel row ``w`` at a time by
   Potter's square-root update: ``f = S^T w``, ``alpha = 1/h + f.f``,
   ``S' = S - (S f) f^T / (alpha + sqrt(alpha / h))``;
2. forgetting ``P+ = P' / beta``, ``beta = exp(-h lambda_f)``, ``S+ = S' / sqrt(beta)``,
   with ``||P||`` measured by ``trace(P) = ||S||_F^2`` (an upper bound of the 2-norm),
   and ``beta >= trace(P') / k_0`` so that the bound holds exactly after the step.

``S S^T`` is a Gram matrix, so P stays symmetric; each factor ``I - c f f^T`` has the
eigenvalue ``(1/h + sqrt(alpha/h)) / (alpha + sqrt(alpha/h)) > 0`` along f, so P stays
positive definite, whatever the rounding. Cost per link and channel: three 13x13
products, O(m n) per step. The joint terms' least-squares gain (doc/design.md §7) uses the
same step 1 on a 3x3 factor.
"""

import math

import numpy as np
from ._jit import njit


def initial_factor(P):
    """``S(0)`` (n, 169) from ``P(0)`` (n, 13, 13): the lower Cholesky factors, row-major."""
    return np.linalg.cholesky(P).reshape(P.shape[0], 169)


@njit(cache=True)
def apply_factored(S, o, x, out, t):
    """``out = S S^T x`` for the row-major 13x13 factor ``S[o:o+169]`` (``t``: 13 scratch)."""
    for c in range(13):
        acc = 0.0
        for r in range(13):
            acc += S[o + 13 * r + c] * x[r]
        t[c] = acc
    for r in range(13):
        acc = 0.0
        for c in range(13):
            acc += S[o + 13 * r + c] * t[c]
        out[r] = acc


@njit(cache=True)
def potter_update(S, w, h, f, Sf):
    """Step 1: ``S`` becomes the factor of ``(S S^T)^-1 + h w^T w`` (one channel row w).

    ``S``: the d x d factor, row-major (d^2 entries), d the length of ``w`` (13 for a
    link, 3 for a joint's terms, doc/design.md §7); ``f`` and ``Sf`` are scratch rows of
    at least d entries.
    """
    d = w.shape[0]
    ff = 0.0
    for c in range(d):
        acc = 0.0
        for r in range(d):
            acc += S[d * r + c] * w[r]
        f[c] = acc
        ff += acc * acc
    if ff == 0.0:
        return
    r_inv = 1.0 / h
    alpha = r_inv + ff
    coef = 1.0 / (alpha + math.sqrt(alpha * r_inv))
    for r in range(d):
        acc = 0.0
        for c in range(d):
            acc += S[d * r + c] * f[c]
        Sf[r] = coef * acc
    for r in range(d):
        for c in range(d):
            S[d * r + c] -= Sf[r] * f[c]


@njit(cache=True)
def bounded_gain_forgetting(S, h, lambda_0, k_0):
    """Step 2: ``S /= sqrt(beta)``; returns ``trace(P)`` after the step (``<= k_0``)."""
    tr = 0.0
    for k in range(169):
        tr += S[k] * S[k]
    lam_f = lambda_0 * max(0.0, 1.0 - tr / k_0)
    beta = max(math.exp(-h * lam_f), tr / k_0)
    if beta != 1.0:
        scale = 1.0 / math.sqrt(beta)
        for k in range(169):
            S[k] *= scale
    return tr / beta
