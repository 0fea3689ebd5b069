"""The O(n) recursive composite adaptive controller (eqs 18-24, doc/design.md §3-4).

Per control period ``h``, with ``s_i = V_i - V_ri``:

    qd_r = qd_d - Lambda (q - q_d),   qdd_r = qdd_d - Lambda (qd - qd_d)           (eq 18)
    V_ri = T V_r,i-1 + z6 qd_ri
    Vdot_ri = T Vdot_r,i-1 + Tdot V_r,i-1 + z6 qdd_ri         (Tdot with the actual qd_i)
    F_ri = (i+1 T_i)^T F_r,i+1 + Y_ri theta_hat_i + K_Di (V_ri - V_i)              (eq 19b)
    tau_i = z6^T F_ri                                                               (eq 20)
    a_1 = z6,  a_j = T_j a_j-1,  adot_j = Tdot_j a_j-1 + T_j adot_j-1     (joint 1's axis, frame j)
    phi_j = a_j^T Ym_j(V_j),  psi_j = -adot_j^T Ym_j(V_j) + a_j^T Yc_j(V_j)   (eqs 21-22, O(n))
    W_j = lambda (phi_j - phi_j^f) + psi_j^f,  y = tau_1^f,  E = sum_j W_j theta_hat_j - y
    theta_hat_dot_i = -P_i (Y_ri^T s_i + gamma W_i^T E)                              (eq 24)

Discretisation (the paper leaves it open): the filter ``lambda / (p + lambda)`` is
discretised exactly, with a zero-order hold for the applied torque (held over the
period, as it is) and a first-order hold for the sampled ``phi`` and ``psi``;
``theta_hat`` takes one step of ``h`` after the torque is computed: explicit
Euler in the tracking term ``Y_ri^T s_i``, implicit (backward Euler) in the
prediction-error term. The latter is a rank-one system in the stacked
``theta_hat``, solved in O(n) by Sherman-Morrison. It matters: with the paper's
``P_i = 100 I`` and ``gamma = 0.1`` the explicit step is unstable at 2 ms
(``h gamma W P W^T`` is far above 2), while the implicit one is stable for any
gain and tends to eq 24 as ``h -> 0``.
``gamma = 0`` is the direct adaptive controller, the paper's baseline.
"""

import math

import numpy as np
from numba import njit

from ._validate import as_array, per_link_matrix, positive_vector, scalar
from rcac_ros.errors import GainError, InputError
from .regressor import bias_row, momentum_row, reference_wrench, regressor_row
from .spatial import P0, RF0, joint_rotation, propagate, rotate, transform_force_T, \
    transform_motion

# packed constants per link: p (3), R_fix (9), Lambda (1), K_D (36), P (169)
LAM, KD0, PG0, CONST_COLS = 12, 13, 49, 218
# state per link: theta_hat, phi^f, psi^f, previous phi, previous psi (13 each), s_i (6)
TH, PHF, PSF, PHP, PSP, S0, STATE_COLS = 0, 13, 26, 39, 52, 65, 71
# scalars: gravity (3), lambda, h, gamma, exp(-lambda h), b0, b1, y, tau_1 applied,
# k (steps since the filters started), E, error,
# and two flags: every K_Di diagonal, every P_i diagonal (then the kernel skips the zeros)
I_G = 0
(I_LAM, I_H, I_GAMMA, I_FE, I_FB0, I_FB1, I_Y, I_TAU1, I_K, I_E, I_ERR, I_KD_DIAG, I_P_DIAG,
 SCAL_LEN) = range(3, 17)

INPUT_NAMES = ("q", "qd", "q_d", "qd_d", "qdd_d")


@njit(cache=True)
def reference_motion(C, i, row, q, qd, q_d, qd_d, qdd_d, V, Vr, Vdr, g):
    """Link i's ``V_i`` (eq 9), ``V_ri``, ``Vdot_ri`` (eq 18) and gravity from link i-1's.

    Writes ``C[i]`` (eq 10's rotation); ``q ... qdd_d`` are joint i's scalars, ``row`` its
    packed constants. Returns ``(V, V_r, Vdot_r, g)`` as tuples.
    """
    joint_rotation(row, RF0, q, C, i)
    px, py, pz = row[P0], row[P0 + 1], row[P0 + 2]
    qdr = qd_d - row[LAM] * (q - q_d)
    qddr = qdd_d - row[LAM] * (qd - qd_d)
    vx, vy, vz, wx, wy, wz = transform_motion(C, i, px, py, pz, V[0], V[1], V[2], V[3], V[4],
                                              V[5])
    Vr, Vdr = propagate(C, i, px, py, pz, qd, Vr, Vdr, qdr, qddr)   # Tdot with the actual qd
    return (vx, vy, vz, wx, wy, wz + qd), Vr, Vdr, rotate(C, i, g[0], g[1], g[2])


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


def filter_coefficients(lam, h):
    """Exact discretisation of ``lambda/(p+lambda)``.

    ``x^f_k = e x^f_k-1 + b0 x_k-1 + b1 (x_k - x_k-1)``.

    ``b1 = 0`` is the zero-order hold; the first-order hold adds ``b1 = 1 - b0 / (lambda h)``.
    """
    e = math.exp(-lam * h)
    return e, 1.0 - e, 1.0 - (1.0 - e) / (lam * h)


#: The only signature the step kernels are compiled for: anything else is a TypeError at
#: dispatch (never a silent recompilation), which the Python entry point converts once.
VEC = "float64[::1]"
RCAC_SIGNATURE = f"{VEC}(float64[:, ::1], {VEC}, {VEC}, {VEC}, {VEC}, {VEC})"


@njit(RCAC_SIGNATURE, cache=True)
def rcac_step_kernel(data, q, qd, q_d, qd_d, qdd_d):
    """One control period of eqs 18-24; returns tau (empty on bad input, code in scal[I_ERR]).

    ``data`` (n + 1, CONST_COLS + STATE_COLS) holds, per link, the constants then the state,
    and in its last row the scalars: one argument and one scratch allocation keep the call cheap.
    """
    n = data.shape[0] - 1
    const = data[:n, :CONST_COLS]
    state = data[:n, CONST_COLS:]
    scal = data[n]
    err = check_vectors(n, q, qd, q_d, qd_d, qdd_d)
    if err != 0:
        scal[I_ERR] = err
        return np.empty(0, q.dtype)
    work = np.empty(n * 67 + 39, q.dtype)
    C = work[:9 * n].reshape((n, 9))
    Fs = work[9 * n:15 * n].reshape((n, 6))       # Y_ri theta_hat_i
    G = work[15 * n:28 * n].reshape((n, 13))      # Y_ri^T s_i
    Wm = work[28 * n:41 * n].reshape((n, 13))
    Rn = work[41 * n:54 * n].reshape((n, 13))
    Un = work[54 * n:67 * n].reshape((n, 13))
    tau = np.empty(n, q.dtype)
    phi_row = work[67 * n:67 * n + 13]
    psi_row = work[67 * n + 13:67 * n + 26]
    tmp_row = work[67 * n + 26:67 * n + 39]
    lam, h, gamma = scal[I_LAM], scal[I_H], scal[I_GAMMA]
    fe, fb0, fb1 = scal[I_FE], scal[I_FB0], scal[I_FB1]
    first = scal[I_K] == 0.0
    kd_diag = scal[I_KD_DIAG] != 0.0
    p_diag = scal[I_P_DIAG] != 0.0
    y = 0.0 if first else fe * scal[I_Y] + fb0 * scal[I_TAU1]
    zero = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    V, Vr, Vdr = zero, zero, zero                      # V_i, V_ri, Vdot_ri
    A, Ad = zero, zero                                 # a_j, adot_j (joint 1's axis, frame j)
    g = (scal[I_G], scal[I_G + 1], scal[I_G + 2])
    E = 0.0
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
        # a_1 = z6, a_j = T_j a_j-1 ; adot_j = Tdot_j a_j-1 + T_j adot_j-1
        if i == 0:
            A = (0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        else:
            A, Ad = propagate(C, i, px, py, pz, qdi, A, Ad, 0.0, 0.0)
        avx, avy, avz, awx, awy, awz = A
        bvx, bvy, bvz, bwx, bwy, bwz = Ad
        st = state[i]
        st[S0], st[S0 + 1], st[S0 + 2] = vx - rvx, vy - rvy, vz - rvz
        st[S0 + 3], st[S0 + 4], st[S0 + 5] = wx - rwx, wy - rwy, wz - rwz
        # eq 19b's Y_ri theta_hat_i and eq 24's Y_ri^T s_i, neither forming Y_ri
        f = reference_wrench(st, TH, dvx, dvy, dvz, dwx, dwy, dwz, rvx, rvy, rvz, rwx, rwy,
                             rwz, wx, wy, wz, gx, gy, gz)
        for k in range(6):
            Fs[i, k] = f[k]
        regressor_row(G[i], vx - rvx, vy - rvy, vz - rvz, wx - rwx, wy - rwy, wz - rwz,
                      dvx, dvy, dvz, dwx, dwy, dwz, rvx, rvy, rvz, rwx, rwy, rwz,
                      wx, wy, wz, gx, gy, gz)
        # a_j^T Ym(V_j), adot_j^T Ym(V_j), a_j^T Yc(V_j) for the filtered joint-1 torque
        momentum_row(phi_row, avx, avy, avz, awx, awy, awz, vx, vy, vz, wx, wy, wz)
        momentum_row(tmp_row, bvx, bvy, bvz, bwx, bwy, bwz, vx, vy, vz, wx, wy, wz)
        bias_row(psi_row, avx, avy, avz, awx, awy, awz, vx, vy, vz, wx, wy, wz, gx, gy, gz)
        for c in range(13):
            phi = phi_row[c]
            psi = psi_row[c] - tmp_row[c]
            if first:
                st[PHF + c] = phi
                st[PSF + c] = 0.0
            else:
                st[PHF + c] = (fe * st[PHF + c] + fb0 * st[PHP + c]
                               + fb1 * (phi - st[PHP + c]))
                st[PSF + c] = (fe * st[PSF + c] + fb0 * st[PSP + c]
                               + fb1 * (psi - st[PSP + c]))
            st[PHP + c] = phi
            st[PSP + c] = psi
            w_c = lam * (phi - st[PHF + c]) + st[PSF + c]
            Wm[i, c] = w_c
            E += w_c * st[TH + c]
    E -= y
    fx = fy = fz = nx = ny = nz = 0.0
    for i in range(n - 1, -1, -1):
        row = const[i]
        st = state[i]
        if i < n - 1:
            r = const[i + 1]
            fx, fy, fz, nx, ny, nz = transform_force_T(C, i + 1, r[P0], r[P0 + 1], r[P0 + 2],
                                                       fx, fy, fz, nx, ny, nz)
        # eq 19b: + Y_ri theta_hat_i + K_Di (V_ri - V_i), with V_ri - V_i = -s_i
        for r6 in range(6):
            acc = Fs[i, r6]
            if kd_diag:
                acc -= row[KD0 + 7 * r6] * st[S0 + r6]
            else:
                for k in range(6):
                    acc -= row[KD0 + 6 * r6 + k] * st[S0 + k]
            if r6 == 0:
                fx += acc
            elif r6 == 1:
                fy += acc
            elif r6 == 2:
                fz += acc
            elif r6 == 3:
                nx += acc
            elif r6 == 4:
                ny += acc
            else:
                nz += acc
        tau[i] = nz
        # eq 24, step 1: r_i = theta_hat_i - h P_i (Y_ri^T s_i - gamma W_i^T y), u_i = P_i W_i^T
        grad = G[i]
        for c in range(13):
            grad[c] -= gamma * Wm[i, c] * y
        if p_diag:
            for a in range(13):
                Rn[i, a] = st[TH + a] - h * row[PG0 + 14 * a] * grad[a]
                Un[i, a] = row[PG0 + 14 * a] * Wm[i, a]
        else:
            for a in range(13):
                acc_r = 0.0
                acc_u = 0.0
                for c in range(13):
                    acc_r += row[PG0 + 13 * a + c] * grad[c]
                    acc_u += row[PG0 + 13 * a + c] * Wm[i, c]
                Rn[i, a] = st[TH + a] - h * acc_r
                Un[i, a] = acc_u
    # eq 24, step 2: the prediction-error term taken implicitly (Sherman-Morrison, O(n)):
    # (I + h gamma u W) theta_hat+ = r  =>  theta_hat+ = r - h gamma u (W r) / (1 + h gamma W u)
    Wr = 0.0
    Wu = 0.0
    for i in range(n):
        for c in range(13):
            Wr += Wm[i, c] * Rn[i, c]
            Wu += Wm[i, c] * Un[i, c]
    k = h * gamma * Wr / (1.0 + h * gamma * Wu)
    for i in range(n):
        for c in range(13):
            state[i, TH + c] = Rn[i, c] - k * Un[i, c]
    scal[I_Y] = y
    scal[I_TAU1] = tau[0]
    scal[I_K] += 1.0
    scal[I_E] = E
    return tau


class RecursiveCompositeController:
    """The recursive composite adaptive controller of eqs 18-24, O(n) per step.

    Parameters
    ----------
    model : RobotModel
        Kinematics (``p``, ``R_fix``) and gravity; its inertial parameters are *not*
        used: the controller knows only ``theta_hat``.
    K_D : float, (6,), (6, 6) or (n, 6, 6)
        Link feedback gains ``K_Di`` (eq 19), symmetric positive definite.
    Lambda : float, (n,) or diagonal (n, n)
        ``Lambda`` of eq 18, positive (per joint).
    P : float, (13,), (13, 13) or (n, 13, 13)
        Adaptation gains ``P_i`` (eq 24), symmetric positive definite.
    gamma : float
        Weight of the prediction error (eq 24); ``0`` gives the direct adaptive law.
    lam : float
        Bandwidth ``lambda`` of the filter ``lambda / (p + lambda)``, rad/s (the paper gives none).
    h : float
        Control period, s.
    theta_hat0 : array_like (n, 13), optional
        Initial estimates (default zero, as in the paper).

    Raises
    ------
    GainError
        On a gain of wrong shape, not finite, or not (symmetric) positive definite.
    InputError
        On a ``theta_hat0`` of wrong shape or not finite.
    """

    def __init__(self, model, K_D=1e4, Lambda=1.0, P=100.0, gamma=0.1, lam=10.0, h=0.002,
                 theta_hat0=None):
        self.model = model
        (self.K_D, self.P, self.Lambda, self.gamma, self.lam, self.h, const,
         scal) = pack_gains(model, K_D, Lambda, P, gamma, lam, h)
        n = model.n
        self._data = np.zeros((n + 1, CONST_COLS + STATE_COLS))
        self._data[:n, :CONST_COLS] = const
        self._data[n, :SCAL_LEN] = scal
        self._state = self._data[:n, CONST_COLS:]       # views into the one kernel argument
        self._scal = self._data[n]
        self.adapting = True
        self.reset(theta_hat0)

    @property
    def n(self):
        """Number of joints."""
        return self.model.n

    def reset(self, theta_hat0=None):
        """Restart: estimates to ``theta_hat0`` (default zero), filters and step count to zero."""
        th = np.zeros((self.n, 13)) if theta_hat0 is None else \
            as_array(theta_hat0, (self.n, 13), "theta_hat0")
        self._state[:] = 0.0
        self._state[:, TH:TH + 13] = th
        self._scal[I_Y:I_ERR + 1] = 0.0

    def step(self, q, qd, q_d, qd_d, qdd_d):
        """One control period: returns the joint torques ``tau`` (eq 20) and adapts (eq 24).

        Parameters
        ----------
        q, qd : array_like, shape (n,)
            Measured joint positions and velocities.
        q_d, qd_d, qdd_d : array_like, shape (n,)
            Desired position, velocity and acceleration.

        Returns
        -------
        ndarray, shape (n,)

        Raises
        ------
        InputError
            If a vector has the wrong length or holds NaN/Inf (the state is left untouched).
        """
        try:
            tau = rcac_step_kernel(self._data, q, qd, q_d, qd_d, qdd_d)
        except TypeError:  # not float64 1-D contiguous arrays: convert once, then retry
            values = (q, qd, q_d, qd_d, qdd_d)
            args = [as_array(v, (None,), k) for k, v in zip(INPUT_NAMES, values)]
            tau = rcac_step_kernel(self._data, *args)
        if tau.shape[0] == 0:
            raise input_error(self._scal, self.n, (q, qd, q_d, qd_d, qdd_d))
        return tau

    def set_adaptation(self, enabled):
        """Freeze (``False``) or resume (``True``) the adaptation of eq 24, keeping ``theta_hat``.

        Frozen, every ``P_i`` acts as zero: ``theta_hat`` stays where it is, the torque of
        eqs 19-20 uses it, and the filters and ``E`` keep running (``E`` then measures the
        frozen estimates).
        """
        n = self.n
        self._data[:n, PG0:PG0 + 169] = self.P.reshape(n, 169) if enabled else 0.0
        self.adapting = bool(enabled)

    def set_applied_torque(self, tau):
        """Tell the filter ``y = tau_1^f`` (eq 22) the torque really applied after the last step.

        By default ``y`` filters the torque :meth:`step` returned. When the arm receives
        another one (clipped to an effort limit, or a safe effort), pass it here, or the
        prediction error ``E`` compares the model with a torque the arm never felt.

        Raises
        ------
        InputError
            If ``tau`` has the wrong length or holds NaN/Inf.
        """
        self._scal[I_TAU1] = as_array(tau, (self.n,), "tau")[0]

    def restart_filters(self):
        """Restart the filters of eqs 21-24 at the next step, keeping ``theta_hat``.

        For a gap in the measurements (a watchdog trip): the filters start again as at
        t = 0 (``phi^f = phi``, ``psi^f = 0``, ``y = 0``), so ``E`` is exact from there on.
        """
        self._scal[I_K] = 0.0

    @property
    def theta_hat(self):
        """Current estimates ``theta_hat``, shape (n, 13) (a copy)."""
        return self._state[:, TH:TH + 13].copy()

    @property
    def E(self):
        """Prediction error ``E = sum_j W_j theta_hat_j - y`` of the last step (eq 24)."""
        return float(self._scal[I_E])

    @property
    def y(self):
        """Filtered applied joint-1 torque ``y = tau_1^f`` at the last step."""
        return float(self._scal[I_Y])

    @property
    def link_velocity_error(self):
        """``s_i = V_i - V_ri`` of the last step, shape (n, 6) (a copy)."""
        return self._state[:, S0:S0 + 6].copy()

    @property
    def W(self):
        """The filtered regressor rows ``W_j`` (n, 13) of the last step."""
        st = self._state
        return self.lam * (st[:, PHP:PHP + 13] - st[:, PHF:PHF + 13]) + st[:, PSF:PSF + 13]

    def lyapunov(self, theta):
        """Eqs 25-26: ``sum_i (s_i^T M_i s_i + theta_tilde_i^T P_i^-1 theta_tilde_i) / 2``.

        Uses the link velocity errors of the last step and the true parameters ``theta`` (n, 13).
        """
        from .regressor import link_matrices
        theta = as_array(theta, (self.n, 13), "theta")
        s = self.link_velocity_error
        tt = self.theta_hat - theta
        total = 0.0
        for i in range(self.n):
            M = link_matrices(theta[i], np.zeros(3))[0]
            total += 0.5 * s[i] @ M @ s[i] + 0.5 * tt[i] @ np.linalg.solve(self.P[i], tt[i])
        return float(total)


def pack_gains(model, K_D, Lambda, P, gamma, lam, h):
    """Validate the gains (GainError naming the field) and pack them for the step kernels.

    Returns ``K_D (n,6,6), P (n,13,13), Lambda (n,), gamma, lam, h, const, scal``.
    """
    n = model.n
    K_D = per_link_matrix(K_D, n, 6, "K_D", GainError)
    P = per_link_matrix(P, n, 13, "P", GainError)
    Lambda = positive_vector(Lambda, n, "Lambda", GainError)
    gamma = scalar(gamma, "gamma", GainError, minimum=0.0)
    lam = scalar(lam, "lam", GainError, minimum=0.0, strict=True)
    h = scalar(h, "h", GainError, minimum=0.0, strict=True)
    const = np.zeros((n, CONST_COLS))
    const[:, P0:P0 + 3] = model.p
    const[:, RF0:RF0 + 9] = model.R_fix.reshape(n, 9)
    const[:, LAM] = Lambda
    const[:, KD0:KD0 + 36] = K_D.reshape(n, 36)
    const[:, PG0:PG0 + 169] = P.reshape(n, 169)
    scal = np.zeros(SCAL_LEN)
    scal[I_G:I_G + 3] = model.gravity
    scal[I_LAM], scal[I_H], scal[I_GAMMA] = lam, h, gamma
    scal[I_FE:I_FB1 + 1] = filter_coefficients(lam, h)
    scal[I_KD_DIAG] = float(is_diagonal(K_D))
    scal[I_P_DIAG] = float(is_diagonal(P))
    return K_D, P, Lambda, gamma, lam, h, const, scal


def input_error(scal, n, values):
    """The InputError for the code a kernel left in ``scal[I_ERR]``."""
    code = int(scal[I_ERR])
    scal[I_ERR] = 0.0
    name = INPUT_NAMES[(code - 1) % 10]
    if code < 10:
        return InputError(f"{name}: expected length {n}, got {np.shape(values[code - 1])}")
    return InputError(f"{name}: contains NaN or Inf")


def is_diagonal(stack):
    """True if every matrix of the (n, k, k) ``stack`` is diagonal."""
    k = stack.shape[-1]
    return not np.any(stack * (1.0 - np.eye(k)))
