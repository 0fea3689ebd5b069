"""The controller node: joint states in, efforts out (``ros2 run rcac_ros controller``).

Thin: message -> arrays -> :class:`rcac_ros.core.rcac.RecursiveCompositeController` ->
message. Two timing modes:

* ``lockstep`` (default): one step per valid JointState, the trajectory time taken
  from the state's stamp (deterministic with the simulator node);
* ``timer``: ``rate`` Hz on the latest valid state (real arms). On the steady clock the
  ticks keep absolute deadlines (:class:`rcac_ros.nodes.common.DeadlineLoop`: a late tick
  is caught up, not skipped); with ``use_sim_time`` a ROS-time timer ticks on ``/clock``.

A watchdog publishes ``safe_effort`` while no valid state has arrived for
``state_timeout`` seconds. Parameters are documented in ``config/controller.yaml``.
"""

import math
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, MultiArrayLayout
from trajectory_msgs.msg import JointTrajectory

from rcac_ros import topics
from rcac_ros.core.exceptions import ConfigError, RcacError
from rcac_ros.core.rcac import RecursiveCompositeController
from rcac_ros.core.trajectory import PaperTrajectory
from rcac_ros.nodes.common import (DeadlineLoop, declare, declare_joints, declare_model,
                                   effort_layout, per_joint, Percentiles, positive, QOS,
                                   QOS_MONITOR, RcacNode, run, stamp_ns)
from rcac_ros.nodes.trajectory import ActiveTrajectory, parse_trajectory, TrajectoryRejected

BIG = 1e12


class ControllerNode(RcacNode):
    """The recursive composite adaptive controller as a ROS 2 node.

    Parameters
    ----------
    **kwargs
        Passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``, ...).

    Raises
    ------
    ConfigError
        At construction, on an invalid parameter (the message names it).
    """

    def __init__(self, **kwargs):
        super().__init__(topics.CONTROLLER_NODE, **kwargs)
        self._stats = Percentiles()
        n = self.model.n
        self._warm_up()
        self._pub_effort = self.create_publisher(Float64MultiArray, topics.EFFORT_COMMANDS, QOS)
        self._pub_theta = self.create_publisher(Float64MultiArray, topics.PARAMETER_ESTIMATES,
                                                QOS_MONITOR)
        self._pub_e = self.create_publisher(Float64, topics.PREDICTION_ERROR, QOS_MONITOR)
        self._pub_track = self.create_publisher(Float64MultiArray, topics.TRACKING_ERROR,
                                                QOS_MONITOR)
        self._pub_desired = self.create_publisher(JointState, topics.DESIRED_STATE, QOS_MONITOR)
        self._pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, QOS)
        self._theta_layout = MultiArrayLayout(dim=[
            MultiArrayDimension(label="link", size=n, stride=13 * n),
            MultiArrayDimension(label="parameter", size=13, stride=13)])
        self._joint_layout = MultiArrayLayout(dim=[
            MultiArrayDimension(label="joint", size=n, stride=n)])
        # timer mode reuses its messages (publish serialises at once)
        self._effort_layout = effort_layout(n)
        self._watchdog_layout = effort_layout(n, watchdog=True)
        self._timer_msg = Float64MultiArray(layout=self._effort_layout)
        self._desired_msg = JointState(name=list(self.joints))
        self._names = None                  # the joint names of the last valid state ...
        self._sel = None                    # ... and their indices in model order
        # state
        self._q = self._qd = None           # latest valid state (model order)
        self._last_stamp = None             # ns, of the latest valid state
        self._last_rx = None                # node-clock ns at the latest valid state
        self._q_prev = None                 # for the velocity estimate
        self._qd_filt = None
        self._t0 = None                     # trajectory time origin, ns
        self._steps = 0
        self._hold = None                   # desired state held before a topic trajectory
        self._active = None                 # ActiveTrajectory
        self._paper = None
        self._desired_last = None
        self._watchdog = True               # no valid state yet
        self._watchdog_trips = 0
        self._deadline_misses = 0
        self._late_ticks = 0
        self._last_tick = None
        self._nonfinite = 0
        self._last_answer = None            # lockstep: the last effort message sent
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
        self.create_timer(self.diagnostics_period, self._publish_diagnostics,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.get_logger().info(
            f"{self.mode} mode, model {self.model.name} (n={n}), trajectory "
            f"{self.trajectory_source}, h={self.h * 1e3:g} ms, joints {list(self.joints)}")

    # ------------------------------------------------------------------ parameters
    def _read_parameters(self):
        self.model = declare_model(self)
        n = self.model.n
        self.joints = declare_joints(self, self.model)
        # model order -> message (joints) order
        self._out = np.array([self.model.joint_names.index(j) for j in self.joints])
        self.mode = declare(self, "mode", "lockstep",
                            "timing: 'lockstep' (one step per JointState, simulator) or "
                            "'timer' (rate Hz on the node clock, real arms)",
                            constraints="lockstep | timer")
        if self.mode not in ("lockstep", "timer"):
            raise ConfigError(f"mode: must be 'lockstep' or 'timer', got {self.mode!r}")
        rate = declare(self, "rate", 500.0, "control rate, Hz (h = 1/rate; in lockstep it must "
                       "match the simulator's dt)", lo=1.0, hi=1e5)
        self.h = 1.0 / positive("rate", rate)
        gains = {}
        for name, default, text in (
                ("K_D", 1e4, "link feedback gain K_Di = K_D I6 (eq 19), > 0"),
                ("Lambda", 1.0, "Lambda of eq 18, 1/s, > 0"),
                ("P", 100.0, "adaptation gain P_i = P I13 (eq 24), > 0"),
                ("lambda", 10.0, "bandwidth of the filter lambda/(p+lambda), rad/s, > 0")):
            gains[name] = positive(name, declare(self, name, default, text, lo=0.0, hi=BIG))
        gains["gamma"] = positive("gamma", declare(
            self, "gamma", 0.1, "weight of the prediction error (eq 24); 0 = direct adaptive "
            "law", lo=0.0, hi=BIG), strict=False)
        self.gains = gains
        self.trajectory_source = declare(self, "trajectory", "paper",
                                         "desired motion: 'paper' (built-in Section 4 motion) "
                                         "or 'topic' (~/joint_trajectory)",
                                         constraints="paper | topic")
        if self.trajectory_source not in ("paper", "topic"):
            raise ConfigError(f"trajectory: must be 'paper' or 'topic', "
                              f"got {self.trajectory_source!r}")
        self.paper_reading = declare(self, "paper.reading", "velocity",
                                     "reading of the paper's motion: 'velocity' or 'position'",
                                     constraints="velocity | position")
        if self.paper_reading not in ("velocity", "position"):
            raise ConfigError(f"paper.reading: must be 'velocity' or 'position', "
                              f"got {self.paper_reading!r}")
        self.paper_amplitude = declare(self, "paper.amplitude", 5.0 * math.pi / 180.0,
                                       "amplitude A (rad/s or rad)", lo=0.0, hi=BIG)
        self.paper_period = positive("paper.period", declare(
            self, "paper.period", 20.0, "period of the paper's motion, s", lo=0.0, hi=BIG))
        q0 = declare(self, "paper.q0", Parameter.Type.DOUBLE_ARRAY,
                     "start of the paper's motion, rad (unset: the first state received)")
        self.paper_q0 = per_joint("paper.q0", q0, n, None)
        if self.paper_q0 is not None:   # given in joints order -> model order
            self.paper_q0 = self._to_model(self.paper_q0)
        self.state_timeout = positive("state_timeout", declare(
            self, "state_timeout", 0.02, "watchdog: safe effort after this long without a "
            "valid state, s", lo=0.0, hi=BIG, read_only=False))
        safe = declare(self, "safe_effort", Parameter.Type.DOUBLE_ARRAY,
                       "effort sent by the watchdog, N m, in joints order (unset: zero)")
        self.safe_effort = per_joint("safe_effort", safe, n, 0.0)
        limit = declare(self, "effort_limit", Parameter.Type.DOUBLE_ARRAY,
                        "efforts are clipped to +-effort_limit, N m, in joints order "
                        "(unset: the model's)")
        self.effort_limit = per_joint("effort_limit", limit, n, None, strict_positive=True)
        self.effort_limit = (self.model.effort_limit.copy() if self.effort_limit is None
                             else self._to_model(self.effort_limit))
        self.safe_effort = np.clip(self.safe_effort, -self.effort_limit[self._out],
                                   self.effort_limit[self._out])
        self.velocity_cutoff = positive("velocity_filter_cutoff", declare(
            self, "velocity_filter_cutoff", 50.0, "cut-off of the velocity estimate used when "
            "JointState has no velocities, Hz", lo=0.0, hi=BIG))
        self.publish_every = declare(self, "monitor_decimation", 1,
                                     "publish estimates and errors every k-th step",
                                     lo=1, hi=1_000_000, read_only=False)
        self.diagnostics_period = positive("diagnostics_period", declare(
            self, "diagnostics_period", 1.0, "diagnostics period, s (steady clock)",
            lo=0.0, hi=3600.0))
        try:
            self.ctrl = RecursiveCompositeController(
                self.model, K_D=gains["K_D"], Lambda=gains["Lambda"], P=gains["P"],
                gamma=gains["gamma"], lam=gains["lambda"], h=self.h)
        except RcacError as err:
            raise ConfigError(f"gains: {err}") from None

    def _order(self):
        return np.array([self.joints.index(j) for j in self.model.joint_names])

    def _to_model(self, values_in_joint_order):
        return np.asarray(values_in_joint_order, float)[self._order()]

    def _on_set_parameters(self, params):
        from rcl_interfaces.msg import SetParametersResult
        for p in params:
            if p.name == "state_timeout" and not p.value > 0.0:
                return SetParametersResult(successful=False, reason="state_timeout: must be > 0")
        for p in params:
            if p.name == "state_timeout":
                self.state_timeout = float(p.value)
            elif p.name == "monitor_decimation":
                self.publish_every = int(p.value)
        return SetParametersResult(successful=True)

    def _warm_up(self):
        """Run the compiled step once so the first real step is not slow, then reset."""
        z = np.zeros(self.model.n)
        self.ctrl.step(z, z, z, z, z)
        self.ctrl.reset()

    # ------------------------------------------------------------------ inputs
    def _now_ns(self):
        return self.get_clock().now().nanoseconds

    def _on_state(self, msg):
        names = msg.name
        m = len(names)
        if m == 0 or len(msg.position) == 0:
            return self._throttle.warn("empty", "JointState without names or positions")
        if len(msg.position) != m or (len(msg.velocity) not in (0, m)):
            return self._throttle.warn(
                "length", f"JointState: {m} names, {len(msg.position)} positions, "
                f"{len(msg.velocity)} velocities")
        if names == self._names:
            sel = self._sel                 # the same names as the last valid state
        else:
            if len(set(names)) != m:
                return self._throttle.warn("names", f"JointState: duplicate names {names}")
            index = {name: k for k, name in enumerate(names)}
            missing = [j for j in self.model.joint_names if j not in index]
            if missing:
                return self._throttle.warn("names", f"JointState: missing joints {missing}")
            sel = [index[j] for j in self.model.joint_names]
            self._names, self._sel = list(names), sel
        q = np.asarray(msg.position, dtype=float)[sel]
        qd = np.asarray(msg.velocity, dtype=float)[sel] if len(msg.velocity) else None
        if not np.all(np.isfinite(q)) or (qd is not None and not np.all(np.isfinite(qd))):
            return self._throttle.warn("nan", "JointState: NaN or Inf in position/velocity")
        stamp = stamp_ns(msg.header.stamp)
        now = self._now_ns()
        if self.mode == "lockstep" and self._last_answer is not None \
                and stamp == self._last_stamp and np.array_equal(q, self._q_msg):
            # the same state again (a simulator re-sending after a lost message at start-up):
            # answer it again, do not step twice
            self._pub_effort.publish(self._last_answer)
            self._last_rx = now
            return
        if self._last_stamp is not None and stamp < self._last_stamp:
            return self._throttle.warn(
                "stamp", f"JointState: stamp went backwards ({stamp * 1e-9:.6f} s < "
                f"{self._last_stamp * 1e-9:.6f} s)")
        # velocity: given, or estimated from positions (finite difference, low-pass)
        if qd is None:
            qd = self._estimate_velocity(q, stamp, now)
        else:
            self._q_prev = None
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

    def _estimate_velocity(self, q, stamp, now):
        t = stamp if stamp > 0 else now
        if self._q_prev is None:
            self._qd_filt = np.zeros_like(q)
        else:
            dt = (t - self._t_prev) * 1e-9
            if dt > 0.0:
                raw = (q - self._q_prev) / dt
                alpha = 1.0 - math.exp(-2.0 * math.pi * self.velocity_cutoff * dt)
                self._qd_filt = self._qd_filt + alpha * (raw - self._qd_filt)
        self._q_prev, self._t_prev = q, t
        return self._qd_filt.copy()

    def _on_trajectory(self, msg):
        try:
            parsed = parse_trajectory(msg, self.model.joint_names)
        except TrajectoryRejected as err:
            return self._throttle.warn(f"trajectory {err.kind}", str(err))
        now = self._time_now_ns()
        if self._desired_last is not None:
            q, qd = self._desired_last[0], self._desired_last[1]
        elif self._q is not None:
            q, qd = self._q, np.zeros(self.model.n)
        else:
            return self._throttle.warn("trajectory early", "no joint state received yet")
        self._active = ActiveTrajectory(parsed, now, q, qd)

    def _time_now_ns(self):
        """The time base of trajectories: state stamps in lockstep, the node clock otherwise."""
        if self.mode == "lockstep":
            return self._last_stamp if self._last_stamp else self._steps * round(self.h * 1e9)
        return self._now_ns()

    # ------------------------------------------------------------------ control
    def _desired(self, t_ns):
        n = self.model.n
        if self._t0 is None:
            self._t0 = t_ns
            q_start = self._q if self.paper_q0 is None else self.paper_q0
            self._hold = (q_start.copy(), np.zeros(n), np.zeros(n))
            if self.trajectory_source == "paper":
                self._paper = PaperTrajectory(q_start, reading=self.paper_reading,
                                              amplitude=self.paper_amplitude,
                                              period=self.paper_period)
        if self._paper is not None:
            return self._paper((t_ns - self._t0) * 1e-9)
        if self._active is not None:
            return self._active.sample(t_ns)
        return self._hold

    def _control(self, t_ns, stamp=None):
        q_d, qd_d, qdd_d = self._desired(t_ns)
        self._desired_last = (q_d, qd_d)
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
            self._publish_effort(self.safe_effort, stamp)
            return
        tau = np.clip(tau, -self.effort_limit, self.effort_limit)
        self.ctrl.set_applied_torque(tau)       # the filter of eq 22 sees what was sent
        self._publish_effort(tau[self._out], stamp)
        if self._steps % self.publish_every == 0:
            self._publish_monitors(q_d, qd_d, qdd_d, stamp)

    def _publish_effort(self, values, stamp=None, watchdog=False):
        values = np.asarray(values, dtype=float)
        if not np.all(np.isfinite(values)):      # never publish NaN/Inf
            values = np.zeros_like(values)
        if self.mode == "timer":                 # untagged: one message object, reused
            msg = self._timer_msg
            msg.layout = self._watchdog_layout if watchdog else self._effort_layout
            msg.data = values.tolist()
            self._pub_effort.publish(msg)
            return
        msg = Float64MultiArray(layout=effort_layout(self.model.n, stamp, watchdog),
                                data=values.tolist())
        self._pub_effort.publish(msg)
        if not watchdog:
            self._last_answer = msg

    def _publish_monitors(self, q_d, qd_d, qdd_d, stamp):
        theta = self.ctrl.theta_hat
        self._pub_theta.publish(Float64MultiArray(layout=self._theta_layout,
                                                  data=theta.ravel().tolist()))
        self._pub_e.publish(Float64(data=float(self.ctrl.E[0])))
        err = (self._q - q_d)[self._out]
        self._pub_track.publish(Float64MultiArray(layout=self._joint_layout,
                                                  data=err.tolist()))
        ds = self._desired_msg
        ds.position = q_d[self._out].tolist()
        ds.velocity = qd_d[self._out].tolist()
        ds.effort = qdd_d[self._out].tolist()
        if stamp is not None:
            ds.header.stamp = stamp
        else:
            ds.header.stamp = self.get_clock().now().to_msg()
        self._pub_desired.publish(ds)

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
            self._publish_effort(self.safe_effort, watchdog=True)

    def _on_tick(self):
        """Timer mode: one control step on the latest valid state."""
        now = self._now_ns()
        if self.loop is None and self._last_tick is not None \
                and now - self._last_tick > 1.5 * self.h * 1e9:
            self._late_ticks += 1           # ROS-time timer (the loop counts its own)
        self._last_tick = now
        if self._state_is_stale():
            self._trip()
            self._publish_effort(self.safe_effort, watchdog=True)
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
        return DiagnosticStatus(
            level=level, name=f"{self.get_name()}: control loop", message=message,
            hardware_id=self.model.name,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])

    def _publish_diagnostics(self):
        msg = DiagnosticArray(status=[self.diagnostics()])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._pub_diag.publish(msg)

    # ------------------------------------------------------------------ shutdown
    def on_shutdown(self):
        """Publish one zero-effort command (called on SIGINT/SIGTERM) and wait for delivery."""
        msg = Float64MultiArray(layout=effort_layout(self.model.n, watchdog=True),
                                data=[0.0] * self.model.n)
        self._pub_effort.publish(msg)
        self._pub_effort.wait_for_all_acked(Duration(seconds=0.5))
        self.get_logger().info("shutdown: published a zero effort")


def main(args=None):
    """Entry point of ``controller``."""
    sys.exit(run(ControllerNode, "controller", args))


if __name__ == "__main__":
    main()
