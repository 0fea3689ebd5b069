"""The garbage collector around a 500 Hz loop: start-up objects frozen, pauses measured.

CPython's cyclic collector stops the process while it walks a generation. A full
(generation 2) collection walks every tracked object; a node process holds about 130,000
of them after start-up (rclpy, numpy, numba's dispatchers, the model), and one full
collection took 120-150 ms on the loaded 2-core VM (doc/failsafe.md), 60 control periods.
The collector starts one by itself when enough objects have survived into generation 2.
The steady 500 Hz loop allocates almost no tracked objects (no collection at all in a
10 s ``rcac bench --ros``), but bursts of allocation (parameter changes, trajectories,
services) can.

:func:`freeze_startup` collects once, then moves every object alive into the permanent
generation (:func:`gc.freeze`, the technique CPython documents for forked servers): later
collections walk only what was made after start-up, and a full one took 0.005 ms.
:class:`GcWatch` times every collection through :data:`gc.callbacks`, so the nodes'
diagnostics report the longest pause and the number of full collections.
"""

import gc
import time


def freeze_startup():
    """Collect the start-up garbage, then freeze everything alive (after the JIT warm-up)."""
    gc.collect()
    gc.freeze()


def unfreeze():
    """Hand the frozen objects back to the collector (a lifecycle cleanup drops many)."""
    gc.unfreeze()


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
        """Diagnostics entries: ``gc_pause_max_ms``, ``gc_full_collections``, ``gc_frozen``."""
        return {"gc_pause_max_ms": f"{self.pause_max_s * 1e3:.3f}",
                "gc_full_collections": self.full,
                "gc_frozen_objects": gc.get_freeze_count()}


#: the process's watch: :func:`rcac_ros.nodes.base.run` installs it
WATCH = GcWatch()
