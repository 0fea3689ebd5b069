"""The recursive composite adaptive controller (eqs 18-24, doc/design.md §3-4), with m channels.

Per control period ``h``, with ``s_i = V_i - V_ri``:

    qd_r = qd_d - Lambda (q - q_d),   qdd_r = qdd_d - Lambda (qd - qd_d)           (eq 18)
    V_ri = T V_r,i-1 + z6 qd_ri
    Vdot_ri = T Vdot_r,i-1 + Tdot V_r,i-1 + z6 qdd_ri         (Tdot with the actual qd_i)
    F_ri = (i+1 T_i)^T F_r,i+1 + Y_ri theta_hat_i + K_Di (V_ri - V_i)              (eq 19b)
    tau_i = z6^T F_ri                                                               (eq 20)
    W_cj, y_c, E_c = sum_j W_cj theta_hat_j - y_c      for each channel c (eqs 21-23)
    theta_hat_dot_i = -P_i (Y_ri^T s_i + gamma sum_c W_ci^T E_c)                     (eq 24)
                      - P_i sigma_i (theta_hat_i - theta_0i)          (leakage, optional)

The paper predicts one channel, the filtered torque of joint 1 (``channels=[1]``, the
default). More channels (:mod:`rcac_ros.core.channels`) predict more filtered torques;
``channels="all"`` is the Slotine-Li composite law, computed recursively.

Where each part lives (doc/design.md §3-4):

- :mod:`rcac_ros.core.channels`: the prediction channels, eqs 21-23 (``W_cj``, ``y_c``,
  ``E_c``), filters exact (zero-order hold on the applied torque, first-order hold on
  ``phi``, ``psi``);
- :mod:`rcac_ros.core.adaptation`: eq 24, the adaptation step and its discretisation
  (implicit or explicit), least squares, dead zones, projection, leakage;
- :mod:`rcac_ros.core.composite_kernels` and :mod:`rcac_ros.core.composite_fused`: the
  compiled step (the general kernel; the paper's law's fused one), on the packed arrays of
  :mod:`rcac_ros.core._packing`;
- here: the controller, which validates and packs the gains and options, chooses a kernel
  and reads the state back. With the defaults the law is the paper's, to the last bit.
"""

import numpy as np

from ._blocks import INPUT_NAMES, input_error
from ._packing import (ADAPT_GRADIENT, ADAPT_LS, ADAPT_LS_PREDICTION, BAR_F, BAR_Q, CHAN_COLS,
                       CH_ACTIVE, CH_E, CH_JOINT, CH_Y, CONST_COLS, FILT_COLS, GAIN_K_D, I_ADAPT,
                       I_BARRIER_C, I_DZ_E, I_DZ_S, I_E, I_ERR, I_FORGET, I_FROZEN, I_HOLD,
                       I_IMPLICIT, I_JOINT_FORGET, I_JOINT_LS, I_K, I_LEAK, I_NATURAL, I_PROJECT,
                       I_RETRACT_MIN, I_TRACKING, I_Y, LEAK_M0, NAT_K, NAT_P_NU, P_FACTOR,
                       S_LINK, TAU, THETA_HAT, TRACE_MAX, W_ROW, Gains, block, new_data)
from ._validate import as_array, joint_values, projection_bounds, scalar
from .channels import channel_codes, parse_channels
from ._jit import is_ready, ready
from .composite_kernels import friction_step_kernel, rcac_step_kernel
from .composite_fused import (is_paper_law, is_paper_natural_law, paper_friction_step,
                              paper_natural_step, paper_step)
from rcac_ros.errors import GainError, InputError
from .joint_friction import (F_GAIN, F_HAT, F_LS, F_RATE, F_VC, JFILT_COLS, JOINT_COLS, P_FRICTION,
                             default_beta, friction_gain, gains_at_start, natural_friction_start,
                             rotor_start)
from .law_options import FRICTION_FORGETTING, friction_adaptation_option
from .least_squares import initial_factor
from .natural_step import lane_constants
from .pseudo_inertia import (barrier_blocks, bregman_log_det, check_body, initial_estimates,
                             is_body, lambda_min, matched_gain, natural_metric_option, nu_gain)

UPDATES = ("implicit", "explicit")
GEOMETRIES = ("euclidean", "natural")
ADAPTATIONS = {"gradient": ADAPT_GRADIENT, "least_squares": ADAPT_LS,
               "least_squares_prediction": ADAPT_LS_PREDICTION}


class RecursiveCompositeController:
    """The recursive composite adaptive controller of eqs 18-24, O(m n) per step.

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
        Adaptation gains ``P_i`` (eq 24), symmetric positive definite; with least squares,
        their initial value.
    gamma : float
        Weight of the prediction errors (eq 24); ``0`` gives the direct adaptive law.
    lam : float
        Bandwidth ``lambda`` of the filter ``lambda / (p + lambda)``, rad/s (the paper gives none).
    h : float
        Control period, s.
    theta_hat0 : array_like (n, 13), optional
        Initial estimates (default zero, as in the paper; with ``geometry="natural"``, a
        body per link, default :func:`~rcac_ros.core.pseudo_inertia.default_start` of the
        model's inertials: the nominal model made a body and halved).
    channels : int, str or sequence, optional
        The predicted filtered torques (:func:`~rcac_ros.core.channels.parse_channels`):
        ``[1]`` (default, the paper's), ``"all"``, ``"power"``, or e.g. ``[1, 7, "power"]``.
    update : {"implicit", "explicit"}
        Discretisation of the prediction-error term (:mod:`rcac_ros.core.adaptation`).
    adaptation : {"gradient", "least_squares", "least_squares_prediction"}
        ``P_i`` fixed (default), least squares with bounded-gain forgetting on both terms,
        or least squares on the prediction term only (the tracking term keeps ``P``).
    forgetting : float
        ``lambda_0`` of the bounded-gain forgetting, 1/s (least squares).
    P_max : float, optional
        ``k_0``: bound on every ``trace(P_i)`` (default: each link's ``trace(P_i(0))``).
    dead_zone_s, dead_zone_E : float
        No adaptation of the tracking term while ``max_j |qd_j - qd_rj| <= dead_zone_s``, and
        none from channel c while ``|E_c| <= dead_zone_E`` (0: no dead zone).
    theta_bounds : None, "mass" or (theta_min, theta_max)
        Projection after each step: none (default), mass >= 0, or a box (each bound a
        scalar, (13,) or (n, 13); ``-inf``/``inf`` for none), with mass >= 0 too (and the
        joint terms >= 0 with ``joint_friction``).
    geometry : {"euclidean", "natural"}
        ``"euclidean"`` (default): eq 24 as written. ``"natural"``: every link's estimates
        stay a physical body at every step (doc/design.md §8): the gain ``P_i`` becomes a
        metric with a barrier at the boundary of the cone ``J > 0`` (``natural_metric``),
        and each step is kept inside the cone. With ``adaptation="least_squares"`` the gain
        is ``(H / k_i + Gamma_i)^-1``, ``H`` the Hessian of ``-log det J(theta_hat_i)`` and
        ``Gamma_i`` the least-squares information (doc/design.md §8); not with
        ``"least_squares_prediction"``. With ``joint_friction`` each joint term ``x > 0``
        adapts with the gain ``min(k_f x^2, P_friction)``, ``k_f = P_friction / x_0^2``, and
        a 1-D retraction keeps it > 0.
    natural_gain : float or (n,), optional
        ``k_i`` of the natural geometry (default: matched to ``P_i`` at the start,
        :func:`~rcac_ros.core.pseudo_inertia.matched_gain`).
    natural_metric : {None, "barrier", "log_det"}
        The natural geometry's gain with ``adaptation="gradient"``: ``"barrier"`` (the
        default, ``None``): ``P_mix = (H / (c k_i) + P_i^-1)^-1 <= P_i``, the inverse
        Hessian of ``-(1/(c k_i)) log det J + 1/2 theta^T P_i^-1 theta`` (the Euclidean gain
        away from the cone's boundary, the barrier's near it; doc/design.md §8); its step is
        the Euclidean step with that gain, halved while it would take ``J_hat`` below half
        of itself along some direction
        (:func:`~rcac_ros.core.retraction.retract_short`); ``"log_det"``: ``k_i H^-1``
        on J and ``P_nu`` on nu, with the curved retraction (cheaper, but its gain grows as
        ``|J_hat|^2`` and it tracks worse, doc/design.md §8). ``"barrier"`` only with
        ``geometry="natural"`` and ``adaptation="gradient"``; natural least squares has its
        own metric (``None`` or ``"log_det"``).
    barrier_c : float, optional
        ``c > 0`` of the metric ``"barrier"`` (default
        :data:`~rcac_ros.core.pseudo_inertia.BARRIER_C`).
    joint_friction : bool
        Also estimate each joint's armature, viscous and Coulomb friction
        (:mod:`rcac_ros.core.joint_friction`, doc/design.md §7): ``friction_hat`` (n, 3).
        False (default): the paper's law, to the last bit.
    friction_hat0 : array_like (n, 3), optional
        Initial joint estimates (armature, damping, friction); default the model's (natural
        geometry: every term > 0, default the model's floored at 1e-3, doc/design.md §8).
    P_friction : "feedback", float, (3,) or (n, 3)
        Diagonal adaptation gains of the joint terms, positive; default ``"feedback"``:
        :func:`~rcac_ros.core.joint_friction.feedback_scaled_gain` at the first step's
        measured ``q`` (``beta_f``: :func:`~rcac_ros.core.joint_friction.default_beta`),
        growing with the largest armature estimate (doc/design.md §7
        "Joint terms without per-arm tuning"). Any ``P_friction``: the joint's feedback
        grows with the rotor (:func:`~rcac_ros.core.joint_friction.rotor`).
    friction_adaptation : {None, "gradient", "least_squares"}
        The joint terms' gain: ``"gradient"`` (the default, ``None``): ``P_friction``
        fixed; ``"least_squares"`` (Euclidean geometry only): a 3x3 least-squares gain per
        joint from ``P_friction`` down, with bounded-gain forgetting that keeps it
        ``<= P_friction`` (doc/design.md §7 "Least squares on the joint terms").
    friction_forgetting : float
        ``lambda_0`` (1/s) of the joint terms' bounded-gain forgetting (least squares),
        default :data:`~rcac_ros.core.law_options.FRICTION_FORGETTING`.
    hold_compensation : bool
        False (default): :meth:`step` returns eq 20's torque ``tau_k``. True: eq 20's model
        torque (without feedback) extrapolated to the middle of the period the zero-order
        hold keeps it, ``tau_k + (m_k - m_k-1) / 2``, which removes the hold's half-period
        lag and the O(h) tracking error it causes (doc/design.md §6 "The hold"); the
        paper's law then runs the general kernel.

    Raises
    ------
    GainError
        On a gain or option of wrong shape or value, naming the field.
    InputError
        On a ``theta_hat0`` of wrong shape or not finite.
    """

    #: the paper's law runs its fused kernel (:meth:`use_fused_kernel`)
    _fused = True

    def __init__(self, model, K_D=1e4, Lambda=1.0, P=100.0, gamma=0.1, lam=10.0, h=0.002,
                 theta_hat0=None, channels=(1,), update="implicit", adaptation="gradient",
                 forgetting=0.0, P_max=None, dead_zone_s=0.0, dead_zone_E=0.0,
                 theta_bounds=None, leakage=0.0, leakage_bound=0.0, theta_0=None,
                 joint_friction=False, friction_hat0=None, P_friction=P_FRICTION,
                 friction_adaptation=None, friction_forgetting=FRICTION_FORGETTING,
                 hold_compensation=False, geometry="euclidean", natural_gain=None,
                 natural_metric=None, barrier_c=None):
        self.model = model
        n = model.n
        gains = Gains(model, K_D, Lambda, P, gamma, lam, h)
        self.K_D, self.P, self.Lambda = gains.K_D, gains.P, gains.Lambda
        self.gamma, self.lam, self.h = gains.gamma, gains.lam, gains.h
        self.channels = parse_channels(channels, n)
        self._data = new_data(n)
        gains.pack(model, self._data)
        self._const = self._data[:n, :CONST_COLS]
        self._state = self._data[:n, CONST_COLS:]       # views into the one kernel argument
        self._scal = self._data[n]
        self._configure(update, adaptation, forgetting, P_max, dead_zone_s, dead_zone_E,
                        theta_bounds)
        m = len(self.channels)
        self._buf = np.zeros((m, n + 1, FILT_COLS))    # the kernel's second argument:
        self._filt = self._buf[:, :n]                  # filt[c, :n], and chan as row n
        self._chan = self._buf[:, n, :CHAN_COLS]
        self._chan[:, CH_JOINT] = channel_codes(self.channels)
        self.adapting = True
        self.K_D_scale = 1.0
        self.hold_compensation = bool(hold_compensation)
        self._scal[I_HOLD] = 1.0 if self.hold_compensation else 0.0
        self.joint_friction = bool(joint_friction)
        self._joint_adaptation(friction_adaptation, friction_forgetting, geometry)
        if self.joint_friction:
            self._joint_terms(friction_hat0, P_friction, m)
        self._geometry(geometry, natural_gain, theta_hat0)
        self._metric(natural_metric, barrier_c)
        self.reset(theta_hat0)
        self._leakage(leakage, leakage_bound, theta_hat0 if theta_0 is None else theta_0)
        self._choose_kernel()               # after every scalar the choice reads

    def _leakage(self, leakage, leakage_bound, theta_0):
        self.leakage = scalar(leakage, "leakage", GainError, minimum=0.0)
        self.leakage_bound = joint_values(leakage_bound, self.n, "leakage_bound", GainError)
        if np.any(self.leakage_bound < 0.0):
            raise GainError("leakage_bound: must be >= 0")
        self.theta_0 = np.zeros((self.n, 13)) if theta_0 is None else \
            as_array(theta_0, (self.n, 13), "theta_0", GainError)
        if self.adaptation == "least_squares":
            top = float(self._const[:, TRACE_MAX].max())
        else:
            top = float(np.linalg.eigvalsh(self.P).max())
        if self.h * self.leakage * top >= 1.0:
            raise GainError(f"leakage: h * leakage * lambda_max(P) = "
                            f"{self.h * self.leakage * top:.3g}, must be < 1 (explicit Euler)")
        self._const[:, block("theta_0")] = self.theta_0
        self._scal[I_LEAK] = self.leakage
        self._const[:, LEAK_M0] = self.leakage_bound

    def _geometry(self, geometry, natural_gain, theta_hat0):
        """Pack the natural geometry's gains (doc/design.md §8), matched at the start."""
        if geometry not in GEOMETRIES:
            raise GainError(f"geometry: expected 'euclidean' or 'natural', got {geometry!r}")
        self.geometry = geometry
        self.natural_gain = None
        if geometry == "natural" and self.adaptation == "least_squares_prediction":
            raise GainError("geometry: 'natural' needs adaptation='gradient' or "
                            "'least_squares', got 'least_squares_prediction' (doc/design.md §8)")
        if geometry == "euclidean":
            if natural_gain is not None:
                raise GainError("natural_gain: only with geometry='natural'")
            return
        start = initial_estimates(self.model, self.geometry, theta_hat0)
        if natural_gain is None:
            k = matched_gain(self.P, start)
        else:
            k = joint_values(natural_gain, self.n, "natural_gain", GainError)
            if np.any(k <= 0.0):
                raise GainError("natural_gain: must be > 0")
        self.natural_gain = k
        self._const[:, NAT_K] = k
        self._const[:, NAT_P_NU:NAT_P_NU + 9] = nu_gain(self.P).reshape(self.n, 9)
        if self.joint_friction:                     # the joint terms: k_f x^2, x > 0
            self.friction_hat0 = natural_friction_start(self._friction_hat0_given,
                                                        self.model.joint_terms(), InputError)
        self._scal[I_NATURAL] = 1.0
        self._scal[I_RETRACT_MIN] = 1.0

    def _joint_adaptation(self, friction_adaptation, friction_forgetting, geometry):
        """The joint terms' gain (doc/design.md §7): least squares or the fixed diagonal."""
        self.friction_adaptation = friction_adaptation_option(friction_adaptation, geometry,
                                                              self.joint_friction)
        self.friction_forgetting = scalar(friction_forgetting, "friction_forgetting",
                                          GainError, minimum=0.0)
        if not self.joint_friction:
            return
        self._scal[I_JOINT_LS] = 1.0 if self.friction_adaptation == "least_squares" else 0.0
        self._scal[I_JOINT_FORGET] = self.friction_forgetting

    def _metric(self, natural_metric, barrier_c):
        """The natural geometry's metric (doc/design.md §8): ``c`` into the scalars."""
        self.natural_metric, self.barrier_c = natural_metric_option(
            natural_metric, barrier_c, self.geometry, self.adaptation)
        if self.barrier_c is not None:
            self._scal[I_BARRIER_C] = self.barrier_c
            Q, F = barrier_blocks(self.P)
            self._const[:, BAR_Q:BAR_Q + 55] = Q
            self._const[:, BAR_F:BAR_F + 30] = F.reshape(self.n, 30)
            lanes = lane_constants(self._const, self.barrier_c)     # the fused law's
            n, rows = self.n, -(-lanes.size // FILT_COLS)
            buf = np.zeros((self._buf.shape[0], n + 1 + rows, FILT_COLS))
            buf[:, :n + 1] = self._buf
            buf[0, n + 1:].reshape(-1)[:lanes.size] = lanes
            self._buf, self._filt, self._chan = buf, buf[:, :n], buf[:, n, :CHAN_COLS]

    def _joint_terms(self, friction_hat0, P_friction, m):
        """The joint terms' arrays (doc/design.md §7): gains, v_c, initial estimates.
        ``P_friction="feedback"``: the gain at the zero posture until the first step
        (:meth:`_friction_gain_at_start`)."""
        n = self.n
        self.P_friction = friction_gain(P_friction, n)
        self._friction_default = self.P_friction is None
        self._gain_at_start = True          # rates (and the default gain) at the first state
        self._beta = default_beta(self.channels, n, self.update == "implicit", self.gamma)
        got = gains_at_start(self.model, self.K_D, np.zeros(n), self._friction_default, self.h,
                             self._beta)
        P, self._grow, self._rate = got
        if self._friction_default:
            self.P_friction = P
        self._friction_hat0_given = None if friction_hat0 is None else \
            as_array(friction_hat0, (n, 3), "friction_hat0")
        self.friction_hat0 = self.model.joint_terms() if friction_hat0 is None else \
            self._friction_hat0_given
        self._jdata = np.zeros((n, JOINT_COLS))
        self._jdata[:, F_GAIN:F_GAIN + 3] = self.P_friction
        self._jdata[:, F_VC] = self.model.friction_velocity
        self._jfilt = np.zeros((m, n, JFILT_COLS))

    def _choose_kernel(self):
        """The compiled step: :func:`paper_step`, the paper's law's fused body (faster), for
        that law, adapting or frozen, :func:`paper_natural_step` for it in the natural
        geometry, else the general kernel :func:`rcac_step_kernel`; with the joint terms,
        :func:`~rcac_ros.core.composite_fused.paper_friction_step` or
        :func:`~rcac_ros.core.composite_kernels.friction_step_kernel`. Compiled by
        :meth:`compile` (or the first step)."""
        fused = self._fused and is_paper_law(self._chan, self._scal)
        if self.joint_friction:
            self._entry = paper_friction_step if fused else friction_step_kernel
        elif self._fused and is_paper_natural_law(self._chan, self._scal):
            self._entry = paper_natural_step
        else:
            self._entry = paper_step if fused else rcac_step_kernel
        self._kernel = self._ready_kernel()
        if self.joint_friction and self._gain_at_start:
            self._kernel = self._friction_gain_at_start

    def _ready_kernel(self):
        return self._bind(self._entry) if is_ready(self._entry) else self._compile_step

    def _friction_gain_at_start(self, data, buf, q, *rest):
        """The first step with ``P_friction="feedback"``: the gain
        :func:`~rcac_ros.core.joint_friction.gains_at_start` at the measured ``q`` and the
        current estimates (doc/design.md §7), then the step."""
        got = gains_at_start(self.model, self.K_D, q, self._friction_default, self.h,
                             self._beta)
        if got is not None:
            P, self._grow, self._rate = got
            if P is not None:
                self.P_friction = P
            self._rotor_start()
            self._gain_at_start = False
            self._choose_kernel()
        return self._ready_kernel()(data, buf, q, *rest)

    def _bind(self, kernel):
        if not self.joint_friction:
            return kernel
        jdata, jfilt = self._jdata, self._jfilt
        return lambda data, buf, *x: kernel(data, buf, jdata, jfilt, *x)

    def _compile_step(self, *args):
        self.compile()
        return self._kernel(*args)

    def compile(self):
        """Compile this law's kernel (or load it from the cache), once per process; returns
        ``self``.

        Building the controller compiles nothing; the first :meth:`step` calls this. Every
        path the law can then take runs the same kernel: freezing and resuming the
        adaptation (:meth:`set_adaptation`), scaling ``K_D``, resetting the estimates. With
        an empty cache the general kernel takes several times the paper law's fused one.
        """
        ready(self._entry)
        if self._kernel == self._compile_step:     # (a first step may have chosen already)
            self._kernel = self._bind(self._entry)
        return self

    def use_fused_kernel(self, fused):
        """Let the paper's law run its fused kernel (``True``, the default) or the general
        one (``False``, for benchmarks: the same law, bit for bit without the joint terms,
        to 1e-12 with them)."""
        self._fused = bool(fused)
        self._choose_kernel()

    def _configure(self, update, adaptation, forgetting, P_max, dead_zone_s, dead_zone_E,
                   theta_bounds):
        if update not in UPDATES:
            raise GainError(f"update: expected 'implicit' or 'explicit', got {update!r}")
        if adaptation not in ADAPTATIONS:
            raise GainError(f"adaptation: expected one of {', '.join(ADAPTATIONS)}, "
                            f"got {adaptation!r}")
        self.update, self.adaptation = update, adaptation
        scal = self._scal
        scal[I_IMPLICIT] = 1.0 if update == "implicit" else 0.0
        scal[I_ADAPT] = ADAPTATIONS[adaptation]
        scal[I_FORGET] = scalar(forgetting, "forgetting", GainError, minimum=0.0)
        self._const[:, TRACE_MAX] = np.trace(self.P, axis1=1, axis2=2) if P_max is None else \
            scalar(P_max, "P_max", GainError, minimum=0.0, strict=True)
        scal[I_DZ_S] = scalar(dead_zone_s, "dead_zone_s", GainError, minimum=0.0)
        scal[I_DZ_E] = scalar(dead_zone_E, "dead_zone_E", GainError, minimum=0.0)
        self.theta_min, self.theta_max = projection_bounds(theta_bounds, self.n)
        if self.theta_min is not None:
            self._const[:, block("theta_lo")] = self.theta_min
            self._const[:, block("theta_hi")] = self.theta_max
            scal[I_PROJECT] = 1.0

    @property
    def n(self):
        """Number of joints."""
        return self.model.n

    @property
    def m(self):
        """Number of prediction channels."""
        return len(self.channels)

    def reset(self, theta_hat0=None, friction_hat0=None):
        """Restart: estimates to ``theta_hat0`` (default: 0, or the natural geometry's
        default start), filters, gains and step count.

        With ``joint_friction``, the joint estimates go to ``friction_hat0`` (default: the
        constructor's).

        Raises
        ------
        InputError
            On a ``theta_hat0`` of wrong shape, not finite, or (natural geometry) not a body.
        """
        th = initial_estimates(self.model, self.geometry, theta_hat0)
        if self.joint_friction:
            fh = self.friction_hat0 if friction_hat0 is None else \
                as_array(friction_hat0, (self.n, 3), "friction_hat0")
            if self.geometry == "natural":
                fh = natural_friction_start(fh, None, InputError)
            self._jdata[:, F_HAT:F_HAT + 3] = fh
            self._rotor_start()     # k_f follows the estimate (follow_gain): matched anew
            self._jfilt[:] = 0.0
        self._state[:] = 0.0
        self._state[:, THETA_HAT:THETA_HAT + 13] = th
        self._state[:, P_FACTOR:P_FACTOR + 169] = initial_factor(self.P)
        self._filt[:] = 0.0
        self._chan[:, CH_Y:] = 0.0
        self._scal[[I_K, I_ERR, I_E, I_Y]] = 0.0

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
        tau : ndarray, shape (n,)
            The joint torques of eq 20 (before any effort limit: the caller clips);
            its model torque extrapolated to the middle of the hold with
            ``hold_compensation``.

        Raises
        ------
        InputError
            A vector of the wrong length or with NaN/Inf: the estimates, the filters and
            the prediction errors are left as they were.
        """
        try:
            tau = self._kernel(self._data, self._buf, q, qd, q_d, qd_d, qdd_d)
        except TypeError:  # not float64 1-D contiguous arrays: convert once, then retry
            values = (q, qd, q_d, qd_d, qdd_d)
            args = [as_array(v, (None,), k) for k, v in zip(INPUT_NAMES, values)]
            tau = self._kernel(self._data, self._buf, *args)
        if tau.shape[0] == 0:
            raise input_error(self._scal, self.n, (q, qd, q_d, qd_d, qdd_d))
        return tau

    def set_adaptation(self, enabled):
        """Freeze (``False``) or resume (``True``) the adaptation of eq 24, keeping ``theta_hat``.

        Frozen, ``theta_hat`` (and a least-squares gain) stay where they are, the torque of
        eqs 19-20 uses them, and the filters and ``E`` keep running (``E`` then measures the
        frozen estimates).
        """
        self._scal[I_FROZEN] = 0.0 if enabled else 1.0
        self.adapting = bool(enabled)
        self._choose_kernel()

    def scale_K_D(self, factor):
        """Use ``factor * K_D`` in eq 19b from the next step on (1: the gains as built).

        Only the feedback term ``K_Di (V_ri - V_i)`` changes; :attr:`K_D` keeps the gains as
        built. The degraded mode of a controller whose states come later than the delay
        margin of ``K_D`` allows (doc/failsafe.md, "starved machine").

        Raises
        ------
        GainError
            If ``factor`` is not in (0, 1].
        """
        factor = scalar(factor, "factor", GainError, minimum=0.0, strict=True)
        if factor > 1.0:
            raise GainError(f"factor: must be <= 1, got {factor:g}")
        self._const[:, GAIN_K_D:GAIN_K_D + 36] = factor * self.K_D.reshape(self.n, 36)
        self.K_D_scale = factor
        if self.joint_friction:             # the rotor's feedback k_q = rho_q a_fb too
            self._jdata[:, F_RATE] = factor * self._rate

    def set_applied_torque(self, tau):
        """Tell the filters (``y_c``, eq 22) the torque really applied after the last step.

        By default ``y`` filters the torque :meth:`step` returned. When the arm receives
        another one (clipped to an effort limit, or a safe effort), pass it here, or the
        prediction errors ``E`` compare the model with a torque the arm never felt.

        Raises
        ------
        InputError
            If ``tau`` has the wrong length or holds NaN/Inf.
        """
        self._state[:, TAU] = as_array(tau, (self.n,), "tau")

    def restart_filters(self):
        """Restart the filters of eqs 21-24 at the next step, keeping ``theta_hat``.

        For a gap in the measurements (a watchdog trip): the filters start again as at
        t = 0 (``phi^f = phi``, ``psi^f = 0``, ``y = 0``), so ``E`` is exact from there on.
        With ``hold_compensation`` the next torque is not extrapolated (no last one).
        """
        self._scal[I_K] = 0.0

    @property
    def theta_hat(self):
        """Current estimates ``theta_hat``, shape (n, 13) (a copy)."""
        return self._state[:, THETA_HAT:THETA_HAT + 13].copy()

    @property
    def lambda_min(self):
        """``lambda_min(J(theta_hat_i))`` per link, (n,): > 0 for a physical body
        (doc/design.md §8)."""
        return lambda_min(self._state[:, THETA_HAT:THETA_HAT + 13])

    @property
    def consistent(self):
        """Per link, whether ``theta_hat_i`` is a physical body (``J > 0``), (n,) bool."""
        return is_body(self._state[:, THETA_HAT:THETA_HAT + 13])

    @property
    def retraction_length(self):
        """The natural geometry's smallest step length ``a`` at the last step (1: no link's
        step was shortened; doc/design.md §8)."""
        return float(self._scal[I_RETRACT_MIN])

    @property
    def friction_hat(self):
        """Joint estimates (armature, damping, friction), shape (n, 3) (a copy); None without
        ``joint_friction`` (doc/design.md §7)."""
        if not self.joint_friction:
            return None
        return self._jdata[:, F_HAT:F_HAT + 3].copy()

    def set_friction_hat(self, friction_hat):
        """Set the joint estimates (n, 3), e.g. restored from a file; filters keep running.
        The rotor's reference and the gains restart from them (a least-squares gain at
        ``P_friction``); with ``hold_compensation`` the next torque's extrapolation holds
        half the step of the model torque the new estimates make."""
        if not self.joint_friction:
            raise GainError("friction_hat: the controller has no joint terms "
                            "(joint_friction=False)")
        fh = as_array(friction_hat, (self.n, 3), "friction_hat")
        if self.geometry == "natural":
            fh = natural_friction_start(fh, None, InputError)
        self._jdata[:, F_HAT:F_HAT + 3] = fh
        self._rotor_start()

    def _rotor_start(self):
        """The rotor's reference ``a_ref`` at the armature estimates, and the gains from it
        (:func:`~rcac_ros.core.joint_friction.rotor_start`, doc/design.md §7)."""
        rotor_start(self._jdata, self.P_friction, self._grow, self.K_D_scale * self._rate,
                    self.geometry == "natural")

    @property
    def E(self):
        """Prediction errors ``E_c = sum_j W_cj theta_hat_j - y_c`` of the last step, (m,)."""
        return self._chan[:, CH_E].copy()

    @property
    def y(self):
        """Filtered applied outputs ``y_c`` (e.g. ``tau_1^f``) at the last step, (m,)."""
        return self._chan[:, CH_Y].copy()

    @property
    def link_velocity_error(self):
        """``s_i = V_i - V_ri`` of the last step, shape (n, 6) (a copy)."""
        return self._state[:, S_LINK:S_LINK + 6].copy()

    @property
    def W(self):
        """The filtered regressor rows ``W_cj`` of the last step, (m, n, 13) (a copy)."""
        return self._filt[:, :, W_ROW:W_ROW + 13].copy()

    @property
    def gain(self):
        """The adaptation gain ``P_i`` in use, (n, 13, 13): fixed, or least squares (with
        ``geometry="natural"``: the fixed ``P_i`` the natural gain was matched to, or the
        least-squares ``P_ls,i = Gamma_i^-1`` of the metric ``H / k_i + Gamma_i``; with
        ``natural_metric="barrier"`` the fixed ``P_i`` of ``P_mix``, doc/design.md §8)."""
        if self.adaptation == "gradient":
            return self.P.copy()
        S = self._state[:, P_FACTOR:P_FACTOR + 169].reshape(self.n, 13, 13)
        return S @ S.transpose(0, 2, 1)

    @property
    def friction_gain(self):
        """The joint terms' gain ``P_f,i`` in use, (n, 3, 3): the diagonal ``P_friction``
        (as grown by the rotor), or least squares (doc/design.md §7); None without
        ``joint_friction``."""
        if not self.joint_friction:
            return None
        if self.friction_adaptation == "gradient":
            return np.array([np.diag(g) for g in self._jdata[:, F_GAIN:F_GAIN + 3]])
        T = self._jdata[:, F_LS:F_LS + 9].reshape(self.n, 3, 3)
        r = np.sqrt(self._jdata[:, F_GAIN:F_GAIN + 3])
        return r[:, :, None] * (T @ T.transpose(0, 2, 1)) * r[:, None, :]

    @property
    def adapted(self):
        """Whether the tracking term and each channel adapted at the last step (dead zones)."""
        return bool(self._scal[I_TRACKING]), self._chan[:, CH_ACTIVE] != 0.0

    def lyapunov(self, theta):
        """The Lyapunov function of the law in use, with the true parameters ``theta`` (n, 13).

        Euclidean (eqs 25-26): ``sum_i (s_i^T M_i s_i + theta~_i^T P_i^-1 theta~_i) / 2``,
        ``theta~ = theta_hat - theta``, with the fixed ``P_i`` or the least-squares ``P_i``.
        Natural (doc/design.md §8): the second term becomes the Bregman divergence of the
        law's metric: ``D(J_i || J_hat_i) / k_i + nu~_i^T P_nu,i^-1 nu~_i / 2`` (log-det),
        ``D / (c k_i) + theta~_i^T P_i^-1 theta~_i / 2`` (barrier), ``D / k_i + theta~_i^T
        Gamma_i theta~_i / 2`` (least squares), with ``D`` of
        :func:`~rcac_ros.core.pseudo_inertia.bregman_log_det`; then every ``theta_i`` must be
        a body (else :class:`InputError`).
        Uses the link velocity errors of the last step; the joint terms are not included.
        """
        from .regressor import link_matrices
        theta = as_array(theta, (self.n, 13), "theta")
        s = self.link_velocity_error
        tt = self.theta_hat - theta
        total = 0.0
        for i in range(self.n):
            M = link_matrices(theta[i], np.zeros(3))[0]
            total += 0.5 * s[i] @ M @ s[i]
        P = self.gain
        if self.geometry == "euclidean":
            return float(total + sum(0.5 * tt[i] @ np.linalg.solve(P[i], tt[i])
                                     for i in range(self.n)))
        check_body(theta, "theta")
        D = bregman_log_det(theta, self.theta_hat)
        k = self._const[:, NAT_K]
        if self.adaptation == "least_squares":          # D / k + theta~^T Gamma theta~ / 2
            quad = [tt[i] @ np.linalg.solve(P[i], tt[i]) for i in range(self.n)]
        elif self.barrier_c is not None:                # D / (c k) + theta~^T P^-1 theta~ / 2
            k = k * self.barrier_c
            quad = [tt[i] @ np.linalg.solve(P[i], tt[i]) for i in range(self.n)]
        else:                                           # D / k + nu~^T P_nu^-1 nu~ / 2
            Pnu = self._const[:, NAT_P_NU:NAT_P_NU + 9].reshape(self.n, 3, 3)
            quad = [tt[i, 4:7] @ np.linalg.solve(Pnu[i], tt[i, 4:7]) for i in range(self.n)]
        return float(total + np.sum(D / k) + 0.5 * np.sum(quad))
