"""Desired joint motions ``t -> (q_d, qd_d, qdd_d)``.

The paper's Section 4 motion is ambiguous (doc/design.md §5); both readings are here:

* ``"velocity"`` (default): ``qd_d = A sin(w t)`` from ``q_d(0) = q(0)``, so
  ``q_d = q0 + (A / w) (1 - cos(w t))``: zero initial error, matches ``qdot(0) = 0``.
* ``"position"``: ``q_d = A sin(w t)``, far from ``q(0)``: a large initial error.

with ``A = 5 pi / 180`` and ``w = 2 pi / 20 s`` (``pi t / 10``).
"""

import math

import numpy as np

from ._validate import as_array, joint_values, scalar
from rcac_ros.errors import InputError


class PaperTrajectory:
    """The desired motion of Section 4, in either reading.

    Parameters
    ----------
    q0 : array_like (n,)
        Initial position (the start of the velocity reading).
    reading : {"velocity", "position"}
    amplitude : float
        ``A``, rad/s (velocity reading) or rad (position reading); default 5 deg.
    period : float
        ``2 pi / w``, s; default 20 s.
    """

    def __init__(self, q0, reading="velocity", amplitude=5.0 * math.pi / 180.0, period=20.0):
        self.q0 = as_array(q0, (None,), "q0")
        if reading not in ("velocity", "position"):
            raise InputError(f"reading: must be 'velocity' or 'position', got {reading!r}")
        self.reading = reading
        self.amplitude = scalar(amplitude, "amplitude")
        self.omega = 2.0 * math.pi / scalar(period, "period", minimum=0.0, strict=True)

    def __call__(self, t):
        A, w, one = self.amplitude, self.omega, np.ones_like(self.q0)
        s, c = math.sin(w * t), math.cos(w * t)
        if self.reading == "velocity":
            return self.q0 + A / w * (1.0 - c) * one, A * s * one, A * w * c * one
        return A * s * one, A * w * c * one, -A * w * w * s * one


class SinusoidTrajectory:
    """Per joint ``q_d = offset + amplitude sin(2 pi frequency t + phase)``.

    All arguments broadcast to (n,); ``frequency`` in Hz.
    """

    def __init__(self, offset, amplitude, frequency, phase=0.0):
        self.offset = as_array(offset, (None,), "offset")
        n = self.offset.shape[0]
        self.amplitude = joint_values(amplitude, n, "amplitude")
        self.omega = 2.0 * math.pi * joint_values(frequency, n, "frequency")
        self.phase = joint_values(phase, n, "phase")

    def __call__(self, t):
        arg = self.omega * t + self.phase
        s, c = np.sin(arg), np.cos(arg)
        return (self.offset + self.amplitude * s, self.amplitude * self.omega * c,
                -self.amplitude * self.omega ** 2 * s)


class PolynomialTrajectory:
    """Per joint polynomial ``q_d = sum_k coefficients[:, k] t^k``, held after ``duration``.

    Parameters
    ----------
    coefficients : array_like (n, d + 1)
        Ascending powers of t.
    duration : float, optional
        After it, the position at ``duration`` is held with zero velocity and acceleration.
    """

    def __init__(self, coefficients, duration=None):
        c = as_array(coefficients, (None, None), "coefficients")
        self.duration = None if duration is None else float(duration)
        c = np.hstack([c, np.zeros((c.shape[0], max(0, 3 - c.shape[1])))])  # at least quadratic
        k = np.arange(c.shape[1])
        self.coefficients = c
        self._d1 = c[:, 1:] * k[1:]
        self._d2 = self._d1[:, 1:] * k[1:-1]

    @classmethod
    def quintic(cls, q_start, q_end, duration):
        """Rest-to-rest quintic from ``q_start`` to ``q_end`` in ``duration`` s."""
        q0 = as_array(q_start, (None,), "q_start")
        q1 = as_array(q_end, q0.shape, "q_end")
        T = scalar(duration, "duration", minimum=0.0, strict=True)
        d = q1 - q0
        zero = np.zeros_like(q0)
        coeffs = np.stack([q0, zero, zero, 10 * d / T ** 3, -15 * d / T ** 4, 6 * d / T ** 5], 1)
        return cls(coeffs, T)

    def __call__(self, t):
        held = self.duration is not None and t > self.duration
        t = min(t, self.duration) if self.duration is not None else t
        q = np.polyval(self.coefficients[:, ::-1].T, t)
        if held:
            return q, np.zeros_like(q), np.zeros_like(q)
        return q, np.polyval(self._d1[:, ::-1].T, t), np.polyval(self._d2[:, ::-1].T, t)
