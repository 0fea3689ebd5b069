"""The controller's state input: ``/joint_states`` in, the latest valid ``(q, qd)`` out.

:class:`StateInput` takes the states in its own thread
(:class:`~rcac_ros.nodes.runtime.inputs.SideInput`) with the size cap checked on the serialised
bytes (doc/failsafe.md), reads each message into model order
(:class:`~rcac_ros.nodes.msgs.joint_state.JointStateReader`; from its bytes when its frame and
names repeat the last valid state's), judges its stamp
(:class:`~rcac_ros.nodes.safety.state_guards.StampGate`: a restart of the stream is followed, a
stamp in the future refused), estimates the velocity when none is given and tells the watchdog
that a valid state came. In lockstep mode the control step is the answer to the state, run in
that thread as soon as the state is read.

Threads (timer mode: the states come in the side thread, the control loop runs in its own):

* The side thread owns the reading: the stamp gate, the velocity estimate and the previous
  state. It hands over each valid state as one immutable :class:`Sample` (``q``, ``qd``,
  ``stamp``, ``received``, the count of stream restarts), assigned in one statement (atomic
  under the interpreter lock): the control thread never sees a ``q`` of one state with the
  arrival time of another, and takes no lock on its 500 Hz path.
* The control thread, in :meth:`StateInput.take` at the start of its step, tells the
  watchdog of the valid state and restarts motion and filters after a restart of the
  stream; the side thread never writes to the watchdog or the node.
* A lock is held by the side thread while it reads a state and by :meth:`StateInput.reset`
  (the activation), never by the control step: a reset waits for a state being read (none
  from before it survives it, the gate is never reset halfway through a check).

In lockstep mode the side thread reads the message, then judges the state and answers it holding
the node's lock (:class:`~rcac_ros.nodes.runtime.serial.SerialCallbacks`), which every callback
of the node's executor and the watchdog's thread also hold: no answer runs beside an activation,
a parameter change, a trajectory's hand-over or a watchdog check. The executor is out of the
answer's path (doc/failsafe.md, "Known limitations").
"""

import threading
import time
from collections import namedtuple

import numpy as np
from sensor_msgs.msg import JointState

from rcac_ros import topics
from rcac_ros.nodes.runtime.base import QOS
from rcac_ros.nodes.runtime.inputs import SideInput
from rcac_ros.nodes.runtime.serial import acquire
from rcac_ros.nodes.runtime.stats import PeriodHistogram
from rcac_ros.nodes.msgs.joint_state import (JointStateReader, stamp_ns, StateRejected,
                                             VelocityEstimate)
from rcac_ros.nodes.safety.state_guards import StampGate

#: a valid state as handed over: q, qd (model order), its stamp (ns), the steady ns it came at,
#: the stream restarts so far, and (lockstep) whether it follows the last answered by a period
Sample = namedtuple("Sample", "q qd stamp received restarts unbroken")


class StateInput:
    """``/joint_states`` of a controller: what it reads and what it calls, nothing more.

    Parameters
    ----------
    node : rclpy.node.Node
        Where the subscription lives (rclpy's API only).
    joint_names : sequence of str
        The model's joints.
    lockstep : bool
        Each valid state is answered as it is read (else timer mode: the loop takes the latest).
    h : float
        The control period, s.
    velocity_cutoff : float
        Of the velocity estimate (:class:`~rcac_ros.nodes.msgs.joint_state.VelocityEstimate`).
    gate : StampGate
        The stamps (:class:`~rcac_ros.nodes.safety.state_guards.StampGate`).
    max_bytes : int
        The size cap of a serialised state (``max_state_bytes``; 0: none).
    watchdog : Watchdog
        Told of each valid state; its ``tripped`` lets the gate take a restart at once.
    outputs : ControllerOutputs
        Lockstep: the last answer, sent again for a repeated state.
    log : rclpy logger
        A restart of the stream, a state period that is not ``h``.
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
    serial : threading.RLock, optional
        Lockstep: the node's lock, held to judge and answer a state (not while reading it).

    Attributes
    ----------
    latest : Sample or None
        The latest valid state as one object (set by the side thread of timer mode).
    arrivals : PeriodHistogram
        The periods of the valid states as DDS received them (diagnostics).
    q, qd : ndarray (n,) or None
        Its positions and velocities (model order); ``qd`` measured or estimated.
    stamp : int or None
        Its stamp, ns.
    received : int or None
        Steady-clock ns at which it came.
    """

    def __init__(self, node, *, joint_names, lockstep, h, velocity_cutoff, gate, max_bytes,
                 watchdog, outputs, log, warn, is_running, steps, restarted, control,
                 serial=None):
        self.node = node
        self.lockstep, self.h, self.velocity_cutoff = lockstep, h, velocity_cutoff
        self.gate, self.watchdog, self.outputs = gate, watchdog, outputs
        self.log, self.warn = log, warn
        self.is_running, self.steps = is_running, steps
        self.restarted, self.control = restarted, control
        self._reader = JointStateReader(joint_names)
        self._rate_warned = False
        self._lock = threading.Lock()       # the side thread's reading against reset()
        self._serial, self._closing, self._resets = serial, False, 0
        self._parked = None                 # lockstep: (stamp, q, qd, steady ns) while inactive
        self.arrivals = PeriodHistogram()
        self._side = SideInput(node, JointState, topics.JOINT_STATES, QOS,
                               self._on_state if serial is None else self._on_state_serial,
                               max_bytes, "state", self.warn, prefault=True, fast=self._on_known)
        self.reset()

    def reset(self):
        """A fresh start: no state yet, a new velocity estimate, the stamp gate reset (after
        a state being read, if any)."""
        with self._lock:
            self._resets += 1
            self.velocity = VelocityEstimate(self.velocity_cutoff)
            self.latest = None
            self._restarts = self._taken_restarts = 0
            self._taken = None
            self.gate.reset()

    @property
    def errors(self):
        """Failed takes, buffer allocations and callback exceptions of the side thread, by
        kind."""
        return self._side.errors

    # the latest valid state, each field read from one load of ``latest`` (None: none yet)
    q, qd, stamp, received = (property(lambda self, f=f: getattr(self.latest, f, None))
                              for f in ("q", "qd", "stamp", "received"))

    def take(self):
        """The control thread, before a step: the latest valid state (a :class:`Sample`).

        The watchdog is told of a state not taken before, and a restart of the stream since
        the last step restarts the motion and the filters (``restarted``), here in the
        control thread.
        """
        sample = self.latest
        if sample.restarts != self._taken_restarts:
            self._taken_restarts = sample.restarts
            self.restarted()
        if sample is not self._taken:
            self.watchdog.valid_state(sample.unbroken)  # first: see _stale
            self._taken = sample
        return sample

    @property
    def thread(self):
        """The native id of the side thread (lockstep: the thread of the answers)."""
        return self._side.native_id

    def close(self):
        """Stop the side thread (cleanup; a state waiting for the node's lock is dropped)."""
        self._closing = True
        self._side.close()

    def _restart(self, stamp):
        """The stream restarted (a simulator or driver restart): start over from it (the
        motion and the filters at the next :meth:`take`)."""
        self.log.warning(
            f"joint state stamps restarted ({self.stamp * 1e-9:.6f} s -> "
            f"{stamp * 1e-9:.6f} s): filters, velocity estimate and desired motion restart "
            "from the new state; the estimates are kept")
        self.velocity.reset()
        self._restarts += 1

    def _warn_rate(self, stamp):
        """Lockstep: once, if the state period is not the control period ``h``."""
        h, gap = self.h, (stamp - self.stamp) * 1e-9
        if abs(gap - h) > 0.01 * h:
            self._rate_warned = True
            self.log.warning(f"state period {gap * 1e3:.3f} ms differs from h = "
                             f"{h * 1e3:.3f} ms (set 'rate' to 1/dt of the simulator)")

    def _on_known(self, data):
        """A state read from its bytes (``JointStateReader.read_known``); False: it is
        deserialised and read in full (:meth:`_on_state_serial`, :meth:`_on_state`)."""
        running, resets = self.is_running(), self._resets
        if self._serial is None and not running:
            return True                     # timer mode, inactive: dropped (as _on_state)
        read = self._reader.read_known(data)
        if read is not None and self._serial is None:
            self._answer(*read)
        elif read is not None:
            self._answer_serial(running, resets, *read)
        return read is not None

    def _on_state_serial(self, msg, data=None):
        """Lockstep: read the state, then judge and answer it holding the node's lock. A
        state read while active is not answered after a reset (a deactivation and the
        activation that follows); one that comes while inactive is kept, the latest only,
        for :meth:`answer_parked` at the activation (a simulator started as the controller
        is configured sends its first state before the controller is active)."""
        running, resets = self.is_running(), self._resets
        try:
            q, qd = self._reader.read(msg, data)
        except StateRejected as err:
            return self.warn(err.kind, str(err))
        self._answer_serial(running, resets, msg.header.stamp, q, qd)

    def _answer_serial(self, running, resets, stamp, q, qd):
        if acquire(self._serial, lambda: self._closing):
            try:
                if not self.is_running():
                    self._parked = (stamp, q, qd, time.monotonic_ns())
                elif self._resets == resets or not running:
                    self._answer(stamp, q, qd)
            finally:
                self._serial.release()

    def answer_parked(self):
        """Lockstep, at the activation (holding the node's lock): answer the latest state that
        came while inactive, if it came within the watchdog's ``state_timeout``."""
        parked, self._parked = self._parked, None
        if parked is not None \
                and time.monotonic_ns() - parked[3] <= self.watchdog.state_timeout * 1e9:
            self._answer(*parked[:3])

    def _on_state(self, msg, data=None):
        if not self.is_running():
            return
        try:
            q, qd = self._reader.read(msg, data)
        except StateRejected as err:
            return self.warn(err.kind, str(err))
        self._answer(msg.header.stamp, q, qd)

    def _answer(self, header_stamp, q, qd):
        with self._lock:
            answer = self._hand_over(header_stamp, q, qd)
        if answer is not None:              # lockstep: the step, out of the lock
            self.control(*answer)

    def _stale(self, last):
        """The watchdog has tripped and no state is waiting for the control thread: a
        backward stamp is then a restart (the stamp gate). The watchdog hears of a state
        only when the control thread takes it, up to a period later; in between, a second
        state going back in time is not a restart but a stale message (refused). ``take``
        tells the watchdog before it marks the state taken, so no order of the two threads
        reads a taken state beside a watchdog not yet told."""
        return self.watchdog.tripped and (last is None or last is self._taken)

    def _hand_over(self, header_stamp, q, qd):
        """Judge a read state (its header's stamp, ``sec`` and ``nanosec``) and hand it over
        (under the lock); lockstep: returns the arguments of ``control``, or ``None``."""
        stamp = stamp_ns(header_stamp)
        now = time.monotonic_ns()           # state silence: on the steady clock, always
        lockstep = self.lockstep
        last = self.latest
        if lockstep and self.outputs.last_answer is not None and last is not None \
                and stamp == last.stamp and np.array_equal(q, last.q):
            # the same state again (a simulator re-sending after a lost message at start-up):
            # answer it again, do not step twice
            self.outputs.answer_again()
            self.latest = last._replace(received=now)
            self._taken = self.latest
            return None
        verdict = self.gate.check(stamp, now, stale=self._stale(last))
        if verdict in (StampGate.BACKWARDS, StampGate.FUTURE):
            self.warn(verdict, f"JointState: stamp {stamp * 1e-9:.6f} s "
                      f"after {self.stamp * 1e-9:.6f} s")
            return None
        if verdict == StampGate.RESTART and last is not None:
            self._restart(stamp)
        # velocity: given, or estimated from positions (finite difference, low-pass)
        if qd is None:
            qd = self.velocity.update(q, stamp if stamp > 0 else now)
        else:
            self.velocity.reset()
        if lockstep and verdict == StampGate.OK and last is not None and stamp > 0 \
                and not self._rate_warned:
            self._warn_rate(stamp)
        # lockstep: the state right after the last one answered means no step was lost (the
        # watchdog's tagged safe effort is not applied by a lockstep simulator): keep the filters
        unbroken = lockstep and last is not None \
            and 0 < stamp - last.stamp <= 1.5 * self.h * 1e9
        self.latest = Sample(q, qd, stamp, now, self._restarts, unbroken)  # the hand-over
        self.arrivals.add(self._side.received_ns)
        if lockstep:
            t_ns = stamp if stamp > 0 else self.steps() * round(self.h * 1e9)
            return t_ns, header_stamp
        return None
