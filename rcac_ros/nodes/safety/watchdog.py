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
at once: the simulator waited, the safe effort never acted. In timer mode a control step
that comes ``watchdog.replan_after`` s or more after the law's last effort ends a spell of
that length even if no safe effort went out: the loop itself stalled (its process not
scheduled) while the arm held the last effort (``SafeStop.stalls``); a spell's length
always runs from the law's last effort.

Its clock across threads (doc/failsafe.md, "Watchdog clock"). The watchdog keeps two
times: ``tick_ns`` and the arrival of the latest valid state, which it does not store but
reads through ``state_received()``. In lockstep mode every method of :class:`Watchdog` runs
holding the node's lock (:mod:`rcac_ros.nodes.runtime.serial`): the answers in the state
input's thread, :meth:`check` in the watchdog's thread, the rest in the executor's
callbacks; one at a time, so nothing is read while it is written. In timer mode they run in
the thread that runs the control step: on ``/clock`` the executor's (the ticks and the
steady timer of :meth:`check` are its callbacks), on the deadline loop the node's main
thread, which serves the executor between its ticks. So ``tick_ns``, ``tripped``, ``trips``
and the spells are written and read by one thread. The only time written by another thread
is the arrival of a state in timer mode: the state
input's side thread stamps it (steady clock) into a new immutable
:class:`~rcac_ros.nodes.controller.state_input.Sample` together with the state, and hands it
over by one reference assignment; ``state_received()`` reads that reference once and the
``received`` field of the object it got (an ``int`` fixed at its construction). A reference
load or store is atomic under the interpreter lock, so a reader gets the previous sample or
the new one, each whole: no read can combine the time of one state with another, or see a
half-written integer, and no lock is needed on the 500 Hz path
(``test/ros/test_watchdog_clock.py`` hammers the hand-over). The side thread reads
``tripped`` (one load of a ``bool``); the order of the two threads around it is argued in
:meth:`~rcac_ros.nodes.controller.state_input.StateInput._stale`.
"""

import time


class Watchdog:
    """The watchdog of a controller: what it reads and what it calls, nothing more.

    Parameters
    ----------
    stop : SafeStop
        The spells of safe effort (:class:`~rcac_ros.nodes.safety.state_guards.SafeStop`).
    send_safe_effort : callable
        ``send_safe_effort()`` publishes the safe effort, tagged watchdog.
    state_received : callable
        ``state_received()``: steady-clock ns of the latest valid state, or ``None``.
    state_timeout : float
        s (the node sets :attr:`state_timeout` again when the parameter changes).
    lockstep : bool
        The controller answers each state (else timer mode, where the ticks are watched).
    log : rclpy logger
        One line a spell.
    stepped : callable
        ``stepped()``: the controller has stepped since its last (re)start.
    filters_missed : callable
        ``filters_missed()``: the filters of eqs 21-24 missed states; restart them.
    replan : callable
        ``replan(held)``: after ``held`` s of safe effort the motion restarts from the
        measured state.

    Attributes
    ----------
    tripped : bool
        No valid state for ``state_timeout`` s (or none yet): the stamp gate then takes a
        backward jump as a restart at once.
    trips : int
        Spells of safe effort after a valid state (diagnostics ``watchdog_trips``).
    """

    def __init__(self, *, stop, send_safe_effort, state_received, state_timeout, lockstep, log,
                 stepped, filters_missed, replan):
        self.stop = stop
        self.send_safe_effort = send_safe_effort
        self.state_received = state_received
        self.state_timeout = state_timeout
        self.lockstep = lockstep
        self.log = log
        self.stepped = stepped
        self.filters_missed = filters_missed
        self.replan = replan
        self.trips = 0
        self.reset()

    def reset(self):
        """A fresh start: no valid state yet, no tick, no spell."""
        self.tripped = True
        self.tick_ns = None         # steady ns of the latest tick (timer mode)
        self._step_ns = None        # steady ns of the current control step's start
        self.stop.restart()

    @property
    def check_period(self):
        """s between two :meth:`check` calls of the steady timer (lockstep: the watchdog's
        thread; timer mode on /clock)."""
        return min(self.state_timeout / 2.0, 0.01)

    # ------------------------------------------------------------------ staleness
    def _older(self, ns):
        return ns is None or time.monotonic_ns() - ns > self.state_timeout * 1e9

    def state_is_stale(self):
        """No valid state for ``state_timeout`` s of the steady clock (or none yet)."""
        return self._older(self.state_received())

    def tick_is_stale(self):
        """Timer mode on /clock: no tick for ``state_timeout`` (a frozen or absent /clock)."""
        return self._older(self.tick_ns)

    def ticked(self):
        """A tick of timer mode came now."""
        self.tick_ns = time.monotonic_ns()

    def check(self):
        """Steady clock (the node calls it while active): the safe effort while no valid
        state (lockstep) or no tick (/clock)."""
        stale = self.state_is_stale()
        if stale if self.lockstep else self.tick_is_stale():
            self.send_safe(no_state=stale)

    # ------------------------------------------------------------------ spells
    def send_safe(self, no_state):
        """The safe effort: no valid state (``no_state``), or no tick of /clock."""
        heard = self.state_received() is not None
        if no_state and heard:
            self.tripped = True             # (the stamp gate then takes a restart at once)
        if self.stop.trip(time.monotonic_ns()) and heard:
            self.trips += 1                 # once per spell (state_guards.SafeStop)
            self.log.warning(
                f"watchdog: {'no valid state' if no_state else 'no tick of /clock'} for "
                f"{self.state_timeout * 1e3:g} ms, publishing the safe effort")
        self.send_safe_effort()

    def valid_state(self, unbroken):
        """A valid state came (after :attr:`tripped`: control goes on).

        ``unbroken``: in lockstep mode, the state right after the last one answered: no step
        was lost (a lockstep simulator does not apply the watchdog's tagged safe effort), so
        the filters are kept and the spell is forgotten.
        """
        if not self.tripped:
            return
        self.tripped = False
        if self.stepped() and not unbroken:
            self.filters_missed()           # a gap broke the filters of eqs 21-24
        if unbroken:                        # the lockstep simulator waited: nothing to resume
            self.stop.cancel()
            self.log.info("watchdog: valid state again, control resumed")

    def resume(self):
        """At each control step: end the spell of safe effort, or of a stalled loop (timer
        mode), if one is on; ``True`` if one ended here."""
        self._step_ns = now = time.monotonic_ns()
        stalled = not self.stop.active       # no safe effort went out: only a stall ends here
        resumed = self.stop.resume(now, stalls=not self.lockstep)
        if resumed is None or not self.stepped():
            return resumed is not None
        held, replan = resumed
        self.filters_missed()               # the filters of eqs 21-24 missed the spell
        if replan:                          # the arm drifted: go on from where it is
            self.replan(held)
        what = "the control loop stalled (no effort sent) for" if stalled \
            else "control resumed after"
        self.log.info(f"watchdog: {what} {held:.3f} s without the law's effort"
                      + ("; the motion restarts from the measured state" if replan else ""))
        return True

    def controlled(self):
        """The law's effort of this control step went out."""
        self.stop.controlled(self._step_ns)
