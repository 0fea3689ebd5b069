"""The non-recursive Slotine-Li composite adaptive controller (eqs 2, 7): the baseline.

It builds the joint-space quantities explicitly, as the original scheme does:

    Y   = [J_1^T Y_r1, ..., J_n^T Y_rn]                           (n x 13n, eq 4)
    Phi = [J_j^T Ym_j(V_j)],  Psi = [-Jdot_j^T Ym_j(V_j) + J_j^T Yc_j(V_j)]   (n x 13n)
    W   = lambda (Phi - Phi^f) + Psi^f,  y = tau^f,  e = W theta_hat - y     (eqs 5, 6)
    tau = Y theta_hat - K_D s,  K_D = sum_i J_i^T K_Di J_i                    (eq 2)
    theta_hat_dot = -P (Y^T s + gamma W^T e)                                  (eq 7)

``J_i`` (6 x n) maps joint rates to link i's spatial velocity in frame i, so the
joint-space gain is the one the recursive law applies through its link gains
``K_Di``; the tracking term ``Y^T s`` equals the recursive ``Y_ri^T s_i``. With
``gamma = 0`` both controllers are therefore the same law, computed two ways.
For ``gamma > 0`` this one uses the prediction errors of all n filtered joint
torques (eq 6), the recursive one that of joint 1 only (eqs 21-24).

Discretisation matches the recursive law's (:mod:`rcac_ros.core.channels`,
:mod:`rcac_ros.core.adaptation`): exact filters (zero-order hold for the applied torque,
first-order hold for Phi and Psi), explicit Euler in the tracking term and, in the
prediction-error term, implicit Euler (``update="implicit"``, the default), solved by the
Woodbury identity with an n x n Cholesky factorisation, or explicit Euler
(``update="explicit"``). With the same choice the recursive law with ``channels="all"`` is
this law, step by step.
Cost per step: O(n^3) (``W P W^T``), against O(n) for the recursive law.
"""

import copy
import math

import numpy as np
from ._jit import kernel, njit, ready

from ._blocks import INPUT_NAMES, VEC, cholesky_solve, input_error, rejects_input, \
    reference_motion
from ._packing import (CONST_COLS, GAIN_K_D, GAIN_P, I_E, I_ERR, I_FB0, I_FB1, I_FE, I_G, I_GAMMA,
                       I_H, I_IMPLICIT, I_K, I_LAM, I_Y, LAMBDA, Gains, new_data)
from ._validate import as_array, joint_values
from rcac_ros.errors import GainError, InputError
from .channels import filter_step
from .pseudo_inertia import (barrier_gains_into, initial_estimates, is_body, lambda_min,
                             matched_gain, natural_gains_into, natural_metric_option, nu_gain,
                             pseudo_inertia)
from .retraction import retract_rows
from .joint_friction import (FOLLOW_TIME, P_FRICTION, default_beta, friction_gain,
                             friction_natural_gain, gains_at_start, natural_friction_start,
                             retract_terms)
from .regressor import fill_regressor
from .spatial import P0, propagate


@njit(cache=True)
def finish(filt, scal, tau, y, e, m):
    """Store y, the torque (the applied one unless told otherwise) and e; count the step."""
    for k in range(tau.shape[0]):
        filt[0, k, m] = y[k]
        filt[1, k, m] = tau[k]
        filt[2, k, m] = e[k]
    scal[I_K] += 1.0
    scal[I_E] = e[0]
    scal[I_Y] = y[0]
    return tau


@kernel(f"{VEC}(float64[:, ::1], {VEC}, float64[:, :, ::1], float64[:, ::1], {VEC}, {VEC}, "
        f"{VEC}, {VEC}, {VEC})")
def slotine_li_step_kernel(data, theta_hat, filt, joint, q, qd, q_d, qd_d, qdd_d):
    """One period of eqs 2 and 7 with explicit joint-space matrices.

    ``data`` holds the gains in the layout of :mod:`rcac_ros.core._packing`; ``filt`` is
    (4, n, p + 1): Phi^f, Psi^f, previous Phi, previous Psi, with the filtered applied
    torque y in column p of filt[0], the applied torque in filt[1] and e in filt[2].
    ``joint`` is (0, 4) without joint terms (p = 13n), else (n, 4): the diagonal gain of
    joint j's terms (armature, damping, friction) and v_c; their columns are 13n + 3j + c
    (p = 16n, doc/design.md §7).
    """
    n = data.shape[0] - 1
    const = data[:n, :CONST_COLS]
    scal = data[n]
    if rejects_input(scal, n, q, qd, q_d, qd_d, qdd_d):
        return np.empty(0, q.dtype)
    nj = 13 * n                               # first column of the joint terms
    m = nj + 3 * joint.shape[0]
    lam, h, gamma = scal[I_LAM], scal[I_H], scal[I_GAMMA]
    fe, fb0, fb1 = scal[I_FE], scal[I_FB0], scal[I_FB1]
    first = scal[I_K] == 0.0
    C = np.empty((n, 9), q.dtype)
    J = np.zeros((n, 6, n), q.dtype)          # J_i, columns k <= i
    Jd = np.zeros((n, 6, n), q.dtype)         # Jdot_i
    Yr = np.empty((n, 6, 13), q.dtype)
    Ys = np.empty((2, 6, 13), q.dtype)
    Yj = np.zeros((n, m), q.dtype)            # joint-space regressor Y (eq 4)
    W = np.empty((n, m), q.dtype)
    s = np.empty(n, q.dtype)
    y = np.empty(n, q.dtype)
    zero = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    V, Vr, Vdr = zero, zero, zero
    g = (scal[I_G], scal[I_G + 1], scal[I_G + 2])
    for i in range(n):
        s[i] = qd[i] - (qd_d[i] - const[i, LAMBDA] * (q[i] - q_d[i]))
        y[i] = 0.0 if first else fe * filt[0, i, m] + fb0 * filt[1, i, m]
    for i in range(n):
        row = const[i]
        qdi = qd[i]
        V, Vr, Vdr, g = reference_motion(C, i, row, q[i], qdi, q_d[i], qd_d[i], qdd_d[i],
                                         V, Vr, Vdr, g)
        vx, vy, vz, wx, wy, wz = V
        rvx, rvy, rvz, rwx, rwy, rwz = Vr
        dvx, dvy, dvz, dwx, dwy, dwz = Vdr
        gx, gy, gz = g
        px, py, pz = row[P0], row[P0 + 1], row[P0 + 2]
        # link Jacobian J_i = T_i J_{i-1} + z6 e_i^T and its derivative (explicit, O(n) a link)
        for k in range(i):
            a, b = propagate(C, i, px, py, pz, qdi,
                             (J[i - 1, 0, k], J[i - 1, 1, k], J[i - 1, 2, k], J[i - 1, 3, k],
                              J[i - 1, 4, k], J[i - 1, 5, k]),
                             (Jd[i - 1, 0, k], Jd[i - 1, 1, k], Jd[i - 1, 2, k],
                              Jd[i - 1, 3, k], Jd[i - 1, 4, k], Jd[i - 1, 5, k]), 0.0, 0.0)
            for r in range(6):
                J[i, r, k] = a[r]
                Jd[i, r, k] = b[r]
        J[i, 5, i] = 1.0
        fill_regressor(Yr, i, dvx, dvy, dvz, dwx, dwy, dwz, rvx, rvy, rvz, rwx, rwy, rwz,
                       wx, wy, wz, gx, gy, gz)
        fill_regressor(Ys, 0, vx, vy, vz, wx, wy, wz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                       wx, wy, wz, 0.0, 0.0, 0.0)
        fill_regressor(Ys, 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, vx, vy, vz, wx, wy, wz,
                       wx, wy, wz, gx, gy, gz)
        # block column i of Y, Phi, Psi, all n rows (dense, as the explicit scheme stores them)
        for k in range(n):
            for c in range(13):
                yv = 0.0
                phi = 0.0
                psi = 0.0
                for r in range(6):
                    yv += J[i, r, k] * Yr[i, r, c]
                    phi += J[i, r, k] * Ys[0, r, c]
                    psi += J[i, r, k] * Ys[1, r, c] - Jd[i, r, k] * Ys[0, r, c]
                col = 13 * i + c
                Yj[k, col] = yv
                filt[0, k, col], filt[1, k, col], W[k, col] = filter_step(
                    first, filt[0, k, col], filt[1, k, col], filt[2, k, col], filt[3, k, col],
                    phi, psi, fe, fb0, fb1, lam)
                filt[2, k, col] = phi
                filt[3, k, col] = psi
        if m > nj:
            # joint i's terms, row i only: Y_f = [qdd_ri, qd_ri, sigma(qd_i)],
            # Phi_f = [qd_i, 0, 0], Psi_f = [0, qd_i, sigma(qd_i)]  (doc/design.md §7)
            sig = math.tanh(qdi / joint[i, 3])
            Yj[i, nj + 3 * i] = qdd_d[i] - row[LAMBDA] * (qdi - qd_d[i])
            Yj[i, nj + 3 * i + 1] = qd_d[i] - row[LAMBDA] * (q[i] - q_d[i])
            Yj[i, nj + 3 * i + 2] = sig
            for c in range(3):
                col = nj + 3 * i + c
                phi = qdi if c == 0 else 0.0
                psi = 0.0 if c == 0 else (qdi if c == 1 else sig)
                filt[0, i, col], filt[1, i, col], w = filter_step(
                    first, filt[0, i, col], filt[1, i, col], filt[2, i, col], filt[3, i, col],
                    phi, psi, fe, fb0, fb1, lam)
                filt[2, i, col] = phi
                filt[3, i, col] = psi
                for k in range(n):
                    W[k, col] = 0.0
                W[i, col] = w
    # joint-space feedback gain K = sum_i J_i^T K_Di J_i, then tau = Y theta_hat - K s (eq 2)
    K = np.zeros((n, n), q.dtype)
    for i in range(n):
        for a in range(n):
            for r in range(6):
                kj = 0.0
                for c in range(6):
                    kj += const[i, GAIN_K_D + 6 * r + c] * J[i, c, a]
                for b in range(n):
                    K[b, a] += J[i, r, b] * kj
    tau = np.empty(n, q.dtype)
    e = np.empty(n, q.dtype)
    for k in range(n):
        acc = 0.0
        pe = 0.0
        for col in range(m):
            acc += Yj[k, col] * theta_hat[col]
            pe += W[k, col] * theta_hat[col]
        for b in range(n):
            acc -= K[k, b] * s[b]
        tau[k] = acc
        e[k] = pe - y[k]
    # eq 7, implicit: r = theta_hat - h P (Y^T s - gamma W^T y); (I + h gamma P W^T W) theta+ = r
    # Woodbury: theta+ = r - h gamma P W^T (I + h gamma W P W^T)^-1 W r
    # explicit: theta+ = theta_hat - h P (Y^T s + gamma W^T e)
    implicit = scal[I_IMPLICIT] != 0.0
    g = np.empty(m, q.dtype)
    for col in range(m):
        acc = 0.0
        for k in range(n):
            if implicit:
                acc += Yj[k, col] * s[k] - gamma * W[k, col] * y[k]
            else:
                acc += Yj[k, col] * s[k] + gamma * W[k, col] * e[k]
        g[col] = acc
    PWt = np.empty((m, n), q.dtype)          # P W^T, P block diagonal (13 x 13 per link)
    r = np.empty(m, q.dtype)
    for i in range(n):
        for a in range(13):
            acc = 0.0
            for c in range(13):
                acc += const[i, GAIN_P + 13 * a + c] * g[13 * i + c]
            r[13 * i + a] = theta_hat[13 * i + a] - h * acc
            for k in range(n if implicit else 0):
                acc = 0.0
                for c in range(13):
                    acc += const[i, GAIN_P + 13 * a + c] * W[k, 13 * i + c]
                PWt[13 * i + a, k] = acc
    for col in range(nj, m):                  # the joint terms: diagonal gains
        pf = joint[(col - nj) // 3, (col - nj) % 3]
        r[col] = theta_hat[col] - h * pf * g[col]
        for k in range(n if implicit else 0):
            PWt[col, k] = pf * W[k, col]
    if not implicit:
        theta_hat[:] = r
        return finish(filt, scal, tau, y, e, m)
    A = np.empty((n, n), q.dtype)
    for k in range(n):
        for b in range(n):
            acc = 0.0
            for col in range(m):
                acc += W[k, col] * PWt[col, b]
            A[k, b] = h * gamma * acc
        A[k, k] += 1.0
    z = np.empty(n, q.dtype)
    for k in range(n):
        acc = 0.0
        for col in range(m):
            acc += W[k, col] * r[col]
        z[k] = acc
    cholesky_solve(A, z)
    for col in range(m):
        acc = 0.0
        for k in range(n):
            acc += PWt[col, k] * z[k]
        theta_hat[col] = r[col] - h * gamma * acc
    return finish(filt, scal, tau, y, e, m)


class SlotineLiCompositeController:
    """The composite adaptive controller of Slotine and Li (eqs 2, 7), non-recursive.

    Same parameters (up to ``update``), defaults and exceptions as
    :class:`~rcac_ros.core.composite.RecursiveCompositeController`; ``K_D`` are the link
    gains ``K_Di``, mapped to joint space as ``sum_i J_i^T K_Di J_i``. It predicts all n
    filtered joint torques (``E`` has n entries).

    ``geometry="natural"`` (doc/design.md §8): as in the recursive law (same
    ``natural_gain``, same default start, same metrics). With ``natural_metric="barrier"``
    (the default, ``None``; and ``barrier_c``) before each step the gains ``P_i`` are
    replaced by ``P_mix(theta_hat_i) = (H / (c k_i) + P_i^-1)^-1`` and after it each link's
    step is shortened while it would leave the cone ``J > 0``; with ``"log_det"`` the gains
    are ``P_eff(theta_hat_i)`` and each step is retracted into the cone.
    ``joint_friction``, ``friction_hat0`` and ``P_friction`` add each joint's armature,
    viscous and Coulomb friction as three more columns of its row of ``Y``, ``Phi``, ``Psi``
    (doc/design.md §8).
    """

    def __init__(self, model, K_D=1e4, Lambda=1.0, P=100.0, gamma=0.1, lam=10.0, h=0.002,
                 theta_hat0=None, update="implicit", joint_friction=False, friction_hat0=None,
                 P_friction=P_FRICTION, geometry="euclidean", natural_gain=None,
                 natural_metric=None, barrier_c=None):
        self.model = model
        self._compiled = False              # compile(): this law's kernels ready
        n = model.n
        gains = Gains(model, K_D, Lambda, P, gamma, lam, h)
        self.K_D, self.P, self.Lambda = gains.K_D, gains.P, gains.Lambda
        self.gamma, self.lam, self.h = gains.gamma, gains.lam, gains.h
        self._data = new_data(n)
        gains.pack(model, self._data)
        self._scal = self._data[n]
        if update not in ("implicit", "explicit"):
            raise GainError(f"update: expected 'implicit' or 'explicit', got {update!r}")
        self.update = update
        self._scal[I_IMPLICIT] = 1.0 if update == "implicit" else 0.0
        self.joint_friction = bool(joint_friction)
        if geometry not in ("euclidean", "natural"):
            raise GainError(f"geometry: expected 'euclidean' or 'natural', got {geometry!r}")
        self.geometry = geometry
        self.natural_metric, self.barrier_c = natural_metric_option(natural_metric, barrier_c,
                                                                    geometry)
        self.natural_gain = None
        if geometry == "natural":
            start = initial_estimates(model, geometry, theta_hat0)
            k = matched_gain(self.P, start) if natural_gain is None else \
                joint_values(natural_gain, n, "natural_gain", GainError)
            if np.any(k <= 0.0):
                raise GainError("natural_gain: must be > 0")
            self.natural_gain = k
            self._nu_gain = np.ascontiguousarray(nu_gain(self.P).reshape(n, 9))
            self._prev = np.zeros((n, 13))
            if self.barrier_c is not None:              # P_mix, doc/design.md §8
                self._kc = self.barrier_c * k
                self._P_inv = np.linalg.inv(self.P)
                self._E = pseudo_inertia(np.eye(13))
        elif natural_gain is not None:
            raise GainError("natural_gain: only with geometry='natural'")
        self._joint = np.zeros((n if self.joint_friction else 0, 4))
        if self.joint_friction:
            self.P_friction = friction_gain(P_friction, n)
            self._friction_default = self.P_friction is None
            self._gain_at_start = True      # rates (and the default gain) at the first state
            # every joint's torque informs the prediction term, as channels="all" does
            self._beta = default_beta(range(1, n + 1), n, self.update == "implicit", self.gamma)
            P, self._grow, self._rate = gains_at_start(model, self.K_D, np.zeros(n),
                                                       self._friction_default, self.h, self._beta)
            if self._friction_default:
                self.P_friction = P
            self.friction_hat0 = model.joint_terms() if friction_hat0 is None else \
                as_array(friction_hat0, (n, 3), "friction_hat0")
            self._joint[:, 3] = model.friction_velocity
            if geometry == "natural":                   # doc/design.md §8: k_f x^2, x > 0
                self.friction_hat0 = natural_friction_start(
                    None if friction_hat0 is None else self.friction_hat0,
                    model.joint_terms(), InputError)
        self._p = (16 if self.joint_friction else 13) * n     # number of parameters
        self._theta = np.zeros(self._p)
        self._filt = np.zeros((4, n, self._p + 1))
        self.reset(theta_hat0)

    def _rotor_start(self):
        """``a_ref`` at the armature estimates and the gain from it (as
        :func:`~rcac_ros.core.joint_friction.rotor_start`; natural geometry: the natural gain
        matched to it, anew)."""
        fh = self._theta[13 * self.n:].reshape(self.n, 3)
        self._a_ref = np.maximum(fh[:, 0], 0.0)
        self._a_fb = self._a_ref.copy()
        self._cap = self.P_friction + self._grow * self._a_ref[:, None]
        self._joint[:, :3] = self._cap
        if self.geometry == "natural":
            self._friction_k = friction_natural_gain(self._cap, fh)

    def _rotor(self):
        """:func:`~rcac_ros.core.joint_friction.rotor` of every joint: ``a_fb`` a low-pass of
        the armature estimate, ``a_ref`` its largest value, and the gain (natural geometry:
        its cap) grows with it."""
        a = np.maximum(self._theta[13 * self.n::3], 0.0)
        self._a_fb += min(1.0, self.h / FOLLOW_TIME) * (a - self._a_fb)
        if np.any(self._a_fb > self._a_ref):
            np.maximum(self._a_ref, self._a_fb, out=self._a_ref)
            self._cap = self.P_friction + self._grow * self._a_ref[:, None]
            if self.geometry != "natural":
                self._joint[:, :3] = self._cap

    @property
    def n(self):
        """Number of joints."""
        return self.model.n

    def reset(self, theta_hat0=None, friction_hat0=None):
        """Restart: estimates to ``theta_hat0`` (default zero; natural geometry: its default
        start) and, with the joint terms, to ``friction_hat0`` (default the constructor's);
        filters and step count to zero."""
        nl = 13 * self.n
        self._theta[:nl] = initial_estimates(self.model, self.geometry, theta_hat0).ravel()
        if self.joint_friction:
            fh = self.friction_hat0 if friction_hat0 is None else \
                as_array(friction_hat0, (self.n, 3), "friction_hat0")
            if self.geometry == "natural":
                fh = natural_friction_start(fh, None, InputError)
            self._theta[nl:] = fh.ravel()
            self._rotor_start()
        self._filt[:] = 0.0
        self._scal[[I_K, I_ERR, I_E, I_Y]] = 0.0

    def compile(self):
        """Compile this law's kernels (or load them from the cache), once per process; returns
        ``self``. Building the controller compiles nothing; the first :meth:`step` calls this.
        """
        if not self._compiled:
            ready(slotine_li_step_kernel)
            self._compiled = True
            z = np.zeros(self.n)
            try:
                copy.deepcopy(self).step(z, z, z, z, z)    # the geometry's helpers, on a copy
            except BaseException:
                self._compiled = False
                raise
        return self

    def step(self, q, qd, q_d, qd_d, qdd_d):
        """One control period (eqs 2, 7); same contract as the recursive controller's ``step``."""
        if not self._compiled:
            self.compile()
        if self.joint_friction and self._gain_at_start:     # doc/design.md §7
            got = gains_at_start(self.model, self.K_D, q, self._friction_default, self.h,
                                 self._beta)
            if got is not None:
                P, self._grow, self._rate = got
                if P is not None:
                    self.P_friction = P
                self._rotor_start()
                self._gain_at_start = False
        if self.joint_friction:
            self._rotor()
        if self.geometry == "natural":                      # doc/design.md §8
            th = self._theta[:13 * self.n].reshape(self.n, 13)
            self._prev[:] = th
            if self.barrier_c is None:
                natural_gains_into(th, self.natural_gain, self._nu_gain,
                                   self._data[:self.n, GAIN_P:GAIN_P + 169])
            else:
                barrier_gains_into(th, self._kc, self._P_inv, self._E,
                                   self._data[:self.n, GAIN_P:GAIN_P + 169])
            if self.joint_friction:
                fh = self._theta[13 * self.n:].reshape(self.n, 3)
                self._prev_f = fh.copy()
                a = min(1.0, self.h / FOLLOW_TIME)                  # follow_gain
                self._friction_k *= (self._cap / (self._friction_k * fh * fh)) ** a
                self._joint[:, :3] = np.minimum(self._friction_k * fh * fh,   # term_gain
                                                self._cap)
        try:
            tau = slotine_li_step_kernel(self._data, self._theta, self._filt, self._joint, q, qd,
                                         q_d, qd_d, qdd_d)
        except TypeError:
            values = (q, qd, q_d, qd_d, qdd_d)
            args = [as_array(v, (None,), k) for k, v in zip(INPUT_NAMES, values)]
            tau = slotine_li_step_kernel(self._data, self._theta, self._filt, self._joint,
                                         *args)
        if tau.shape[0] == 0:
            raise input_error(self._scal, self.n, (q, qd, q_d, qd_d, qdd_d))
        if self.joint_friction:                 # the rotor's feedback -rho a_fb s_q
            s_q = np.subtract(qd, qd_d) + self.Lambda * np.subtract(q, q_d)
            tau -= self._rate * self._a_fb * s_q
            self._filt[1, :, self._p] = tau         # y filters the torque returned
        if self.geometry == "natural":
            self.retraction_length = retract_rows(self._prev,
                                                  self._theta[:13 * self.n].reshape(self.n, 13),
                                                  self.barrier_c is not None)
            if self.joint_friction:
                self.retraction_length = min(self.retraction_length, retract_terms(
                    self._prev_f, self._theta[13 * self.n:].reshape(self.n, 3)))
        return tau

    @property
    def lambda_min(self):
        """``lambda_min(J(theta_hat_i))`` per link (doc/design.md §8)."""
        return lambda_min(self.theta_hat)

    @property
    def consistent(self):
        """Per link, whether ``theta_hat_i`` is a physical body."""
        return is_body(self.theta_hat)

    def set_applied_torque(self, tau):
        """The torques really applied after the last step (see the recursive controller's)."""
        self._filt[1, :, self._p] = as_array(tau, (self.n,), "tau")

    @property
    def theta_hat(self):
        """Current estimates, shape (n, 13) (a copy)."""
        return self._theta[:13 * self.n].reshape(self.n, 13).copy()

    @property
    def friction_hat(self):
        """Joint estimates (armature, damping, friction), (n, 3); None without the joint terms."""
        if not self.joint_friction:
            return None
        return self._theta[13 * self.n:].reshape(self.n, 3).copy()

    @property
    def E(self):
        """Prediction errors ``e`` of the n filtered joint torques at the last step (eq 6)."""
        return self._filt[2, :, self._p].copy()

    @property
    def y(self):
        """Filtered applied joint torques ``y = tau^f`` at the last step, (n,)."""
        return self._filt[0, :, self._p].copy()
