"""The controller node: joint states in, efforts out (``ros2 run rcac_ros controller``).

A managed node (:class:`~rcac_ros.nodes.runtime.managed.ManagedNode`): configure reads the
parameters into a frozen config (:mod:`.params`) and compiles the law's kernels in a thread
(:mod:`.compiling`), activate starts the efforts once they are ready, deactivate sends one
zero effort. Thin: message -> arrays ->
:class:`~rcac_ros.core.composite.RecursiveCompositeController` -> message, in ``lockstep``
(one step, :mod:`.control`, per valid JointState as the state input's thread reads it, time
from its stamp; the node's callbacks and the watchdog's thread share its lock,
:mod:`rcac_ros.nodes.runtime.serial`) or ``timer`` mode
(``rate`` Hz on the latest valid state, on :class:`~rcac_ros.nodes.runtime.pacing.DeadlineLoop`
or ``/clock``). Its parts, each given what it uses: the state input (:mod:`.state_input`),
the watchdog (:mod:`rcac_ros.nodes.safety.watchdog`), the desired motion (:mod:`.motion`,
also the FollowJointTrajectory server's sink), the ``~/joint_trajectory`` topic
(:mod:`.trajectory_input`), the outputs (:mod:`.outputs`), the estimate services
(:mod:`.estimate_services`) and the fail-safe guards (:mod:`rcac_ros.nodes.safety.failsafe`).
doc/nodes.md, doc/failsafe.md; parameters: ``config/controller.yaml``, doc/parameters.md.
"""

import sys
import time
import traceback

from rclpy.clock import Clock, ClockType

from rcac_ros import params, topics
from rcac_ros.nodes.runtime.base import run
from rcac_ros.nodes.controller.control import ControlStep
from rcac_ros.nodes.controller.compiling import CompileWatch, KernelWarmup
from rcac_ros.nodes.controller.freeze import AdaptationFreeze
from rcac_ros.nodes.controller.diagnostics import diagnostics, LoopCounts
from rcac_ros.nodes.controller.starvation import Starvation
from rcac_ros.nodes.controller.state_input import StateInput
from rcac_ros.nodes.controller.outputs import ControllerOutputs
from rcac_ros.nodes.controller.params import read_parameters
from rcac_ros.nodes.controller.motion import ControllerMotion
from rcac_ros.nodes.controller.trajectory_input import TrajectoryInput
from rcac_ros.nodes.safety.watchdog import Watchdog
from rcac_ros.nodes.controller.estimate_services import EstimateServices
from rcac_ros.nodes.safety.failsafe import ControllerGuards
from rcac_ros.nodes.fjt.server import create_server, FollowJointTrajectoryServer
from rcac_ros.nodes.controller.lookahead import StatePredictor
from rcac_ros.nodes.runtime.managed import FAILURE, ManagedNode
from rcac_ros.nodes.runtime.pacing import DeadlineLoop
from rcac_ros.nodes.runtime.realtime import RealtimeOptions
from rcac_ros.nodes.runtime.serial import SerialCallbacks, SerialTimer


#: s an interrupt waits for the answer being computed before the zero effort goes out
INTERRUPT_WAIT = 1.0


class ControllerNode(ControlStep, SerialCallbacks, ManagedNode):
    """The recursive composite adaptive controller as a managed ROS 2 node.

    Constructed as :class:`~rcac_ros.nodes.runtime.managed.ManagedNode` (keyword arguments of
    :class:`rclpy.node.Node`): with ``autostart`` and no ``description_topic``, an invalid
    parameter raises :class:`ConfigError` naming it; otherwise configure fails and says so.

    Attributes: ``config`` (:class:`~.params.ControllerConfig`, frozen), ``ctrl`` (the core
    controller), ``counts`` (what its loop counted), ``states`` (:class:`StateInput`, the
    latest valid state), ``motion`` (:class:`ControllerMotion`, the desired motion),
    ``watchdog``, ``failsafe`` (the guards), ``filters_stale`` (the
    filters of eqs 21-24 missed states: the next control step restarts them).
    """

    PARAMETERS = params.CONTROLLER
    #: ``gains.<joint>.<gain>``: declared and checked by the gains reader (controller/gains.py)
    READ_PREFIXES = (params.GAINS_PREFIX,)

    def __init__(self, **kwargs):
        self.ctrl = None
        self.loop = None                    # the steady-clock pacing of timer mode
        self._starvation = None             # timer mode's starvation guard
        self.realtime = None                # its real-time options, once configured
        self.realtime_applied = None        # run()'s Realtime, once applied
        super().__init__(topics.CONTROLLER_NODE, **kwargs)

    # ------------------------------------------------------------------ lifecycle
    def _configure(self, values):
        """Parameters, kernels (compiling), publishers, subscriptions, timers, services."""
        self.config, self.ctrl = read_parameters(self, values)     # checked; nothing compiled
        cfg, log, lockstep = self.config, self.get_logger(), self.config.mode == "lockstep"
        self.adaptation = AdaptationFreeze(self.ctrl)  # set_adaptation's and starvation's
        self.failsafe = ControllerGuards(values, self.model, cfg.h, cfg.effort_limit, log.warning,
                                         cfg.out)
        self.realtime = RealtimeOptions.from_values(values)     # applied by run()
        self._lookahead = None if values["timer.lookahead"] is None or cfg.mode != "timer" \
            else StatePredictor(self.model, values["timer.lookahead"])
        self._starvation = Starvation(      # doc/failsafe.md
            values, ctrl=self.ctrl, adaptation=self.adaptation, h=cfg.h, q0=cfg.paper_q0,
            state_received=lambda: self.states.received, log=log) \
            if cfg.mode == "timer" and values["starvation.delay_margin"] != 0.0 else None
        self.kernels = self.keep(KernelWarmup.close, KernelWarmup(     # beside the spinning node
            self.ctrl, self.failsafe.limiter, log, after=[self.failsafe.clip.warm] + [
                part.prepare for part in (self._starvation, self._lookahead) if part]))
        self.compile_watch = self.keep(CompileWatch.close, CompileWatch(self, log))
        self.phase_error_ns = 0
        self._outputs = self.keep(ControllerOutputs.destroy, ControllerOutputs(
            self, self.joints, cfg.out, tagged=lockstep,
            channels=cfg.channel_names, joint_friction=self.ctrl.joint_friction))
        self.counts = LoopCounts()
        self.watchdog = Watchdog(
            stop=self.failsafe.stop, state_timeout=cfg.state_timeout, lockstep=lockstep, log=log,
            send_safe_effort=lambda: self._outputs.effort(cfg.safe_effort, watchdog=True),
            state_received=lambda: self.states.received, stepped=lambda: self.counts.steps > 0,
            filters_missed=self._filters_missed, replan=self._replan)
        self.states = self.keep(StateInput.close, StateInput(
            self, joint_names=self.model.joint_names, lockstep=lockstep, h=cfg.h,
            velocity_cutoff=cfg.velocity_cutoff, gate=self.failsafe.gate,
            max_bytes=self.failsafe.max_state_bytes, watchdog=self.watchdog,
            outputs=self._outputs, log=log, warn=self._throttle.warn,
            is_running=lambda: self.running, steps=lambda: self.counts.steps,
            restarted=self._stream_restarted, control=self._step,
            serial=self.callback_lock if lockstep else None))
        self.inputs = [self.states]         # their side threads' errors: diagnostics
        self.motion = ControllerMotion(     # sampled by the control step, driven by the sources
            paper=cfg.paper, start=cfg.paper_q0, joint_names=self.model.joint_names,
            limiter=self.failsafe.limiter, check_goal=self.failsafe.check_goal,
            now_ns=self.time_now_ns, is_running=lambda: self.running,
            position=lambda: self.states.q)
        self._reset_motion()
        self._fjt = None                    # the FollowJointTrajectory server, if any
        if cfg.trajectory_source == "topic":    # checked aside, applied in this thread
            self.inputs.append(self.keep(TrajectoryInput.close, TrajectoryInput(
                self, joint_names=self.model.joint_names, guards=self.failsafe,
                warn=self._throttle.warn, motion=self.motion, replaced=self._abort_goal)))
            self._fjt = create_server(self, self.motion, defaults=cfg.tolerances)
            if self._fjt is not None:
                self.keep(FollowJointTrajectoryServer.destroy, self._fjt)
        timer = self.destroy_timer
        if cfg.mode == "timer" and self.get_parameter("use_sim_time").value:
            self.keep(timer, self.create_timer(cfg.h, self._on_tick))  # ticks on /clock
        elif cfg.mode == "timer":
            self.loop = DeadlineLoop(cfg.h, self._on_tick)  # run() (or a test) drives it
            self.keep(self._drop_loop, self.loop)
        if lockstep:                        # beside the answers, without the executor
            self.keep(SerialTimer.close, SerialTimer(
                self.watchdog.check_period, self._on_watchdog, self.callback_lock,
                f"{self.get_name()} watchdog", self._thread_fatal))
        elif self.loop is None:             # timer mode on /clock
            self.keep(timer, self.create_timer(self.watchdog.check_period, self._on_watchdog,
                                               clock=Clock(clock_type=ClockType.STEADY_TIME)))
        self.keep(EstimateServices.destroy, EstimateServices(
            self, ctrl=self.ctrl, adaptation=self.adaptation, model=self.model, log=log,
            theta0=cfg.theta0, friction0=cfg.friction0, initial=values["initial_estimates"],
            urdf_links=cfg.urdf_links,
            estimates_file=lambda: self.get_parameter("estimates_file").value))
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.keep(self.remove_post_set_parameters_callback, self._apply_parameters)
        if self.realtime_applied is not None:   # configured again: its loop's thread is new
            self.realtime_applied.move(self.loop_thread)
        log.info(f"configured: {cfg.mode} mode, model {self.model.name} (n={self.model.n}), "
                 f"trajectory {cfg.trajectory_source}, h={cfg.h * 1e3:g} ms, joints "
                 f"{list(self.joints)}; compiling the law's kernels")

    @property
    def loop_thread(self):
        """Native id of the thread of the control step when it is not the main one (lockstep:
        the state input's; its real-time options, :func:`run`), else ``None``."""
        states = getattr(self, "states", None)
        return states.thread if states is not None and self.config.mode == "lockstep" else None

    def _ready_to_activate(self):
        return self.kernels.done.is_set()

    def on_activate(self, state):
        """Activate once the kernels are ready (waits for them); FAILURE if they failed."""
        if not self.kernels.wait():
            return FAILURE
        self.states.arrivals.reset()        # the periods of this activation
        self.counts.efforts.reset()
        result = super().on_activate(state)
        if self.running and self.config.mode == "lockstep":
            with self.callback_lock:        # the state that came while inactive, if recent
                self.states.answer_parked()
        return result

    def _reset_motion(self):
        """A fresh start: the motion, the state input and the watchdog restart."""
        self.motion.restart()
        self.states.reset()
        self.watchdog.reset()
        self._last_tick = None
        self.filters_stale = False          # the loop restarts the filters at its next step
        self._outputs.last_answer = None
        self.adaptation.freeze(AdaptationFreeze.RECOVERING, False)
        if self._starvation is not None:
            self._starvation.reset()

    def _stream_restarted(self):
        """The state stream restarted: the motion starts at the new state, the filters too."""
        self.motion.restart()
        self.filters_stale = self.counts.steps > 0

    def _filters_missed(self):          # the watchdog's: eqs 21-24 missed states
        self.filters_stale = True

    def _drop_loop(self, loop):         # cleanup: timer mode's pacing goes with the rest
        self.loop = None

    def _replan(self, held):
        """The arm went ``held`` s without the law's effort: the motion restarts from it,
        and the adaptation holds until the law's effort is within its limits again (the
        control step lifts :attr:`AdaptationFreeze.RECOVERING`)."""
        self.motion.restart(at_arm=True)
        self.adaptation.freeze(AdaptationFreeze.RECOVERING, True)
        self._recovering_since = time.monotonic()
        self._abort_goal(f"the arm went {held:.3f} s without the controller's effort")

    def _abort_goal(self, text):
        """Abort the FollowJointTrajectory goal, if any."""
        if self._fjt is not None:
            self._fjt.abort(text)

    def _on_watchdog(self):
        """The watchdog's steady timer (lockstep: its own thread; timer mode on /clock)."""
        if self.running:
            self.watchdog.check()

    def _thread_fatal(self, text):
        """The watchdog's thread raised: as an executor callback's fault in :func:`run`, the
        traceback in the log, one zero effort, and the node stops (exit code 1). Not after
        rclpy's shutdown (Ctrl-C, a launch's end): its publish then fails, the run is over."""
        if not self.context.ok():
            return
        try:
            print(f"controller: fatal: {text}", file=sys.stderr, flush=True)
            self.get_logger().fatal(f"a callback raised; the node stops:\n{text}")
            self.on_interrupt()
        except Exception:               # noqa: BLE001 -- already failing: report, stop
            print(f"controller: the stop failed too: {traceback.format_exc()}", file=sys.stderr)
        finally:
            self.exit_code, self.finished = 1, True

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
        """SIGINT/SIGTERM (from :func:`run`): if active, one zero effort, delivered (after a
        lockstep answer being computed, so that none follows it)."""
        lock = self.callback_lock
        taken = lock.acquire(timeout=INTERRUPT_WAIT)
        try:
            if self.running:
                self.running = False
                self._deactivate()
                if not taken and lock.acquire(timeout=INTERRUPT_WAIT):
                    taken = True            # an answer held the lock: its effort went out
                    self._outputs.zero_effort()     # after the zero effort; once more
        finally:
            if taken:
                lock.release()

    # ------------------------------------------------------------------ parameters
    def _apply_parameters(self, changed):
        """Post-set callback: the run-time parameters take effect (a new config)."""
        self.config = self.config.changed(changed)
        self.watchdog.state_timeout = self.config.state_timeout

    # ------------------------------------------------------------------ time
    def _now_ns(self):
        return self.get_clock().now().nanoseconds

    def time_now_ns(self):
        """The time base of trajectories: state stamps in lockstep, the node clock otherwise."""
        if self.config.mode == "lockstep":
            stamp = self.states.stamp
            return stamp if stamp else self.counts.steps * round(self.config.h * 1e9)
        return self._now_ns()

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self):
        """The current diagnostics as a DiagnosticStatus (and restart the timing window)."""
        return diagnostics(self, self.counts, self._throttle, self._starvation, self.inputs)


def main(args=None):
    """Entry point of ``controller``."""
    sys.exit(run(ControllerNode, "controller", args))


if __name__ == "__main__":
    main()
