"""The controller node: joint states in, efforts out (``ros2 run rcac_ros controller``).

A managed node (:class:`~rcac_ros.nodes.managed.ManagedNode`, ``~/get_state``,
``~/change_state``): configure reads the parameters, the model, the gains (and their
overrides ``gains.<joint>.<gain>``) and warms the kernels; activate starts the efforts (the
motion starts again from the next state); deactivate sends one zero effort, then silence;
``autostart`` (default) does both at start-up. Services ``~/reset_estimates``,
``~/set_adaptation``, ``~/save_estimates`` (:mod:`~rcac_ros.nodes.estimate_services`);
``~/controller_state/*`` (:mod:`~rcac_ros.nodes.controller_state`); doc/nodes.md.

Thin: message -> arrays -> :class:`~rcac_ros.core.rcac.RecursiveCompositeController` ->
message. ``lockstep`` (default): one step per valid JointState, the trajectory time taken
from its stamp (deterministic with the simulator node); ``timer``: ``rate`` Hz on the
latest valid state (real arms), on absolute deadlines of the steady clock
(:class:`~rcac_ros.nodes.pacing.DeadlineLoop`), or on ``/clock`` with ``use_sim_time``.
A watchdog publishes ``safe_effort`` while no valid state has arrived for
``state_timeout`` s of the steady clock (in timer mode on ``/clock``, also while no tick
comes: a frozen clock); after ``watchdog.replan_after`` s of it, control resumes with the
motion restarted from the measured state (doc/failsafe.md). Fail-safe guards (issue 9,
:class:`~rcac_ros.nodes.failsafe.ControllerGuards`): stamps through a
:class:`~rcac_ros.nodes.guards.StampGate` (a restart is followed, a stamp in the future
refused), size caps checked before deserialising, trajectories parsed in their own thread
(in timer mode the states too: the loop only ticks) and checked against the model's limits,
the desired state rate-limited. Parameters: ``config/controller.yaml``, doc/parameters.md.
"""

import sys
import time

import numpy as np
from rclpy.clock import Clock, ClockType
from sensor_msgs.msg import JointState

from rcac_ros import params, topics
from rcac_ros.errors import RcacError
from rcac_ros.nodes.base import Percentiles, QOS, run
from rcac_ros.nodes.controller_diagnostics import diagnostics
from rcac_ros.nodes.controller_outputs import ControllerOutputs
from rcac_ros.nodes.controller_params import read_parameters
from rcac_ros.nodes.controller_trajectory import ActionSink, TrajectoryInput
from rcac_ros.nodes.estimate_services import EstimateServices
from rcac_ros.nodes.failsafe import ControllerGuards
from rcac_ros.nodes.follow_joint_trajectory import create_server, FollowJointTrajectoryServer
from rcac_ros.nodes.guards import StampGate
from rcac_ros.nodes.inputs import capped, SideInput
from rcac_ros.nodes.joint_state import (JointStateReader, stamp_ns, StateRejected,
                                        VelocityEstimate)
from rcac_ros.nodes.lookahead import StatePredictor
from rcac_ros.nodes.managed import ManagedNode
from rcac_ros.nodes.pacing import DeadlineLoop
from rcac_ros.nodes.trajectory_msg import DesiredMotion


class ControllerNode(ManagedNode):
    """The recursive composite adaptive controller as a managed ROS 2 node.

    Constructed as :class:`~rcac_ros.nodes.managed.ManagedNode` (keyword arguments of
    :class:`rclpy.node.Node`): with ``autostart`` and no ``description_topic``, an invalid
    parameter raises :class:`ConfigError` naming it; otherwise configure fails and says so.
    """

    PARAMETERS = params.CONTROLLER

    def __init__(self, **kwargs):
        self.ctrl = None
        self.loop = None                    # the steady-clock pacing of timer mode
        super().__init__(topics.CONTROLLER_NODE, **kwargs)

    # ------------------------------------------------------------------ lifecycle
    def _configure(self, values):
        """Parameters, kernels (warmed), publishers, subscriptions, timers, services."""
        read_parameters(self, values)      # ... and the core controller, its kernels warmed
        self.failsafe = ControllerGuards(values, self.model, self.h, self.effort_limit,
                                         self.get_logger().warning)
        self._lookahead = None if values["timer.lookahead"] is None or self.mode != "timer" \
            else StatePredictor(self.model, values["timer.lookahead"])
        self._stats = Percentiles()
        self._outputs = self.keep(ControllerOutputs.destroy, ControllerOutputs(
            self, self.joints, self._out, tagged=self.mode == "lockstep",
            channels=self.channel_names))
        self._reader = JointStateReader(self.model.joint_names)
        self._steps = self._watchdog_trips = self._deadline_misses = 0
        self._late_ticks = self._nonfinite = 0
        self._rate_warned = False
        self._reset_motion()
        sub, timer, fs = self.destroy_subscription, self.destroy_timer, self.failsafe
        if self.mode == "timer":            # states in their own thread: the loop only ticks
            self.keep(SideInput.close, SideInput(
                self, JointState, topics.JOINT_STATES, QOS, self._on_state,
                fs.max_state_bytes, "state", self._throttle.warn))
        else:                               # lockstep: the answer is the state's callback
            self.keep(sub, self.create_subscription(JointState, topics.JOINT_STATES, capped(
                JointState, fs.max_state_bytes, "state", self._on_state, self._throttle.warn),
                QOS, raw=True))
        self._fjt = None                    # the FollowJointTrajectory server, if any
        if self.trajectory_source == "topic":   # checked aside, applied in this thread
            self.keep(TrajectoryInput.close, TrajectoryInput(self))
            self._fjt = create_server(self, ActionSink(self), defaults=self.tolerances)
            if self._fjt is not None:
                self.keep(FollowJointTrajectoryServer.destroy, self._fjt)
        if self.mode == "timer" and self.get_parameter("use_sim_time").value:
            self.keep(timer, self.create_timer(self.h, self._on_tick))  # ticks on /clock
        elif self.mode == "timer":
            self.loop = DeadlineLoop(self.h, self._on_tick)  # run() (or a test) drives it
            self.keep(lambda _: setattr(self, "loop", None), self.loop)
        if self.loop is None:               # lockstep, or timer mode on /clock
            self.keep(timer, self.create_timer(min(self.state_timeout / 2.0, 0.01),
                                               self._on_watchdog,
                                               clock=Clock(clock_type=ClockType.STEADY_TIME)))
        self.keep(EstimateServices.destroy, EstimateServices(self))
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.keep(self.remove_post_set_parameters_callback, self._apply_parameters)
        self.get_logger().info(
            f"configured: {self.mode} mode, model {self.model.name} (n={self.model.n}), "
            f"trajectory {self.trajectory_source}, h={self.h * 1e3:g} ms, "
            f"joints {list(self.joints)}")

    def _reset_motion(self):
        """A fresh start: the motion, the velocity estimate and the watchdog restart."""
        self._motion = DesiredMotion(self.paper, self.paper_q0)
        self._velocity = VelocityEstimate(self.velocity_cutoff)
        self._q = self._qd = None           # latest valid state (model order)
        self._state = None                  # the same, as one tuple (read by the loop)
        self._last_stamp = None             # ns, of the latest valid state
        self._last_rx = None                # steady-clock ns at the latest valid state
        self._watchdog = True               # no valid state yet
        self._last_tick = None
        self._last_tick_steady = None
        self._restart_filters = False       # the loop restarts them at its next step
        self.failsafe.gate.reset()
        self.failsafe.limiter.reset()
        self.failsafe.stop.cancel()
        self._q_msg = None
        self._outputs.last_answer = None

    def _activate(self):
        """Efforts on; the motion starts again from the next valid state."""
        self._reset_motion()
        self.ctrl.restart_filters()
        if self.loop is not None:
            self.loop.start()
        self.get_logger().info("active: publishing efforts")

    def _deactivate(self):
        """One zero effort, then silence (the lifecycle publishers are disabled next)."""
        if self.loop is not None:
            self.loop.stop()
        if self._fjt is not None:
            self._fjt.abort("the controller was deactivated")
        self._outputs.zero_effort()
        self.get_logger().info("inactive: one zero effort sent, then silence")

    def on_interrupt(self):
        """SIGINT/SIGTERM (from :func:`run`): if active, one zero effort, delivered."""
        if self.running:
            self.running = False
            self._deactivate()

    def follow(self, parsed):
        """Follow a parsed trajectory (:func:`parse_trajectory`) from the desired state now.

        The entry point of every trajectory source (the topic, an action server). Returns
        ``False`` (nothing started) before the first joint state or when not active.
        """
        if not self.running:
            return False
        return self._motion.follow(parsed, self._time_now_ns(), self._q)

    def hold_position(self):
        """Stop any trajectory and hold the measured position (``False``: no state yet)."""
        if not self.running or self._q is None:
            return False
        self._motion.hold(self._q)
        return True

    # ------------------------------------------------------------------ parameters
    def _apply_parameters(self, changed):
        """Post-set callback: the run-time parameters take effect."""
        for p in changed:
            if p.name == "state_timeout":
                self.state_timeout = float(p.value)
            elif p.name == "monitor_decimation":
                self.publish_every = int(p.value)

    # ------------------------------------------------------------------ inputs
    def _now_ns(self):
        return self.get_clock().now().nanoseconds

    def _restart(self, stamp):
        """The state stream restarted (a simulator or driver restart): start over from it."""
        self.get_logger().warning(
            f"joint state stamps restarted ({self._last_stamp * 1e-9:.6f} s -> "
            f"{stamp * 1e-9:.6f} s): filters, velocity estimate and desired motion restart "
            "from the new state; the estimates are kept")
        self._velocity.reset()
        self._motion = DesiredMotion(self.paper, self.paper_q0)
        self.failsafe.limiter.reset()       # the new motion starts at the measured state
        self._restart_filters = self._steps > 0

    def _on_state(self, msg):
        if not self.running:
            return
        try:
            q, qd = self._reader.read(msg)
        except StateRejected as err:
            return self._throttle.warn(err.kind, str(err))
        stamp = stamp_ns(msg.header.stamp)
        now = time.monotonic_ns()           # state silence: on the steady clock, always
        if self.mode == "lockstep" and self._outputs.last_answer is not None \
                and stamp == self._last_stamp and np.array_equal(q, self._q_msg):
            # the same state again (a simulator re-sending after a lost message at start-up):
            # answer it again, do not step twice
            self._outputs.answer_again()
            self._last_rx = now
            return
        verdict = self.failsafe.gate.check(stamp, now, stale=self._watchdog)
        if verdict in (StampGate.BACKWARDS, StampGate.FUTURE):
            return self._throttle.warn(verdict, f"JointState: stamp {stamp * 1e-9:.6f} s "
                                       f"after {self._last_stamp * 1e-9:.6f} s")
        if verdict == StampGate.RESTART and self._last_stamp is not None:
            self._restart(stamp)
        # velocity: given, or estimated from positions (finite difference, low-pass)
        if qd is None:
            qd = self._velocity.update(q, stamp if stamp > 0 else now)
        else:
            self._velocity.reset()
        if self.mode == "lockstep" and verdict == StampGate.OK and self._last_stamp is not None \
                and stamp > 0 and not self._rate_warned:
            gap = (stamp - self._last_stamp) * 1e-9
            if abs(gap - self.h) > 0.01 * self.h:
                self._rate_warned = True
                self.get_logger().warning(
                    f"state period {gap * 1e3:.3f} ms differs from h = {self.h * 1e3:.3f} ms "
                    "(set 'rate' to 1/dt of the simulator)")
        # lockstep: the state right after the last one answered means no step was lost (the
        # watchdog's tagged safe effort is not applied by a lockstep simulator): keep the filters
        unbroken = self.mode == "lockstep" and self._last_stamp is not None \
            and 0 < stamp - self._last_stamp <= 1.5 * self.h * 1e9
        self._state = (q, qd)
        self._q, self._qd, self._q_msg = q, qd, q
        self._last_stamp = stamp
        self._last_rx = now
        if self._watchdog:
            self._watchdog = False
            if self._steps:
                self._restart_filters |= not unbroken   # a gap broke the filters of eqs 21-24
            if unbroken:                    # the lockstep simulator waited: nothing to resume
                self.failsafe.stop.cancel()
                self.get_logger().info("watchdog: valid state again, control resumed")
        if self.mode == "lockstep":
            t_ns = stamp if stamp > 0 else self._steps * round(self.h * 1e9)
            self._control(t_ns, msg.header.stamp)

    def _time_now_ns(self):
        """The time base of trajectories: state stamps in lockstep, the node clock otherwise."""
        if self.mode == "lockstep":
            return self._last_stamp if self._last_stamp else self._steps * round(self.h * 1e9)
        return self._now_ns()

    # ------------------------------------------------------------------ control
    def _control(self, t_ns, stamp=None):
        q, qd = self._state                 # one snapshot (timer mode: set by another thread)
        resumed = self.failsafe.stop.resume(time.monotonic_ns())
        if resumed is not None and self._steps:
            self._resume(*resumed)
        if self._restart_filters:
            self._restart_filters = False
            self.ctrl.restart_filters()
        if self._lookahead is not None:     # timer mode: the state when the effort acts
            q, qd = self._lookahead(q, qd, time.monotonic_ns() - self._last_rx)
        q_d, qd_d, qdd_d = self.failsafe.limiter(*self._motion.sample(t_ns, q))
        start = time.perf_counter()
        theta_before = self.ctrl.theta_hat
        try:
            tau = self.ctrl.step(q, qd, q_d, qd_d, qdd_d)
        except RcacError as err:
            self._throttle.warn("step", str(err))
            tau = None
        elapsed = time.perf_counter() - start
        self._stats.add(elapsed)
        if elapsed > self.h:
            self._deadline_misses += 1
        self._steps += 1
        if tau is None or not np.all(np.isfinite(tau)):
            self._nonfinite += 1
            self._throttle.warn("non-finite effort", "the controller produced NaN/Inf: "
                                "publishing the safe effort, estimates restored")
            self.ctrl.reset(theta_before)       # not poisoned for good: the last finite ones
            self._outputs.effort(self.safe_effort, stamp)
            return
        tau = np.clip(tau, -self.effort_limit, self.effort_limit)
        self.ctrl.set_applied_torque(tau)       # the filter of eq 22 sees what was sent
        if self._lookahead is not None:
            self._lookahead.applied = tau
        self._outputs.effort(tau[self._out], stamp)
        if self._steps % self.publish_every == 0:
            self._outputs.monitors(self.ctrl.theta_hat, self.ctrl.E, q, qd, q_d,
                                   qd_d, qdd_d, tau, stamp)
        if self._fjt is not None:
            self._fjt.update(t_ns, self._q, self._qd, q_d, qd_d, qdd_d)

    def _state_is_stale(self):
        if self._last_rx is None:
            return True
        return time.monotonic_ns() - self._last_rx > self.state_timeout * 1e9

    def _tick_is_stale(self):
        """Timer mode on /clock: no tick for ``state_timeout`` (a frozen or absent /clock)."""
        last = self._last_tick_steady
        return last is None or time.monotonic_ns() - last > self.state_timeout * 1e9

    def _send_safe(self, no_state):
        """The watchdog's safe effort: no valid state (``no_state``), or no tick of /clock."""
        if no_state and self._last_rx is not None:
            self._watchdog = True           # (the stamp gate then takes a restart at once)
        if self.failsafe.stop.trip(time.monotonic_ns()) and self._last_rx is not None:
            self._watchdog_trips += 1       # once per spell (guards.SafeStop)
            self.get_logger().warning(
                f"watchdog: {'no valid state' if no_state else 'no tick of /clock'} for "
                f"{self.state_timeout * 1e3:g} ms, publishing the safe effort")
        self._outputs.effort(self.safe_effort, watchdog=True)

    def _resume(self, held, replan):
        """The first step after ``held`` s of safe effort; ``replan``: the motion restarts."""
        self._restart_filters = True        # the filters of eqs 21-24 missed the spell
        if replan:                          # the arm drifted: go on from where it is
            self._motion = DesiredMotion(self.paper)
            self.failsafe.limiter.reset()
            if self._fjt is not None:
                self._fjt.abort(f"the controller sent the safe effort for {held:.3f} s")
        self.get_logger().info(f"watchdog: control resumed after {held:.3f} s of safe effort"
                               + ("; the motion restarts from the measured state" if replan
                                  else ""))

    def _on_watchdog(self):
        """Steady clock: the safe effort while no valid state (lockstep) or no tick (/clock)."""
        if not self.running:
            return
        stale = self._state_is_stale()
        if stale if self.mode == "lockstep" else self._tick_is_stale():
            self._send_safe(no_state=stale)

    def _on_tick(self):
        """Timer mode: one control step on the latest valid state."""
        if not self.running:
            return
        now = self._now_ns()
        if self.loop is None and self._last_tick is not None \
                and now - self._last_tick > 1.5 * self.h * 1e9:
            self._late_ticks += 1           # ROS-time timer (the loop counts its own)
        self._last_tick = now
        self._last_tick_steady = time.monotonic_ns()
        if self._state_is_stale():
            return self._send_safe(no_state=True)
        self._control(now)

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self):
        """The current diagnostics as a DiagnosticStatus (and restart the timing window)."""
        return diagnostics(self)


def main(args=None):
    """Entry point of ``controller``."""
    sys.exit(run(ControllerNode, "controller", args))


if __name__ == "__main__":
    main()
