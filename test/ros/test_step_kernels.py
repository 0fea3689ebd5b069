"""The per-step guards compiled as numba kernels (``DesiredLimiter``, ``EffortClip`` in
``rcac_ros/nodes/safety/guards.py``) against the same rules written with numpy calls, value
for value (bits: NaN and the sign of zero included)."""

import math

import numpy as np
import pytest

from rcac_ros.nodes.safety.guards import DesiredLimiter, EffortClip

H = 0.002


class NumpyLimiter:
    """The desired-state limiter as numpy calls (the reference)."""

    def __init__(self, dq, dqd, h, n):
        self.dq = np.broadcast_to(np.asarray(dq, float), (n,)).copy()
        self.dqd = np.broadcast_to(np.asarray(dqd, float), (n,)).copy()
        self.amax, self.vmax = self.dqd / h, self.dq / h
        self.limited, self.prev = 0, None

    def __call__(self, q_d, qd_d, qdd_d):
        if self.prev is None:
            self.prev = (np.array(q_d, float), np.array(qd_d, float))
            return q_d, qd_d, qdd_d
        q = self.prev[0] + np.clip(q_d - self.prev[0], -self.dq, self.dq)
        qd_c = np.clip(qd_d, -self.vmax, self.vmax)
        qd = self.prev[1] + np.clip(qd_c - self.prev[1], -self.dqd, self.dqd)
        clipped = bool(np.any(np.abs(q_d - self.prev[0]) > self.dq)
                       or np.any(np.abs(qd_c - self.prev[1]) > self.dqd)
                       or np.any(np.abs(qd_d) > self.vmax))
        self.prev = (q, qd)
        if clipped:
            self.limited += 1
            qdd_d = np.clip(qdd_d, -self.amax, self.amax)
        return q, qd, qdd_d


def bits(x):
    return np.asarray(x, dtype="<f8").tobytes()


EDGES = [0.0, -0.0, 1e-3, -1e-3, 5.0, -5.0, 1e300, -1e300, math.inf, -math.inf, math.nan]


def desired(rng, n):
    """A desired state: mostly small moves, some jumps, and now and then an edge value."""
    x = rng.normal(0.0, rng.choice([1e-3, 1e-2, 1.0, 100.0]), (3, n))
    edge = rng.random((3, n)) < 0.05
    x[edge] = rng.choice(EDGES, edge.sum())
    return x


@pytest.mark.parametrize("dq, dqd", [(0.01, 1.0), (1e-4, 0.1), ([0.01, 0.02, 1e9], 1.0),
                                     (math.inf, math.inf)])
def test_the_limiter_kernel_gives_the_numpy_rules_values(dq, dqd):
    rng = np.random.default_rng(3)
    n = 3
    ours, ref = DesiredLimiter(dq, dqd, H, n), NumpyLimiter(dq, dqd, H, n)
    ours.warm()
    for k in range(3000):
        if k % 500 == 0:                        # a new motion: taken as it is
            ours.reset()
            ref.prev = None
        x = desired(rng, n)
        if k % 500 == 1:                        # start from a finite state
            x = np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=-1.0)
        got, want = ours(*x), ref(*x)
        for a, b in zip(got, want):
            assert bits(a) == bits(b), (k, got, want)
        if not np.all(np.isfinite(ours._prev)):     # the reference's state is as broken
            ours.reset()
            ref.prev = None
    assert ours.limited == ref.limited
    assert ref.limited > 100 if np.all(np.isfinite(dq)) else ref.limited == 0


@pytest.mark.parametrize("limit", [[1.0, 2.0, 3.0, 4.0], [math.inf] * 4,
                                   [1e-6, math.inf, 50.0, 0.5]])
def test_the_effort_clip_kernel_gives_the_numpy_rules_values(limit):
    rng = np.random.default_rng(5)
    limit = np.array(limit)
    out = np.array([2, 0, 3, 1])
    clip = EffortClip(limit, out)
    clip.warm()
    verdicts = set()
    for _ in range(3000):
        tau = rng.normal(0.0, rng.choice([0.1, 1.0, 10.0]), 4)
        edge = rng.random(4) < 0.05
        tau[edge] = rng.choice(EDGES + list(limit) + list(-limit), edge.sum())
        verdict, clipped, ordered = clip(tau)
        verdicts.add(verdict)
        if not np.all(np.isfinite(tau)):
            assert verdict == EffortClip.NON_FINITE
            continue
        within = bool(np.all(np.abs(tau) < limit))
        assert verdict == (EffortClip.WITHIN if within else EffortClip.CLIPPED)
        want = np.clip(tau, -limit, limit)
        assert bits(clipped) == bits(want) and bits(ordered) == bits(want[out])
    assert EffortClip.NON_FINITE in verdicts and EffortClip.WITHIN in verdicts
