"""The controller node: joint states in, efforts out (``ros2 run rcac_ros controller``).

Thin: message -> arrays -> :class:`rcac_ros.core.rcac.RecursiveCompositeController` ->
message. Two timing modes:

* ``lockstep`` (default): one step per valid JointState, the trajectory time taken
  from the state's stamp (deterministic with the simulator node);
* ``timer``: ``rate`` Hz on the latest valid state (real arms). On the steady clock the
  ticks keep absolute deadlines (:class:`rcac_ros.nodes.pacing.DeadlineLoop`: a late tick
  is caught up, not skipped); with ``use_sim_time`` a ROS-time timer ticks on ``/clock``.

A watchdog publishes ``safe_effort`` while no valid state has arrived for
``state_timeout`` seconds. Parameters are documented in ``config/controller.yaml``.
"""

import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from rcac_ros import params, topics
from rcac_ros.core.rcac import RecursiveCompositeController
from rcac_ros.errors import ConfigError, RcacError
from rcac_ros.nodes.base import Percentiles, QOS, RcacNode, run
from rcac_ros.nodes.controller_outputs import ControllerOutputs
from rcac_ros.nodes.joint_state import (JointStateReader, stamp_ns, StateRejected,
                                        VelocityEstimate)
from rcac_ros.nodes.pacing import DeadlineLoop
from rcac_ros.nodes.trajectory_msg import DesiredMotion, parse_trajectory, TrajectoryRejected


class ControllerNode(RcacNode):
    """The recursive composite adaptive controller as a ROS 2 node.

    Constructed as :class:`~rcac_ros.nodes.base.RcacNode` (keyword arguments of
    :class:`rclpy.node.Node`; :class:`ConfigError` naming an invalid parameter).
    """

    PARAMETERS = params.CONTROLLER

    def __init__(self, **kwargs):
        super().__init__(topics.CONTROLLER_NODE, **kwargs)
        self._stats = Percentiles()
        n = self.model.n
        self._warm_up()
        self._outputs = ControllerOutputs(self, self.joints, self._out,
                                          tagged=self.mode == "lockstep")
        self._motion = DesiredMotion(self.paper, self.paper_q0)
        self._reader = JointStateReader(self.model.joint_names)
        self._velocity = VelocityEstimate(self.velocity_cutoff)
        # state
        self._q = self._qd = None           # latest valid state (model order)
        self._last_stamp = None             # ns, of the latest valid state
        self._last_rx = None                # node-clock ns at the latest valid state
        self._steps = 0
        self._watchdog = True               # no valid state yet
        self._watchdog_trips = 0
        self._deadline_misses = 0
        self._late_ticks = 0
        self._last_tick = None
        self._nonfinite = 0
        self._q_msg = None
        self._rate_warned = False
        self.loop = None                    # the steady-clock pacing of timer mode
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_state, QOS)
        if self.trajectory_source == "topic":
            self.create_subscription(JointTrajectory, topics.JOINT_TRAJECTORY,
                                     self._on_trajectory, QOS)
        if self.mode == "timer" and self.get_parameter("use_sim_time").value:
            self.create_timer(self.h, self._on_tick)        # ROS time: ticks on /clock
        elif self.mode == "timer":
            self.loop = DeadlineLoop(self.h, self._on_tick)  # run() (or a test) drives it
            self.loop.start()
        else:
            self.create_timer(min(self.state_timeout / 2.0, 0.01), self._on_watchdog)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.get_logger().info(
            f"{self.mode} mode, model {self.model.name} (n={n}), trajectory "
            f"{self.trajectory_source}, h={self.h * 1e3:g} ms, joints {list(self.joints)}")

    # ------------------------------------------------------------------ parameters
    def _read_parameters(self, v):
        n = self.model.n
        self.mode = v["mode"]
        self.h = 1.0 / v["rate"]
        self.trajectory_source = v["trajectory"]
        self.paper = None if v["trajectory"] != "paper" else dict(
            reading=v["paper.reading"], amplitude=v["paper.amplitude"], period=v["paper.period"])
        q0 = params.per_joint("paper.q0", v["paper.q0"], n, None)
        self.paper_q0 = None if q0 is None else q0[self._order]   # joints -> model order
        self.state_timeout = v["state_timeout"]
        limit = params.per_joint("effort_limit", v["effort_limit"], n, None)
        self.effort_limit = (self.model.effort_limit.copy() if limit is None
                             else limit[self._order])
        self.safe_effort = np.clip(params.per_joint("safe_effort", v["safe_effort"], n, 0.0),
                                   -self.effort_limit[self._out], self.effort_limit[self._out])
        self.velocity_cutoff = v["velocity_filter_cutoff"]
        self.publish_every = v["monitor_decimation"]
        try:
            self.ctrl = RecursiveCompositeController(
                self.model, K_D=v["K_D"], Lambda=v["Lambda"], P=v["P"], gamma=v["gamma"],
                lam=v["lambda"], h=self.h)
        except RcacError as err:
            raise ConfigError(f"gains: {err}") from None

    def _apply_parameters(self, changed):
        """Post-set callback: the run-time parameters take effect."""
        for p in changed:
            if p.name == "state_timeout":
                self.state_timeout = float(p.value)
            elif p.name == "monitor_decimation":
                self.publish_every = int(p.value)

    def _warm_up(self):
        """Run the compiled step once so the first real step is not slow, then reset."""
        z = np.zeros(self.model.n)
        self.ctrl.step(z, z, z, z, z)
        self.ctrl.reset()

    # ------------------------------------------------------------------ inputs
    def _now_ns(self):
        return self.get_clock().now().nanoseconds

    def _on_state(self, msg):
        try:
            q, qd = self._reader.read(msg)
        except StateRejected as err:
            return self._throttle.warn(err.kind, str(err))
        stamp = stamp_ns(msg.header.stamp)
        now = self._now_ns()
        if self.mode == "lockstep" and self._outputs.last_answer is not None \
                and stamp == self._last_stamp and np.array_equal(q, self._q_msg):
            # the same state again (a simulator re-sending after a lost message at start-up):
            # answer it again, do not step twice
            self._outputs.answer_again()
            self._last_rx = now
            return
        if self._last_stamp is not None and stamp < self._last_stamp:
            return self._throttle.warn(
                "stamp", f"JointState: stamp went backwards ({stamp * 1e-9:.6f} s < "
                f"{self._last_stamp * 1e-9:.6f} s)")
        # velocity: given, or estimated from positions (finite difference, low-pass)
        if qd is None:
            qd = self._velocity.update(q, stamp if stamp > 0 else now)
        else:
            self._velocity.reset()
        if self.mode == "lockstep" and self._last_stamp is not None and stamp > 0 \
                and not self._rate_warned:
            gap = (stamp - self._last_stamp) * 1e-9
            if abs(gap - self.h) > 0.01 * self.h:
                self._rate_warned = True
                self.get_logger().warning(
                    f"state period {gap * 1e3:.3f} ms differs from h = {self.h * 1e3:.3f} ms "
                    "(set 'rate' to 1/dt of the simulator)")
        self._q, self._qd, self._q_msg = q, qd, q
        self._last_stamp = stamp
        self._last_rx = now
        if self._watchdog:
            self._watchdog = False
            if self._steps:
                self.ctrl.restart_filters()     # the gap broke the filters of eqs 21-24
                self.get_logger().info("watchdog: valid state again, control resumed")
        if self.mode == "lockstep":
            t_ns = stamp if stamp > 0 else self._steps * round(self.h * 1e9)
            self._control(t_ns, msg.header.stamp)

    def _on_trajectory(self, msg):
        try:
            parsed = parse_trajectory(msg, self.model.joint_names)
        except TrajectoryRejected as err:
            return self._throttle.warn(f"trajectory {err.kind}", str(err))
        if not self._motion.follow(parsed, self._time_now_ns(), self._q):
            self._throttle.warn("trajectory early", "no joint state received yet")

    def _time_now_ns(self):
        """The time base of trajectories: state stamps in lockstep, the node clock otherwise."""
        if self.mode == "lockstep":
            return self._last_stamp if self._last_stamp else self._steps * round(self.h * 1e9)
        return self._now_ns()

    # ------------------------------------------------------------------ control
    def _control(self, t_ns, stamp=None):
        q_d, qd_d, qdd_d = self._motion.sample(t_ns, self._q)
        start = time.perf_counter()
        theta_before = self.ctrl.theta_hat
        try:
            tau = self.ctrl.step(self._q, self._qd, q_d, qd_d, qdd_d)
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
        self._outputs.effort(tau[self._out], stamp)
        if self._steps % self.publish_every == 0:
            self._outputs.monitors(self.ctrl.theta_hat, self.ctrl.E, self._q, q_d, qd_d, qdd_d,
                                   stamp)

    def _state_is_stale(self):
        if self._last_rx is None:
            return True
        return self._now_ns() - self._last_rx > self.state_timeout * 1e9

    def _trip(self):
        if not self._watchdog and self._last_rx is not None:
            self._watchdog = True
            self._watchdog_trips += 1
            self.get_logger().warning(
                f"watchdog: no valid state for {self.state_timeout * 1e3:g} ms, "
                "publishing the safe effort")

    def _on_watchdog(self):
        """Lockstep: a periodic check; publishes the safe effort while the state is stale."""
        if self._state_is_stale():
            self._trip()
            self._outputs.effort(self.safe_effort, watchdog=True)

    def _on_tick(self):
        """Timer mode: one control step on the latest valid state."""
        now = self._now_ns()
        if self.loop is None and self._last_tick is not None \
                and now - self._last_tick > 1.5 * self.h * 1e9:
            self._late_ticks += 1           # ROS-time timer (the loop counts its own)
        self._last_tick = now
        if self._state_is_stale():
            self._trip()
            self._outputs.effort(self.safe_effort, watchdog=True)
            return
        self._control(now)

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self):
        """The current diagnostics as a DiagnosticStatus (and restart the timing window)."""
        count, p50, p99, worst = self._stats.pop()
        skipped = 0 if self.loop is None else self.loop.skipped
        level = DiagnosticStatus.OK
        message = "running"
        if self._watchdog:
            level, message = DiagnosticStatus.WARN, "watchdog: safe effort (no valid state)"
        values = {
            "mode": self.mode, "steps": self._steps, "steps_in_window": count,
            "compute_time_p50_us": f"{p50:.1f}", "compute_time_p99_us": f"{p99:.1f}",
            "compute_time_max_us": f"{worst:.1f}",
            "compute_time_max_all_us": f"{self._stats.max_all * 1e6:.1f}",
            "deadline_us": f"{self.h * 1e6:.1f}",
            "deadline_misses": self._deadline_misses + skipped,
            "compute_overruns": self._deadline_misses,
            "late_ticks": self._late_ticks if self.loop is None else self.loop.late,
            "skipped_ticks": skipped,
            "watchdog": "tripped" if self._watchdog else "ok",
            "watchdog_trips": self._watchdog_trips,
            "rejected_messages": self._throttle.total,
            "non_finite_efforts": self._nonfinite,
            "prediction_error": f"{self.ctrl.E[0]:.6g}",
        }
        for kind, c in sorted(self._throttle.counts.items()):
            values[f"rejected_{kind.replace(' ', '_')}"] = c
        return self.status(level, "control loop", message, values)

    # ------------------------------------------------------------------ shutdown
    def on_shutdown(self):
        """Publish one zero-effort command (called on SIGINT/SIGTERM) and wait for delivery."""
        self._outputs.zero_effort()
        self.get_logger().info("shutdown: published a zero effort")


def main(args=None):
    """Entry point of ``controller``."""
    sys.exit(run(ControllerNode, "controller", args))


if __name__ == "__main__":
    main()
