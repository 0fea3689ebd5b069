"""Pacing of a node's main loop: a fixed-rate loop on absolute deadlines of the steady clock."""

import time

from rcac_ros.errors import ConfigError


class DeadlineLoop:
    """A fixed-rate loop on absolute deadlines of the steady clock, driving an executor.

    ``rclpy`` timers skip the ticks they miss instead of catching up, so a loaded machine
    loses rate (doc/nodes.md, "Timing"). Here the
    deadlines are ``start + k period``: :meth:`spin_once` serves the executor
    (``spin_once(timeout = deadline - now)``) until the next deadline has passed, then calls
    ``tick``, and the next deadline is one period later, so a late tick is followed by an early
    one and the average rate stays exact. More than ``resync`` periods behind, the missed
    deadlines are skipped (counted in :attr:`skipped`) instead of being run back to back.

    Parameters
    ----------
    period : float
        Seconds between ticks, > 0.
    tick : callable
        Called with no argument at each deadline.
    resync : int
        How many periods late a tick may be before the loop skips ahead (25: 50 ms at
        500 Hz, longer than the 20-30 ms stalls seen on the loaded 2-core VM, so those are
        caught up and the average rate holds; the catch-up ticks then run back to back).
    clock : callable
        Integer nanoseconds of a steady clock (tests pass their own).
    """

    def __init__(self, period, tick, resync=25, clock=time.monotonic_ns):
        if not period > 0.0:
            raise ConfigError(f"period: must be > 0 s, got {period}")
        self.period_ns = max(1, round(period * 1e9))
        self.tick = tick
        self.resync_ns = resync * self.period_ns
        self.clock = clock
        self.next_ns = None         # the next deadline; None: stopped
        self.ticks = 0
        self.skipped = 0            # deadlines dropped at a resynchronisation
        self.late = 0               # ticks started more than half a period after the deadline

    @property
    def running(self):
        """Whether the loop has been started (and not stopped)."""
        return self.next_ns is not None

    def start(self, delay=None):
        """Start ticking: the first deadline is ``delay`` s from now (default: one period)."""
        first = self.period_ns if delay is None else round(delay * 1e9)
        self.next_ns = self.clock() + first
        _fine_timer_slack()

    def stop(self):
        """Stop ticking (:meth:`spin_once` then only serves the executor)."""
        self.next_ns = None

    def due(self):
        """Run the tick if its deadline has passed; return the ns to the next deadline."""
        if self.next_ns is None:
            return None
        now = self.clock()
        wait = self.next_ns - now
        if wait > 0:
            return wait
        behind = -wait
        if behind > self.resync_ns:
            missed = behind // self.period_ns
            self.skipped += missed
            self.next_ns += missed * self.period_ns
            behind -= missed * self.period_ns
        if 2 * behind > self.period_ns:
            self.late += 1
        self.next_ns += self.period_ns
        self.ticks += 1
        self.tick()
        if self.next_ns is None:
            return None
        return self.next_ns - self.clock()

    def lock_phase(self, event_ns, offset_ns, gain=0.25):
        """Move the next deadline toward ``event_ns + offset_ns``, modulo the period.

        A first-order phase-locked loop: with ``e`` the phase error of the next deadline
        against the target, wrapped into ``[-period/2, period/2)``, the deadline moves by
        ``-gain e``, at most an eighth of a period per call, so the error decays as
        ``(1 - gain)^k`` over ``k`` calls and no period shrinks or grows by more than 12.5 %.
        Timer mode calls it at each tick with the steady time of the newest state: the
        ticks then come ``offset_ns`` after the states arrive, whatever the phase the two
        loops started with, and follow a driver whose clock drifts.

        Returns
        -------
        int
            The phase error before the move, ns (0 if stopped).
        """
        if self.next_ns is None:
            return 0
        half = self.period_ns // 2
        err = (self.next_ns - event_ns - offset_ns + half) % self.period_ns - half
        move = max(-self.period_ns // 8, min(self.period_ns // 8, round(gain * err)))
        self.next_ns -= move
        return err

    def spin_once(self, executor, idle=0.05):
        """Tick if due, else serve the executor until the next deadline (``idle`` s if stopped).

        One call handles at most one executor callback or one tick; call it in a loop.
        """
        wait = self.due()
        if wait is None:
            executor.spin_once(timeout_sec=idle)
        else:   # behind (wait <= 0): still serve one ready callback, without waiting
            executor.spin_once(timeout_sec=max(wait, 0) * 1e-9)


def wait_for_acks(publisher, seconds, step=0.1):
    """Whether every reliable reader of ``publisher`` acknowledged what it wrote within
    ``seconds``; waits in slices of ``step`` s, so that a signal is handled meanwhile."""
    from rclpy.duration import Duration
    end = time.monotonic() + seconds
    while not publisher.wait_for_all_acked(Duration(seconds=step)):
        if time.monotonic() > end:
            return False
    return True


def _fine_timer_slack():
    """Ask Linux for 1 ns of timer slack on this thread (default 50 us); best effort."""
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(29, 1, 0, 0, 0)     # PR_SET_TIMERSLACK
    except (OSError, AttributeError):
        pass


def spin_node_once(executor, node, idle=0.05):
    """One step of a node's main loop: its :class:`DeadlineLoop` if it has one."""
    loop = getattr(node, "loop", None)
    if loop is None:
        executor.spin_once(timeout_sec=idle)
    else:
        loop.spin_once(executor, idle)
