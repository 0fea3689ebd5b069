"""The garbage collector around a 500 Hz loop: every collection timed.

CPython's cyclic collector stops the process while it walks a generation; a full
(generation 2) collection walks every tracked object, about 130,000 in a node process
after start-up (rclpy, numpy, numba's dispatchers, the model): 120-150 ms on the loaded
2-core VM. :class:`GcWatch` times every collection through :data:`gc.callbacks`, so the
nodes' diagnostics report the longest pause and the number of full collections.

Measured (doc/failsafe.md): the steady loop allocates almost no tracked objects, and a 20 s
``rcac bench ros`` saw no collection at all in the controller. Freezing the start-up
objects (:func:`gc.freeze`, so a full collection would walk only newer ones) was tried and
measured worse: in the fault benchmark's nominal case it brought 22-26 gaps of more than two
periods per 20 s against 0-1 without, and watchdog trips, for a reason not found. The nodes
do not freeze.
"""

import gc
import time


class GcWatch:
    """Times each collection of this process (from :func:`install` to :meth:`close`).

    Attributes
    ----------
    pause_max_s : float
        The longest collection, s.
    full : int
        Full (generation 2) collections.
    collections : int
        Collections of any generation.
    """

    def __init__(self, clock=time.perf_counter):
        self.clock = clock
        self.active = False
        self.pause_max_s = 0.0
        self.full = 0
        self.collections = 0
        self._start = None

    def install(self):
        """Start timing (append to :data:`gc.callbacks`); returns self."""
        if self._callback not in gc.callbacks:
            gc.callbacks.append(self._callback)
        self.active = True
        return self

    def close(self):
        """Stop timing."""
        if self._callback in gc.callbacks:
            gc.callbacks.remove(self._callback)
        self.active = False

    def _callback(self, phase, info):
        if phase == "start":
            self._start = self.clock()
            return
        if self._start is None:
            return
        self.pause_max_s = max(self.pause_max_s, self.clock() - self._start)
        self._start = None
        self.collections += 1
        if info["generation"] == 2:
            self.full += 1

    def values(self):
        """Diagnostics entries: ``gc_pause_max_ms``, ``gc_full_collections``,
        ``gc_collections``."""
        return {"gc_pause_max_ms": f"{self.pause_max_s * 1e3:.3f}",
                "gc_full_collections": self.full, "gc_collections": self.collections}


#: the process's watch: :func:`rcac_ros.nodes.runtime.base.run` installs it
WATCH = GcWatch()
