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

Per step the kernels (:mod:`rcac_ros.core.composite_kernels`) call, for every channel,
:func:`start_channels` (``y_c``), :func:`predict_link` link by link in the forward pass
(``W_cj``, ``E_c``) and :func:`close_channels` (``E_c -= y_c``, the dead zone on E).

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
from ._jit import njit

from ._packing import (CH_ACTIVE, CH_AXIS, CH_AXIS_DOT, CH_E, CH_JOINT, CH_Y, I_DZ_E, I_E, I_FB0,
                       I_FE, I_H, I_Y, PHI_F, PHI_PREV, POWER, PSI_F, PSI_PREV, Q_PREV, TAU,
                       THETA_HAT, W_ROW)
from .law_options import ALL, parse_channels  # noqa: F401  (re-exported)
from .regressor import bias_terms, momentum_terms

AXIS_Z = (0.0, 0.0, 0.0, 0.0, 0.0, 1.0)      #: z6, a joint channel's axis at its joint
AXIS_0 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def channel_codes(channels):
    """The ``CH_JOINT`` codes of parsed channels: 0-based joints, :data:`POWER` for power."""
    return np.array([POWER if c == "power" else c - 1 for c in channels], dtype=float)


@njit(cache=True)
def axis_terms(A, Ad, V, g):
    """``phi_j = a_j^T Ym(V_j)`` and ``psi_j = -adot_j^T Ym(V_j) + a_j^T Yc(V_j)`` (eq 22) for
    the axis ``A = a_j``, ``Ad = adot_j`` (6-tuples), as two 13-tuples."""
    return link_axis_terms(A, Ad, V, g)


@njit(cache=True, inline="always")
def link_axis_terms(A, Ad, V, g):
    """:func:`axis_terms`, inlined where it is called: :func:`predict_link` runs it for
    every channel at every link."""
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
def axis_terms_at_joint(V, g):
    """:func:`axis_terms` at a joint channel's own joint: ``a_j = z6``, ``adot_j = 0``, so
    ``psi_j = a_j^T Yc(V_j)`` (``adot_j^T Ym(V_j)`` is zero)."""
    vx, vy, vz, wx, wy, wz = V
    phi = momentum_terms(0.0, 0.0, 0.0, 0.0, 0.0, 1.0, vx, vy, vz, wx, wy, wz)
    psi = bias_terms(0.0, 0.0, 0.0, 0.0, 0.0, 1.0, vx, vy, vz, wx, wy, wz, g[0], g[1], g[2])
    return phi, psi


@njit(cache=True, inline="always")
def transform_axis(Ci, px, py, pz, x):
    """Eq 9's transform of a 6-vector ``x`` (a tuple) into the next link's frame, the rotation
    ``C[j]`` as a 9-tuple ``Ci``: the operations of :func:`~rcac_ros.core.spatial.propagate`."""
    c0, c1, c2, c3, c4, c5, c6, c7, c8 = Ci
    x0, x1, x2, x3, x4, x5 = x
    ux = x0 + x4 * pz - x5 * py
    uy = x1 + x5 * px - x3 * pz
    uz = x2 + x3 * py - x4 * px
    return (c0 * ux + c1 * uy + c2 * uz, c3 * ux + c4 * uy + c5 * uz, c6 * ux + c7 * uy + c8 * uz,
            c0 * x3 + c1 * x4 + c2 * x5, c3 * x3 + c4 * x4 + c5 * x5, c6 * x3 + c7 * x4 + c8 * x5)


@njit(cache=True, inline="always")
def propagate_axis(Ci, px, py, pz, qd, A, Ad):
    """A channel's ``(a_j, adot_j)`` from ``(a_j-1, adot_j-1)``: eqs 9-12 as
    :func:`~rcac_ros.core.spatial.propagate` with ``(u, ud) = (0, 0)``, the same operations,
    the rotation ``C[j]`` passed as a 9-tuple ``Ci`` (read once per link, not per channel).
    """
    tvx, tvy, tvz, twx, twy, twz = transform_axis(Ci, px, py, pz, A)
    dvx, dvy, dvz, dwx, dwy, dwz = transform_axis(Ci, px, py, pz, Ad)
    return ((tvx, tvy, tvz, twx, twy, twz + 0.0),
            (dvx + qd * tvy, dvy + -qd * tvx, dvz, dwx + qd * twy, dwy + -qd * twx, dwz + 0.0))


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
def filter_step(first, phf, psf, php, psp, ph, ps, fe, fb0, fb1, lam):
    """Eqs 22-23 for one entry of ``phi``, ``psi``: ``(phi^f, psi^f, W)`` after this period.

    ``phf``, ``psf`` are the filtered values and ``php``, ``psp`` the samples of the last
    period, ``ph``, ``ps`` this period's; the filter is the first-order hold of the module
    docstring (coefficients ``fe``, ``fb0``, ``fb1``), started at ``(phi, 0)`` on the first
    period; ``W = lambda (phi - phi^f) + psi^f``. Scalars in and out: no array argument.
    """
    if first:
        phf, psf = ph, 0.0
    else:
        phf = fe * phf + fb0 * php + fb1 * (ph - php)
        psf = fe * psf + fb0 * psp + fb1 * (ps - psp)
    return phf, psf, lam * (ph - phf) + psf


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
            u += state[j, TAU] * (q[j] - state[j, Q_PREV])
        u /= scal[I_H]
    return scal[I_FE] * chan[c, CH_Y] + scal[I_FB0] * u


@njit(cache=True, inline="always")
def channel_start(code):
    """The first link (0-based) the channel of ``CH_JOINT`` code ``code`` reaches."""
    return 0 if code == POWER else int(code)


@njit(cache=True, inline="always")
def start_channels(chan, state, scal, q, first):
    """Each ``y_c`` for this step (the filtered applied output), ``E_c`` reset to 0."""
    for c in range(chan.shape[0]):
        chan[c, CH_Y] = filtered_output(chan, c, state, scal, q, first)
        chan[c, CH_E] = 0.0


@njit(cache=True, inline="always")
def predict_link(chan, filt, i, C, p, qd, V, g, state, coef, first, pp):
    """Link i's share of every channel: ``W_ci`` and ``E_c += W_ci theta_hat_i`` (eqs 22-23).

    A joint channel k carries its axis in ``chan[c]``: ``a_k = z6``, ``adot_k = 0``, then
    ``a_j = T_j a_j-1``, ``adot_j = Tdot_j a_j-1 + T_j adot_j-1`` (doc/design.md §4). The
    filters use a first-order hold on the samples and start at ``phi(0)`` and 0, so that E
    is exact from the first step. The channel loop calls no helper taking an array (each
    would cost atomic reference counts per channel and link): it updates them in place.
    ``phi_ci``, ``psi_ci`` go through the scratch ``pp`` (26): the filter loop then reads an
    array, not a 13-tuple at a varying index (a switch per read). ``p`` is joint i's offset
    ``(px, py, pz)``, ``state`` the links' packed state (``theta_hat_i`` in row i): no view
    per link either.
    """
    fe, fb0, fb1, lam = coef
    px, py, pz = p
    Ci = (C[i, 0], C[i, 1], C[i, 2], C[i, 3], C[i, 4], C[i, 5], C[i, 6], C[i, 7], C[i, 8])
    for c in range(chan.shape[0]):
        code = chan[c, CH_JOINT]
        if code == POWER:
            phi, psi = power_terms(V, g)
        elif i < code:
            continue
        else:
            if i == code:
                A, Ad = AXIS_Z, AXIS_0
            else:
                A = (chan[c, CH_AXIS], chan[c, CH_AXIS + 1], chan[c, CH_AXIS + 2],
                     chan[c, CH_AXIS + 3], chan[c, CH_AXIS + 4], chan[c, CH_AXIS + 5])
                Ad = (chan[c, CH_AXIS_DOT], chan[c, CH_AXIS_DOT + 1], chan[c, CH_AXIS_DOT + 2],
                      chan[c, CH_AXIS_DOT + 3], chan[c, CH_AXIS_DOT + 4], chan[c, CH_AXIS_DOT + 5])
                A, Ad = propagate_axis(Ci, px, py, pz, qd, A, Ad)
            for r in range(6):
                chan[c, CH_AXIS + r] = A[r]
                chan[c, CH_AXIS_DOT + r] = Ad[r]
            if i == code:
                phi, psi = axis_terms_at_joint(V, g)
            else:
                phi, psi = link_axis_terms(A, Ad, V, g)
        (pp[0], pp[1], pp[2], pp[3], pp[4], pp[5], pp[6], pp[7], pp[8], pp[9], pp[10],
         pp[11], pp[12]) = phi
        (pp[13], pp[14], pp[15], pp[16], pp[17], pp[18], pp[19], pp[20], pp[21], pp[22],
         pp[23], pp[24], pp[25]) = psi
        E = chan[c, CH_E]
        for k in range(13):
            ph = pp[k]
            ps = pp[13 + k]
            filt[c, i, PHI_F + k], filt[c, i, PSI_F + k], w = filter_step(
                first, filt[c, i, PHI_F + k], filt[c, i, PSI_F + k], filt[c, i, PHI_PREV + k],
                filt[c, i, PSI_PREV + k], ph, ps, fe, fb0, fb1, lam)
            filt[c, i, PHI_PREV + k] = ph
            filt[c, i, PSI_PREV + k] = ps
            filt[c, i, W_ROW + k] = w
            E += w * state[i, THETA_HAT + k]
        chan[c, CH_E] = E


@njit(cache=True, inline="always")
def close_channels(chan, scal):
    """``E_c -= y_c`` and the dead zone on E: a channel adapts only if ``|E_c| > dz``."""
    dz = scal[I_DZ_E]
    for c in range(chan.shape[0]):
        chan[c, CH_E] -= chan[c, CH_Y]
        chan[c, CH_ACTIVE] = 1.0 if dz <= 0.0 or abs(chan[c, CH_E]) > dz else 0.0
    scal[I_E] = chan[0, CH_E]
    scal[I_Y] = chan[0, CH_Y]
