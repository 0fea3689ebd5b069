"""Opt-in real-time options of a node process, each best-effort (doc/failsafe.md, "real time").

* ``SCHED_FIFO`` priority of the thread of the node's loop, and one below it for the
  process's other threads (DDS reception and events, the input threads) and those they
  start: on a loaded machine a state that DDS received must not wait behind busy processes
  before the loop can use it, nor the loop for the interpreter lock held by a thread that
  such processes preempted;
* ``mlockall`` of the current and future pages (no page fault in the loop);
* CPU affinity of the loop's thread;
* a hold on ``/dev/cpu_dma_latency``: while the file stays open with a value written, the
  kernel keeps the CPUs out of deep idle states, which cuts the wake-up tail of a timer
  (the PM QoS interface, Documentation/power/pm_qos_interface.rst).

Each option that the process is not permitted to use (no ``CAP_SYS_NICE``, a memlock
limit, no such device) gives one warning and the node runs on without it.
"""

import ctypes
import ctypes.util
import os
import struct
import threading

MCL_CURRENT = 1
MCL_FUTURE = 2
DMA_LATENCY = "/dev/cpu_dma_latency"


def process_threads():
    """The native ids of this process's threads (``/proc/self/task``)."""
    return [int(tid) for tid in os.listdir("/proc/self/task")]


class RealtimeOptions:
    """What to ask for; the defaults ask for nothing.

    Parameters
    ----------
    priority : int
        SCHED_FIFO priority 1-99 of the loop thread, the process's other threads one below
        (at least 1); 0: leave the scheduler alone.
    lock_memory : bool
        ``mlockall(MCL_CURRENT | MCL_FUTURE)``.
    cpus : sequence of int
        CPUs the control thread may run on; empty: any.
    dma_latency_us : int
        Hold ``/dev/cpu_dma_latency`` at this many microseconds (0: the shallowest idle
        state); negative: no hold.
    """

    def __init__(self, priority=0, lock_memory=False, cpus=(), dma_latency_us=-1):
        self.priority = int(priority)
        self.lock_memory = bool(lock_memory)
        self.cpus = tuple(int(c) for c in cpus)
        self.dma_latency_us = int(dma_latency_us)

    @classmethod
    def from_values(cls, values):
        """The options of a node's checked ``realtime.*`` parameters (:mod:`rcac_ros.params`)."""
        return cls(priority=values["realtime.priority"],
                   lock_memory=values["realtime.lock_memory"],
                   cpus=values["realtime.cpus"] or (),
                   dma_latency_us=values["realtime.cpu_dma_latency"])

    @property
    def any(self):
        """Whether any option is asked for."""
        return bool(self.priority or self.lock_memory or self.cpus
                    or self.dma_latency_us >= 0)


class Realtime:
    """Apply :class:`RealtimeOptions` to the loop thread; :meth:`release` undoes the hold.

    Parameters
    ----------
    options : RealtimeOptions
    warn : callable, optional
        ``warn(text)``: an option not applied.
    loop_thread : int, optional
        Native id of the thread that runs the control step (the lockstep controller's
        state input); default the calling thread.

    Attributes
    ----------
    applied : list of str
        The options in force.
    warnings : list of str
        One line per option that could not be applied (also passed to ``warn``).
    """

    def __init__(self, options, warn=None, loop_thread=None):
        self.options = options
        self._caller = threading.get_native_id()
        self.loop_thread = self._caller if loop_thread is None else loop_thread
        self.applied = []
        self.warnings = []
        self._warn = warn
        self._dma = None
        if options.cpus:
            self._try("cpu_affinity", self._affinity)
        if options.lock_memory:
            self._try("mlockall", self._mlockall)
        if options.priority:
            self._try("sched_fifo", self._fifo)
        if options.dma_latency_us >= 0:
            self._try("cpu_dma_latency", self._dma_hold)

    @classmethod
    def for_node(cls, node):
        """Apply a node's opt-in options (its ``realtime`` attribute, a
        :class:`RealtimeOptions`) to its loop's thread (its ``loop_thread``, a native id, if
        it has one; else this thread) and, for the priority, to the process's other threads;
        logged, kept as the node's ``realtime_applied`` (configured again, the node moves
        them: :meth:`move`). ``None`` if none is asked for."""
        options = getattr(node, "realtime", None)
        if options is None or not options.any:
            return None
        rt = cls(options, warn=node.get_logger().warning,
                 loop_thread=getattr(node, "loop_thread", None))
        if rt.applied:
            node.get_logger().info(f"real-time options: {', '.join(rt.applied)}")
        node.realtime_applied = rt
        return rt

    def _try(self, name, action):
        try:
            self.applied.append(f"{name} ({action()})")
        except (OSError, ValueError) as err:
            text = f"real-time option {name} not applied: {err}; running without it"
            self.warnings.append(text)
            if self._warn is not None:
                self._warn(text)

    def _affinity(self):
        os.sched_setaffinity(self.loop_thread, self.options.cpus)
        return f"CPUs {sorted(os.sched_getaffinity(self.loop_thread))}"

    def _mlockall(self):
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
            errno = ctypes.get_errno()
            raise OSError(errno, f"mlockall: {os.strerror(errno)} (raise RLIMIT_MEMLOCK, "
                          "ulimit -l)")
        return "current and future pages"

    def _fifo(self):
        prio = self.options.priority
        top = os.sched_get_priority_max(os.SCHED_FIFO)
        if not 1 <= prio <= top:
            raise ValueError(f"priority {prio} outside 1..{top}")
        own = self.loop_thread
        others = [tid for tid in process_threads() if tid != own]
        try:
            os.sched_setscheduler(own, os.SCHED_FIFO, os.sched_param(prio))
        except PermissionError as err:
            raise OSError(err.errno, "SCHED_FIFO needs CAP_SYS_NICE or an rtprio limit "
                          "(/etc/security/limits.conf)") from None
        below = max(prio - 1, 1)
        for tid in others:
            try:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(below))
            except ProcessLookupError:      # the thread ended meanwhile
                pass
        return f"priority {prio}, the process's {len(others)} other threads {below}"

    def move(self, loop_thread=None):
        """The loop moved to another thread (``None``: the thread that applied the options),
        as when a node is configured again: the CPUs and the priority follow it, the former
        loop thread, if it still runs, goes one below. Best effort, as at the start."""
        new = self._caller if loop_thread is None else loop_thread
        old, self.loop_thread = self.loop_thread, new
        if new == old:
            return
        fifo = any(a.startswith("sched_fifo") for a in self.applied)
        prio = self.options.priority
        for tid, cpus, level in ((new, self.options.cpus, prio), (old, None, max(prio - 1, 1))):
            try:
                if cpus:
                    os.sched_setaffinity(tid, cpus)
                if fifo:
                    os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(level))
            except ProcessLookupError:      # the thread ended (the former loop's, closed)
                pass
            except OSError as err:
                text = f"real-time options not moved to thread {tid}: {err}"
                self.warnings.append(text)
                if self._warn is not None:
                    self._warn(text)

    def _dma_hold(self):
        fd = os.open(DMA_LATENCY, os.O_WRONLY)
        try:
            os.write(fd, struct.pack("i", self.options.dma_latency_us))
        except OSError:
            os.close(fd)
            raise
        self._dma = fd
        return f"{self.options.dma_latency_us} us"

    def release(self):
        """Close the ``cpu_dma_latency`` hold (the kernel drops the request on close)."""
        if self._dma is not None:
            os.close(self._dma)
            self._dma = None
