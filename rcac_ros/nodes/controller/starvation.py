"""The controller's starvation guard: the degraded mode of a machine that cannot keep up.

Timer mode only. At each control step :class:`Starvation` feeds the age of the state used
(steady clock) to a :class:`~rcac_ros.nodes.safety.delay_guard.DelayGuard`; while the
smoothed delay is past the delay margin of ``K_D`` the core's feedback gain is scaled down
(:meth:`~rcac_ros.core.composite.RecursiveCompositeController.scale_K_D`) and the adaptation
of eq 24 is frozen (the estimates do not learn from errors that the delay made); once the
delay has stayed within the margin for ``starvation.recover_after`` s the nominal gains and
the adaptation return. One log line each way; diagnostics ``starved``, ``starved_spells``,
``K_D_scale``, ``delay_ms``, ``delay_worst_ms``, ``delay_margin_ms`` (doc/failsafe.md,
"Starved machine").
"""

import time

import numpy as np

from rcac_ros.nodes.safety.delay_guard import DelayGuard, default_margin


def largest_K_D(ctrl):
    """The largest eigenvalue of the core controller's ``K_Di`` (N m s/rad)."""
    return float(np.max(np.linalg.eigvalsh(ctrl.K_D)))


class Starvation:
    """The starvation guard of a controller ``node`` (configured, timer mode).

    Parameters
    ----------
    node : ControllerNode
        Its ``ctrl``, ``h``, ``states.received`` and logger are used.
    values : dict
        The checked parameters (``starvation.*``).
    """

    def __init__(self, node, values):
        self.node = node
        margin = values["starvation.delay_margin"]
        if margin is None:
            margin = default_margin(largest_K_D(node.ctrl))
        self.guard = DelayGuard(margin, node.config.h, values["starvation.recover_after"],
                                values["starvation.min_scale"])
        self._resume_adaptation = False

    def reset(self):
        """A fresh start (activation): nominal gains."""
        if self.guard.starved:
            self._leave()
        self.guard.reset()

    def after_spell(self):
        """A spell of safe effort ended: its length is the watchdog's, not a held effort of
        this loop (a frozen ``/clock`` must not read as a starved loop); the smoothed delay
        and the degraded mode, if on, are kept (a starved machine also trips the watchdog)."""
        self.guard.forget_gap()

    def step(self):
        """Before a control step: judge the delay, scale ``K_D`` (and say so once)."""
        ctrl = self.node.ctrl
        now = time.monotonic_ns()
        event = self.guard.step(now, now - self.node.states.received)
        if event == "starved":
            self._resume_adaptation = ctrl.adapting
            ctrl.set_adaptation(False)
            self.node.get_logger().warning(
                f"starved: the control loop's delay {self.guard.delay * 1e3:.1f} ms is past "
                f"the delay margin of K_D ({self.guard.margin * 1e3:.1f} ms): K_D scaled by "
                f"{self.guard.scale:.3g} and adaptation frozen until the delay stays within "
                f"the margin for {self.guard.recover_after:g} s")
        elif event == "recovered":
            self._leave()
            self.node.get_logger().info(
                f"starvation over: nominal K_D and adaptation again (worst delay "
                f"{self.guard.worst * 1e3:.1f} ms)")
        if self.guard.scale != ctrl.K_D_scale:
            ctrl.scale_K_D(self.guard.scale)

    def _leave(self):
        ctrl = self.node.ctrl
        ctrl.scale_K_D(1.0)
        if self._resume_adaptation:
            ctrl.set_adaptation(True)
        self._resume_adaptation = False

    def diagnostics(self):
        """Key-value pairs for the node's diagnostics."""
        g = self.guard
        return {"starved": "yes" if g.starved else "no", "starved_spells": g.spells,
                "K_D_scale": f"{g.scale:.4g}", "delay_ms": f"{g.delay * 1e3:.2f}",
                "delay_worst_ms": f"{g.worst * 1e3:.2f}",
                "delay_margin_ms": f"{g.margin * 1e3:.2f}"}
