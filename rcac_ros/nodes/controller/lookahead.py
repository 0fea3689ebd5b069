"""Timer mode's compensation of the state's age: predict it to when the effort acts.

In timer mode the effort answers the latest state, received up to a period before the
tick, and acts until the next tick: with the paper's K_D = 1e4 that delay matters
(doc/nodes.md, "Timing"). :class:`StatePredictor` integrates the model's forward dynamics (the
articulated-body algorithm, RK4: :func:`rcac_ros.core.simulator.rk4_kernel`, the
simulator's integrator) from the state over its age plus a fixed lookahead, holding the
effort being applied.
"""

import numpy as np

from rcac_ros.core.simulator import rk4_kernel

#: the prediction is integrated in steps of at most this, s
MAX_STEP = 0.001


class StatePredictor:
    """Predict ``(q, qd)`` ahead with the model and the effort applied meanwhile.

    Parameters
    ----------
    model : RobotModel
    lookahead : float
        Seconds beyond the state's age (transport to the arm, the hold until the next
        tick), >= 0.

    Attributes
    ----------
    applied : ndarray (n,)
        The effort being applied (model order); the node updates it at each step.
    """

    def __init__(self, model, lookahead):
        self.lookahead = float(lookahead)
        self.applied = np.zeros(model.n)
        self._kin = model.packed
        self._g = np.asarray(model.gravity, float)

    def prepare(self):
        """Compile (or load) the integrator's kernel now (the controller's warm-up thread)."""
        z = np.zeros(self.applied.shape[0])
        rk4_kernel(self._kin, self._g, z, z, z, MAX_STEP, 1)

    def __call__(self, q, qd, age_ns):
        """The state ``age_ns`` + ``lookahead`` after ``(q, qd)``."""
        horizon = max(age_ns, 0) * 1e-9 + self.lookahead
        steps = int(np.ceil(horizon / MAX_STEP))
        if steps == 0:
            return q, qd
        return rk4_kernel(self._kin, self._g, q, qd, self.applied, horizon, steps)
