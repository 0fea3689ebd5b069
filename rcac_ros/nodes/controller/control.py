"""The controller's control step (a part of :class:`~.node.ControllerNode`).

One step: the latest valid state, the watchdog and the starvation guard, the desired
motion, the law's step, the effort (clipped; the safe effort for a NaN/Inf one, with the
last finite estimates restored), the monitors and the FollowJointTrajectory feedback.
After a spell long enough to restart the motion (the watchdog's replan) the adaptation of
eq 24 holds until the law's effort is within its limits again: while the effort is clipped
the arm does not feel the torque of eqs 19-20, the tracking term of eq 24 would learn from
errors the saturation made (anti-windup). A
fault of the step itself sends the safe effort and is counted (doc/failsafe.md, "Thread
failures").
"""

import time
import traceback

from rcac_ros.errors import RcacError
from rcac_ros.nodes.controller.freeze import AdaptationFreeze
from rcac_ros.nodes.safety.guards import EffortClip


class ControlStep:
    """The control step of :class:`~.node.ControllerNode` (a mixin: it reads the node's
    ``states``, ``watchdog``, ``failsafe``, ``motion``, ``ctrl``, ``counts``, ``config``,
    ``_outputs``, ``_starvation``, ``_lookahead``, ``_fjt``, ``loop``, ``adaptation``)."""

    def _step(self, t_ns, stamp=None):
        """One control step; if it raises (a fault of this code or of a library, not of the
        law's inputs), the safe effort goes out unless the step's effort did, the filters
        restart at the next step, and the fault is counted (``control_errors``) and logged
        with its traceback, once per type (doc/failsafe.md, "Thread failures")."""
        self._effort_sent = False
        try:
            self._control(t_ns, stamp)
        except Exception as err:        # noqa: BLE001 -- the arm must not keep a stale effort
            if self.counts.control_failed(err):
                self.get_logger().error(
                    "the control step raised; the safe effort goes out (counted in "
                    "control_errors; further ones of this type are not logged):\n"
                    + traceback.format_exc().rstrip())
            self.filters_stale = True
            if not self._effort_sent:   # (one answer per state in lockstep)
                self._outputs.effort(self.config.safe_effort, stamp)

    def _control(self, t_ns, stamp=None):
        state = self.states.take()          # one snapshot (timer mode: set by another thread)
        q, qd = state.q, state.qd
        spell = self.watchdog.resume()      # a spell of safe effort (or a stall) ends here
        if self._starvation is not None:    # timer mode: K_D within the delay margin
            self._starvation.step(after_spell=spell)
        if self.filters_stale:
            self.filters_stale = False
            self.ctrl.restart_filters()
        if self._lookahead is not None:     # timer mode: the state when the effort acts
            q, qd = self._lookahead(q, qd, time.monotonic_ns() - state.received)
        q_d, qd_d, qdd_d = self.motion.sample(t_ns, q)      # limited
        start = time.perf_counter()
        theta_before = self.ctrl.theta_hat
        friction_before = self.ctrl.friction_hat        # None without joint_friction
        try:
            tau = self.ctrl.step(q, qd, q_d, qd_d, qdd_d)
        except RcacError as err:
            self._throttle.warn("step", str(err))
            tau = None
        self.counts.stepped(time.perf_counter() - start, self.config.h)
        verdict, tau, ordered = self.failsafe.clip(tau) if tau is not None \
            else (EffortClip.NON_FINITE, None, None)
        if verdict == EffortClip.NON_FINITE:
            self.counts.non_finite += 1
            self._throttle.warn("non-finite effort", "the controller produced NaN/Inf: "
                                "publishing the safe effort, estimates restored")
            self.ctrl.reset(theta_before, friction_before)  # the last finite ones
            self._outputs.effort(self.config.safe_effort, stamp)
            self._effort_sent = True
            return
        self.counts.efforts.add(time.time_ns())     # handed to DDS (the clock of its stamps)
        self._outputs.effort(ordered, stamp)    # the answer first; what follows does not change it
        self._effort_sent = True
        if AdaptationFreeze.RECOVERING in self.adaptation.reasons \
                and verdict == EffortClip.WITHIN:   # the law has the arm again: adapt
            self.adaptation.freeze(AdaptationFreeze.RECOVERING, False)
            self.get_logger().info(
                "adaptation again: the law's effort is within its limits "
                f"{time.monotonic() - self._recovering_since:.3f} s after the spell")
        self.ctrl.set_applied_torque(tau)       # the filter of eq 22 sees what was sent
        if self._lookahead is not None:
            self._lookahead.applied = tau
        self.watchdog.controlled()
        if self.counts.steps % self.config.publish_every == 0:
            self._outputs.monitors(self.ctrl.theta_hat, self.ctrl.E, q, qd, q_d,
                                   qd_d, qdd_d, tau, stamp, self.ctrl.friction_hat)
        if self._fjt is not None:
            self._fjt.update(t_ns, state.q, state.qd, q_d, qd_d, qdd_d)

    def _on_tick(self):
        """Timer mode: one control step on the latest valid state."""
        if not self.running:
            return
        now = self._now_ns()
        if self.loop is None and self._last_tick is not None \
                and now - self._last_tick > 1.5 * self.config.h * 1e9:
            self.counts.late_ticks += 1     # ROS-time timer (the loop counts its own)
        self._last_tick = now
        self.watchdog.ticked()
        if self.watchdog.state_is_stale():
            return self.watchdog.send_safe(no_state=True)
        self._step(now)
        if self.config.phase_offset_ns is not None and self.loop is not None:
            self.phase_error_ns = self.loop.lock_phase(self.states.received,
                                                       self.config.phase_offset_ns)
