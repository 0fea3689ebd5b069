"""Prediction channels: which filtered torques the composite law predicts (doc/design.md §4).

A channel is a fixed weighted combination ``c^T tau`` of the joint torques. It is predicted
by one recursion over the links, with ``a_j`` the channel's axis seen in frame j:

    a_j = T_j a_j-1 + c_j z6,   adot_j = Tdot_j a_j-1 + T_j adot_j-1
    c^T tau = sum_j a_j^T F*_j = sum_j [d/dt(phi_j) + psi_j] theta_j
    phi_j = a_j^T Ym_j(V_j),   psi_j = -adot_j^T Ym_j(V_j) + a_j^T Yc_j(V_j)

- **joint k** (``c = e_k``): ``a_j = 0`` for j < k, ``a_k = z6``; ``k = 1`` is the paper's.
- **power** (``c = qd``, varying): ``qd^T tau = sum_j V_j^T F*_j
  = d/dt(1/2 sum_j V_j^T M_j V_j) + sum_j V_j^T G_j`` (the energy model: no accelerations),
  so ``phi_j = 1/2 V_j^T Ym_j(V_j)`` and ``psi_j = V_j^T G_j`` as a row in theta_j.

Each channel is filtered by ``lambda / (p + lambda)`` (eq 22-23): ``W_cj = lambda (phi_cj -
phi_cj^f) + psi_cj^f``, ``y_c`` = the applied ``c^T tau`` filtered, ``E_c = sum_j W_cj
theta_hat_j - y_c``.

Discretisation and its error (with the true parameters, E_c measures only this):

- ``y``: a joint channel's torque is held over the period, so its zero-order hold is
  exact. The power channel's integrand ``qd^T tau`` varies within the period; its exact
  integral is ``tau^T (q_k - q_k-1)``, and ``y`` filters that mean power with a zero-order
  hold, an error of about ``lambda h^2 / 12`` times the power's rate of change.
- ``phi^f``, ``psi^f``: a first-order hold on the samples, exact when ``phi theta`` and
  ``psi theta`` are linear within a period, O(h^2) otherwise. For a first joint whose
  axis is fixed and parallel to gravity (the CSS arm's joint 1), ``sum_j psi_j theta_j = 0``
  and ``sum_j phi_j theta_j`` (the angular momentum about the axis) has the held torque as
  its rate: E is then at rounding level (3e-13 of max |y| on the paper's motion).
  Without gravity the power channel is exact too (``psi = 0``; the mean-power hold of y
  and the first-order hold of the kinetic energy ``phi theta`` are the same interpolation).
  Every other channel has the O(h^2) error: on the paper's motion at h = 2 ms, at most
  2e-6 of max |y_c| (joints 2-7 and power, measured; halving h divides it by 4).
"""

import numpy as np
from numba import njit

from ._packing import CH_JOINT, CH_Y, I_FB0, I_FE, I_H, POWER, QPREV, TAU
from rcac_ros.errors import GainError
from .regressor import bias_terms, momentum_terms

#: The value of ``channels`` that gives every joint.
ALL = "all"


def parse_channels(value, n):
    """Validate ``channels``: ``[1]``, ``"all"``, ``"power"``, ``"1,power"`` or a list of those.

    Parameters
    ----------
    value : int, str or sequence of int/str
        Joint numbers are 1-based; ``"power"`` is the energy channel; ``"all"`` is 1..n.
    n : int or None
        Number of joints; None checks the syntax only (``"all"`` stays ``"all"``).

    Returns
    -------
    tuple
        The channels in order, each an ``int`` in 1..n or ``"power"``.

    Raises
    ------
    GainError
        One line naming ``channels`` and the bad entry.
    """
    items = value.split(",") if isinstance(value, str) else value
    if isinstance(items, (int, np.integer)):
        items = [items]
    try:
        items = list(items)
    except TypeError:
        raise GainError(f"channels: expected joint numbers, 'power' or 'all', got {value!r}") \
            from None
    joints = "joint number" if n is None else f"joint number (1..{n})"
    out = []
    for item in items:
        if isinstance(item, str):
            word = item.strip().lower()
            if word == ALL:
                out.extend([ALL] if n is None else range(1, n + 1))
                continue
            if word == "power":
                out.append("power")
                continue
            if not word.lstrip("+").isdigit():
                raise GainError(f"channels: {item!r} is not a {joints}, 'power' or 'all'")
            item = int(word)
        if isinstance(item, (bool, np.bool_)) or not isinstance(item, (int, np.integer)):
            raise GainError(f"channels: {item!r} is not a {joints}, 'power' or 'all'")
        if item < 1 or (n is not None and item > n):
            raise GainError(f"channels: joint {item} is out of range 1..{n or 'n'}")
        out.append(int(item))
    if not out:
        raise GainError("channels: empty (give at least one joint number, 'power' or 'all')")
    dup = sorted({str(c) for c in out if out.count(c) > 1})
    if dup:
        raise GainError(f"channels: listed twice: {', '.join(dup)}")
    return tuple(out)


def channel_codes(channels):
    """The ``CH_JOINT`` codes of parsed channels: 0-based joints, :data:`POWER` for power."""
    return np.array([POWER if c == "power" else c - 1 for c in channels], dtype=float)


def first_link(code):
    """The first link (0-based) whose W row a channel can make non-zero."""
    return 0 if code == POWER else int(code)


@njit(cache=True)
def axis_terms(A, Ad, V, g):
    """``phi_j = a_j^T Ym(V_j)`` and ``psi_j = -adot_j^T Ym(V_j) + a_j^T Yc(V_j)`` (eq 22) for
    the axis ``A = a_j``, ``Ad = adot_j`` (6-tuples), as two 13-tuples."""
    vx, vy, vz, wx, wy, wz = V
    a0, a1, a2, a3, a4, a5 = A
    b0, b1, b2, b3, b4, b5 = Ad
    phi = momentum_terms(a0, a1, a2, a3, a4, a5, vx, vy, vz, wx, wy, wz)
    d = momentum_terms(b0, b1, b2, b3, b4, b5, vx, vy, vz, wx, wy, wz)
    b = bias_terms(a0, a1, a2, a3, a4, a5, vx, vy, vz, wx, wy, wz, g[0], g[1], g[2])
    psi = (b[0] - d[0], b[1] - d[1], b[2] - d[2], b[3] - d[3], b[4] - d[4], b[5] - d[5],
           b[6] - d[6], b[7] - d[7], b[8] - d[8], b[9] - d[9], b[10] - d[10], b[11] - d[11],
           b[12] - d[12])
    return phi, psi


@njit(cache=True, inline="always")
def power_terms(V, g):
    """The energy channel: ``phi_j = 1/2 V_j^T Ym(V_j)``, ``psi_j = V_j^T G_j`` (13-tuples).

    ``V^T G = -(m v.g + w.(h x g)) = -m v.g + h.(w x g)`` (G of doc/design.md §2).
    """
    vx, vy, vz, wx, wy, wz = V
    gx, gy, gz = g
    t = momentum_terms(vx, vy, vz, wx, wy, wz, vx, vy, vz, wx, wy, wz)
    phi = (0.5 * t[0], 0.5 * t[1], 0.5 * t[2], 0.5 * t[3], 0.5 * t[4], 0.5 * t[5],
           0.5 * t[6], 0.5 * t[7], 0.5 * t[8], 0.5 * t[9], 0.5 * t[10], 0.5 * t[11],
           0.5 * t[12])
    psi = (-(vx * gx + vy * gy + vz * gz), wy * gz - wz * gy, wz * gx - wx * gz,
           wx * gy - wy * gx, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    return phi, psi


@njit(cache=True, inline="always")
def filtered_output(chan, c, state, scal, q, first):
    """``y_c``: the applied ``c^T tau`` of the last period through the filter (zero-order hold).

    A joint channel's torque was held, so its hold is exact; the power channel holds the
    period's mean power ``tau^T (q - q_prev) / h``, whose integral is exact.
    """
    if first:
        return 0.0
    k = int(chan[c, CH_JOINT])
    if k >= 0:
        u = state[k, TAU]
    else:
        u = 0.0
        for j in range(q.shape[0]):
            u += state[j, TAU] * (q[j] - state[j, QPREV])
        u /= scal[I_H]
    return scal[I_FE] * chan[c, CH_Y] + scal[I_FB0] * u
