"""What a node counts: throttled warnings by kind, and compute-time statistics.

:class:`Throttle` logs one warning per kind of rejected input per period and counts them
all (diagnostics ``rejected_messages``, ``rejected_<kind>``); :class:`Percentiles` keeps
the compute time of each step over a diagnostics window (``compute_time_*_us``).
"""

import math
import time

import numpy as np


class Throttle:
    """One warning per kind per ``period`` seconds (steady clock), with counts per kind."""

    def __init__(self, logger, period=1.0):
        self.logger = logger
        self.period = period
        self.counts = {}
        self._last = {}

    def warn(self, kind, text):
        """Count a rejection of ``kind`` and log ``text`` unless one was logged recently."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        now = time.monotonic()
        if now - self._last.get(kind, -math.inf) >= self.period:
            self._last[kind] = now
            suppressed = self.counts[kind]
            self.logger.warning(f"rejected ({kind}): {text} [{suppressed} so far]")

    @property
    def total(self):
        """Total number of rejections."""
        return sum(self.counts.values())


class Percentiles:
    """Compute-time statistics over a window (p50, p99, max) in microseconds."""

    def __init__(self):
        self._samples = []
        self.max_all = 0.0
        self._last = (math.nan, math.nan, math.nan)

    def add(self, seconds):
        """Record one sample, in seconds."""
        self._samples.append(seconds)
        self.max_all = max(self.max_all, seconds)

    def pop(self):
        """Return ``(count, p50, p99, max)`` in µs over the window, and start a new window.

        An empty window (the node is idle) repeats the figures of the last non-empty one.
        """
        if not self._samples:
            return (0,) + self._last
        arr = np.asarray(self._samples) * 1e6
        self._samples = []
        self._last = (float(np.percentile(arr, 50)), float(np.percentile(arr, 99)),
                      float(arr.max()))
        return (arr.size,) + self._last
