"""The ROS loop's timing per controller mode, from a run (``make readme-bench``).

Runs ``rcac bench ros`` (:func:`rcac_ros.tools.bench.ros.run_ros_bench`) once per
controller mode, one after the other: the free-running timer, the timer locked to the
states' arrival (``timer.phase_offset`` 0) and ``on_state`` (the controller's ``lockstep``
mode answering each state of the real-time simulator), then the timer and ``on_state``
again with both nodes real time (``--rt``). It stores the figures of each run and its
conditions (duration, rate, gains; the machine and the load average are in the record's
provenance) as the source ``bench_ros_modes`` of doc/results.md
(``doc/results/bench_ros_modes.json``) and renders the page. The rows that matter are the
ratios (doc/nodes.md, "Timing"): what the controller adds to its input, which the load of
the machine moves less than the absolute times.
"""

import argparse
import datetime
import json
import os
import sys
import time

from rcac_ros.tools.bench.commands import RT_OPTIONS, SIM_RT_OPTIONS
from rcac_ros.tools.results.blocks import BENCH_ROS_ROWS as ROWS  # noqa: F401

#: column -> (controller mode of the bench, controller overrides, simulator overrides)
MODES = {
    "timer": ("timer", {}, {}),
    "timer, locked (`timer.phase_offset` 0)": ("timer", {"timer.phase_offset": 0.0}, {}),
    "`on_state`": ("on_state", {}, {}),
    "timer, `--rt`": ("timer", RT_OPTIONS, SIM_RT_OPTIONS),
    "`on_state`, `--rt`": ("on_state", RT_OPTIONS, SIM_RT_OPTIONS),
}


def measure(duration, rate=500.0):
    """Run the bench once per mode; return ``(results, conditions)``."""
    from rcac_ros.tools.bench.ros import BENCH_CONTROLLER, run_ros_bench
    results = {}
    for column, (mode, over, sim_over) in MODES.items():
        print(f"readme-bench: {column}", flush=True)
        results[column] = run_ros_bench(duration, rate=rate, controller_mode=mode,
                                        controller_overrides=over,
                                        simulator_overrides=sim_over)
    conditions = (
        f"{duration:g} s per mode in turn, {rate:g} Hz, "
        f"K_D = {BENCH_CONTROLLER['K_D']:g}; `--rt`: the controller at SCHED_FIFO "
        f"{RT_OPTIONS['realtime.priority']}, the simulator at "
        f"{SIM_RT_OPTIONS['realtime.priority']}.")
    return results, conditions


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m rcac_ros.tools.results.ros_modes",
                                     description=__doc__.split("\n")[0])
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
        return page.store("bench_ros_modes", data, record, "readme-bench")
    return 0


if __name__ == "__main__":
    sys.exit(main())
