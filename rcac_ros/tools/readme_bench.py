"""The ROS loop's timing per controller mode, from a run (``make readme-bench``).

Runs ``rcac bench ros`` (:func:`rcac_ros.tools.bench.ros.run_ros_bench`) once per
controller mode, one after the other: the free-running timer, the timer locked to the
states' arrival (``timer.phase_offset`` 0) and ``on_state`` (the controller's ``lockstep``
mode answering each state of the real-time simulator), then the timer and ``on_state``
again with both nodes real time (``--rt``). It stores the figures of each run and the
conditions (cores, load average before and after) as the source ``bench_ros_modes`` of
doc/results.md (``doc/results/bench_ros_modes.json``) and renders the page. The rows that matter
are the ratios (doc/nodes.md, "Timing"): what the controller adds to its input, which the
load of the machine moves less than the absolute times.
"""

import argparse
import datetime
import json
import os
import sys
import time

from rcac_ros.tools.bench.commands import RT_OPTIONS, SIM_RT_OPTIONS

#: column -> (controller mode of the bench, controller overrides, simulator overrides)
MODES = {
    "timer": ("timer", {}, {}),
    "timer, locked (`timer.phase_offset` 0)": ("timer", {"timer.phase_offset": 0.0}, {}),
    "`on_state`": ("on_state", {}, {}),
    "timer, `--rt`": ("timer", RT_OPTIONS, SIM_RT_OPTIONS),
    "`on_state`, `--rt`": ("on_state", RT_OPTIONS, SIM_RT_OPTIONS),
}

#: (row label, how to format the figures of one run)
ROWS = (
    ("controller rate (Hz)", lambda r: _f(r["controller_rate_hz"], 1)),
    ("effort period p99 (ms)", lambda r: _f(r["period_p99_ms"], 2)),
    ("state period p99 (ms)", lambda r: _f(r["state_period_p99_ms"], 2)),
    ("**effort p99 / state p99** (goal <= 1.1)", lambda r: _f(r["period_ratio"], 2)),
    ("state→effort latency p50 / p99 (ms)",
     lambda r: f"{_f(r['state_to_effort_latency_p50_ms'], 2)} / "
               f"{_f(r['state_to_effort_latency_p99_ms'], 2)}"),
    ("plain DDS ping, one way p50 (ms)", lambda r: _f(r["ping_one_way_p50_ms"], 2)),
    ("**latency p50 / ping p50**", lambda r: _f(r["latency_ratio"], 2)),
    ("effort periods > 1.5 h", lambda r: str(r["late_periods"])),
    ("controller compute p50 / p99 (µs)",
     lambda r: f"{_f(r.get('controller_compute_time_p50_us'), 0)} / "
               f"{_f(r.get('controller_compute_time_p99_us'), 0)}"),
)


def _f(v, digits):
    return "-" if v is None else f"{v:.{digits}f}"


def measure(duration, rate=500.0):
    """Run the bench once per mode; return ``(results, conditions)``."""
    from rcac_ros.tools.bench.ros import BENCH_CONTROLLER, run_ros_bench
    load0 = os.getloadavg()[0]
    results = {}
    for column, (mode, over, sim_over) in MODES.items():
        print(f"readme-bench: {column}", flush=True)
        results[column] = run_ros_bench(duration, rate=rate, controller_mode=mode,
                                        controller_overrides=over,
                                        simulator_overrides=sim_over)
    load1 = os.getloadavg()[0]
    conditions = (
        f"{os.cpu_count()} cores, 1-minute load average {load0:.1f} before and {load1:.1f} "
        f"after, {duration:g} s per mode one after the other, {rate:g} Hz, "
        f"K_D = {BENCH_CONTROLLER['K_D']:g}; `--rt`: the controller at SCHED_FIFO "
        f"{RT_OPTIONS['realtime.priority']}, the simulator at "
        f"{SIM_RT_OPTIONS['realtime.priority']}.")
    return results, conditions


def main(argv=None):
    parser = argparse.ArgumentParser(prog="readme_bench", description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=20.0,
                        help="seconds measured per mode (default 20)")
    parser.add_argument("--dry-run", action="store_true", help="print the figures, write nothing")
    args = parser.parse_args(argv)
    from rcac_ros.tools.results import page
    started, rev = datetime.datetime.now(datetime.timezone.utc), page.revision()
    load0, t0 = os.getloadavg()[0], time.monotonic()
    results, conditions = measure(args.duration)
    data = json.loads(json.dumps({"conditions": conditions, "columns": results}, default=float))
    command = "make readme-bench" + ("" if args.duration == 20.0
                                     else f" (--duration {args.duration:g})")
    record = page.provenance(command, started, time.monotonic() - t0, load0,
                             os.getloadavg()[0], rev=rev)
    print(json.dumps(data, indent=1))
    if not args.dry_run:
        page.write_source("bench_ros_modes", data, record)
        try:
            page.render()
        except page.SourceError as err:
            print(f"readme-bench: stored the source, but doc/results.md was not rendered: {err}",
                  file=sys.stderr)
            return 1
        print("readme-bench: wrote doc/results/bench_ros_modes.json, doc/results.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
