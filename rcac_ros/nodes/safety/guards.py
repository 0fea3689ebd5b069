"""Guards between the wires and the controller: what a node accepts, and what it commands.

Pure Python and numpy (numba for the per-step limiter), no rclpy, so that each rule is
unit-tested on its own (doc/failsafe.md). The guards of the state stream in time (its stamps, its
silences) are in :mod:`rcac_ros.nodes.safety.state_guards`.

* :func:`oversize`: the size cap checked on the serialised bytes, before deserialising.
* :func:`check_end`: a trajectory that ends in the past is refused, as
  joint_trajectory_controller does (the one implementation of that rule, for the topic
  through :func:`check_goal` and for the FollowJointTrajectory server).
* :func:`check_goal`: a trajectory that ends in the past, or leaves the model's position
  or velocity limits (URDF ``<limit>``), is refused with a reason.
* :class:`DesiredLimiter`: the desired state moves by at most a given step per control
  period, so no goal produces a jump in effort.
"""

from rcac_ros.core._jit import njit
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

    def warm(self):
        """Compile (or load) the per-step kernel now, leaving this limiter's state as it is."""
        z = np.zeros(self.dq.shape[0])
        _limit_step(z, z, self.dq, np.empty_like(z))

    def __call__(self, q_d, qd_d, qdd_d):
        """The desired ``(q_d, qd_d, qdd_d)`` moved at most one step from the previous."""
        if self._prev is None:
            self._prev = True
            self._q[:] = q_d
            self._qd[:] = qd_d
            return q_d, qd_d, qdd_d
        q = np.empty_like(self._q)
        qd = np.empty_like(self._qd)
        c1 = _limit_step(self._q, np.ascontiguousarray(q_d, float), self.dq, q)
        c2 = _limit_step(self._qd, np.clip(qd_d, -self.vmax, self.vmax), self.dqd, qd)
        c2 |= bool(np.any(np.abs(qd_d) > self.vmax))
        self._q[:] = q
        self._qd[:] = qd
        if c1 or c2:
            self.limited += 1
            qdd_d = np.clip(qdd_d, -self.amax, self.amax)
        return q, qd, qdd_d
