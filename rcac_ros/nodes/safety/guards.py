"""Guards between the wires and the controller: what a node accepts, and what it commands.

Pure Python and numpy (numba for the per-step limiter and clip), no rclpy, so that each rule is
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
* :class:`EffortClip`: the law's effort within its limits, in the command's joint order.

The two per-step guards are one compiled kernel each, declared with their signature and
compiled (or loaded from the cache) by their ``warm()``, which the node's warm-up and
``python -m rcac_ros.tools.warm`` call. Their clip is numpy's ``clip`` element by element
(a NaN passes through).
"""

import numpy as np

from rcac_ros.core._jit import kernel, njit, ready

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
@njit(cache=True, inline="always")
def _clip(x, lo, hi):
    """numpy's clip of one float: ``min(max(x, lo), hi)``, a NaN ``x`` kept."""
    if x != x:
        return x
    x = x if x > lo else lo
    return x if x < hi else hi


@njit(cache=True, inline="always")
def _within_step(d, step):
    """``(clip(d, -step, step), whether it moved d)``, a NaN ``d`` kept."""
    if d > step:
        return step, True
    if d < -step:
        return -step, True
    return d, False


#: (limits rows dq, dqd, vmax, amax; previous rows q, qd; q_d; qd_d; qdd_d; out rows q, qd, qdd)
LIMIT_SIGNATURE = "boolean(float64[:, ::1], float64[:, ::1], float64[::1], float64[::1], " \
    "float64[::1], float64[:, ::1])"


@kernel(LIMIT_SIGNATURE)
def _limit(limits, prev, q_d, qd_d, qdd_d, out):
    """One step of :class:`DesiredLimiter`: ``out`` the limited desired state, ``prev`` set to
    its position and velocity; returns whether a limit acted."""
    n = q_d.shape[0]
    clipped = False
    for i in range(n):
        d, hit = _within_step(q_d[i] - prev[0, i], limits[0, i])
        clipped |= hit
        out[0, i] = prev[0, i] + d
        vmax = limits[2, i]
        if abs(qd_d[i]) > vmax:
            clipped = True
        d, hit = _within_step(_clip(qd_d[i], -vmax, vmax) - prev[1, i], limits[1, i])
        clipped |= hit
        out[1, i] = prev[1, i] + d
    for i in range(n):
        prev[0, i] = out[0, i]
        prev[1, i] = out[1, i]
        out[2, i] = _clip(qdd_d[i], -limits[3, i], limits[3, i]) if clipped else qdd_d[i]
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
        self._limits = np.ascontiguousarray([self.dq, self.dqd, self.vmax, self.amax])
        self._prev = np.empty((2, n))
        self._started = False

    def reset(self):
        """Forget the previous desired state: the next one is taken as it is."""
        self._started = False

    def warm(self):
        """Compile (or load) the per-step kernel now, leaving this limiter's state as it is."""
        ready(_limit)

    def __call__(self, q_d, qd_d, qdd_d):
        """The desired ``(q_d, qd_d, qdd_d)`` moved at most one step from the previous."""
        if not self._started:
            self._started = True
            self._prev[0] = q_d
            self._prev[1] = qd_d
            return q_d, qd_d, qdd_d
        out = np.empty((3, self._prev.shape[1]))
        if _limit(self._limits, self._prev, np.ascontiguousarray(q_d, float),
                  np.ascontiguousarray(qd_d, float), np.ascontiguousarray(qdd_d, float), out):
            self.limited += 1
        return out[0], out[1], out[2]


# ------------------------------------------------------------------ effort
#: (tau, limit, out, clipped, ordered)
CLIP_SIGNATURE = "int64(float64[::1], float64[::1], int64[::1], float64[::1], float64[::1])"


@kernel(CLIP_SIGNATURE)
def _clip_effort(tau, limit, out, clipped, ordered):
    """``clipped = clip(tau, -limit, limit)``, ``ordered = clipped[out]``; returns -1 (nothing
    written) if ``tau`` holds NaN or Inf, 1 if every ``|tau| < limit``, else 0."""
    within = 1
    for i in range(tau.shape[0]):
        if not np.isfinite(tau[i]):
            return -1
        if not abs(tau[i]) < limit[i]:
            within = 0
    for i in range(tau.shape[0]):
        clipped[i] = _clip(tau[i], -limit[i], limit[i])
    for k in range(out.shape[0]):
        ordered[k] = clipped[out[k]]
    return within


class EffortClip:
    """The law's effort within ``+-limit`` (model order), and in the command's order.

    Parameters
    ----------
    limit : ndarray (n,)
        The effort limits (model order; inf: none).
    out : ndarray of int (n,)
        Model order -> command order.
    """

    #: what :meth:`__call__` says of an effort
    NON_FINITE, CLIPPED, WITHIN = -1, 0, 1

    def __init__(self, limit, out):
        self.limit = np.array(limit, dtype=float)           # (a copy: writable, as the
        self.out = np.array(out, dtype=np.int64)            # kernel's signature has it)

    def warm(self):
        """Compile (or load) the kernel now."""
        ready(_clip_effort)

    def __call__(self, tau):
        """``(verdict, clipped, ordered)``: :attr:`NON_FINITE` (then the arrays are not
        written), :attr:`WITHIN` (every ``|tau| < limit``) or :attr:`CLIPPED`; ``tau``
        clipped to the limits (model order) and the same in the command's order."""
        clipped, ordered = np.empty(self.limit.shape[0]), np.empty(self.out.shape[0])
        return _clip_effort(np.ascontiguousarray(tau, float), self.limit, self.out, clipped,
                            ordered), clipped, ordered
