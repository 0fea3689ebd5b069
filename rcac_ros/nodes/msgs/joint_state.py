"""Reading a sensor_msgs/JointState into the model's joint order, and a velocity estimate.

Pure numpy: no rclpy types beyond reading the message fields. A state whose frame and joint
names are byte-equal to those of the last valid one is read from its serialised bytes
(:mod:`~rcac_ros.nodes.msgs.cdr`), without a message object.
"""

import math

import numpy as np

from rcac_ros.errors import InputError
from rcac_ros.nodes.msgs.cdr import joint_arrays, names_layout


def stamp_ns(stamp):
    """A builtin_interfaces/Time as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class StateRejected(InputError):
    """A JointState that cannot be used; ``kind`` says why (for the throttled warning)."""

    def __init__(self, kind, text):
        super().__init__(text)
        self.kind = kind


class JointStateReader:
    """Positions and velocities of the model's joints from a JointState, by joint name.

    The mapping from the message's names is cached while the names stay the same, and so are
    the serialised bytes of the frame and the names of the last valid state read with its
    bytes (:meth:`read_known` reads a state that repeats them).
    """

    def __init__(self, joint_names):
        self.joint_names = tuple(joint_names)
        self._names = None      # the joint names of the last valid state ...
        self._sel = None        # ... and their indices in model order
        self._known = None      # (frame and names bytes, their end, count, indices, spans)

    def read_known(self, data):
        """``(stamp, q, qd)`` of a serialised JointState whose frame and names are byte-equal to
        those of the last valid state read with its bytes (``stamp``: a
        :class:`~rcac_ros.nodes.msgs.cdr.Stamp`), as :meth:`read` gives them.

        ``None`` for any other, and for one that :meth:`read` would refuse (counts that do not
        match, NaN or Inf, bytes too short): :meth:`read` judges those from the message.
        """
        known = self._known
        if known is None or data[:2] != b"\x00\x01" or data[12:known[1]] != known[0] \
                and any(data[a:b] != part for a, b, part in known[4]):
            return None                     # (the second test: the padding bytes aside)
        arrays = joint_arrays(data, known[1], known[2])
        if arrays is None:
            return None
        stamp, position, velocity = arrays
        sel = known[3]
        q = position[sel]
        qd = None if velocity is None else velocity[sel]
        if not np.isfinite(q).all() or (qd is not None and not np.isfinite(qd).all()):
            return None                     # NaN or Inf: read() refuses it
        return stamp, q, qd

    def read(self, msg, data=None):
        """``(q, qd)`` in model order; ``qd`` is ``None`` when the message has no velocities.
        ``data``: the message's serialised bytes, kept for :meth:`read_known` once it is valid.

        Raises
        ------
        StateRejected
            No names or positions, mismatched lengths, duplicate or missing joint names,
            NaN or Inf.
        """
        names = msg.name
        m = len(names)
        if m == 0 or len(msg.position) == 0:
            raise StateRejected("empty", "JointState without names or positions")
        if len(msg.position) != m or (len(msg.velocity) not in (0, m)):
            raise StateRejected("length", f"JointState: {m} names, {len(msg.position)} "
                                f"positions, {len(msg.velocity)} velocities")
        if names == self._names:
            sel = self._sel                 # the same names as the last valid state
        else:
            if len(set(names)) != m:
                raise StateRejected("names", f"JointState: duplicate names {names}")
            index = {name: k for k, name in enumerate(names)}
            missing = [j for j in self.joint_names if j not in index]
            if missing:
                raise StateRejected("names", f"JointState: missing joints {missing}")
            sel = [index[j] for j in self.joint_names]
            self._names, self._sel = list(names), sel
        q = np.asarray(msg.position, dtype=float)[sel]
        qd = np.asarray(msg.velocity, dtype=float)[sel] if len(msg.velocity) else None
        if not np.all(np.isfinite(q)) or (qd is not None and not np.all(np.isfinite(qd))):
            raise StateRejected("nan", "JointState: NaN or Inf in position/velocity")
        if data is not None:
            layout = names_layout(data)
            self._known = None if layout is None or layout[1] != m else \
                (data[12:layout[0]], layout[0], m, np.asarray(sel),
                 [(a, b, data[a:b]) for a, b in layout[2]])
        return q, qd


class VelocityEstimate:
    """Joint velocities from positions: a finite difference through a first-order low-pass.

    Parameters
    ----------
    cutoff : float
        Cut-off frequency of the low-pass, Hz.
    """

    def __init__(self, cutoff):
        self.cutoff = cutoff
        self._q_prev = self._t_prev = self._qd = None

    def reset(self):
        """Start again at the next position (velocities were given meanwhile)."""
        self._q_prev = None

    def update(self, q, t_ns):
        """The estimate after the position ``q`` at ``t_ns`` (zero at the first one)."""
        if self._q_prev is None:
            self._qd = np.zeros_like(q)
        else:
            dt = (t_ns - self._t_prev) * 1e-9
            if dt > 0.0:
                raw = (q - self._q_prev) / dt
                alpha = 1.0 - math.exp(-2.0 * math.pi * self.cutoff * dt)
                self._qd = self._qd + alpha * (raw - self._qd)
        self._q_prev, self._t_prev = q, t_ns
        return self._qd.copy()
