"""The controller's state input: ``/joint_states`` in, the latest valid ``(q, qd)`` out.

:class:`StateInput` subscribes with the size cap checked on the serialised bytes (doc/failsafe.md;
in timer mode in its own thread, :class:`~rcac_ros.nodes.runtime.inputs.SideInput`, so the loop
thread only ticks), reads each message into model order
(:class:`~rcac_ros.nodes.msgs.joint_state.JointStateReader`), judges its stamp
(:class:`~rcac_ros.nodes.safety.state_guards.StampGate`: a restart of the stream is followed, a
stamp in the future refused), estimates the velocity when none is given and tells the
watchdog that a valid state came. In lockstep mode the control step is the answer to the
state, run in its callback.
"""

import time

import numpy as np
from sensor_msgs.msg import JointState

from rcac_ros import topics
from rcac_ros.nodes.runtime.base import QOS
from rcac_ros.nodes.runtime.inputs import capped, SideInput
from rcac_ros.nodes.msgs.joint_state import (JointStateReader, stamp_ns, StateRejected,
                                             VelocityEstimate)
from rcac_ros.nodes.safety.state_guards import StampGate


class StateInput:
    """``/joint_states`` of a controller: what it reads and what it calls, nothing more.

    Parameters
    ----------
    node : rclpy.node.Node
        Where the subscription lives (rclpy's API only), and its logger.
    joint_names : sequence of str
        The model's joints.
    lockstep : bool
        Each valid state is answered in its callback (else timer mode: a side thread).
    h : float
        The control period, s.
    velocity_cutoff : float
        Of the velocity estimate (:class:`~rcac_ros.nodes.msgs.joint_state.VelocityEstimate`).
    guards : ControllerGuards
        ``gate`` (the stamps) and ``max_state_bytes``.
    watchdog : Watchdog
        Told of each valid state; its ``tripped`` lets the gate take a restart at once.
    outputs : ControllerOutputs
        Lockstep: the last answer, sent again for a repeated state.
    warn : callable
        ``warn(kind, text)``: a throttled warning.
    is_running : callable
        The controller is active.
    steps : callable
        The controller's steps since its start.
    restarted : callable
        ``restarted()``: the stream restarted; the motion and the filters start over.
    control : callable
        Lockstep: ``control(t_ns, header_stamp)``, the answer to a valid state.

    Attributes
    ----------
    q, qd : ndarray (n,) or None
        The latest valid state (model order); ``qd`` measured or estimated.
    latest : tuple or None
        ``(q, qd)`` as one object (read by the loop thread of timer mode).
    stamp : int or None
        Its stamp, ns.
    received : int or None
        Steady-clock ns at which it came.
    """

    def __init__(self, node, joint_names, lockstep, h, velocity_cutoff, guards, watchdog,
                 outputs, warn, is_running, steps, restarted, control):
        self.node = node
        self.lockstep, self.h, self.velocity_cutoff = lockstep, h, velocity_cutoff
        self.gate, self.watchdog, self.outputs, self.warn = guards.gate, watchdog, outputs, warn
        self.is_running, self.steps = is_running, steps
        self.restarted, self.control = restarted, control
        self._reader = JointStateReader(joint_names)
        self._rate_warned = False
        cap = guards.max_state_bytes
        if not lockstep:                    # states in their own thread: the loop only ticks
            self._side = SideInput(node, JointState, topics.JOINT_STATES, QOS, self._on_state,
                                   cap, "state", self.warn)
            self._sub = None
        else:                               # lockstep: the answer is the state's callback
            self._side = None
            self._sub = node.create_subscription(
                JointState, topics.JOINT_STATES,
                capped(JointState, cap, "state", self._on_state, self.warn), QOS, raw=True)
        self.reset()

    def reset(self):
        """A fresh start: no state yet, a new velocity estimate, the stamp gate reset."""
        self.velocity = VelocityEstimate(self.velocity_cutoff)
        self.q = self.qd = None
        self.latest = None
        self.stamp = None
        self.received = None
        self.gate.reset()

    def close(self):
        """Stop the side thread or destroy the subscription (cleanup)."""
        if self._side is not None:
            self._side.close()
        else:
            self.node.destroy_subscription(self._sub)

    def _restart(self, stamp):
        """The stream restarted (a simulator or driver restart): start over from it."""
        self.node.get_logger().warning(
            f"joint state stamps restarted ({self.stamp * 1e-9:.6f} s -> "
            f"{stamp * 1e-9:.6f} s): filters, velocity estimate and desired motion restart "
            "from the new state; the estimates are kept")
        self.velocity.reset()
        self.restarted()

    def _warn_rate(self, stamp):
        """Lockstep: once, if the state period is not the control period ``h``."""
        h = self.h
        gap = (stamp - self.stamp) * 1e-9
        if abs(gap - h) > 0.01 * h:
            self._rate_warned = True
            self.node.get_logger().warning(
                f"state period {gap * 1e3:.3f} ms differs from h = {h * 1e3:.3f} ms "
                "(set 'rate' to 1/dt of the simulator)")

    def _on_state(self, msg):
        if not self.is_running():
            return
        try:
            q, qd = self._reader.read(msg)
        except StateRejected as err:
            return self.warn(err.kind, str(err))
        stamp = stamp_ns(msg.header.stamp)
        now = time.monotonic_ns()           # state silence: on the steady clock, always
        lockstep = self.lockstep
        if lockstep and self.outputs.last_answer is not None \
                and stamp == self.stamp and np.array_equal(q, self.q):
            # the same state again (a simulator re-sending after a lost message at start-up):
            # answer it again, do not step twice
            self.outputs.answer_again()
            self.received = now
            return
        verdict = self.gate.check(stamp, now, stale=self.watchdog.tripped)
        if verdict in (StampGate.BACKWARDS, StampGate.FUTURE):
            return self.warn(verdict, f"JointState: stamp {stamp * 1e-9:.6f} s "
                             f"after {self.stamp * 1e-9:.6f} s")
        if verdict == StampGate.RESTART and self.stamp is not None:
            self._restart(stamp)
        # velocity: given, or estimated from positions (finite difference, low-pass)
        if qd is None:
            qd = self.velocity.update(q, stamp if stamp > 0 else now)
        else:
            self.velocity.reset()
        if lockstep and verdict == StampGate.OK and self.stamp is not None and stamp > 0 \
                and not self._rate_warned:
            self._warn_rate(stamp)
        # lockstep: the state right after the last one answered means no step was lost (the
        # watchdog's tagged safe effort is not applied by a lockstep simulator): keep the filters
        unbroken = lockstep and self.stamp is not None \
            and 0 < stamp - self.stamp <= 1.5 * self.h * 1e9
        self.latest = (q, qd)
        self.q, self.qd = q, qd
        self.stamp = stamp
        self.received = now
        self.watchdog.valid_state(unbroken)
        if lockstep:
            t_ns = stamp if stamp > 0 else self.steps() * round(self.h * 1e9)
            self.control(t_ns, msg.header.stamp)
