"""``rcac bench BENCHMARK``: one subcommand per benchmark, each with its own options.

=============  ===========================================================  ================
core           the recursive controller against Pinocchio, the Slotine-Li   :mod:`.core`
               baseline and itself, offline (µs per step, operation count)
ros            the two nodes over ROS 2 at 500 Hz: rate, jitter, latency    :mod:`.ros`
faults         the closed loop over ROS under faults, one case at a time    :mod:`.faults`
soak           the direct fault case for minutes: memory growth, late       :mod:`.faults`
               ticks
delay-margin   offline, tracking RMS against K_D with the effort 0-2        :mod:`.delay_margin`
               periods late (the stable range of timer mode)
startup        how long the package takes to start, cold (empty cache)  :mod:`.startup`
               and warm: import, a bad argument, the controller's first
               answer and first effort, the warm-up
noise          10-minute closed loops with sensor noise: are the estimates  :mod:`.noise`
               bounded? (``--sources``: where the paper law's drift comes
               from)
=============  ===========================================================  ================

Only the chosen benchmark's module is imported, when it runs; the ROS ones need rclpy
(``tools/extras.py`` says so in one line where it is missing).
"""

import argparse
import sys

from rcac_ros.errors import ConfigError
from rcac_ros.tools.args import (non_negative_float, non_negative_int, output_dir, output_file,
                                 positive_float)
from rcac_ros.tools.extras import require


def add_core(p):
    p.add_argument("--json", type=output_file, metavar="FILE",
                   help="also write the results as JSON")
    p.add_argument("--budget", type=positive_float, default=0.3,
                   help="seconds of timing per cell (default 0.3)")
    p.add_argument("--natural", action="store_true",
                   help="only the natural geometry's cost against the Euclidean law, along "
                        "a recorded closed loop (n = 7, 14, 28) and at its worst case")


#: the controller's real-time options of ``--rt``
RT_OPTIONS = {"realtime.priority": 80, "realtime.lock_memory": True,
              "realtime.cpu_dma_latency": 0}
#: the simulator's (the arm's driver) real-time options of ``--rt``: below the controller's,
#: as a driver's thread beside a controller manager's on one machine
SIM_RT_OPTIONS = {"realtime.priority": 70, "realtime.lock_memory": True}


def add_controller(p):
    """The nodes' options of the benchmarks over ROS (ros, faults, soak): the controller's,
    and with ``--rt`` the simulator's real-time options."""
    p.add_argument("--json", type=output_file, metavar="FILE",
                   help="also write the results as JSON")
    p.add_argument("--rt", action="store_true",
                   help="both nodes with their real-time options, best effort: the "
                        "controller SCHED_FIFO 80 (its process's other threads 79), mlockall, "
                        "cpu_dma_latency 0; the simulator, which stands for the arm's driver, "
                        "SCHED_FIFO 70 (69), mlockall")
    p.add_argument("--K_D", type=positive_float, default=None,
                   help="the controller's K_D (default: the bench's)")
    p.add_argument("--lookahead", type=non_negative_float, default=None, metavar="SECONDS",
                   help="the controller's timer.lookahead (state prediction; default: none)")
    p.add_argument("--phase-offset", type=non_negative_float, default=None, metavar="SECONDS",
                   help="the controller's timer.phase_offset (ticks locked to the states' "
                        "arrival plus this; default: not locked)")


def controller_overrides(args):
    """The controller parameters the options of :func:`add_controller` set."""
    over = dict(RT_OPTIONS) if args.rt else {}
    if args.K_D is not None:
        over["K_D"] = float(args.K_D)
    if args.lookahead is not None:
        over["timer.lookahead"] = float(args.lookahead)
    if args.phase_offset is not None:
        over["timer.phase_offset"] = float(args.phase_offset)
    return over


def simulator_overrides(args):
    """The simulator parameters the options of :func:`add_controller` set."""
    return dict(SIM_RT_OPTIONS) if args.rt else {}


def add_ros(p):
    p.add_argument("--duration", type=positive_float, default=60.0,
                   help="seconds of the run (default 60)")
    p.add_argument("--mode", choices=("timer", "on_state"), default="on_state",
                   help="the controller answering each joint state (default, the node's "
                        "default mode) or on its 500 Hz timer")
    add_controller(p)


def add_faults(p):
    p.add_argument("--duration", type=positive_float, default=60.0,
                   help="seconds per case (default 60)")
    p.add_argument("--cases", type=fault_cases, default=None,
                   help="comma-separated cases (default: all)")
    p.add_argument("--plot", type=output_file, metavar="FILE",
                   help="tracking errors per case (PNG)")
    _add_discovery_range(p)
    add_controller(p)


def _add_discovery_range(p):
    p.add_argument("--discovery-range", choices=("LOCALHOST", "SUBNET"), default="LOCALHOST",
                   help="ROS_AUTOMATIC_DISCOVERY_RANGE of every process (default LOCALHOST: "
                        "nothing leaves the machine; SUBNET is ROS's default; see the joiners "
                        "case in doc/failsafe.md)")


def add_soak(p):
    p.add_argument("minutes", type=positive_float, metavar="MINUTES",
                   help="minutes of the direct case (no fault, no relay)")
    p.add_argument("--plot", type=output_file, metavar="FILE", help="the tracking error (PNG)")
    p.add_argument("--busy", type=non_negative_int, default=0, metavar="N",
                   help="N busy processes beside the nodes for the whole soak, start-up "
                        "included (a starved machine; default 0)")
    _add_discovery_range(p)
    add_controller(p)


def add_delay_margin(p):
    p.add_argument("--plot", type=output_file, metavar="FILE",
                   help="tracking RMS against K_D (PNG)")
    p.add_argument("--model", choices=("css_arm", "panda", "ur5"), default="css_arm",
                   help="the CSS arm (gain K_D, the paper's), the Panda of payload-demo "
                        "(gain kappa, K_Di = kappa M_i) or the UR5 (gain K_D, K_Di = K_D I6)")
    p.add_argument("--gains", metavar="LIST", type=_floats,
                   help="comma-separated gains (default: a grid for the model)")
    p.add_argument("--delays", metavar="LIST", type=_periods, default=(0, 1, 2),
                   help="comma-separated effort delays, periods (default 0,1,2)")
    p.add_argument("--frozen", action="store_true",
                   help="adaptation frozen (what the starvation guard does)")
    p.add_argument("--no-predict", action="store_true", help="no runs with the prediction")
    p.add_argument("--check", action="store_true",
                   help="instead, check the derived delay margin on the Panda, the UR5 and "
                        "the CSS arm: the loop tracks 0.7 margin late, not 1.5 margin late")
    p.add_argument("--json", type=output_file, metavar="FILE",
                   help="with --check: also write the rows as JSON")


def _floats(text):
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a list of numbers: {text!r}") from None
    if not all(v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"gains must be > 0: {text!r}")
    return values


def _periods(text):
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a list of integers: {text!r}") from None
    if not all(v >= 0 for v in values):
        raise argparse.ArgumentTypeError(f"delays must be >= 0 periods: {text!r}")
    return values


def _choices(text, sep, known):
    items = [v.strip() for v in text.split(sep)]
    if "" in items:
        raise argparse.ArgumentTypeError(f"an empty name in {text!r} (known: "
                                         f"{sep.join(known)})")
    bad = [v for v in items if v not in known]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown {', '.join(bad)} (known: "
                                         f"{sep.join(known)})")
    return items


def fault_cases(text):
    """``--cases``: comma-separated names of :data:`rcac_ros.tools.bench.fault_cases.CASES`."""
    from rcac_ros.tools.bench.fault_cases import CASES
    return tuple(_choices(text, ",", CASES))


def noise_laws(text):
    """``--laws``: ';'-separated names of :data:`rcac_ros.tools.bench.noise.LAWS`."""
    from rcac_ros.tools.bench.noise import LAWS
    return _choices(text, ";", tuple(LAWS))


def noise_variants(text):
    """``--variants``: comma-separated names of :data:`rcac_ros.tools.bench.noise.VARIANTS`."""
    from rcac_ros.tools.bench.noise import VARIANTS
    return tuple(_choices(text, ",", VARIANTS))


def add_noise(p):
    p.add_argument("--duration", type=positive_float, default=600.0,
                   help="seconds of each run (default 600)")
    p.add_argument("--sources", action="store_true",
                   help="instead, where the paper law's drift comes from (noise on q only, qd "
                        "only, another seed, half, gamma = 0)")
    p.add_argument("--laws", type=noise_laws, default=None,
                   help="laws, ';'-separated, among paper; 4,6; all (default: all three)")
    p.add_argument("--variants", type=noise_variants, default=None,
                   help="variants, comma-separated, among plain, dead zone, sigma, switching "
                        "(default: all; the clean run always)")
    p.add_argument("--out", type=output_dir, default="results/noise", help="output directory")


def add_startup(p):
    p.add_argument("--json", type=output_file, metavar="FILE",
                   help="also write the results as JSON")
    p.add_argument("--laws", type=startup_laws, default=None,
                   help="the controller's laws, comma-separated, among default, all, "
                        "joint_friction (default: default)")


def startup_laws(text):
    """``--laws``: comma-separated names of :data:`rcac_ros.tools.bench.startup.LAWS`, each
    once."""
    from rcac_ros.tools.bench.startup import LAWS
    return tuple(dict.fromkeys(_choices(text, ",", tuple(LAWS))))


def run_startup(args):
    from rcac_ros.tools.bench.startup import failures, run_startup_bench
    report = run_startup_bench(laws=args.laws or ("default",), json_path=args.json)
    bad = failures(report)
    for line in bad:
        print(f"rcac bench startup: {line}", file=sys.stderr)
    return 1 if bad else 0


def run_core(args):
    from rcac_ros.tools.bench.core import main
    return main(budget=args.budget, json_path=args.json, natural=args.natural)


def run_ros(args):
    from rcac_ros.tools.bench.ros import run_ros_bench
    result = run_ros_bench(args.duration, json_path=args.json, controller_mode=args.mode,
                           controller_overrides=controller_overrides(args),
                           simulator_overrides=simulator_overrides(args))
    return 0 if result else 1


def run_faults(args, cases=None, soak_minutes=None):
    from rcac_ros.tools.bench.faults import CASES, run_faults
    from rcac_ros.tools.bench.ros import BENCH_CONTROLLER
    if cases is None:
        cases = CASES if args.cases is None else args.cases
    run_faults(getattr(args, "duration", 60.0), cases,
               dict(BENCH_CONTROLLER, **controller_overrides(args)),
               simulator=simulator_overrides(args), json_path=args.json,
               plot_path=args.plot, soak_minutes=soak_minutes,
               discovery_range=args.discovery_range)
    return 0


def run_soak(args):
    from rcac_ros.tools.bench.fault_cases import start_busy, stop_busy
    if args.busy:
        print(f"soak: {args.busy} busy processes beside the nodes until the end", flush=True)
    busy = start_busy(args.busy)
    try:
        return run_faults(args, cases=("direct",), soak_minutes=args.minutes)
    finally:
        stop_busy(busy)


def run_delay_margin(args):
    from rcac_ros.tools.bench.delay_margin import check_margins, run_delay_margin
    if args.json is not None and not args.check:
        raise ConfigError("--json: the rows of --check; without it the sweep prints its table "
                          "(and --plot draws it)")
    if args.plot is not None and args.check:
        raise ConfigError("--plot: draws the sweep, which --check does not run")
    if args.check:
        rows = check_margins(json_path=args.json)
        return 0 if all(r["holds"] for r in rows) else 1
    run_delay_margin(gains=args.gains, delays=args.delays, plot_path=args.plot,
                     model_name=args.model, adapt=not args.frozen, predict=not args.no_predict)
    return 0


def run_noise(args):
    from rcac_ros.tools.bench.noise import run_noise_bench, run_noise_sources, VARIANTS
    if args.sources:
        run_noise_sources(args.duration, args.out)
    else:
        run_noise_bench(args.duration, args.out, laws=args.laws,
                        variants=args.variants or VARIANTS)
    return 0


#: benchmark -> (one-line help, its options, its run, what it needs)
BENCHMARKS = {
    "core": ("the controller against Pinocchio, the Slotine-Li baseline and itself, offline",
             add_core, run_core, ()),
    "ros": ("the two nodes over ROS 2 at 500 Hz (rate, jitter, latency)",
            add_ros, run_ros, ("ros",)),
    "faults": ("the closed loop over ROS under faults (drops, jitter, noise, simulator "
               "restart, frozen /clock, flood, hostile flood, starved machine, nodes "
               "joining)",
               add_faults, run_faults, ("ros",)),
    "soak": ("the direct fault case (no relay) for MINUTES (memory growth, late ticks)",
             add_soak, run_soak, ("ros",)),
    "delay-margin": ("offline, tracking RMS against K_D with the effort 0-2 periods late",
                     add_delay_margin, run_delay_margin, ()),
    "startup": ("how long the package takes to start, cold and warm (import, bad argument, "
                "the controller's first effort, the warm-up)", add_startup, run_startup,
                ("ros",)),
    "noise": ("10-minute closed loops with sensor noise (are the estimates bounded?)",
              add_noise, run_noise, ()),
}


def add_arguments(parser):
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK")
    sub.required = True
    for name, (help_text, add, _, _) in BENCHMARKS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        add(p)


def run(args):
    _, _, run_benchmark, needs = BENCHMARKS[args.benchmark]
    require(*needs)
    return run_benchmark(args)
