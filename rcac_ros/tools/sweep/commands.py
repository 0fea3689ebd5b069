"""``rcac sweep``: Monte Carlo campaigns of closed-loop runs on Dask distributed.

Four forms::

    rcac sweep CAMPAIGN --out DIR [--samples N] [--duration S] [--workers K]
               [--scheduler tcp://HOST:PORT] [--chunk C] [--resume]
    rcac sweep report RESULTS [--worst N] [--plot PNG]
    rcac sweep rerun RESULTS INDEX [--plot PNG]
    rcac sweep --bench [CAMPAIGN] [--samples N] [--duration S] [--out DIR]

The command line only: the campaign file is :mod:`~rcac_ros.tools.sweep.campaign`, the
runs on Dask :mod:`~rcac_ros.tools.sweep.engine`, the results directory
:mod:`~rcac_ros.tools.sweep.store`, the summary and the rerun
:mod:`~rcac_ros.tools.sweep.report`, ``--bench`` :mod:`~rcac_ros.tools.sweep.bench`
(doc/campaigns.md).
"""

import argparse
import time

from rcac_ros.errors import ConfigError
from rcac_ros.tools.args import (non_negative_int, output_dir, output_file, positive_float,
                                 positive_int)
from rcac_ros.tools.sweep import campaign as cp

ACTIONS = ("report", "rerun")


def scheduler_address(text):
    """argparse type of ``--scheduler``: ``tcp://HOST:PORT`` (or another Dask protocol)."""
    proto, sep, rest = text.partition("://")
    host, colon, port = rest.rpartition(":")
    if not sep or not proto or not colon or not host or not port.isdigit():
        raise argparse.ArgumentTypeError(f"expected tcp://HOST:PORT, got {text!r}")
    return text


def add_arguments(parser, argv=()):
    """The run form, or (``rcac sweep report|rerun ...``: ``argv``, the words after
    ``sweep``, starts with one) the two result subcommands."""
    parser.epilog = ("also: 'rcac sweep report RESULTS' (summary and plot) and "
                     "'rcac sweep rerun RESULTS INDEX' (one run again, alone)")
    if argv[:1] and argv[0] in ACTIONS:
        sub = parser.add_subparsers(dest="action", metavar="ACTION")
        sub.required = True
        rep = sub.add_parser("report", help="failure rate, worst cases, distributions, "
                             "sensitivity; printed and plotted")
        rep.add_argument("results", help="a results directory or its results.parquet")
        rep.add_argument("--worst", type=positive_int, default=10,
                         help="worst runs listed (default 10)")
        rep.add_argument("--plot", type=output_file, default=None,
                         help="PNG (default RESULTS_DIR/report.png)")
        rep.add_argument("--json", type=output_file, default=None, metavar="FILE",
                         help="also write the summary as JSON")
        rer = sub.add_parser("rerun", help="rerun one run alone and compare with its row")
        rer.add_argument("results", help="a results directory or its results.parquet")
        rer.add_argument("index", type=non_negative_int, help="the run's index")
        rer.add_argument("--plot", type=output_file, default=None,
                         help="PNG (default RESULTS_DIR/rerun_INDEX.png)")
        return
    parser.set_defaults(action="run")
    parser.add_argument("campaign", nargs="?", metavar="CAMPAIGN", help="campaign YAML file")
    parser.add_argument("--out", type=output_dir, default=None, metavar="DIR",
                        help="results directory")
    parser.add_argument("--samples", type=positive_int, metavar="N", default=None,
                        help="random draws per grid cell (overrides the campaign's)")
    parser.add_argument("--duration", type=positive_float, metavar="S", default=None,
                        help="seconds simulated per run (overrides the scenario's)")
    parser.add_argument("--workers", type=non_negative_int, metavar="K", default=None,
                        help="LocalCluster workers (default: one per core; 0: this process, "
                             "no Dask)")
    parser.add_argument("--scheduler", type=scheduler_address, metavar="ADDRESS", default=None,
                        help="address of a running Dask scheduler, tcp://HOST:PORT")
    parser.add_argument("--chunk", type=positive_int, metavar="C", default=None,
                        help="runs per task (default: about 8 tasks per worker, <= 25)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the campaign in --out, skipping finished runs")
    parser.add_argument("--bench", action="store_true",
                        help="runs/s on 1 and 2 workers, scaling efficiency, overhead per run")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args):
    """The form's work; every argument, and the campaign file, is checked before Dask or a
    kernel is imported."""
    if args.action == "report":
        from rcac_ros.tools.sweep.report import report
        return report(args.results, worst=args.worst, plot=args.plot, json_path=args.json)
    if args.action == "rerun":
        from rcac_ros.tools.sweep.report import rerun
        return rerun(args.results, args.index, plot=args.plot)
    if args.bench:
        if args.campaign is not None:
            cp.load(args.campaign)                # a bad file stops here, before Dask loads
        from rcac_ros.tools.sweep.bench import bench
        return bench(args.campaign, args.samples, args.duration, args.out)
    if args.campaign is None:
        raise ConfigError("CAMPAIGN: missing (rcac sweep CAMPAIGN --out DIR)")
    if args.out is None:
        raise ConfigError("--out: missing (the results directory)")
    if args.scheduler is not None and args.workers is not None:
        raise ConfigError("--workers: not with --scheduler (the cluster has its workers)")
    campaign = cp.with_overrides(cp.load(args.campaign), args.samples, args.duration)
    total = cp.run_count(campaign)
    from rcac_ros.tools.sweep.engine import execute, reachable
    from rcac_ros.tools.sweep.store import Store
    cp.setup(campaign, 0)                  # a campaign that cannot build a run fails here
    if args.scheduler is not None:
        reachable(args.scheduler)          # before the results directory is claimed
    store = Store(args.out)
    store.claim(campaign, resume=args.resume)
    t0 = time.perf_counter()
    done = execute(campaign, store, workers=args.workers, scheduler=args.scheduler,
                   chunk=args.chunk, progress=not args.quiet)
    table = store.merge()
    failed = int(sum(table.column("diverged").to_pylist()))
    print(f"{done} runs in {time.perf_counter() - t0:.1f} s; {table.num_rows}/{total} runs in "
          f"{store.results}; {failed} diverged; summary and plot: rcac sweep report {args.out}")
    return 0
