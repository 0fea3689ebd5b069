"""Guards between the wires and the controller: what a node accepts, and what it commands.

Pure Python and numpy (numba for the per-step limiter), no rclpy, so that each rule is
unit-tested on its own (issue 9):

* :class:`StampGate`: JointState stamps must move forward at about the pace of the steady
  clock. A stamp far in the future is refused and does not become the reference; a
  restart (stamps start again at 0) is accepted once the watchdog has tripped, or after
  ``restart_count`` consecutive consistent messages.
* :func:`oversize`: the size cap checked on the serialised bytes, before deserialising.
* :func:`check_end`: a trajectory that ends in the past is refused, as
  joint_trajectory_controller does (the one implementation of that rule, for the topic
  through :func:`check_goal` and for the FollowJointTrajectory server).
* :func:`check_goal`: a trajectory that ends in the past, or leaves the model's position
  or velocity limits (URDF ``<limit>``), is refused with a reason.
* :class:`DesiredLimiter`: the desired state moves by at most a given step per control
  period, so no goal produces a jump in effort.
* :class:`SafeStop`: the spells of safe effort (the watchdog), counted once each, and how
  control resumes after one: a long one restarts the motion from the measured state.
"""

from numba import njit
import numpy as np

from rcac_ros.errors import InputError

#: default size caps of the serialised messages, bytes. A 7-joint JointState is ~300 B;
#: 64 KiB still holds ~1000 named joints. 1 MiB holds ~6000 points of a 7-joint trajectory
#: with positions, velocities and accelerations.
MAX_STATE_BYTES = 65_536
MAX_TRAJECTORY_BYTES = 1_048_576


class Rejected(InputError):
    """An input refused by a guard; ``kind`` names the rule (for throttled warnings)."""

    def __init__(self, kind, text):
        super().__init__(text)
        self.kind = kind


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

    Parameters
    ----------
    replan_after : float
        Seconds of safe effort from which the motion restarts from the measured state.
    """

    def __init__(self, replan_after=0.5):
        self.replan_after_ns = round(replan_after * 1e9)
        self.spells = 0             # spells started
        self.replans = 0            # spells ended with the motion restarted
        self.since = None           # steady ns of the first safe effort of this spell

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

    def resume(self, now):
        """A control step at steady time ``now`` (ns).

        Returns
        -------
        tuple or None
            ``None`` when no spell was on; else ``(seconds of safe effort, replan)``,
            ``replan`` telling that the motion must restart from the measured state.
        """
        if self.since is None:
            return None
        held = now - self.since
        self.since = None
        replan = held >= self.replan_after_ns
        self.replans += replan
        return held * 1e-9, replan


# ------------------------------------------------------------------ sizes
def oversize(nbytes, cap, what):
    """Raise :class:`Rejected` (kind ``size``) if ``nbytes`` is above ``cap`` (0: no cap)."""
    if cap and nbytes > cap:
        raise Rejected("size", f"{what}: {nbytes} bytes, above the cap of {cap} "
                       f"(parameter max_{what.lower()}_bytes)")


# ------------------------------------------------------------------ goals
def check_end(start_ns, times, now_ns):
    """Refuse a parsed trajectory whose last point is before now (JTC refuses it too).

    Parameters
    ----------
    start_ns : int or None
        Start time of the trajectory (``None``: now, never in the past).
    times : ndarray (m,)
        ``time_from_start`` of each point, s.
    now_ns : int
        Now, on the same time base as ``start_ns``.

    Raises
    ------
    Rejected
        ``past``, with how long ago the trajectory ended.
    """
    if start_ns is not None:
        end_ns = start_ns + round(float(times[-1]) * 1e9)
        if end_ns < now_ns:
            raise Rejected("past", f"trajectory ends {(now_ns - end_ns) * 1e-9:.3f} s in the "
                           "past (header.stamp + last time_from_start < now)")


def check_goal(start_ns, times, pos, vel, now_ns, lower, upper, vmax):
    """Refuse a parsed trajectory that cannot be followed safely.

    Parameters
    ----------
    start_ns : int or None
        Start time of the trajectory (``None``: now), on the controller's time base.
    times : ndarray (m,)
        ``time_from_start`` of each point, s.
    pos, vel : ndarray (m, n)
        Positions and velocities (``vel`` may be ``None``), model order.
    now_ns : int or None
        The controller's time now; ``None``: the end is not checked here (the
        FollowJointTrajectory server checks it, :func:`check_end`, for any sink).
    lower, upper, vmax : ndarray (n,)
        The model's position and velocity limits (infinite: no limit).

    Raises
    ------
    Rejected
        ``past`` (:func:`check_end`); ``position limit`` or ``velocity limit``: a point
        leaves the model's limits.
    """
    if now_ns is not None:
        check_end(start_ns, times, now_ns)
    _within("position limit", "positions", pos, lower, upper)
    if vel is not None:
        _within("velocity limit", "velocities", vel, -vmax, vmax)


def _within(kind, field, values, lo, hi):
    bad = np.argwhere((values < lo) | (values > hi))
    if bad.size:
        k, j = bad[0]
        raise Rejected(kind, f"points[{k}].{field}[{j}] = {values[k, j]:.6g} outside "
                       f"[{lo[j]:.6g}, {hi[j]:.6g}] (the model's limits)")


# ------------------------------------------------------------------ desired state
@njit(cache=True)
def _limit_step(prev, value, step, out):
    """``out = prev + clip(value - prev, -step, step)``; returns whether it clipped."""
    clipped = False
    for i in range(value.shape[0]):
        d = value[i] - prev[i]
        if d > step[i]:
            d = step[i]
            clipped = True
        elif d < -step[i]:
            d = -step[i]
            clipped = True
        out[i] = prev[i] + d
    return clipped


class DesiredLimiter:
    """Bound how far the desired state moves in one control period.

    Parameters
    ----------
    max_position_step : float or array_like (n,)
        rad per step (inf: no limit); the desired velocity is bounded by
        ``max_position_step / h`` too.
    max_velocity_step : float or array_like (n,)
        rad/s per step; the desired acceleration is bounded by ``max_velocity_step / h``.
    h : float
        The control period, s.
    n : int
        Number of joints.
    """

    def __init__(self, max_position_step, max_velocity_step, h, n):
        self.dq = np.broadcast_to(np.asarray(max_position_step, float), (n,)).copy()
        self.dqd = np.broadcast_to(np.asarray(max_velocity_step, float), (n,)).copy()
        self.amax = self.dqd / h
        self.vmax = self.dq / h     # the position moves at most dq per step
        self.limited = 0            # steps at which a limit acted
        self._q = np.empty(n)
        self._qd = np.empty(n)
        self._prev = None

    def reset(self):
        """Forget the previous desired state: the next one is taken as it is."""
        self._prev = None

    def __call__(self, q_d, qd_d, qdd_d):
        """The desired ``(q_d, qd_d, qdd_d)`` moved at most one step from the previous."""
        if self._prev is None:
            self._prev = True
            self._q[:] = q_d
            self._qd[:] = qd_d
            return q_d, qd_d, qdd_d
        q = np.empty_like(self._q)
        qd = np.empty_like(self._qd)
        c1 = _limit_step(self._q, np.asarray(q_d, float), self.dq, q)
        c2 = _limit_step(self._qd, np.clip(qd_d, -self.vmax, self.vmax), self.dqd, qd)
        c2 |= bool(np.any(np.abs(qd_d) > self.vmax))
        self._q[:] = q
        self._qd[:] = qd
        if c1 or c2:
            self.limited += 1
            qdd_d = np.clip(qdd_d, -self.amax, self.amax)
        return q, qd, qdd_d
