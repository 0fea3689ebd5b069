"""One lock around every callback of a node, so that threads of its own can join them.

The controller's lockstep answer runs in its state input's thread
(:class:`~rcac_ros.nodes.runtime.inputs.SideInput`), not in the executor: rclpy's executor
rebuilds its wait set in Python at every spin, about 0.3 ms holding the interpreter lock
(doc/failsafe.md, "Known limitations"), which would sit between a state's arrival and its
answer. The node's other callbacks (lifecycle transitions, parameters, services, the
trajectory hand-over, the action server) still run in the executor and change what the
answer reads. :class:`SerialCallbackGroup` makes them take the node's lock: rclpy's Python
executors (single- and multi-threaded) call :meth:`~SerialCallbackGroup.beginning_execution`
before each callback of a group's entity and :meth:`~SerialCallbackGroup.ending_execution`
after it (the experimental ``EventsExecutor`` calls neither: not for these nodes). The
lifecycle transitions, also when triggered outside a callback, and ``destroy_node`` hold it
too. A thread that holds the same lock therefore never runs beside any of them: the node's
state has one writer at a time.

:class:`SerialTimer` is a steady timer of the same kind: its thread wakes at its period and
runs its callback holding the lock, without the executor. The watchdog checks at 100 Hz; as
an executor timer its spins would hold the interpreter lock about 3 % of the time, an answer
waiting meanwhile; its own thread holds it for the check alone.
"""

import threading
import time
import traceback

from rclpy.callback_groups import CallbackGroup


class SerialCallbackGroup(CallbackGroup):
    """Every callback of the group runs holding ``lock``.

    Parameters
    ----------
    lock : threading.RLock
        The node's lock (re-entrant: the thread that holds it may take it again).

    A callback whose coroutine suspends holds the lock until it completes; the nodes'
    callbacks do not suspend (the FollowJointTrajectory server's execute task is not a
    callback of a group).
    """

    def __init__(self, lock):
        super().__init__()
        self.lock = lock

    def can_execute(self, entity):
        """Always: the lock, not the group, serialises."""
        return True

    def beginning_execution(self, entity):
        """Wait for the lock; the callback may run."""
        self.lock.acquire()
        return True

    def ending_execution(self, entity):
        """Release the lock."""
        self.lock.release()


class SerialCallbacks:
    """A node mixin (before :class:`rclpy.node.Node` in the bases): its entities are created
    in one :class:`SerialCallbackGroup` by default, whose lock is :attr:`callback_lock`; its
    lifecycle transitions and ``destroy_node`` hold the lock (a transition triggered by a
    direct call, not by a service, as autostart does).

    rclpy's node creates its parameter and lifecycle services in its constructor, in
    ``default_callback_group``; the group is made at the first access, so those are in it
    too.
    """

    def on_configure(self, state):
        with self.callback_lock:
            return super().on_configure(state)

    def on_activate(self, state):
        with self.callback_lock:
            return super().on_activate(state)

    def on_deactivate(self, state):
        with self.callback_lock:
            return super().on_deactivate(state)

    def on_cleanup(self, state):
        with self.callback_lock:
            return super().on_cleanup(state)

    def on_shutdown(self, state):
        with self.callback_lock:
            return super().on_shutdown(state)

    def on_error(self, state):
        with self.callback_lock:
            return super().on_error(state)

    def destroy_node(self):
        """The node's ``destroy_node``, holding the lock (its threads, waiting for the lock
        to answer, see that they are closed and end)."""
        with self.callback_lock:
            return super().destroy_node()

    @property
    def callback_lock(self):
        """The lock every callback of the node's default group holds."""
        return self.default_callback_group.lock

    @property
    def default_callback_group(self):
        """The node's :class:`SerialCallbackGroup` (rclpy's default for new entities)."""
        group = self.__dict__.get("_serial_group")
        if group is None:
            group = self.__dict__["_serial_group"] = SerialCallbackGroup(threading.RLock())
        return group


def acquire(lock, stopped, poll=0.05):
    """Take ``lock``, unless ``stopped()`` becomes true while waiting (checked every ``poll``
    s): True if taken. A closing node's executor may hold the lock while it joins the
    thread that waits here."""
    while not lock.acquire(timeout=poll):
        if stopped():
            return False
    return True


class SerialTimer:
    """A steady-clock timer in its own thread; its callback runs holding ``lock``.

    Parameters
    ----------
    period : float
        s between calls (absolute deadlines; after a stall the missed ones are skipped).
    callback : callable
        Called with no argument, holding ``lock``.
    lock : threading.RLock
        The node's :attr:`SerialCallbacks.callback_lock`.
    name : str
        The thread's name.
    fatal : callable
        ``fatal(text)``, called (without the lock) with the traceback if ``callback``
        raises; the thread then ends. As an exception of an executor callback does in
        :func:`~rcac_ros.nodes.runtime.base.run`, the node should stop safely.
    """

    def __init__(self, period, callback, lock, name, fatal):
        self.period_ns = max(1, round(period * 1e9))
        self._callback, self._lock, self._fatal = callback, lock, fatal
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self):
        deadline = time.monotonic_ns() + self.period_ns
        while not self._stop.wait(max(0, deadline - time.monotonic_ns()) * 1e-9):
            now = time.monotonic_ns()
            deadline += max(1, (now - deadline) // self.period_ns + 1) * self.period_ns
            if not acquire(self._lock, self._stop.is_set):
                return
            failed = None
            try:
                self._callback()
            except Exception:       # noqa: BLE001 -- reported; the node stops safely
                failed = traceback.format_exc().rstrip()
            finally:
                self._lock.release()
            if failed is not None:
                return self._fatal(failed)

    def close(self):
        """Stop the thread (waits for a call in progress, unless called from it)."""
        self._stop.set()
        if threading.current_thread() is not self._thread:
            self._thread.join(2.0)
