"""The controller's kernels: compiled at configure, in a thread of their own; watched after.

Configure checks every parameter at once (a bad one fails the transition before anything
compiles), builds the law, then :class:`KernelWarmup` compiles (or loads from the cache,
:mod:`rcac_ros.core._jit`) what the active loop can run: the law's kernel (the same one
adapting, frozen by ``~/set_adaptation`` or the starvation guard, or with ``K_D`` scaled)
and the command limiter's. Meanwhile the node spins: its lifecycle services answer
and its diagnostics say ``compiling``. Autostart activates when the warm-up ends; an
activate requested before waits for it (and the node's services wait with it). A cleanup
or a shutdown waits for the kernel being compiled (numba cannot be interrupted) and skips
the rest.

After activation nothing may compile: :class:`CompileWatch` counts numba's compilations
from then on (``compiles_after_activate`` in the diagnostics, an ERROR line at the first).
"""

import threading
import time
import traceback

from numba.core import event


class KernelWarmup:
    """Compile the active loop's kernels in a daemon thread, started at construction.

    Parameters
    ----------
    ctrl : RecursiveCompositeController
        The configured law (:meth:`compile` only changes which function its step calls:
        its estimates and filters are not touched, so the services may use it meanwhile).
    limiter : DesiredLimiter
        Its kernel (:meth:`warm`: its state is not touched).
    after : sequence of callables
        Then run in this thread: what needs compiled kernels to be built (timer mode's
        delay margin, derived by stepping the law; the state predictor's integrator).
    log : rclpy logger
    """

    def __init__(self, ctrl, limiter, log, after=()):
        self.done = threading.Event()
        self.error = None                   # the exception's one line, if the warm-up failed
        self.seconds = None
        self._closed = threading.Event()
        self._args = ctrl, limiter, after
        self._log = log
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="rcac-compile", daemon=True)
        self._thread.start()

    def _run(self):
        ctrl, limiter, after = self._args
        try:
            for part in (ctrl.compile, limiter.warm, *after):
                if self._closed.is_set():
                    self.error = "the node was cleaned up while compiling"
                    return
                part()
        except Exception as exc:  # reported by status and at activate; the thread ends
            self.error = f"{type(exc).__name__}: {exc}"
            self._log.error(f"compiling the kernels failed:\n{traceback.format_exc()}")
        finally:
            self.seconds = time.monotonic() - self._t0
            self._args = None
            self.done.set()
        if self.error is None:
            self._log.info(f"kernels ready in {self.seconds:.1f} s")

    def close(self):
        """Skip what is left and wait for the kernel being compiled (configure's cleanup),
        saying so when it must wait."""
        self._closed.set()
        if not self.done.is_set():
            self._log.info("cleanup: waiting for the kernel being compiled to finish")
        self._thread.join()

    @property
    def status(self):
        """``compiling``, ``ready`` or ``failed``."""
        if not self.done.is_set():
            return "compiling"
        return "failed" if self.error else "ready"

    def wait(self):
        """Block until the warm-up ended (saying so when it must wait); True if its kernels
        are ready, else False with an ERROR line (activation is then refused)."""
        if not self.done.is_set():
            self._log.info("activate: waiting for the kernels to compile")
        self.done.wait()
        if self.error is not None:
            self._log.error(f"activate refused: the kernels did not compile ({self.error})")
        return self.error is None


class CompileWatch(event.Listener):
    """Count numba's compilations while ``node.running`` (registered until :meth:`close`)."""

    def __init__(self, node, log):
        self.count = 0
        self._node = node
        self._log = log
        event.register("numba:compile", self)

    def on_start(self, ev):
        if self._node.running:
            self.count += 1
            if self.count == 1:
                name = getattr(ev.data.get("dispatcher"), "__name__", "?")
                self._log.error(f"a kernel compiled after activate ({name}): the loop stalled "
                                f"while it compiled")

    def on_end(self, ev):
        pass

    def close(self):
        """Stop listening."""
        event.unregister("numba:compile", self)
