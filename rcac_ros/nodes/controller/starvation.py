"""The controller's starvation guard: the degraded mode of a machine that cannot keep up.

Timer mode only. At each control step :class:`Starvation` feeds the age of the state used
(steady clock) to a :class:`~rcac_ros.nodes.safety.delay_guard.DelayGuard`; while the
smoothed delay is past the delay margin of ``K_D`` over ``SAFETY`` the core's feedback gain
is scaled down (:meth:`~rcac_ros.core.composite.RecursiveCompositeController.scale_K_D`) and
the adaptation
of eq 24 is frozen (the estimates do not learn from errors that the delay made); once the
delay has stayed within the margin for ``starvation.recover_after`` s the nominal gains
return, and the adaptation unless the operator froze it (the guard holds its own reason,
:class:`~rcac_ros.nodes.controller.freeze.AdaptationFreeze`). One log line each way;
diagnostics ``starved``, ``starved_spells``, ``K_D_scale``, ``delay_ms``,
``delay_worst_ms``, ``delay_margin_ms`` (doc/failsafe.md, "Starved machine").
"""

import time
from collections import namedtuple

import numpy as np

from rcac_ros.core.composite import RecursiveCompositeController
from rcac_ros.core.crba import mass_matrix
from rcac_ros.nodes.controller.freeze import AdaptationFreeze
from rcac_ros.nodes.safety.delay_guard import DelayGuard, SAFETY


#: the delay margin of the law's feedback in its most delay-sensitive mode: the margin, s, and
#: that mode's crossover frequency, rad/s, and phase margin, rad
Margin = namedtuple("Margin", "margin omega_c phase_margin")


def feedback_gains(ctrl, q, eps=1e-4):
    """``(D, K)``: the law's velocity and position feedback at rest on the desired state at ``q``.

    ``D = -d tau / d qd`` and ``K = d tau / d q_d`` of eqs 19-20 at ``qd = qd_d = qdd_d = 0``,
    ``q_d = q`` (``K`` through ``q_d``: the estimated gravity, a function of the measured
    ``q``, stays out of it): ``D = sum_i J_i^T K_Di J_i + Lambda M`` (the latter through
    ``qdd_r``, with the estimates ``theta_hat``) and ``K = Lambda sum_i J_i^T K_Di J_i``,
    by central differences on a new controller with ``ctrl``'s gains and estimates and its
    adaptation frozen (``ctrl`` itself is not stepped; only the feedback gains and the
    estimates are copied, deliberately: the geometry and the adaptation do not enter a
    frozen law's feedback). Both symmetrised.
    """
    probe = RecursiveCompositeController(
        ctrl.model, K_D=ctrl.K_D, Lambda=ctrl.Lambda, P=ctrl.P, gamma=ctrl.gamma,
        lam=ctrl.lam, h=ctrl.h, theta_hat0=ctrl.theta_hat)
    probe.set_adaptation(False)
    q = np.asarray(q, float)
    n, zero = q.shape[0], np.zeros(q.shape[0])
    D, K = np.empty((n, n)), np.empty((n, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = eps
        taus = []
        for args in ((q, e, q), (q, -e, q), (q, zero, q + e), (q, zero, q - e)):
            probe.restart_filters()
            taus.append(probe.step(*args, zero, zero))
        D[:, j] = (taus[1] - taus[0]) / (2.0 * eps)
        K[:, j] = (taus[2] - taus[3]) / (2.0 * eps)
    return 0.5 * (D + D.T), 0.5 * (K + K.T)


def modal_margin(M, D, K, h):
    """The delay margin of ``M qdd = -(D qd + K q)(t - d)`` sampled every ``h``: a
    :class:`Margin`, the smallest over the modes.

    The modes: with ``M = L L^T``, the eigenvectors ``v_i`` of ``A = L^-1 D L^-T``, of
    eigenvalues ``a_i``, and ``b_i = v_i^T L^-1 K L^-T v_i`` (exact when ``A`` and ``B``
    commute, as for this law with a scalar ``Lambda``: both are functions of
    ``L^-1 sum J^T K_D J L^-T``). Each mode is ``x'' = -(a x' + b x)(t - d)``: its open loop
    ``(a s + b) e^(-s d) / s^2`` crosses unit gain at ``omega_c^2 = (a^2 + sqrt(a^4 +
    4 b^2)) / 2`` with the phase margin ``phi = atan2(a omega_c, b)``, lost at
    ``d = phi / omega_c``. The effort held over a period (the zero-order hold) already
    delays it by about ``h / 2``, which the margin of a further delay leaves out.
    """
    L = np.linalg.cholesky(M)
    A = np.linalg.solve(L, np.linalg.solve(L, D).T)
    B = np.linalg.solve(L, np.linalg.solve(L, K).T)
    a, V = np.linalg.eigh(0.5 * (A + A.T))
    b = np.einsum("ji,jk,ki->i", V, 0.5 * (B + B.T), V)
    omega_c = np.sqrt(0.5 * (a ** 2 + np.sqrt(a ** 4 + 4.0 * b ** 2)))
    phi = np.arctan2(a * omega_c, b)
    margins = phi / omega_c - 0.5 * h
    i = int(np.argmin(margins))
    return Margin(float(margins[i]), float(omega_c[i]), float(phi[i]))


def delay_margin(ctrl, q):
    """The delay margin of the law's feedback at ``q`` (a :class:`Margin`): the effort may
    come this much later than in the undelayed loop before the most delay-sensitive mode
    loses its phase margin (:func:`feedback_gains`, :func:`modal_margin`, ``M(q)`` the
    model's joint-space inertia, the joint terms left out).

    Against the closed loop holding a posture with the effort ``d`` periods late
    (``rcac bench delay-margin --check``, adaptation frozen): it settles below the margin and
    not above it, on the CSS arm, the Panda and the UR5 (doc/failsafe.md, "Delay margin per
    arm").
    """
    D, K = feedback_gains(ctrl, q)
    return modal_margin(mass_matrix(ctrl.model, np.asarray(q, float)), D, K, ctrl.h)


def feedback_margin(ctrl, q):
    """:func:`delay_margin`'s margin, s."""
    return delay_margin(ctrl, q).margin


class Starvation:
    """The starvation guard of a controller (configured, timer mode).

    Parameters
    ----------
    values : dict
        The checked parameters ``starvation.*`` (``delay_margin``: ``None`` for
        :func:`delay_margin` at ``q0``).
    ctrl : RecursiveCompositeController
        The core controller: its ``K_D`` is scaled
        (:meth:`~rcac_ros.core.composite.RecursiveCompositeController.scale_K_D`).
    adaptation : AdaptationFreeze
        The guard holds its own reason, :attr:`AdaptationFreeze.STARVED`.
    h : float
        The control period, s.
    q0 : ndarray (n,) or None
        Where the default delay margin is computed (``paper.q0``; ``None``: zero).
    state_received : callable
        ``state_received()``: steady-clock ns of the state the step uses.
    log : rclpy logger
        One line each way.
    """

    def __init__(self, values, *, ctrl, adaptation, h, q0, state_received, log):
        self.ctrl, self.adaptation = ctrl, adaptation
        self.state_received, self.log = state_received, log
        self.guard = None                   # prepare(): the delay margin's guard
        self._values, self._h, self._q0 = values, h, q0
        if values["starvation.delay_margin"] is not None:
            self.prepare()                  # nothing to derive

    def prepare(self):
        """The delay margin (derived: it steps the law, so the controller's warm-up thread
        calls this after compiling), its guard, and the log line that reports it."""
        if self.guard is not None:          # (an explicit margin: done at construction)
            return
        values, h, q0, ctrl, log = self._values, self._h, self._q0, self.ctrl, self.log
        margin = values["starvation.delay_margin"]
        if margin is None:                  # at the motion's start, or the zero position
            where = "the zero position" if q0 is None else "paper.q0"
            derived = delay_margin(ctrl, np.zeros(ctrl.model.n) if q0 is None else q0)
            margin = derived.margin
            source = (f"derived from model {ctrl.model.name} and the gains at {where}: phase "
                      f"margin {derived.phase_margin:.3g} rad / crossover "
                      f"{derived.omega_c:.4g} rad/s, less h/2")
            if margin <= 0.0:               # the undelayed loop is at its edge already
                log.warning(f"starvation guard: the gains leave no delay margin at h = "
                            f"{h * 1e3:g} ms ({source}); the guard takes h/2")
                margin = 0.5 * h
        else:
            source = "starvation.delay_margin"
        self.guard = DelayGuard(margin, h, values["starvation.recover_after"],
                                values["starvation.min_scale"])
        log.info(f"starvation guard: delay margin {margin * 1e3:.3g} ms ({source}); K_D is "
                 f"scaled down past a smoothed delay of {self.guard.limit * 1e3:.3g} ms "
                 "(diagnostics delay_margin_ms)")

    def reset(self):
        """A fresh start (activation): nominal gains."""
        if self.guard is None:              # not prepared yet: nothing started
            return
        if self.guard.starved:
            self._leave()
        self.guard.reset()

    def step(self, after_spell=False):
        """Before a control step: judge the delay, scale ``K_D`` (and say so once).

        ``after_spell``: a spell of safe effort ended; its length is the watchdog's, not a
        held effort of this loop (a frozen ``/clock`` must not read as a starved loop): the
        gap is forgotten, the smoothed delay and the degraded mode, if on, are kept (a
        starved machine also trips the watchdog).
        """
        if after_spell:
            self.guard.forget_gap()
        ctrl = self.ctrl
        now = time.monotonic_ns()
        event = self.guard.step(now, now - self.state_received())
        if event == "starved":
            self.adaptation.freeze(AdaptationFreeze.STARVED, True)
            self.log.warning(
                f"starved: the control loop's delay {self.guard.delay * 1e3:.1f} ms is past "
                f"{self.guard.limit * 1e3:.1f} ms (the delay margin of K_D, "
                f"{self.guard.margin * 1e3:.1f} ms, over {SAFETY:g}): K_D scaled by "
                f"{self.guard.scale:.3g} and adaptation frozen until the delay stays within "
                f"the margin for {self.guard.recover_after:g} s")
        elif event == "recovered":
            self._leave()
            user = AdaptationFreeze.USER in self.adaptation.reasons
            self.log.info(
                f"starvation over: nominal K_D and "
                f"{'adaptation still frozen (by set_adaptation)' if user else 'adaptation again'}"
                f" (worst delay {self.guard.worst * 1e3:.1f} ms)")
        if self.guard.scale != ctrl.K_D_scale:
            ctrl.scale_K_D(self.guard.scale)

    def _leave(self):
        self.ctrl.scale_K_D(1.0)
        self.adaptation.freeze(AdaptationFreeze.STARVED, False)

    def diagnostics(self):
        """Key-value pairs for the node's diagnostics (empty values before :meth:`prepare`)."""
        g = self.guard
        if g is None:
            return dict.fromkeys(("starved", "starved_spells", "K_D_scale", "delay_ms",
                                  "delay_worst_ms", "delay_margin_ms"), "")
        return {"starved": "yes" if g.starved else "no", "starved_spells": g.spells,
                "K_D_scale": f"{g.scale:.4g}", "delay_ms": f"{g.delay * 1e3:.2f}",
                "delay_worst_ms": f"{g.worst * 1e3:.2f}",
                "delay_margin_ms": f"{g.margin * 1e3:.2f}"}
