"""Identifiability and physical consistency of a run's estimates (doc/design.md §2).

Excitation. The composite law learns link i's parameters through the rows ``W_ci`` of the
prediction channels (eq 24). Over a run the information it gathered is
``Sigma_i = sum_k h sum_c W_ci(k)^T W_ci(k)`` (13 x 13); its smallest singular value and
condition number say how well the run excited link i, and its numerical rank how many
combinations of the 13 parameters it could identify (at most 10-11, doc/design.md §2).

Consistency. From the 13 parameters ``m``, ``h = m c``, the inertia about the frame origin
``I_o`` (doc/design.md §2), the inertia about the centre of mass is
``I_c = I_o - (|h|^2 I - h h^T) / m``. A physical link has ``m > 0``, ``I_c`` positive
definite, and principal moments obeying the triangle inequalities
``I_1 + I_2 >= I_3`` (every permutation).
"""

import numpy as np
from ._jit import njit

from ._validate import as_array

#: Relative threshold on the singular values for the numerical rank of the excitation.
RANK_TOL = 1e-8


@njit(cache=True)
def accumulate(sigma, W, h):
    """``sigma[i] += h sum_c W[c, i]^T W[c, i]`` for sigma (n, 13, 13), W (m, n, 13)."""
    m, n = W.shape[0], W.shape[1]
    for i in range(n):
        for c in range(m):
            for a in range(13):
                wa = h * W[c, i, a]
                if wa == 0.0:
                    continue
                for b in range(13):
                    sigma[i, a, b] += wa * W[c, i, b]


class Excitation:
    """Accumulates ``Sigma_i`` over a run from a controller's ``W`` (m, n, 13) each step."""

    def __init__(self, n, h):
        self.sigma = np.zeros((n, 13, 13))
        self.h = float(h)

    def add(self, W):
        """One step's rows ``W`` (m, n, 13)."""
        W = as_array(W, (None, self.sigma.shape[0], 13), "W")
        accumulate(self.sigma, W, self.h)

    def report(self, rank_tol=RANK_TOL):
        """Per link: smallest and largest singular value, condition number, numerical rank."""
        out = []
        for S in self.sigma:
            sv = np.linalg.svd(S, compute_uv=False)
            top = sv[0]
            rank = int(np.sum(sv > rank_tol * top)) if top > 0.0 else 0
            out.append({"sigma_min": float(sv[-1]), "sigma_max": float(top),
                        "condition": float(top / sv[-1]) if sv[-1] > 0.0 else float("inf"),
                        "identifiable_combinations": rank})
        return out


def inertia_about_com(theta):
    """``(m, c, I_c)`` of one link's 13 parameters (doc/design.md §2); c and I_c NaN if m == 0."""
    t = as_array(theta, (13,), "theta")
    m, h = t[0], t[1:4]
    I_o = np.array([[t[10] + t[5] + t[6], -t[7], -t[8]],
                    [-t[7], t[11] + t[4] + t[6], -t[9]],
                    [-t[8], -t[9], t[12] + t[4] + t[5]]])
    if m == 0.0:
        return m, np.full(3, np.nan), np.full((3, 3), np.nan)
    return m, h / m, I_o - (h @ h * np.eye(3) - np.outer(h, h)) / m


def consistency(theta, tol=0.0):
    """Physical consistency of estimates ``theta`` (n, 13), per link.

    Returns a list of dicts: ``mass_positive``, ``inertia_pd`` (I_c positive definite),
    ``triangle`` (principal moments obey the triangle inequalities), ``consistent`` (all
    three), and the smallest principal moment and triangle margin.
    """
    theta = as_array(theta, (None, 13), "theta")
    out = []
    for t in theta:
        m, _, I_c = inertia_about_com(t)
        if not m > 0.0:
            out.append(dict(mass_positive=False, inertia_pd=False, triangle=False,
                            consistent=False, min_principal_moment=float("nan"),
                            triangle_margin=float("nan")))
            continue
        ev = np.linalg.eigvalsh(0.5 * (I_c + I_c.T))
        margin = float(ev[0] + ev[1] - ev[2])
        pd = bool(ev[0] > tol)
        tri = bool(margin >= -tol)
        out.append(dict(mass_positive=True, inertia_pd=pd, triangle=tri,
                        consistent=pd and tri, min_principal_moment=float(ev[0]),
                        triangle_margin=margin))
    return out


def summary(excitation, theta):
    """One dict for a run: per-link excitation and consistency, and counts over links."""
    exc = excitation.report()
    cons = consistency(theta)
    return {
        "links": [dict(link=i + 1, **e, **c) for i, (e, c) in enumerate(zip(exc, cons))],
        "identifiable_combinations_total": int(sum(e["identifiable_combinations"]
                                                   for e in exc)),
        "consistent_links": int(sum(c["consistent"] for c in cons)),
        "worst_condition": float(max(e["condition"] for e in exc)),
    }
