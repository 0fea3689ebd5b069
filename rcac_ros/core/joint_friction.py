"""Joint friction and rotor inertia in the recursive composite law (doc/design.md §7).

Each joint i adds three parameters ``theta_f,i = (armature_i, damping_i, friction_i)`` and,
in joint i's row of the joint-space regressor only, three columns. So the recursion stays
O(n): the link terms are the paper's, and joint i's terms are local to joint i.

    tau_i = z6^T F_ri + Y_f,i theta_f_hat_i,   Y_f,i = [qdd_ri, qd_ri, sigma(qd_i)]  (eq 20)
    sigma(v) = tanh(v / v_c)

(``qd_ri``, as the link terms use ``V_ri``: the viscous term then adds the dissipation
``damping s_i^2`` to the closed loop; the Coulomb term uses the actual velocity, as
``C(w)`` does.) The adaptation of eq 24 gains the joint terms:

    theta_f_hat_dot_i = -P_f,i (Y_f,i^T s_qi + gamma sum_c W_f,ci^T E_c),  s_qi = qd_i - qd_ri

The prediction channels (:mod:`rcac_ros.core.channels`) predict the joint torques with
these terms: ``tau_f,k = d/dt(armature_k qd_k) + damping_k qd_k + friction_k sigma(qd_k)``,
so for joint k's channel ``phi_f = [qd_k, 0, 0]``, ``psi_f = [0, qd_k, sigma(qd_k)]`` at
link k and nothing elsewhere; for the power channel ``qd^T tau_f = d/dt(sum 1/2 armature_i
qd_i^2) + sum (damping_i qd_i^2 + friction_i qd_i sigma(qd_i))``, so ``phi_f = [qd_i^2 / 2,
0, 0]``, ``psi_f = [0, qd_i^2, qd_i sigma(qd_i)]`` at every joint. They are filtered exactly
as the link terms (``W_f = lambda (phi_f - phi_f^f) + psi_f^f``).

Options: the joint terms use their diagonal gain ``P_f,i`` (whatever the link terms use), by
default :func:`feedback_scaled_gain` at the first step's posture, growing with the rotor
(:func:`rotor`, which also adds the rotor's feedback), or (``friction_adaptation=
"least_squares"``) a 3x3 least-squares gain below it (:func:`update_joint_least_squares`);
the leakage acts on the link terms only; the projection keeps the joint terms >= 0.
Natural geometry (doc/design.md §8): each term adapts in the positive orthant's geometry
(gain ``min(k_f x^2, P_f)`` at the step's start, :func:`term_gain`, with ``k_f`` following
the estimate, :func:`follow_gain`, then :func:`retract_term`), so it stays > 0.
Discretisation as the link terms' (explicit Euler on the tracking term, implicit or explicit
on the prediction term, one joint solve over all parameters).
"""

import math

import numpy as np
from ._jit import njit

from ._validate import numeric
from rcac_ros.errors import GainError
from ._blocks import VEC, cholesky_solve
from ._packing import (CH_ACTIVE, CH_E, CH_JOINT, CH_Y, I_GAMMA, I_H, I_IMPLICIT,
                       I_JOINT_FORGET, I_JOINT_LS, POWER, THETA_HAT, U_ROW, W_ROW)
from .channels import channel_start, filter_step
from .least_squares import potter_update

# ---- joint j: jdata[j, :] ------------------------------------------------------------------
F_HAT = 0           #: theta_f_hat_j = (armature, damping, friction) estimates (3)
F_GAIN = 3          #: P_f,j, the diagonal gain (3)
F_R = 6             #: R_f,j = theta_f_hat_j - h P_f,j (...), eq 24 step 1 (3)
F_Y = 9             #: Y_f,j = [qdd_rj, qd_rj, sigma(qd_j)] (3)
F_SQ = 12           #: s_qj = qd_j - qd_rj
F_VC = 13           #: v_c of sigma
F_K = 14            #: natural geometry: k_f,j, the natural gain (3) (doc/design.md §8)
F_PREV = 17         #: natural geometry: theta_f_hat_j before the step (3)
F_CAP = 20          #: natural geometry: the largest gain, P_f,j (3) (doc/design.md §8)
F_RATE = 23         #: rho_q,j, the rotor's rate (1/s, gains_at_start; times K_D's scale)
F_AREF = 24         #: a_ref,j: the largest a_fb,j so far (>= 0)
F_BASE = 25         #: P_f,j at a_ref,j = 0 (3)
F_GROW = 28         #: dP_f,j / da_ref,j (3): beta rho_q,j w with the default gain, else 0
F_AFB = 31          #: a_fb,j: the armature estimate (>= 0) low-passed over FOLLOW_TIME
F_LS = 32           #: least squares: T_j, P_f,j = G^1/2 T_j T_j^T G^1/2, G = diag(P_f,j) (9)
JOINT_COLS = 41

# ---- channel c, joint j: jfilt[c, j, :] ----------------------------------------------------
JPHI_F = 0          #: phi_f^f (3)
JPSI_F = 3          #: psi_f^f (3)
JPHI_PREV = 6       #: phi_f at the last step (3)
JPSI_PREV = 9       #: psi_f at the last step (3)
JW = 12             #: W_f,cj (3)
JU = 15             #: U_f,cj = P_f,j W_f,cj^T (3)
JFILT_COLS = 18

#: Default ``P_friction``: each joint's gain scaled from its feedback at the start
#: (:func:`feedback_scaled_gain`, doc/design.md §7 "Joint terms without per-arm tuning").
from .law_options import P_FRICTION  # noqa: E402  (defined where the boundaries read it)
#: ``beta_f`` (s) of :func:`feedback_scaled_gain`: the joint terms' rate per unit of the
#: weighted ``|Y_f,i|^2``.
BETA_FRICTION = 30.0
#: ``beta_f`` (s) when every joint has its own prediction channel (``channels="all"``), whose
#: implicit step (doc/design.md §6) informs each joint's terms: of 30, 100 and 300, the best
#: over unseen plants (doc/design.md §7)
BETA_FRICTION_ALL = 100.0
#: Relative weights ``w`` of the three terms (armature, damping, friction) in
#: :func:`feedback_scaled_gain`: the armature's column ``qdd_ri`` is the largest and the
#: fastest-varying of the three.
TERM_WEIGHTS = (0.1, 1.0, 1.0)
#: ``N``: the rotor's feedback ``rho_q a_fb`` keeps the sampled joint loop stable while the
#: armature estimate is below ``N`` times the joint's true rotor plus link inertia
#: (``h rho_q N <= 2``, :func:`gains_at_start`)
ROTOR_TOLERANCE = 30.0
#: natural geometry: the default start floors each model term at this value (SI units)
START_FLOOR = 1e-3
#: natural geometry: no joint term goes below this (rounding never reaches 0)
TERM_FLOOR = 1e-12
#: natural geometry: the time constant (s) with which a joint term's natural gain follows
#: its estimate (:func:`follow_gain`)
FOLLOW_TIME = 0.2

FRICTION_SIGNATURE = (f"{VEC}(float64[:, ::1], float64[:, :, ::1], float64[:, ::1], "
                      f"float64[:, :, ::1], {VEC}, {VEC}, {VEC}, {VEC}, {VEC})")


@njit(cache=True, inline="always")
def joint_terms(code, qd, sig):
    """``phi_f``, ``psi_f`` of one joint for a channel of ``CH_JOINT`` code ``code`` (3-tuples).

    Called only where the channel sees the joint: its own joint, or any joint for power.
    """
    if code == POWER:
        return (0.5 * qd * qd, 0.0, 0.0), (0.0, qd * qd, qd * sig)
    return (qd, 0.0, 0.0), (0.0, qd, sig)


@njit(cache=True, inline="always")
def predict_joint(chan, jfilt, i, qd, sig, jrow, coef, first):
    """Joint i's share of every channel that sees it: ``W_f,ci`` and ``E_c += W_f,ci theta_f_i``.

    A joint channel k sees joint k only; the power channel sees every joint.
    """
    fe, fb0, fb1, lam = coef
    for c in range(chan.shape[0]):
        code = chan[c, CH_JOINT]
        if code != POWER and code != i:
            continue
        phi, psi = joint_terms(code, qd, sig)
        E = chan[c, CH_E]
        for k in range(3):
            ph = phi[k]
            ps = psi[k]
            jfilt[c, i, JPHI_F + k], jfilt[c, i, JPSI_F + k], w = filter_step(
                first, jfilt[c, i, JPHI_F + k], jfilt[c, i, JPSI_F + k],
                jfilt[c, i, JPHI_PREV + k], jfilt[c, i, JPSI_PREV + k], ph, ps, fe, fb0, fb1,
                lam)
            jfilt[c, i, JPHI_PREV + k] = ph
            jfilt[c, i, JPSI_PREV + k] = ps
            jfilt[c, i, JW + k] = w
            E += w * jrow[F_HAT + k]
        chan[c, CH_E] = E


@njit(cache=True, inline="always")
def rotor(jrow, natural, a):
    """The rotor's share of joint j (doc/design.md §7 "The rotor"): ``a_fb,j`` moves the
    fraction ``a = min(1, h / T_f)`` toward ``max(a_hat_j, 0)``; ``a_ref,j`` becomes
    ``max(a_ref,j, a_fb,j)`` and, when it grows, the gain ``P_f,j = base + grow a_ref,j``
    (in the natural geometry its cap ``F_CAP``). Returns the rotor's feedback
    ``k_q,j = rho_q,j a_fb,j`` (the torque adds ``-k_q,j s_qj``).

    So joint j's feedback ``D_jj + k_q,j`` is ``rho_q,j`` times its inertia with the rotor,
    ``M_jj + a_fb,j`` (when ``rho_q,j = D_jj / M_jj``), and its gain follows it without
    shrinking (a gain that only grows keeps the Lyapunov function's ``d/dt P_f^-1 <= 0``;
    any ``k_q >= 0`` keeps its ``-s^T K s``).
    """
    x = max(jrow[F_HAT], 0.0)
    jrow[F_AFB] += a * (x - jrow[F_AFB])
    if jrow[F_AFB] > jrow[F_AREF]:
        jrow[F_AREF] = jrow[F_AFB]
        col = F_CAP if natural else F_GAIN
        for k in range(3):
            jrow[col + k] = jrow[F_BASE + k] + jrow[F_GROW + k] * jrow[F_AREF]
    return jrow[F_RATE] * jrow[F_AFB]


@njit(cache=True, inline="always")
def sees(code, i):
    """Whether a channel of code ``code`` has joint i's friction terms (W_f,ci != 0)."""
    return code == POWER or code == i


@njit(cache=True, inline="always")
def term_gain(k, cap, x):
    """A joint term's natural gain at ``x > 0``: ``min(k x^2, cap)`` (doc/design.md §8).

    The inverse Hessian of the potential with ``psi'' = max(1 / (k x^2), 1 / cap)``: the
    log barrier's metric near 0, the Euclidean law's fixed gain ``cap`` above
    ``sqrt(cap / k)``, so the gain never exceeds the Euclidean one.
    """
    return min(k * x * x, cap)


@njit(cache=True, inline="always")
def follow_gain(k, cap, x, a):
    """The natural gain ``k_f`` of a joint term following its estimate ``x > 0``
    (doc/design.md §8): ``log k_f`` moves the fraction ``a = min(1, h / T_f)`` of the way
    to ``log(cap / x^2)``, the value at which :func:`term_gain` is ``cap`` at ``x``. So the
    knee ``sqrt(cap / k_f)`` of ``min(k_f x^2, cap)`` is a low-pass of the estimate, in
    the positive orthant's (logarithmic) coordinate, with the time constant
    :data:`FOLLOW_TIME`: a term driven toward 0 within a few ``T_f`` meets the barrier, and
    one that settles anywhere (0.1 x or 10 x its start) is adapted with the gain ``cap``
    after a few ``T_f``, whatever its start."""
    return k * (cap / (k * x * x)) ** a


@njit(cache=True, inline="always")
def retract_term(v, op, on):
    """The 1-D retraction of :func:`~rcac_ros.core.retraction.retract` (doc/design.md
    §8): the step ``x = v[op] -> v[on]`` of a term > 0 becomes ``x (1 + r + r^2/2)``,
    ``r = a z``, ``z = (v[on] - x) / x``, ``a = min(1, 1/|z|)``: so ``x+ >= x / 2 > 0`` for
    any gain and error. A step that is not finite is not taken; ``x+`` is kept >= FLOOR.
    Returns ``a``."""
    x = v[op]
    z = (v[on] - x) / x
    if not math.isfinite(z):
        v[on] = x
        return 0.0
    a = 1.0 if abs(z) <= 1.0 else 1.0 / abs(z)
    r = a * z
    v[on] = max(x * (1.0 + r + 0.5 * r * r), TERM_FLOOR)
    return a


@njit(cache=True, inline="always")
def ls_gain_times(jrow, x0, x1, x2):
    """``P_f,j x = G^1/2 T T^T G^1/2 x``: joint j's least-squares gain (:data:`F_LS`),
    ``G = diag(P_f,j)`` its diagonal gain (doc/design.md §7)."""
    S = F_LS
    r0, r1, r2 = (math.sqrt(jrow[F_GAIN]), math.sqrt(jrow[F_GAIN + 1]),
                  math.sqrt(jrow[F_GAIN + 2]))
    x0, x1, x2 = r0 * x0, r1 * x1, r2 * x2
    t0 = jrow[S] * x0 + jrow[S + 3] * x1 + jrow[S + 6] * x2
    t1 = jrow[S + 1] * x0 + jrow[S + 4] * x1 + jrow[S + 7] * x2
    t2 = jrow[S + 2] * x0 + jrow[S + 5] * x1 + jrow[S + 8] * x2
    return (r0 * (jrow[S] * t0 + jrow[S + 1] * t1 + jrow[S + 2] * t2),
            r1 * (jrow[S + 3] * t0 + jrow[S + 4] * t1 + jrow[S + 5] * t2),
            r2 * (jrow[S + 6] * t0 + jrow[S + 7] * t1 + jrow[S + 8] * t2))


@njit(cache=True, inline="always")
def largest_eigenvalue(a00, a01, a02, a11, a12, a22):
    """The largest eigenvalue of a symmetric 3x3 matrix, closed form (O. K. Smith,
    Comm. ACM 4(4), 1961: the trigonometric solution of the characteristic cubic); to about
    1e-15 relative, 1e-8 at a double largest eigenvalue (``acos`` near +-1)."""
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    if p1 == 0.0:
        return max(a00, a11, a22)
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1) / 6.0)
    if p * p * p == 0.0:                   # off-diagonals below the underflow of p^3
        return q
    det = (b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02)
           + a02 * (a01 * a12 - b11 * a02))
    r = min(max(det / (2.0 * p * p * p), -1.0), 1.0)
    return q + 2.0 * p * math.cos(math.acos(r) / 3.0)


@njit(cache=True, inline="always")
def row_dot(T, a, b):
    """``(T T^T)_ab`` of a row-major 3x3 ``T``."""
    return T[3 * a] * T[3 * b] + T[3 * a + 1] * T[3 * b + 1] + T[3 * a + 2] * T[3 * b + 2]


@njit(cache=True, inline="always")
def joint_forgetting(T, h, lambda_0):
    """Bounded-gain forgetting of the normalised factor ``T`` (``Q = T T^T``): ``T /=
    sqrt(beta)``, ``beta = max(exp(-h lambda_f), mu)``, ``lambda_f = lambda_0 (1 - mu)``,
    ``mu = lambda_max(Q)``; so ``Q <= I`` after the step: ``P_f,j <= diag(P_f,j)``."""
    mu = largest_eigenvalue(row_dot(T, 0, 0), row_dot(T, 0, 1), row_dot(T, 0, 2),
                            row_dot(T, 1, 1), row_dot(T, 1, 2), row_dot(T, 2, 2))
    beta = max(math.exp(-h * lambda_0 * max(0.0, 1.0 - mu)), mu)
    if beta != 1.0:
        scale = 1.0 / math.sqrt(beta)
        for k in range(9):
            T[k] *= scale


@njit(cache=True, inline="always")
def joint_gradient(chan, jfilt, i, jrow, gamma, implicit, tracking, k):
    """Term k of ``Y_f,i^T s_qi + gamma sum_c W_f,ci^T E_c`` (implicit: ``- gamma sum_c
    W_f,ci^T y_c``; the solve adds the rest), over the active channels that see joint i."""
    g = jrow[F_Y + k] * jrow[F_SQ] if tracking else 0.0
    for c in range(chan.shape[0]):
        if chan[c, CH_ACTIVE] == 0.0 or not sees(chan[c, CH_JOINT], i):
            continue
        if implicit:
            g -= gamma * jfilt[c, i, JW + k] * chan[c, CH_Y]
        else:
            g += gamma * jfilt[c, i, JW + k] * chan[c, CH_E]
    return g


@njit(cache=True, inline="always")
def adapt_joint(chan, jfilt, i, jrow, scal, tracking):
    """Eq 24, step 1, joint i's terms: ``R_f,i = theta_f_hat_i - h P_f,i (Y_f,i^T s_qi
    + prediction part)``, and ``U_f,ci = P_f,i W_f,ci^T`` for the implicit solve; ``P_f,i``
    the diagonal gain, or the least-squares gain (``scal[I_JOINT_LS]``, :func:`ls_gain_times`)."""
    h, gamma = scal[I_H], scal[I_GAMMA]
    implicit = scal[I_IMPLICIT] != 0.0
    g0 = joint_gradient(chan, jfilt, i, jrow, gamma, implicit, tracking, 0)
    g1 = joint_gradient(chan, jfilt, i, jrow, gamma, implicit, tracking, 1)
    g2 = joint_gradient(chan, jfilt, i, jrow, gamma, implicit, tracking, 2)
    if scal[I_JOINT_LS] != 0.0:
        p0, p1, p2 = ls_gain_times(jrow, g0, g1, g2)
        jrow[F_R] = jrow[F_HAT] - h * p0
        jrow[F_R + 1] = jrow[F_HAT + 1] - h * p1
        jrow[F_R + 2] = jrow[F_HAT + 2] - h * p2
        if implicit:
            for c in range(chan.shape[0]):
                jfilt[c, i, JU], jfilt[c, i, JU + 1], jfilt[c, i, JU + 2] = ls_gain_times(
                    jrow, jfilt[c, i, JW], jfilt[c, i, JW + 1], jfilt[c, i, JW + 2])
        return
    jrow[F_R] = jrow[F_HAT] - h * jrow[F_GAIN] * g0
    jrow[F_R + 1] = jrow[F_HAT + 1] - h * jrow[F_GAIN + 1] * g1
    jrow[F_R + 2] = jrow[F_HAT + 2] - h * jrow[F_GAIN + 2] * g2
    if implicit:
        for c in range(chan.shape[0]):
            for k in range(3):
                jfilt[c, i, JU + k] = jrow[F_GAIN + k] * jfilt[c, i, JW + k]


@njit(cache=True, inline="always")
def update_joint_least_squares(chan, jfilt, jdata, scal, f):
    """The joint terms' least-squares gain (doc/design.md §7): per joint,
    ``d/dt P_f,i^-1 = -lambda_f P_f,i^-1 + gamma sum_c W_f,ci^T W_f,ci`` over the active
    channels that see it: Potter's update of the normalised factor ``T_i`` with the rows
    ``G^1/2 W_f,ci^T`` (:func:`~rcac_ros.core.least_squares.potter_update`), then
    :func:`joint_forgetting`. ``f``: 9 scratch entries."""
    h = scal[I_H]
    hg = h * scal[I_GAMMA]
    for i in range(jdata.shape[0]):
        jrow = jdata[i]
        T = jrow[F_LS:F_LS + 9]
        if hg > 0.0:
            for c in range(chan.shape[0]):
                if chan[c, CH_ACTIVE] != 0.0 and sees(chan[c, CH_JOINT], i):
                    for k in range(3):
                        f[6 + k] = math.sqrt(jrow[F_GAIN + k]) * jfilt[c, i, JW + k]
                    potter_update(T, f[6:9], hg, f[0:3], f[3:6])
        joint_forgetting(T, h, scal[I_JOINT_FORGET])


@njit(cache=True, inline="always")
def implicit_solve_joint(chan, filt, state, R, jfilt, jdata, A, z, idx, scal):
    """Eq 24, step 2, over link and joint terms: ``(I + h gamma U W) theta+ = R`` by Woodbury.

    ``theta+ = R - h gamma U (I + h gamma W U)^-1 W R`` with W, U the rows of every active
    channel over all parameters (13 per link and 3 per joint); m x m, O(m^2 n + m^3).
    ``A`` (m * m), ``z`` and ``idx`` (m) are scratch.
    """
    n, m = R.shape[0], chan.shape[0]
    hg = scal[I_H] * scal[I_GAMMA]
    na = 0
    for c in range(m):
        if chan[c, CH_ACTIVE] != 0.0:
            idx[na] = c
            na += 1
    for i in range(n):
        for k in range(13):
            state[i, THETA_HAT + k] = R[i, k]
        for k in range(3):
            jdata[i, F_HAT + k] = jdata[i, F_R + k]
    if na == 0:
        return
    Aa = A[:na * na].reshape((na, na))
    for a in range(na):
        ca = int(idx[a])
        sa = channel_start(chan[ca, CH_JOINT])
        acc = 0.0
        for i in range(sa, n):
            for k in range(13):
                acc += filt[ca, i, W_ROW + k] * R[i, k]
            if sees(chan[ca, CH_JOINT], i):
                for k in range(3):
                    acc += jfilt[ca, i, JW + k] * jdata[i, F_R + k]
        z[a] = acc
        for b in range(a + 1):
            cb = int(idx[b])
            s0 = max(sa, channel_start(chan[cb, CH_JOINT]))
            acc = 0.0
            for i in range(s0, n):
                for k in range(13):
                    acc += filt[ca, i, W_ROW + k] * filt[cb, i, U_ROW + k]
                if sees(chan[ca, CH_JOINT], i) and sees(chan[cb, CH_JOINT], i):
                    for k in range(3):
                        acc += jfilt[ca, i, JW + k] * jfilt[cb, i, JU + k]
            Aa[a, b] = hg * acc
            Aa[b, a] = hg * acc
        Aa[a, a] += 1.0
    zz = z[:na]
    cholesky_solve(Aa, zz)
    for a in range(na):
        ca = int(idx[a])
        zc = hg * zz[a]
        for i in range(channel_start(chan[ca, CH_JOINT]), n):
            for k in range(13):
                state[i, THETA_HAT + k] -= zc * filt[ca, i, U_ROW + k]
            if sees(chan[ca, CH_JOINT], i):
                for k in range(3):
                    jdata[i, F_HAT + k] -= zc * jfilt[ca, i, JU + k]


@njit(cache=True)
def retract_terms(prev, theta):
    """:func:`retract_term` of every joint term's step ``prev[i] -> theta[i]`` ((n, 3) each),
    in place; the smallest step length (the non-recursive law's, doc/design.md §8)."""
    v = np.empty(2)
    a_min = 1.0
    for i in range(theta.shape[0]):
        for k in range(theta.shape[1]):
            v[0], v[1] = prev[i, k], theta[i, k]
            a_min = min(a_min, retract_term(v, 0, 1))
            theta[i, k] = v[1]
    return a_min


def natural_friction_start(friction_hat0, model_terms, exc):
    """The natural geometry's joint start (doc/design.md §8): ``friction_hat0`` (every
    term must be > 0), default the model's terms floored at :data:`START_FLOOR`."""
    if friction_hat0 is None:
        return np.maximum(model_terms, START_FLOOR)
    if np.any(friction_hat0 <= 0.0):
        raise exc("friction_hat0: every joint term must be > 0 with geometry='natural' "
                  "(doc/design.md §8)")
    return friction_hat0


def friction_natural_gain(P_friction, start):
    """The natural gain of the joint terms at the start, ``k_f = P_f / x0^2``: the natural
    law's gain ``min(k_f x^2, P_f)`` (:func:`term_gain`) equals ``P_friction`` from the start
    up, and falls as ``x^2`` below it; then ``k_f`` follows the estimate
    (:func:`follow_gain`, doc/design.md §8)."""
    return P_friction / start ** 2


def feedback_matrix(model, K_D, q):
    """``D(q) = sum_j J_j^T K_Dj J_j`` (n, n): the joint-space feedback gain at ``q`` (eq 2),
    ``J_j`` (6, n) the spatial velocity ``[v; w]`` of link j's frame (in its own axes, about
    its origin) per unit joint speed (column i: joint i <= j). With ``K_Dj = kappa M_j`` it
    is ``kappa M(q)``, the rigid arm's mass matrix."""
    from .kinematics import forward_kinematics
    R, o = forward_kinematics(model, q)
    n = model.n
    z = np.array([R[i][:, 2] for i in range(n)])
    D = np.zeros((n, n))
    for j in range(n):
        lin = np.cross(z[:j + 1], o[j] - o[:j + 1]) @ R[j]     # rows: R_j^T (z_i x r_ij)
        S = np.concatenate((lin, z[:j + 1] @ R[j]), axis=1)     # (j + 1, 6): J_j^T
        D[:j + 1, :j + 1] += S @ K_D[j] @ S.T
    return D


def joint_feedback(model, K_D, q):
    """``D_ii`` (n,): the diagonal of :func:`feedback_matrix`, the links' feedback on joint i
    with every other joint held."""
    return np.diag(feedback_matrix(model, K_D, q)).copy()


def effective_feedback(D):
    """``1 / (D^-1)_ii`` (n,): the feedback joint i meets with every other joint free (the
    Schur complement of the others in ``D``), ``<= D_ii``, equal where joint i is decoupled;
    ``diag(1 / (D^-1)_ii) <= n D`` (trace bound), where ``diag(D_ii)`` is unbounded against
    ``D`` when joints are coupled (doc/design.md §7). ``D_ii`` where ``D`` is not positive
    definite."""
    try:
        L = np.linalg.cholesky(D)
    except np.linalg.LinAlgError:
        return np.diag(D).copy()
    Li = np.linalg.inv(L)
    return 1.0 / np.einsum("ki,ki->i", Li, Li)                 # (D^-1)_ii = |L^-1 e_i|^2


def feedback_scaled_gain(model, K_D, q, beta=BETA_FRICTION, weights=TERM_WEIGHTS):
    """``P_f,i = beta D_eff,i(q) w`` (n, 3): joint i's gain proportional to its effective
    feedback :func:`effective_feedback` at ``q`` (doc/design.md §7 "Joint terms without
    per-arm tuning").

    The joint terms' adaptation acts on the arm as a stiffness ``diag(P_f,i |Y_f,i|^2)``
    against the feedback ``D``: with ``P_f,i`` proportional to ``D_eff,i`` it is at most
    ``n beta |Y_f|_w^2 D`` for any coupling of the joints (with ``D_ii`` it can exceed ``D``
    without bound along a direction the joints share), and the same on every arm, for any
    scale of its masses and of ``K_D``.
    """
    D = effective_feedback(feedback_matrix(model, K_D, np.asarray(q, dtype=float)))
    return beta * np.outer(D, np.asarray(weights, dtype=float))


def joint_rates(model, K_D, q):
    """``(rho, D)``, (n,) each: ``D_ii(q)`` the links' feedback on joint i
    (:func:`joint_feedback`) and ``rho_i = D_ii / M_ii(q)`` (1/s) over its inertia in the
    model without the rotors (doc/design.md §7 "The rotor"); 0 where ``M_ii`` is 0. With
    ``K_Dj = kappa M_j`` every ``rho_i`` is ``kappa``."""
    from .crba import mass_matrix
    q = np.asarray(q, dtype=float)
    D = joint_feedback(model, K_D, q)
    M = np.diag(mass_matrix(model, q)) - np.asarray(model.armature, dtype=float)
    return np.divide(D, M, out=np.zeros_like(D), where=M > 0.0), D


def rotor_start(jdata, P, grow, rate, natural):
    """Joint data for the rotor (:func:`rotor`) from the current estimates: ``a_ref`` the
    armature estimate (>= 0), the base gain ``P`` and its growth ``grow`` ((n, 3) each),
    the rotor's rates ``rate`` (n,), the gain ``P + grow a_ref`` (natural geometry: the cap,
    and the natural gain matched to it at the estimates; least squares: the factor of the
    gain, which restarts there)."""
    a = np.maximum(jdata[:, F_HAT], 0.0)
    jdata[:, F_AREF] = a
    jdata[:, F_AFB] = a
    jdata[:, F_RATE] = rate
    jdata[:, F_BASE:F_BASE + 3] = P
    jdata[:, F_GROW:F_GROW + 3] = grow
    gain = P + grow * a[:, None]
    jdata[:, F_GAIN:F_GAIN + 3] = gain
    jdata[:, F_LS:F_LS + 9] = np.eye(3).ravel()       # least squares: P_f(0) = the gain
    if natural:
        jdata[:, F_CAP:F_CAP + 3] = gain
        jdata[:, F_K:F_K + 3] = friction_natural_gain(gain, jdata[:, F_HAT:F_HAT + 3])


def start_posture(q, n):
    """``q`` as a finite float array of n values, or None (the step then reports the bad
    input, and the gain waits for the next)."""
    try:
        q = np.asarray(q, dtype=float)
    except (TypeError, ValueError):
        return None
    return q if q.shape == (n,) and np.all(np.isfinite(q)) else None


def default_beta(channels, n, implicit, gamma):
    """``beta_f`` of the default gain: :data:`BETA_FRICTION_ALL` when every joint 1..n has
    its own prediction channel in ``channels`` (a parsed tuple), stepped implicitly and
    weighted (``gamma > 0``), else :data:`BETA_FRICTION`."""
    every = set(range(1, n + 1)) <= set(channels)
    return BETA_FRICTION_ALL if every and implicit and gamma > 0.0 else BETA_FRICTION


def gains_at_start(model, K_D, q, default, h, beta=BETA_FRICTION):
    """At the first state: ``(P, grow, rate)``: ``rate`` the rotor's rates
    ``rho_q,i = min(rho_i, 2 / (N h))`` (:func:`joint_rates` at the measured ``q``, ``N``
    :data:`ROTOR_TOLERANCE`) and, with the default gain
    (``default``), ``P`` the gain :func:`feedback_scaled_gain` at ``q`` with ``beta`` and
    ``grow = beta rho_q,i w`` its growth with the rotor (doc/design.md §7; else ``P`` None
    and ``grow`` 0); None if ``q`` is not a posture (the step reports it, and the gains wait
    for the next)."""
    q0 = start_posture(q, model.n)
    if q0 is None:
        return None
    rate = np.minimum(joint_rates(model, K_D, q0)[0], 2.0 / (ROTOR_TOLERANCE * h))
    if not default:
        return None, np.zeros((model.n, 3)), rate
    w = np.asarray(TERM_WEIGHTS, dtype=float)
    return feedback_scaled_gain(model, K_D, q0, beta=beta), beta * np.outer(rate, w), rate


def friction_gain(value, n):
    """``P_friction`` as (n, 3) positive diagonal gains: a scalar, a (3,) or an (n, 3).
    ``"feedback"`` (:data:`P_FRICTION`) gives None: the caller scales it from the joint's
    feedback at the start (:func:`feedback_scaled_gain`)."""
    if isinstance(value, str):
        if value != P_FRICTION:
            raise GainError(f"P_friction: expected {P_FRICTION!r}, a scalar, 3 values or "
                            f"({n}, 3) values, got {value!r}")
        return None
    arr = numeric(value, "P_friction", GainError)
    if arr.ndim > 2 or (arr.ndim == 1 and arr.shape != (3,)) or \
            (arr.ndim == 2 and arr.shape != (n, 3)):
        raise GainError(f"P_friction: expected a scalar, 3 values or ({n}, 3) values, "
                        f"got {value!r}")
    arr = np.broadcast_to(arr, (n, 3)).copy()
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
        raise GainError("P_friction: every entry must be finite and > 0")
    return arr
