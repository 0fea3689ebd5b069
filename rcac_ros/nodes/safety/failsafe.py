"""The controller's fail-safe guards, built from its parameters (doc/failsafe.md).

:class:`ControllerGuards` holds the objects the node's hooks call: the stamp gate, the size
caps, the goal check against the model's limits, the limiter of the desired state, the clip
of the effort, the spells of safe effort and how control resumes after them
(:mod:`rcac_ros.nodes.safety.guards`, :mod:`rcac_ros.nodes.safety.state_guards`).
The parameters are rows of :mod:`rcac_ros.params`.
"""

import numpy as np

from rcac_ros.nodes.safety.guards import check_goal, DesiredLimiter, EffortClip
from rcac_ros.nodes.safety.state_guards import SafeStop, StampGate


class ControllerGuards:
    """The guards of one controller node.

    Parameters
    ----------
    values : dict
        The node's checked parameter values (name -> value).
    model : RobotModel
        Its position and velocity limits bound the accepted trajectories.
    h : float
        The control period, s.
    effort_limit : ndarray (n,)
        The node's effort limits (model order).
    warn : callable
        Called with one line per joint set without an effort limit.
    out : ndarray of int (n,), optional
        Model order -> the effort command's order (default: the same).

    Attributes: ``gate``, ``stop``, ``limiter`` (:class:`DesiredLimiter`), ``clip``
    (:class:`EffortClip`), ``max_state_bytes``, ``max_trajectory_bytes``.
    """

    def __init__(self, values, model, h, effort_limit, warn, out=None):
        self.model = model
        self.max_state_bytes = values["max_state_bytes"]
        self.max_trajectory_bytes = values["max_trajectory_bytes"]
        self.gate = StampGate(values["stamp.max_jump"], values["stamp.restart_count"])
        self.stop = SafeStop(values["watchdog.replan_after"])
        self.limiter = DesiredLimiter(values["desired.max_position_step"],
                                      values["desired.max_velocity_step"], h, model.n)
        self.clip = EffortClip(effort_limit, np.arange(model.n) if out is None else out)
        free = [model.joint_names[i] for i in np.flatnonzero(~np.isfinite(effort_limit))]
        if free:
            warn(f"no effort limit for joints {free} (neither the model nor effort_limit gives "
                 "one): their efforts are not bounded")

    def check_goal(self, parsed, now_ns):
        """Refuse a parsed trajectory (:func:`rcac_ros.nodes.safety.guards.check_goal`)."""
        start_ns, times, pos, vel, _ = parsed
        m = self.model
        check_goal(start_ns, times, pos, vel, now_ns, m.position_lower, m.position_upper,
                   m.velocity_limit)
