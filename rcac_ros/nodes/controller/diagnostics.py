"""The controller's diagnostics (diagnostic_msgs/DiagnosticStatus on /diagnostics)."""

from diagnostic_msgs.msg import DiagnosticStatus

from rcac_ros.nodes.runtime.stats import PeriodHistogram, Percentiles


class LoopCounts:
    """What the controller's loop counts since configure: the node adds, :func:`diagnostics`
    reads."""

    def __init__(self):
        self.steps = 0                  # control steps
        self.compute = Percentiles()    # the compute time of each step
        self.efforts = PeriodHistogram()    # the law's efforts as sent (from the activation)
        self.compute_overruns = 0       # steps whose computation took longer than h
        self.late_ticks = 0             # late ticks of the ROS-time timer (timer mode, /clock)
        self.non_finite = 0             # NaN/Inf efforts (the safe effort went out instead)
        self.control_errors = 0         # control steps that raised (the safe effort instead)
        self._error_types = set()       # the exception types of those, logged once each

    def stepped(self, elapsed, h):
        """A control step took ``elapsed`` s (the period is ``h`` s)."""
        self.compute.add(elapsed)
        if elapsed > h:
            self.compute_overruns += 1
        self.steps += 1

    def control_failed(self, err):
        """A control step raised ``err``: count it; True if its type is new (log it)."""
        self.control_errors += 1
        new = type(err) not in self._error_types
        self._error_types.add(type(err))
        return new


def diagnostics(node, counts, rejected, starvation, inputs):
    """The controller ``node``'s current status (and restart its timing window).

    From the node's public parts (``config``, ``ctrl``, ``adaptation``, ``watchdog``, ``failsafe``,
    ``loop``, ``running``, ``phase_error_ns``, ``status``), what its loop counted
    (``counts``, :class:`LoopCounts`), its rejected inputs (``rejected``, a
    :class:`~rcac_ros.nodes.runtime.stats.Throttle`) and timer mode's starvation guard
    (``starvation``, :class:`~rcac_ros.nodes.controller.starvation.Starvation`, or ``None``),
    and its inputs (``inputs``, each with ``errors``, the failed takes, buffer allocations,
    callback exceptions and restarts of its side thread's loop by kind:
    ``input_errors_<kind>``, doc/failsafe.md "Thread failures").
    """
    count, p50, p99, worst = counts.compute.pop()
    skipped = 0 if node.loop is None else node.loop.skipped
    E = node.ctrl.E
    cfg = node.config
    level = DiagnosticStatus.OK
    message = "running" if node.running else "inactive: no effort published"
    if node.kernels.status == "compiling":
        message = "inactive: compiling the law's kernels (no effort until they are ready)"
    elif node.kernels.status == "failed":
        level, message = DiagnosticStatus.ERROR, f"the kernels did not compile: " \
            f"{node.kernels.error}"
    tripped = node.watchdog.tripped or node.failsafe.stop.active
    if node.running and tripped:
        level, message = DiagnosticStatus.WARN, \
            "watchdog: safe effort (no valid state, or no tick of /clock)"
    values = {
        "mode": cfg.mode, "steps": counts.steps, "steps_in_window": count,
        "compute_time_p50_us": f"{p50:.1f}", "compute_time_p99_us": f"{p99:.1f}",
        "compute_time_max_us": f"{worst:.1f}",
        "compute_time_max_all_us": f"{counts.compute.max_all * 1e6:.1f}",
        "deadline_us": f"{cfg.h * 1e6:.1f}",
        "deadline_misses": counts.compute_overruns + skipped,
        "compute_overruns": counts.compute_overruns,
        "late_ticks": counts.late_ticks if node.loop is None else node.loop.late,
        "skipped_ticks": skipped,
        "phase_error_us": f"{node.phase_error_ns * 1e-3:.1f}",   # timer.phase_offset's lock
        # what the controller adds to its input's jitter: the p99 period of the valid states
        # as DDS received them, and of the law's efforts as sent (since the activation)
        "input_period_p99_us": f"{node.states.arrivals.percentile_us(99):.0f}",
        "effort_period_p99_us": f"{counts.efforts.percentile_us(99):.0f}",
        "watchdog": "tripped" if tripped else "ok",
        "watchdog_trips": node.watchdog.trips,
        "watchdog_replans": node.failsafe.stop.replans,
        "loop_stalls": node.failsafe.stop.stalls,
        "rejected_messages": rejected.total,
        "stamp_restarts": node.failsafe.gate.restarts,
        "desired_limited": node.failsafe.limiter.limited,
        "non_finite_efforts": counts.non_finite,
        "control_errors": counts.control_errors,
        "prediction_error": f"{E[0]:.6g}",        # the first channel's (joint 1 by default)
        "channels": ",".join(cfg.channel_names),
        "adaptation": "on" if node.ctrl.adapting else "frozen",
        # the causes that hold it (controller/freeze.py): user (set_adaptation), starved,
        # recovering (after a spell, until the effort is within its limits)
        "adaptation_frozen_by": ",".join(sorted(node.adaptation.reasons)) or "none",
        "kernels": node.kernels.status,
        "kernels_ready_s": "" if node.kernels.seconds is None else f"{node.kernels.seconds:.2f}",
        "compiles_after_activate": node.compile_watch.count,
    }
    if starvation is not None:          # timer mode's starvation guard (doc/failsafe.md)
        values.update(starvation.diagnostics())
        if node.running and starvation.guard.starved and level == DiagnosticStatus.OK:
            level, message = DiagnosticStatus.WARN, \
                "starved: K_D scaled down and adaptation frozen (the loop's delay is past " \
                "the delay margin)"
    for name, e in zip(cfg.channel_names, E):     # every channel's E_c
        values[f"prediction_error_{name}"] = f"{e:.6g}"
    for kind in ("take", "alloc", "callback", "thread"):
        values[f"input_errors_{kind}"] = sum(i.errors.get(kind, 0) for i in inputs)
    for kind, c in sorted(rejected.counts.items()):
        values[f"rejected_{kind.replace(' ', '_')}"] = c
    return node.status(level, "control loop", message, values)
