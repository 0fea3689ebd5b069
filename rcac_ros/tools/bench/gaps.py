"""Where the gaps between efforts come from (``python -m rcac_ros.tools.bench.gaps``).

Runs ``rcac bench ros`` in timer mode beside a *sentinel*: a third process with no ROS
and no numpy that sleeps to absolute deadlines every 2 ms and notes each wake-up more than
1 ms late. Then, for every gap between two efforts longer than two periods (the sender's
stamps, so the DDS transport is not in it), it looks at the same instant (+-2 periods) for

* the sentinel late by more than one period: the machine did not run a ready process in
  time (the scheduler; the cores were busy);
* a gap of more than two periods in the simulator's states: the simulator was held too;
* neither: a cause inside the controller's process.

It prints the counts, the controller's own diagnostics (garbage collections and their
longest pause, compute time, late ticks) and the load average (doc/failsafe.md, "How to
check a machine"). ``--rt`` gives both nodes their real-time options (``rcac bench ros --rt``):
what remains then is what a busy machine does not explain.
"""

import argparse
import json
import os
import signal
import sys
import tempfile
import time

import numpy as np

from rcac_ros.tools.launch import spawn

PERIOD_NS = 2_000_000


def sentinel(out_path):
    """The sentinel loop, until SIGTERM; writes ``{"late": [[realtime ns, late ns]...]}``."""
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    offset = time.time_ns() - time.monotonic_ns()
    t, ticks, late = time.monotonic_ns(), 0, []
    while not stop:
        t += PERIOD_NS
        wait = t - time.monotonic_ns()
        if wait > 0:
            time.sleep(wait * 1e-9)
        now = time.monotonic_ns()
        if now - t > PERIOD_NS // 2:
            late.append((t + offset, now - t))
        if now - t > 25 * PERIOD_NS:        # far behind: start again from now
            t = now
        ticks += 1
    with open(out_path, "w") as f:
        json.dump({"late": late, "ticks": ticks}, f)


def attribute(effort_src, state_src, sentinel_late, h_ns=PERIOD_NS):
    """Per gap > 2 h between efforts: ``(gap ns, simulator held, sentinel late)``.

    ``effort_src``, ``state_src``: source stamps (ns, realtime); ``sentinel_late``: rows of
    ``(deadline realtime ns, lateness ns)``. The window is the gap widened by 2 h each side.
    """
    eff = np.sort(np.asarray(effort_src, np.int64))
    st = np.sort(np.asarray(state_src, np.int64))
    late = np.asarray(sentinel_late, np.int64).reshape(-1, 2)
    rows = []
    for i in np.nonzero(np.diff(eff) > 2 * h_ns)[0]:
        a, b = eff[i] - 2 * h_ns, eff[i + 1] + 2 * h_ns
        seg = st[max(np.searchsorted(st, a) - 1, 0):np.searchsorted(st, b) + 1]
        held = bool(seg.size > 1 and np.diff(seg).max() > 2 * h_ns)
        m = (late[:, 0] >= a) & (late[:, 0] <= b)
        rows.append((int(eff[i + 1] - eff[i]), held, bool(np.any(late[m, 1] > h_ns))))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(prog="gaps", description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--rt", action="store_true",
                        help="both nodes with their real-time options (rcac bench ros --rt)")
    parser.add_argument("--sentinel", metavar="OUT", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.sentinel:
        sentinel(args.sentinel)
        return 0
    from rcac_ros.tools.bench import ros
    from rcac_ros.tools.bench.commands import RT_OPTIONS, SIM_RT_OPTIONS
    probes = []

    class Probe(ros.Probe):                 # keeps the probe: its stamps are needed here
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            probes.append(self)
    ros.Probe = Probe
    out = os.path.join(tempfile.mkdtemp(prefix="rcac_gaps_"), "sentinel.json")
    proc = spawn([sys.executable, "-m", "rcac_ros.tools.bench.gaps", "--sentinel", out])
    load0 = os.getloadavg()[0]
    try:
        r = ros.run_ros_bench(args.duration, controller_mode="timer", verbose=False,
                              controller_overrides=dict(RT_OPTIONS) if args.rt else {},
                              simulator_overrides=dict(SIM_RT_OPTIONS) if args.rt else {})
    finally:
        proc.terminate()
        proc.wait()
    load1 = os.getloadavg()[0]
    with open(out) as f:
        late = json.load(f)["late"]
    p = probes[0]
    rows = attribute([e[0] for e in p.efforts if not e[2]], [s[0] for s in p.states], late)
    machine = sum(1 for _, held, slow in rows if slow or held)
    print(f"timer mode{' --rt' if args.rt else ''}, {r['window_s']:.0f} s, load average "
          f"{load0:.1f} -> {load1:.1f}: {r['efforts']} efforts ({r['controller_rate_hz']:.0f} "
          f"Hz), {len(rows)} gaps > 2 periods (longest "
          f"{max((g for g, _, _ in rows), default=0) * 1e-6:.1f} ms)")
    print(f"  the sentinel late or the simulator held at the same time: {machine}; "
          f"sentinel late alone: {sum(1 for _, h, s in rows if s and not h)}; "
          f"neither: {len(rows) - machine}")
    print("  controller: garbage collections {:.0f} (longest pause {:.2f} ms), compute p99 "
          "{:.0f} us, late / skipped ticks {:.0f} / {:.0f}".format(
              r.get("controller_gc_full_collections", float("nan")),
              r.get("controller_gc_pause_max_ms", float("nan")),
              r.get("controller_compute_time_p99_us", float("nan")),
              r.get("controller_late_ticks", float("nan")),
              r.get("controller_skipped_ticks", float("nan"))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
