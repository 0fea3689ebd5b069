"""The named layout of the arrays the step kernels read, and the packing of the gains into it.

A step kernel takes few arguments (each costs a dispatch check and a reference count), so
the controllers pack their constants, state and scalars into two float64 arrays: ``data``,
and ``filt`` with ``chan`` as its row n, ``(m, n + 1, FILT_COLS)``:

``data`` (n + 1, LINK_COLS)
    row ``i < n``: link i's constants (``CONST``), then its state (``STATE``);
    row ``n``: the scalars (``I_*``).
``filt`` (m, n, FILT_COLS)
    channel c, link j: the filters of eqs 21-23 (``phi^f``, ``psi^f``, the previous ``phi``,
    ``psi``), the filtered regressor row ``W_cj`` and ``U_cj = P_j W_cj^T`` (eq 24).
``chan`` (m, CHAN_COLS): ``filt[:, n, :CHAN_COLS]``
    channel c: its joint (0-based, :data:`POWER` for the energy channel), ``y_c``, ``E_c``,
    whether it adapts this step (dead zone), and its axis ``a_j``, ``adot_j`` while the
    forward pass runs (doc/design.md §4).

Every offset below is a module constant, so numba folds it; :func:`block` gives the
slices the Python side reads.
"""

import math

import numpy as np

from ._validate import per_link_matrix, positive_vector, scalar
from rcac_ros.errors import GainError
from .model import P0, RF0

# ---- per-link constants: data[i, :CONST_COLS] ----------------------------------------------
#: p_i (3) and R_fix_i (9) at the columns of :func:`rcac_ros.core.model.pack_kinematics` (P0, RF0)
LAMBDA = 12         #: Lambda_i (eq 18)
GAIN_K_D = 13       #: K_Di, 6x6 row-major (eq 19b)
GAIN_P = 49         #: P_i, 13x13 row-major (eq 24): the fixed adaptation gain
THETA_MIN = 218     #: lower bounds of theta_i (13): projection
THETA_MAX = 231     #: upper bounds of theta_i (13)
TRACE_MAX = 244     #: k_0 of link i: the bound on trace(P_i) (least squares)
THETA_0 = 245       #: theta_0i (13), the nominal estimates the leakage pulls toward
LEAK_M0 = 258       #: M_0 of link i, the switching leakage's radius (0: fixed sigma)
NAT_K = 259         #: k_i, the natural geometry's gain (doc/design.md §8)
NAT_P_NU = 260      #: P_nu,i, 3x3 row-major, its gain on nu (doc/design.md §8)
BAR_Q = 269         #: metric "barrier": (A P_i A^T)^-1, P_i's metric on J's 10 entries with nu
#:                     eliminated (10x10 lower, packed by rows: 55), doc/design.md §8
BAR_F = 324         #: metric "barrier": F_i = C_i E_i^-1, the coupling of J's entries and nu in
#:                     the metric P_i^-1 (10 x 3, row-major), doc/design.md §8
CONST_COLS = 354

# ---- per-link state: data[i, CONST_COLS:] (offsets relative to the state block) ------------
THETA_HAT = 0       #: theta_hat_i (13)
S_LINK = 13         #: s_i = V_i - V_ri (6)
TAU = 19            #: the torque of joint i applied over the last period
Q_PREV = 20         #: q_i at the last step (the power channel's tau^T dq)
P_FACTOR = 21       #: S_i, 13x13 row-major, with P_i = S_i S_i^T (least squares)
THETA_PREV = 190    #: theta_hat_i before this step's update (the natural retraction)
NAT_LS_CHOL = 203   #: natural least squares: Cholesky factor of I + S^T H S / k (13x13 lower,
#:                     row-major); metric "barrier": the factor of H_J / (c k) + (A P A^T)^-1
#:                     (10x10 lower, row-major, its diagonal inverted), doc/design.md §8
NAT_LS_N = 372      #: natural least squares: the whitened J(S e_j) of S's 13 columns (13 x 10)
TAU_FF = 502        #: hold_compensation: joint i's model torque (eq 20 without feedback) at
#:                     the last step
STATE_COLS = 510    #: padded: LINK_COLS a multiple of 8, each link's row on a 64-byte line
LINK_COLS = CONST_COLS + STATE_COLS

# ---- scalars: data[n, :] -------------------------------------------------------------------
I_G = 0             #: gravity in the base frame (3)
I_LAM = 3           #: filter bandwidth lambda
I_H = 4             #: control period h
I_GAMMA = 5         #: gamma, weight of the prediction errors (eq 24)
I_FE = 6            #: exp(-lambda h)
I_FB0 = 7           #: 1 - exp(-lambda h)            (zero-order hold)
I_FB1 = 8           #: 1 - (1 - exp(-lambda h)) / (lambda h)   (first-order hold)
I_K = 9             #: steps since the filters started
I_ERR = 10          #: input error code left by the kernel
I_KD_DIAG = 11      #: 1 if every K_Di is diagonal (the kernel skips the zeros)
I_P_DIAG = 12       #: 1 if every P_i is diagonal
I_IMPLICIT = 13     #: 1: implicit Euler in the prediction-error term, 0: explicit
I_ADAPT = 14        #: ADAPT_GRADIENT, ADAPT_LS or ADAPT_LS_PREDICTION
I_FORGET = 15       #: lambda_0 of the bounded-gain forgetting, 1/s
I_FROZEN = 16       #: 1: adaptation frozen (set_adaptation(False)): theta_hat and P held
I_DZ_S = 17         #: dead zone on max |qd - qd_r| (0: none)
I_DZ_E = 18         #: dead zone on |E_c| (0: none)
I_PROJECT = 19      #: 1: clip theta_hat to [THETA_MIN, THETA_MAX] after each step
I_E = 20            #: E of the first channel (the paper's scalar E)
I_Y = 21            #: y of the first channel
I_TRACKING = 22     #: 1 if the tracking term adapted at the last step (dead zone)
I_LEAK = 23         #: sigma_0 of the leakage toward theta_0 (0: none)
I_NATURAL = 24      #: 1: natural geometry, estimates kept consistent (doc/design.md §8)
I_RETRACT_MIN = 25  #: the smallest step length a of the retraction at the last step
I_BARRIER_C = 26    #: natural geometry, metric "barrier": c of P_mix (0: "log_det"), §8
I_JOINT_LS = 27     #: 1: the joint terms' gain is least squares (doc/design.md §7)
I_JOINT_FORGET = 28  #: lambda_0 of the joint terms' bounded-gain forgetting, 1/s
I_HOLD = 29         #: 1: hold_compensation (doc/design.md §6 "The hold")
SCAL_LEN = 30

ADAPT_GRADIENT, ADAPT_LS, ADAPT_LS_PREDICTION = 0.0, 1.0, 2.0

# ---- channel c, link j: filt[c, j, :] ------------------------------------------------------
PHI_F = 0           #: phi^f (13)
PSI_F = 13          #: psi^f (13)
PHI_PREV = 26       #: phi at the last step (13)
PSI_PREV = 39       #: psi at the last step (13)
W_ROW = 52          #: W_cj (13)
U_ROW = 65          #: U_cj = P_j W_cj^T (13)
FILT_COLS = 78

# ---- channel c: chan[c, :] -----------------------------------------------------------------
CH_JOINT = 0        #: 0-based joint k of the channel, or POWER
CH_Y = 1            #: y_c: the filtered applied c^T tau
CH_E = 2            #: E_c = sum_j W_cj theta_hat_j - y_c
CH_ACTIVE = 3       #: 1 if E_c adapts at this step (outside the dead zone)
CH_AXIS = 4         #: a_j (6), the channel's axis in frame j, during the forward pass
CH_AXIS_DOT = 10    #: adot_j (6)
CHAN_COLS = 16
POWER = -1.0

#: Python-side slices of the blocks above (per-link state columns are relative to CONST_COLS).
BLOCKS = {
    "theta_hat": slice(CONST_COLS + THETA_HAT, CONST_COLS + THETA_HAT + 13),
    "s": slice(CONST_COLS + S_LINK, CONST_COLS + S_LINK + 6),
    "S": slice(CONST_COLS + P_FACTOR, CONST_COLS + P_FACTOR + 169),
    "W": slice(W_ROW, W_ROW + 13),
    "theta_lo": slice(THETA_MIN, THETA_MIN + 13),
    "theta_hi": slice(THETA_MAX, THETA_MAX + 13),
    "theta_0": slice(THETA_0, THETA_0 + 13),
}


def block(name):
    """The slice of a named block (see :data:`BLOCKS`)."""
    return BLOCKS[name]


def filter_coefficients(lam, h):
    """Exact discretisation of ``lambda/(p+lambda)``.

    ``x^f_k = e x^f_k-1 + b0 x_k-1 + b1 (x_k - x_k-1)``.

    ``b1 = 0`` is the zero-order hold; the first-order hold adds ``b1 = 1 - b0 / (lambda h)``.
    """
    e = math.exp(-lam * h)
    return e, 1.0 - e, 1.0 - (1.0 - e) / (lam * h)


def is_diagonal(stack):
    """True if every matrix of the (n, k, k) ``stack`` is diagonal."""
    k = stack.shape[-1]
    return not np.any(stack * (1.0 - np.eye(k)))


class Gains:
    """The validated gains of eqs 18-24 (GainError naming the field).

    Attributes: ``K_D`` (n, 6, 6), ``P`` (n, 13, 13), ``Lambda`` (n,), ``gamma``, ``lam``, ``h``.
    """

    def __init__(self, model, K_D, Lambda, P, gamma, lam, h):
        n = model.n
        self.K_D = per_link_matrix(K_D, n, 6, "K_D", GainError)
        self.P = per_link_matrix(P, n, 13, "P", GainError)
        self.Lambda = positive_vector(Lambda, n, "Lambda", GainError)
        self.gamma = scalar(gamma, "gamma", GainError, minimum=0.0)
        self.lam = scalar(lam, "lam", GainError, minimum=0.0, strict=True)
        self.h = scalar(h, "h", GainError, minimum=0.0, strict=True)

    def pack(self, model, data):
        """Write the constants into ``data[:n]`` and the scalars into ``data[n]``."""
        n = model.n
        const, scal = data[:n], data[n]
        const[:, P0:P0 + 3] = model.p
        const[:, RF0:RF0 + 9] = model.R_fix.reshape(n, 9)
        const[:, LAMBDA] = self.Lambda
        const[:, GAIN_K_D:GAIN_K_D + 36] = self.K_D.reshape(n, 36)
        const[:, GAIN_P:GAIN_P + 169] = self.P.reshape(n, 169)
        const[:, THETA_MIN:THETA_MIN + 13] = -np.inf
        const[:, THETA_MAX:THETA_MAX + 13] = np.inf
        scal[I_G:I_G + 3] = model.gravity
        scal[I_LAM], scal[I_H], scal[I_GAMMA] = self.lam, self.h, self.gamma
        scal[I_FE:I_FB1 + 1] = filter_coefficients(self.lam, self.h)
        scal[I_KD_DIAG] = float(is_diagonal(self.K_D))
        scal[I_P_DIAG] = float(is_diagonal(self.P))
        scal[I_IMPLICIT] = 1.0
        scal[I_ADAPT] = ADAPT_GRADIENT


def new_data(n):
    """A zeroed ``data`` array for n links."""
    return np.zeros((n + 1, LINK_COLS))
