"""The controller's starvation guard: the degraded mode of a machine that cannot keep up.

Timer mode only. At each control step :class:`Starvation` feeds the age of the state used
(steady clock) to a :class:`~rcac_ros.nodes.safety.delay_guard.DelayGuard`; while the
smoothed delay is past the delay margin of ``K_D`` the core's feedback gain is scaled down
(:meth:`~rcac_ros.core.composite.RecursiveCompositeController.scale_K_D`) and the adaptation
of eq 24 is frozen (the estimates do not learn from errors that the delay made); once the
delay has stayed within the margin for ``starvation.recover_after`` s the nominal gains
return, and the adaptation unless the operator froze it (the guard holds its own reason,
:class:`~rcac_ros.nodes.controller.freeze.AdaptationFreeze`). One log line each way;
diagnostics ``starved``, ``starved_spells``, ``K_D_scale``, ``delay_ms``,
``delay_worst_ms``, ``delay_margin_ms`` (doc/failsafe.md, "Starved machine").
"""

import math
import time

import numpy as np

from rcac_ros.core.composite import RecursiveCompositeController
from rcac_ros.core.crba import mass_matrix
from rcac_ros.nodes.controller.freeze import AdaptationFreeze
from rcac_ros.nodes.safety.delay_guard import DelayGuard


def feedback_bandwidth(ctrl, q, eps=1e-4):
    """``omega = lambda_max(M(q)^-1 D)``, 1/s: how fast the law's velocity feedback acts at ``q``.

    ``D = -d tau / d qd`` of eqs 19-20 at rest on the desired state (``qd_d = qdd_d = 0``,
    ``q_d = q``): ``sum_i J_i^T K_Di J_i`` plus ``Lambda M`` through ``qdd_r`` (with the
    estimates ``theta_hat``), by central differences on a new controller with ``ctrl``'s
    gains and estimates and its adaptation frozen (``ctrl`` itself is not stepped; only the
    feedback gains and the estimates are copied, deliberately: the geometry and the
    adaptation do not enter a frozen law's feedback);
    ``M(q)`` is the model's joint-space inertia (the joint terms are left out).
    """
    probe = RecursiveCompositeController(
        ctrl.model, K_D=ctrl.K_D, Lambda=ctrl.Lambda, P=ctrl.P, gamma=ctrl.gamma,
        lam=ctrl.lam, h=ctrl.h, theta_hat0=ctrl.theta_hat)
    probe.set_adaptation(False)
    q = np.asarray(q, float)
    n, zero = q.shape[0], np.zeros(q.shape[0])
    D = np.empty((n, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = eps
        probe.restart_filters()
        plus = probe.step(q, e, q, zero, zero)
        probe.restart_filters()
        minus = probe.step(q, -e, q, zero, zero)
        D[:, j] = (minus - plus) / (2.0 * eps)
    D = 0.5 * (D + D.T)
    return float(np.max(np.linalg.eigvals(np.linalg.solve(mass_matrix(ctrl.model, q), D)).real))


def feedback_margin(ctrl, q):
    """The delay margin of the law's feedback at ``q``: ``(pi / 2) / omega``, s.

    A velocity loop ``M qdd = -D qd(t - d)`` loses its phase margin at ``d = pi / (2 omega)``
    (:func:`feedback_bandwidth`). Against the closed loop with the effort ``d`` periods late
    (``rcac bench delay-margin``, adaptation frozen; doc/failsafe.md "Starved machine"): the
    CSS arm at K_D = 1e4 gives 8.8-9.0 ms and tracked at 8 ms, diverged at 10 ms; the
    Panda of the payload demo (kappa = 100) gives 14.3 ms and tracked at 10 ms, not at
    20 ms.
    """
    return (math.pi / 2.0) / feedback_bandwidth(ctrl, q)


class Starvation:
    """The starvation guard of a controller (configured, timer mode).

    Parameters
    ----------
    values : dict
        The checked parameters ``starvation.*`` (``delay_margin``: ``None`` for
        :func:`feedback_margin` at ``q0``).
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
        margin = values["starvation.delay_margin"]
        if margin is None:                  # at the motion's start, or the zero position
            where = "the zero position" if q0 is None else "paper.q0"
            omega = feedback_bandwidth(ctrl, np.zeros(ctrl.model.n) if q0 is None else q0)
            margin = (math.pi / 2.0) / omega
            source = (f"(pi/2) / {omega:.4g} 1/s, the bandwidth lambda_max(M^-1 D) of the "
                      f"velocity feedback of model {ctrl.model.name} at {where}")
        else:
            source = "starvation.delay_margin"
        self.guard = DelayGuard(margin, h, values["starvation.recover_after"],
                                values["starvation.min_scale"])
        log.info(f"starvation guard: delay margin {margin * 1e3:.3g} ms = {source}; K_D is "
                 f"scaled down past a smoothed delay of {self.guard.limit * 1e3:.3g} ms "
                 "(diagnostics delay_margin_ms)")

    def reset(self):
        """A fresh start (activation): nominal gains."""
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
                f"the delay margin of K_D ({self.guard.margin * 1e3:.1f} ms): K_D scaled by "
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
        """Key-value pairs for the node's diagnostics."""
        g = self.guard
        return {"starved": "yes" if g.starved else "no", "starved_spells": g.spells,
                "K_D_scale": f"{g.scale:.4g}", "delay_ms": f"{g.delay * 1e3:.2f}",
                "delay_worst_ms": f"{g.worst * 1e3:.2f}",
                "delay_margin_ms": f"{g.margin * 1e3:.2f}"}
