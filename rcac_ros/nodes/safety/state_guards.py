"""Guards of the JointState stream in time: its stamps and its silences (doc/failsafe.md).

Pure Python, no rclpy, so that each rule is unit-tested on its own (the guards of what a
node accepts and commands are in :mod:`rcac_ros.nodes.safety.guards`):

* :class:`StampGate`: JointState stamps must move forward at about the pace of the steady
  clock. A stamp far in the future is refused and does not become the reference; a
  restart (stamps start again at 0) is accepted once the watchdog has tripped, or after
  ``restart_count`` consecutive consistent messages.
* :class:`SafeStop`: the spells of safe effort (the watchdog), counted once each, and how
  control resumes after one: a long one restarts the motion from the measured state.
"""


# ------------------------------------------------------------------ stamps
class StampGate:
    """Accept or refuse JointState stamps without ever locking out.

    A stamp is *consistent* with a reference (stamp ``s0`` received at steady time
    ``r0``) when ``s0 <= stamp <= s0 + (now - r0) + max_jump``: it does not go back, and
    it is not further ahead than the steady time elapsed, plus a margin (a lockstep
    simulator may run faster than real time, one step at a time).

    Parameters
    ----------
    max_jump : float
        Seconds a stamp may run ahead of the steady clock since the last accepted one.
    restart_count : int
        Consecutive mutually consistent messages, inconsistent with the reference, after
        which the reference is replaced (a restart, or a clock jump), even while the
        watchdog has not tripped.
    """

    #: verdicts (the refusals double as the kinds of the throttled warnings)
    OK, RESTART, BACKWARDS, FUTURE = "ok", "restart", "stamp", "stamp future"

    def __init__(self, max_jump=1.0, restart_count=10):
        self.max_jump_ns = round(max_jump * 1e9)
        self.restart_count = int(restart_count)
        self.restarts = 0
        self.reset()

    def reset(self):
        """Forget the reference: the next stamp is accepted as is."""
        self.last = None            # stamp ns of the last accepted message
        self._rx = None             # steady ns when it was received
        self._run = None            # (stamp, rx) of the last candidate message
        self._run_length = 0

    def _consistent(self, ref, rx, stamp, now):
        return ref <= stamp <= ref + max(now - rx, 0) + self.max_jump_ns

    def check(self, stamp, now, stale=False):
        """Judge one stamp (ns) received at steady time ``now`` (ns).

        ``stale`` tells that the watchdog has tripped (no valid state for a while): a
        backward jump is then a restart, accepted at once.

        Returns
        -------
        str
            :attr:`OK` (accepted), :attr:`RESTART` (accepted as a new reference: the
            caller restarts its filters), :attr:`BACKWARDS` or :attr:`FUTURE` (refused).
        """
        if self.last is None:
            return self._accept(stamp, now, self.OK)
        if self._consistent(self.last, self._rx, stamp, now):
            self._run, self._run_length = None, 0
            return self._accept(stamp, now, self.OK)
        if stale and stamp < self.last:
            return self._restart(stamp, now)
        if self._run is not None and stamp > self._run[0] \
                and self._consistent(self._run[0], self._run[1], stamp, now):
            self._run_length += 1
        else:
            self._run_length = 1
        self._run = (stamp, now)
        if self._run_length >= self.restart_count:
            return self._restart(stamp, now)
        return self.BACKWARDS if stamp < self.last else self.FUTURE

    def _accept(self, stamp, now, verdict):
        self.last, self._rx = stamp, now
        return verdict

    def _restart(self, stamp, now):
        self.restarts += 1
        self._run, self._run_length = None, 0
        return self._accept(stamp, now, self.RESTART)


# ------------------------------------------------------------------ safe stops
class SafeStop:
    """The spells of safe effort, and how control resumes after each.

    A spell starts at the first safe effort the watchdog sends (no valid state, or no tick
    of a frozen ``/clock``) and ends at the next control step. While the safe effort is
    applied the arm is not controlled: it coasts (or falls). After a short spell the
    desired motion goes on; after one of ``replan_after`` s or more it cannot be
    followed on time any more (a time-indexed motion would ask for the whole distance
    lost at once, far outside the range the gains were tuned for), so the motion restarts
    from the measured state.

    A spell's length runs from the law's last effort (:meth:`controlled`), not from the
    first safe effort: a control loop that stalled (its process not scheduled) trips the
    watchdog only when it runs again, while the arm held the last effort all along. A
    stall of ``replan_after`` s or more that the watchdog did not see at all (the state
    came in time for the first step after it) is a spell of the same length when
    :meth:`resume` is told to look for one (:attr:`stalls`; timer mode: a lockstep
    simulator waits for the effort).

    Parameters
    ----------
    replan_after : float
        Seconds of safe effort from which the motion restarts from the measured state.
    """

    def __init__(self, replan_after=0.5):
        self.replan_after_ns = round(replan_after * 1e9)
        self.spells = 0             # spells started
        self.replans = 0            # spells ended with the motion restarted
        self.stalls = 0             # stalls of the loop without a safe effort
        self.since = None           # steady ns of the first safe effort of this spell
        self.effort_ns = None       # steady ns of the law's last effort

    @property
    def active(self):
        """Whether the safe effort is being sent (a spell has not ended)."""
        return self.since is not None

    def trip(self, now):
        """A safe effort goes out at steady time ``now`` (ns); ``True`` if a spell starts."""
        if self.since is not None:
            return False
        self.since = now
        self.spells += 1
        return True

    def cancel(self):
        """Forget the spell: the safe effort never acted (a lockstep simulator ignores it)."""
        self.since = None

    def restart(self):
        """A fresh start: no spell, no effort of the law yet."""
        self.since = self.effort_ns = None

    def controlled(self, now):
        """The law's effort of the step that began at steady time ``now`` (ns) went out."""
        self.effort_ns = now

    def resume(self, now, stalls=False):
        """A control step at steady time ``now`` (ns).

        ``stalls``: a step ``replan_after`` s or more after the law's last effort ends a
        spell even when no safe effort went out (a stall of the loop).

        Returns
        -------
        tuple or None
            ``None`` when no spell was on; else ``(seconds without the law's effort,
            replan)``, ``replan`` telling that the motion must restart from the measured
            state.
        """
        last = self.effort_ns
        if self.since is None:
            if not stalls or last is None or now - last < self.replan_after_ns:
                return None
            self.stalls += 1
            since = last
        else:
            since = self.since if last is None else min(self.since, last)
        held = now - since
        self.since = None
        replan = held >= self.replan_after_ns
        self.replans += replan
        return held * 1e-9, replan
