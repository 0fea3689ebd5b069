"""What a node counts: throttled warnings by kind, compute-time and period statistics.

:class:`Throttle` logs one warning per kind of rejected input per period and counts them
all (diagnostics ``rejected_messages``, ``rejected_<kind>``); :class:`Percentiles` keeps
the compute time of each step over a diagnostics window (``compute_time_*_us``);
:class:`PeriodHistogram` the periods of the states as received and of the efforts as sent,
since the activation (``input_period_p99_us``, ``effort_period_p99_us``).
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


class PeriodHistogram:
    """The periods between successive events (ns stamps of one clock), binned: a cumulative
    p99 in O(1) per event and O(bins) per reading.

    Parameters
    ----------
    bin_ns : int
        Width of a bin, ns; a percentile is the upper edge of its bin (at most ``bin_ns``
        above the exact one).
    bins : int
        Bins below the overflow one (periods of at least ``bins * bin_ns`` fall there).
    """

    def __init__(self, bin_ns=10_000, bins=5_000):
        self.bin_ns, self.bins = int(bin_ns), int(bins)
        self.reset()

    def reset(self):
        """Forget every period and the last event."""
        self._counts = [0] * (self.bins + 1)
        self._last = None
        self.count = 0

    def add(self, t_ns):
        """An event at ``t_ns``; the period since the last one is counted (not one that goes
        backwards: a stamp of another clock)."""
        last, self._last = self._last, t_ns
        if last is None or t_ns < last:
            return
        self._counts[min((t_ns - last) // self.bin_ns, self.bins)] += 1
        self.count += 1

    def percentile_us(self, q):
        """The ``q``-th percentile of the periods, µs (upper edge of its bin); NaN with none.
        In the overflow bin: ``inf``."""
        counts = list(self._counts)         # one snapshot (another thread may add)
        total = sum(counts)
        if total == 0:
            return math.nan
        rank, seen = math.ceil(q / 100.0 * total), 0
        for b, c in enumerate(counts):
            seen += c
            if seen >= max(rank, 1):
                return math.inf if b == self.bins else (b + 1) * self.bin_ns * 1e-3
        return math.inf
