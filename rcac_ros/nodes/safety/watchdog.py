"""The controller's watchdog: the safe effort while it is blind, and how control resumes.

Measured on the steady clock, always (doc/failsafe.md): :class:`Watchdog` sends the node's
``safe_effort`` while no valid state has arrived for ``state_timeout`` s and, in timer mode
on ``/clock``, also while no tick comes (a frozen or absent clock). In lockstep mode and on
``/clock`` a steady timer calls :meth:`Watchdog.check`; on the deadline loop of timer mode
each tick checks the state's age itself.

A spell of safe effort (:class:`~rcac_ros.nodes.safety.state_guards.SafeStop`) is one trip and one
log line. It ends at the next control step (:meth:`Watchdog.resume`), where the filters of
eqs 21-24 restart; after ``watchdog.replan_after`` s of it the motion restarts from the
measured state. In lockstep mode a state that follows the last one answered ends the spell
at once: the simulator waited, the safe effort never acted.
"""

import time

from rclpy.clock import Clock, ClockType


class Watchdog:
    """The watchdog of a controller ``node``.

    Parameters
    ----------
    node : ControllerNode
        Configured: its ``failsafe.stop`` (the spells), ``state_timeout``, ``safe_effort``,
        ``mode``, ``_outputs`` and its state input ``states`` (the time of the latest valid
        state, ``states.received``) are read.

    Attributes
    ----------
    tripped : bool
        No valid state for ``state_timeout`` s (or none yet): the stamp gate then takes a
        backward jump as a restart at once.
    trips : int
        Spells of safe effort after a valid state (diagnostics ``watchdog_trips``).
    """

    def __init__(self, node):
        self.node = node
        self.stop = node.failsafe.stop
        self.trips = 0
        self.reset()

    def reset(self):
        """A fresh start: no valid state yet, no tick, no spell."""
        self.tripped = True
        self.tick_ns = None         # steady ns of the latest tick (timer mode)
        self.stop.cancel()

    def timer(self):
        """The steady timer that calls :meth:`check` (lockstep, or timer mode on /clock)."""
        node = self.node
        return node.create_timer(min(node.state_timeout / 2.0, 0.01), self.check,
                                 clock=Clock(clock_type=ClockType.STEADY_TIME))

    # ------------------------------------------------------------------ staleness
    def _older(self, ns):
        return ns is None or time.monotonic_ns() - ns > self.node.state_timeout * 1e9

    def state_is_stale(self):
        """No valid state for ``state_timeout`` s of the steady clock (or none yet)."""
        return self._older(self.node.states.received)

    def tick_is_stale(self):
        """Timer mode on /clock: no tick for ``state_timeout`` (a frozen or absent /clock)."""
        return self._older(self.tick_ns)

    def ticked(self):
        """A tick of timer mode came now."""
        self.tick_ns = time.monotonic_ns()

    def check(self):
        """Steady clock: the safe effort while no valid state (lockstep) or no tick (/clock)."""
        node = self.node
        if not node.running:
            return
        stale = self.state_is_stale()
        if stale if node.mode == "lockstep" else self.tick_is_stale():
            self.send_safe(no_state=stale)

    # ------------------------------------------------------------------ spells
    def send_safe(self, no_state):
        """The safe effort: no valid state (``no_state``), or no tick of /clock."""
        node = self.node
        heard = node.states.received is not None
        if no_state and heard:
            self.tripped = True             # (the stamp gate then takes a restart at once)
        if self.stop.trip(time.monotonic_ns()) and heard:
            self.trips += 1                 # once per spell (state_guards.SafeStop)
            node.get_logger().warning(
                f"watchdog: {'no valid state' if no_state else 'no tick of /clock'} for "
                f"{node.state_timeout * 1e3:g} ms, publishing the safe effort")
        node._outputs.effort(node.safe_effort, watchdog=True)

    def valid_state(self, unbroken):
        """A valid state came (after :attr:`tripped`: control goes on).

        ``unbroken``: in lockstep mode, the state right after the last one answered: no step
        was lost (a lockstep simulator does not apply the watchdog's tagged safe effort), so
        the filters are kept and the spell is forgotten.
        """
        if not self.tripped:
            return
        node = self.node
        self.tripped = False
        if node._steps:
            node.filters_stale |= not unbroken  # a gap broke the filters of eqs 21-24
        if unbroken:                        # the lockstep simulator waited: nothing to resume
            self.stop.cancel()
            node.get_logger().info("watchdog: valid state again, control resumed")

    def resume(self):
        """At each control step: end the spell of safe effort, if one is on."""
        resumed = self.stop.resume(time.monotonic_ns())
        node = self.node
        if resumed is None or not node._steps:
            return
        held, replan = resumed
        node.filters_stale = True           # the filters of eqs 21-24 missed the spell
        if replan:                          # the arm drifted: go on from where it is
            node.restart_motion()
            if node._fjt is not None:
                node._fjt.abort(f"the controller sent the safe effort for {held:.3f} s")
        node.get_logger().info(f"watchdog: control resumed after {held:.3f} s of safe effort"
                               + ("; the motion restarts from the measured state" if replan
                                  else ""))
