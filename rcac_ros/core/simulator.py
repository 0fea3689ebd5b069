"""The plant: forward dynamics (articulated-body algorithm) integrated by RK4, torque held.

The model's joint terms (armature, damping, smooth Coulomb friction, doc/design.md §7) are in
the articulated-body algorithm, so the plant has them whenever its model does.
"""

import numpy as np
from ._jit import njit

from ._validate import as_array, joint_values, scalar
from .aba import aba_kernel
from .payload import Payload, with_payload
from rcac_ros.errors import InputError


def plant_period(dt, substeps):
    """A plant's period ``dt`` (s, > 0) and its ``substeps`` (an integer >= 1), checked: the
    options this simulator shares with the plants of :mod:`rcac_ros.plants`."""
    dt = scalar(dt, "dt", minimum=0.0, strict=True)
    steps = scalar(substeps, "substeps", minimum=1.0)
    if steps != int(steps):
        raise InputError(f"substeps: must be an integer >= 1, got {substeps!r}")
    return dt, int(steps)


def effort_limits(model, effort_limit):
    """A plant's torque limits (n,): ``effort_limit`` (a scalar or n values, Inf allowed,
    each > 0), default the model's ``effort_limit``."""
    limit = model.effort_limit if effort_limit is None else effort_limit
    limits = joint_values(limit, model.n, "effort_limit", finite=False)
    if np.any(limits <= 0.0):
        raise InputError("effort_limit: every entry must be > 0")
    return limits


def initial_state(n, q0=None, qd0=None):
    """A plant's ``(q, qd)`` from the optional initial state (default zero), checked."""
    q = np.zeros(n) if q0 is None else as_array(q0, (n,), "q0")
    qd = np.zeros(n) if qd0 is None else as_array(qd0, (n,), "qd0")
    return q, qd


def held_torque(tau, effort_limit):
    """The torque a plant holds over one period: ``tau`` checked (n finite values, InputError
    otherwise) and clipped to ``+-effort_limit``."""
    tau = as_array(tau, effort_limit.shape, "tau")
    return np.clip(tau, -effort_limit, effort_limit)


@njit(cache=True)
def rk4_kernel(kin, g, q, qd, tau, dt, substeps):
    """Integrate ``qdd = ABA(q, qd, tau)`` over ``dt`` with ``substeps`` classical RK4 steps."""
    hs = dt / substeps
    for _ in range(substeps):
        k1q = qd
        k1v = aba_kernel(kin, g, q, qd, tau)
        q2 = q + 0.5 * hs * k1q
        v2 = qd + 0.5 * hs * k1v
        k2v = aba_kernel(kin, g, q2, v2, tau)
        q3 = q + 0.5 * hs * v2
        v3 = qd + 0.5 * hs * k2v
        k3v = aba_kernel(kin, g, q3, v3, tau)
        q4 = q + hs * v3
        v4 = qd + hs * k3v
        k4v = aba_kernel(kin, g, q4, v4, tau)
        q = q + hs / 6.0 * (k1q + 2.0 * v2 + 2.0 * v3 + v4)
        qd = qd + hs / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    return q, qd


class Simulator:
    """A serial arm integrated by RK4, the torque held over each period (zero-order hold).

    Parameters
    ----------
    model : RobotModel
        The true plant.
    dt : float
        Period over which one torque is held, s (the control period; default 2 ms).
    q0, qd0 : array_like (n,), optional
        Initial state (default zero).
    substeps : int
        RK4 steps per period (default 1: RK4 at the control period, as the paper's 2 ms).
    effort_limit : float or array_like (n,), optional
        Torques are clipped to +-effort_limit (default: the model's ``effort_limit``).
    """

    def __init__(self, model, dt=0.002, q0=None, qd0=None, substeps=1, effort_limit=None):
        self.model = model
        self.base_model = model             # the arm without a payload
        self.payload = Payload()
        self.dt, self.substeps = plant_period(dt, substeps)
        self.effort_limit = effort_limits(model, effort_limit)
        self._kin = model.packed
        self.reset(q0, qd0)

    def set_payload(self, payload):
        """Hold ``payload`` (a :class:`~rcac_ros.core.payload.Payload`) with the last link
        from the next step on, in place of any previous one (mass 0: release it); the state
        is kept. ``model`` becomes the loaded arm."""
        self.model = with_payload(self.base_model, payload)
        self.payload = payload
        self._kin = self.model.packed

    def reset(self, q0=None, qd0=None, t=0.0):
        """Set the state (default zero) and the time."""
        n = self.model.n
        self.q, self.qd = initial_state(n, q0, qd0)
        self.t = float(t)
        self.applied = np.zeros(n)          # the torque held over the last step, after clipping

    def step(self, tau):
        """Hold ``tau`` (clipped to the effort limit) for ``dt``; return the new ``(q, qd)``.

        The clipped torque is left in ``applied``.

        Raises
        ------
        InputError
            If ``tau`` has the wrong length or holds NaN/Inf (the state is left untouched).
        """
        self.applied = held_torque(tau, self.effort_limit)
        self.q, self.qd = rk4_kernel(self._kin, self.model.gravity, self.q, self.qd,
                                     self.applied, self.dt, self.substeps)
        self.t += self.dt
        return self.q.copy(), self.qd.copy()
