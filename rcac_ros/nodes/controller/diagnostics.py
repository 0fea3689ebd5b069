"""The controller's diagnostics (diagnostic_msgs/DiagnosticStatus on /diagnostics)."""

from diagnostic_msgs.msg import DiagnosticStatus


def diagnostics(node):
    """The controller ``node``'s current status (and restart its timing window)."""
    count, p50, p99, worst = node._stats.pop()
    skipped = 0 if node.loop is None else node.loop.skipped
    E = node.ctrl.E
    level = DiagnosticStatus.OK
    message = "running" if node.running else "inactive: no effort published"
    tripped = node.watchdog.tripped or node.failsafe.stop.active
    if node.running and tripped:
        level, message = DiagnosticStatus.WARN, \
            "watchdog: safe effort (no valid state, or no tick of /clock)"
    values = {
        "mode": node.mode, "steps": node._steps, "steps_in_window": count,
        "compute_time_p50_us": f"{p50:.1f}", "compute_time_p99_us": f"{p99:.1f}",
        "compute_time_max_us": f"{worst:.1f}",
        "compute_time_max_all_us": f"{node._stats.max_all * 1e6:.1f}",
        "deadline_us": f"{node.h * 1e6:.1f}",
        "deadline_misses": node._deadline_misses + skipped,
        "compute_overruns": node._deadline_misses,
        "late_ticks": node._late_ticks if node.loop is None else node.loop.late,
        "skipped_ticks": skipped,
        "phase_error_us": f"{node.phase_error_ns * 1e-3:.1f}",   # timer.phase_offset's lock
        "watchdog": "tripped" if tripped else "ok",
        "watchdog_trips": node.watchdog.trips,
        "watchdog_replans": node.failsafe.stop.replans,
        "rejected_messages": node._throttle.total,
        "stamp_restarts": node.failsafe.gate.restarts,
        "desired_limited": node.failsafe.limiter.limited,
        "non_finite_efforts": node._nonfinite,
        "prediction_error": f"{E[0]:.6g}",        # the first channel's (joint 1 by default)
        "channels": ",".join(node.channel_names),
        "adaptation": "on" if node.ctrl.adapting else "frozen",
    }
    if node._starvation is not None:    # timer mode's starvation guard (doc/failsafe.md)
        values.update(node._starvation.diagnostics())
        if node.running and node._starvation.guard.starved and level == DiagnosticStatus.OK:
            level, message = DiagnosticStatus.WARN, \
                "starved: K_D scaled down and adaptation frozen (the loop's delay is past " \
                "the delay margin)"
    for name, e in zip(node.channel_names, E):     # every channel's E_c
        values[f"prediction_error_{name}"] = f"{e:.6g}"
    for kind, c in sorted(node._throttle.counts.items()):
        values[f"rejected_{kind.replace(' ', '_')}"] = c
    return node.status(level, "control loop", message, values)
