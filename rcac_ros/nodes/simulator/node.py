"""The simulator node: efforts in, joint states and /clock out (``ros2 run rcac_ros simulator``).

Thin: message -> arrays -> the plant -> message. The plant is the parameter ``engine``:
``builtin`` (:class:`rcac_ros.core.simulator.Simulator`) or ``mujoco``
(:class:`rcac_ros.plants.mujoco_plant.MujocoPlant`, the same interface; doc/plants.md).
Two modes:

* ``lockstep`` (default): state k is published (stamp = /clock = k dt); the node
  steps when the effort answering state k arrives, or after ``lockstep_timeout``
  (the previous effort held, a miss counted). Deterministic on a loaded machine.
* ``realtime``: free-running every ``dt`` on absolute deadlines of the steady clock
  (:class:`rcac_ros.nodes.runtime.pacing.DeadlineLoop`: a late step is caught up, not skipped),
  the latest effort held; never paced on ROS time, which stops when ``use_sim_time`` is set
  (a ``/**`` parameter block may set it on this node too) and nothing publishes /clock.

A payload held by the last link (``payload.mass``, ``payload.com``, ``payload.inertia``,
settable at run time: a capture, mass 0 a release) changes the plant at the next step; each
change is checked as a whole (:mod:`rcac_ros.core.payload`: a refusal is the one-line reason
of the parameter result, the plant unchanged), logged, in the diagnostics and published on
``~/payload`` (doc/nodes.md, "Payload").

Parameters are documented in ``config/simulator.yaml``.
"""

import sys
import time

from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import InertiaStamped
import numpy as np
from rclpy.clock import Clock, ClockType
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from rcac_ros import params, topics
from rcac_ros.core.model import PAPER_Q0
from rcac_ros.core.payload import arm_reach, inertia_values
from rcac_ros.plants import make_plant
from rcac_ros.errors import ConfigError, RcacError
from rcac_ros.nodes.runtime.base import QOS, QOS_MONITOR, RcacNode, run
from rcac_ros.nodes.runtime.pacing import DeadlineLoop, wait_for_acks
from rcac_ros.nodes.runtime.realtime import RealtimeOptions
from rcac_ros.nodes.simulator.payload import PayloadParameters, QOS_PAYLOAD

NS = 1_000_000_000
#: s the end of a finite run waits for its readers to acknowledge the last states
ACK_WAIT = 5.0


class SimulatorNode(PayloadParameters, RcacNode):
    """The arm simulator as a ROS 2 node.

    Constructed as :class:`~rcac_ros.nodes.runtime.base.RcacNode` (keyword arguments of
    :class:`rclpy.node.Node`; :class:`ConfigError` naming an invalid parameter).
    """

    PARAMETERS = params.SIMULATOR

    def __init__(self, **kwargs):
        super().__init__(topics.SIMULATOR_NODE, **kwargs)
        n = self.model.n
        self._tau = np.zeros(n)            # model order, the effort held
        self._applied = np.zeros(n)
        self.k = 0
        self.misses = 0
        self.late = 0
        self.repeated = 0                  # extra answers to the re-sent first state
        self._resent_ns = None             # stamp of the state re-sent (answered more than once)
        self.ignored_watchdog = 0
        self.started = False
        self._waiting_since = None
        self._wall_start = None
        self._wall_end = None
        self._rng = np.random.default_rng(self.noise_seed)
        self.sim.step(np.zeros(n))         # compile/load the integrator before starting
        self.sim.reset(self.q0, self.qd0)
        # one message object each, reused (publish serialises at once)
        self._state_msg = JointState(name=list(self.joints))
        self._clock_msg = ClockMsg()
        #: realtime pacing (started with the simulation; run() or a test drives it)
        self.loop = DeadlineLoop(self.dt, self._on_tick) if self.mode == "realtime" else None
        self._pub_state = self.create_publisher(JointState, topics.JOINT_STATES, QOS_MONITOR)
        self._pub_clock = self.create_publisher(ClockMsg, topics.CLOCK, QOS)
        self._sub = self.create_subscription(Float64MultiArray, topics.EFFORT_COMMANDS,
                                             self._on_effort, QOS)
        self._pub_payload = self.create_publisher(InertiaStamped, topics.PAYLOAD, QOS_PAYLOAD)
        self._pending_payload = None       # a payload set at run time, for the next step
        self.payload_changes = 0
        self.add_post_set_parameters_callback(self._on_parameters_set)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._start_timer = self.create_timer(0.01, self._try_start, clock=steady)
        if self.mode == "lockstep":
            self.create_timer(min(self.lockstep_timeout / 5.0, 0.005), self._check_timeout,
                              clock=steady)
        self.get_logger().info(
            f"{self.mode} mode, {self.engine} engine, model {self.model.name} (n={n}), "
            f"dt={self.dt * 1e3:g} ms, "
            f"duration {'unlimited' if self.duration == 0 else f'{self.duration:g} s'}")

    # ------------------------------------------------------------------ parameters
    def _read_parameters(self, v):
        n = self.model.n
        self.mode = v["mode"]
        self.dt = v["dt"]
        self.dt_ns = round(self.dt * NS)
        self.duration = v["duration"]
        self.lockstep_timeout = v["lockstep_timeout"]
        self.max_speed = v["lockstep_max_speed"]
        self.wait_for_controller = v["wait_for_controller"]
        self.min_subscribers = v["min_subscribers"]
        if v["q0"] is None and self.model.name == "css_arm" and n == len(PAPER_Q0):
            self.q0 = np.array(PAPER_Q0)        # already in model order
        else:
            self.q0 = params.per_joint("q0", v["q0"], n, 0.0)[self._order]
        self.qd0 = params.per_joint("qd0", v["qd0"], n, 0.0)[self._order]
        self.position_noise = v["position_noise"]
        self.velocity_noise = v["velocity_noise"]
        self.noise_seed = v["noise_seed"]
        self.publish_velocity = v["publish_velocity"]
        self.realtime = RealtimeOptions.from_values(v)         # applied by run()
        self.engine = v["engine"]
        limit = params.per_joint("effort_limit", v["effort_limit"], n, None)
        try:
            self.sim = make_plant(self.model, v["engine"], dt=self.dt, q0=self.q0,
                                  qd0=self.qd0, substeps=v["substeps"],
                                  effort_limit=None if limit is None else limit[self._order])
        except RcacError as err:
            raise ConfigError(f"simulator: {err}") from None
        self._reach = arm_reach(self.model)
        self.sim.set_payload(self._payload_from(v))     # ConfigError naming the parameter

    # ------------------------------------------------------------------ loop
    def _try_start(self):
        if self.started or self.finished:
            return
        if self.wait_for_controller and (
                self._pub_state.get_subscription_count() < self.min_subscribers
                or self._sub.get_publisher_count() == 0):
            return
        self.started = True
        self._start_timer.cancel()
        self._wall_start = time.monotonic()
        self.get_logger().info("controller found: starting" if self.wait_for_controller
                               else "starting")
        self._publish_payload()
        self._publish_state()
        if self.loop is not None:
            self.loop.start()

    def _publish_state(self):
        stamp_ns = self.k * self.dt_ns
        stamp = TimeMsg(sec=stamp_ns // NS, nanosec=stamp_ns % NS)
        self._clock_msg.clock = stamp
        self._pub_clock.publish(self._clock_msg)
        q = self.sim.q
        qd = self.sim.qd
        if self.position_noise > 0.0:
            q = q + self._rng.normal(0.0, self.position_noise, q.shape)
        if self.velocity_noise > 0.0:
            qd = qd + self._rng.normal(0.0, self.velocity_noise, qd.shape)
        msg = self._state_msg
        msg.position = q[self._out].tolist()
        if self.publish_velocity:
            msg.velocity = qd[self._out].tolist()
        msg.effort = self._applied[self._out].tolist()
        msg.header.stamp = stamp
        self._pub_state.publish(msg)
        self._last_state = msg
        self._resent = 0
        self._pending_ns = stamp_ns
        self._waiting_since = time.monotonic()

    def _advance(self):
        """Step once with the held effort, then publish the new state (or finish)."""
        self._applied = np.clip(self._tau, -self.sim.effort_limit, self.sim.effort_limit)
        if self._pending_payload is not None:
            self._apply_payload()
        self.sim.step(self._tau)
        self.k += 1
        if self.mode == "lockstep" and self.max_speed > 0.0:   # no faster than the cap
            delay = self._wall_start + self.k * self.dt / self.max_speed - time.monotonic()
            if delay > 0.0:
                time.sleep(delay)
        if self.duration > 0.0 and self.k * self.dt_ns >= round(self.duration * NS):
            self._publish_state()
            self._finish()
            return
        self._publish_state()

    def _finish(self):
        self._waiting_since = None
        self.finished = True
        if self.loop is not None:
            self.loop.stop()
        self._wall_end = time.monotonic()
        wall = self._wall_end - self._wall_start
        if not wait_for_acks(self._pub_state, ACK_WAIT):
            self.get_logger().warning(f"a reader of the joint states did not acknowledge the "
                                      f"last ones within {ACK_WAIT:g} s: it may miss them")
        self.get_logger().info(
            f"finished: {self.k} steps, sim time {self.k * self.dt:.3f} s, wall {wall:.2f} s "
            f"({self.k / max(wall, 1e-9):.0f} steps/s), lockstep misses {self.misses}, "
            f"late efforts {self.late}, rejected {self._throttle.total}")

    def _on_effort(self, msg):
        n = self.model.n
        data = np.asarray(msg.data, dtype=float)
        if data.size == 0:
            return self._throttle.warn("empty", "effort message without data")
        if data.size != n:
            return self._throttle.warn("length", f"effort: expected {n} values, "
                                       f"got {data.size}")
        if not np.all(np.isfinite(data)):
            return self._throttle.warn("nan", "effort: NaN or Inf")
        tau = data[self._order]
        if self.mode == "realtime":
            self._tau = tau
            return
        if not self.started or self.finished or self._waiting_since is None:
            return
        tag = topics.effort_tag(msg.layout.dim[0].label) if msg.layout.dim else None
        if tag is not None and tag[0] == "watchdog":
            self.ignored_watchdog += 1
            return
        if tag is not None and tag[1] != self._pending_ns:
            if tag[1] == self._resent_ns:
                self.repeated += 1         # the answer to the copy of a state sent twice
            else:
                self.late += 1             # an answer to an earlier state (after a timeout)
            return
        self._tau = tau
        self._advance()

    def _check_timeout(self):
        if self._waiting_since is None or self.finished:
            return
        waited = time.monotonic() - self._waiting_since
        if self.k == 0 and waited > 0.05 * (self._resent + 1) and waited <= self.lockstep_timeout:
            # the first state can be lost while discovery is still settling on the controller's
            # side: re-send it (the controller answers a repeated state without stepping again)
            self._resent += 1
            self._resent_ns = self._pending_ns
            self._pub_state.publish(self._last_state)
            return
        if waited > self.lockstep_timeout:
            self.misses += 1
            self._resent_ns = None         # an answer to it from now on is late
            self._throttle.warn("lockstep miss", f"no effort for state {self.k} within "
                                f"{self.lockstep_timeout:g} s: holding the previous effort")
            self._advance()

    def _on_tick(self):
        if not self.finished:
            self._advance()

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self):
        """The current diagnostics as a DiagnosticStatus."""
        wall = 0.0 if self._wall_start is None else \
            (self._wall_end or time.monotonic()) - self._wall_start
        level = DiagnosticStatus.OK if self.misses == 0 else DiagnosticStatus.WARN
        pacing = {} if self.loop is None else {
            "deadline_misses": self.loop.skipped, "skipped_ticks": self.loop.skipped,
            "late_ticks": self.loop.late}
        values = {
            "mode": self.mode, "started": self.started, "steps": self.k,
            "sim_time": f"{self.k * self.dt:.6f}", "wall_time": f"{wall:.3f}",
            "steps_per_second": f"{self.k / wall:.1f}" if wall > 0 else "nan",
            "real_time_factor": f"{self.k * self.dt / wall:.3f}" if wall > 0 else "nan",
            "lockstep_misses": self.misses, "late_efforts": self.late,
            "repeated_answers": self.repeated,
            "ignored_watchdog_efforts": self.ignored_watchdog,
            "rejected_messages": self._throttle.total, **pacing,
            "payload_mass": f"{self.sim.payload.mass:g}",
            "payload_com": str(self.sim.payload.com.tolist()),
            "payload_inertia": str(inertia_values(self.sim.payload.inertia).tolist()),
            "payload_changes": self.payload_changes,
        }
        return self.status(level, "simulation",
                           "waiting for a controller" if not self.started else "running", values)

    def on_interrupt(self):
        """Nothing to send on an interrupt: just report."""
        self.get_logger().info(f"interrupted after {self.k} steps")


def main(args=None):
    """Entry point of ``simulator``."""
    sys.exit(run(SimulatorNode, "simulator", args))


if __name__ == "__main__":
    main()
