"""``rcac experiment``: the paper's Section 4 for the direct and the composite laws.

Both laws run on the CSS arm (Table 1, g = 0, frames of doc/design.md §5) from
``theta_hat(0) = 0``, with the paper's gains, the plant integrated by RK4 at the
control period with the torque held. Writes ``metrics.json``,
``tracking_errors.png`` (Figure 3) and ``parameter_estimates.png`` (Figure 4).
"""

import json
import os
import time

import numpy as np

from rcac_ros.core import PAPER_GAINS, PAPER_Q0, PaperTrajectory, css_arm
from rcac_ros.core.law_options import parse_channels
from rcac_ros.tools.args import (add_engine_argument, add_gain_arguments, check_period,
                                 output_dir, positive_float, positive_int)
from rcac_ros.tools.runs.closed_loop import closed_loop
from rcac_ros.tools.runs.metrics import estimates, LAST_WINDOW, prediction, torque, tracking


def metrics(run, theta_true, last_seconds=LAST_WINDOW):
    """The figures of ``metrics.json`` for one run (:mod:`rcac_ros.tools.runs.metrics`)."""
    return {**tracking(run["t"], run["q"] - run["q_d"], last_seconds),
            **estimates(run["theta_hat"], theta_true),
            **prediction(run["E"]), **torque(run["tau"])}


def run_experiment(duration=20.0, reading="velocity", gains=None, substeps=1, progress=True,
                   channels=(1,), engine="builtin"):
    """Section 4 for both laws: ``{"direct": run, "composite": run}`` and their metrics.

    ``channels``: the composite law's prediction channels (default the paper's, joint 1);
    ``engine``: the plant (``builtin`` or ``mujoco``, doc/plants.md).
    """
    model = css_arm()
    parse_channels(channels, model.n)                 # refused before a kernel is imported
    from rcac_ros.core import RecursiveCompositeController
    g = dict(PAPER_GAINS, **(gains or {}))
    q0 = np.array(PAPER_Q0)
    trajectory = PaperTrajectory(q0, reading=reading)
    runs, report = {}, {}
    for law, gamma in (("direct", 0.0), ("composite", g["gamma"])):
        ctrl = RecursiveCompositeController(model, **dict(g, gamma=gamma), channels=channels)
        t0 = time.perf_counter()
        runs[law] = closed_loop(ctrl, trajectory, duration, q0=q0, qd0=np.zeros(model.n),
                                substeps=substeps, strict=True, engine=engine,
                                progress=f"{law:>9s}" if progress else None)
        report[law] = metrics(runs[law], model.theta())
        report[law]["wall_time_s"] = time.perf_counter() - t0
    return model, runs, report


def write_outputs(model, runs, report, out_dir, settings):
    """metrics.json, tracking_errors.png and parameter_estimates.png into ``out_dir``."""
    from rcac_ros.tools.plots import plot_parameter_estimates, plot_tracking_errors
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, "metrics.json"), "w", encoding="utf-8") as f:
        json.dump(dict(report, settings=settings), f, indent=2)
    t = runs["direct"]["t"]
    plot_tracking_errors(t, {f"{law} adaptive": r["q"] - r["q_d"] for law, r in runs.items()},
                         os.path.join(out_dir, "tracking_errors.png"), list(model.joint_names),
                         title="Joint tracking errors (Figure 3)")
    plot_parameter_estimates(t, {law: r["theta_hat"][:, -1] for law, r in runs.items()},
                             model.theta()[-1], os.path.join(out_dir, "parameter_estimates.png"),
                             link=model.n)


def add_arguments(parser):
    from rcac_ros.tools.demos.compare import channel_list
    parser.add_argument("--duration", type=positive_float, default=20.0,
                        help="seconds (default 20)")
    parser.add_argument("--out", type=output_dir, default="results/experiment",
                        help="output directory")
    parser.add_argument("--trajectory", choices=("velocity", "position"), default="velocity",
                        help="reading of the paper's desired motion (doc/design.md §5)")
    add_gain_arguments(parser, PAPER_GAINS, (
        ("K_D", "link gain K_Di = K_D I6"),
        ("Lambda", "Lambda = value * I"),
        ("P", "adaptation gain P_i = P I13"),
        ("gamma", "prediction-error weight of the composite law"),
        ("lam", "filter bandwidth lambda, rad/s"),
        ("h", "control period, s")))
    parser.add_argument("--substeps", type=positive_int, default=1,
                        help="RK4 steps of the plant per control period (default 1)")
    add_engine_argument(parser)
    parser.add_argument("--channels", type=channel_list, default=(1,),
                        help="prediction channels of the composite law, e.g. 1,power or all "
                             "(default 1, the paper's)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args):
    check_period(args.h, args.duration)
    gains = dict(K_D=args.K_D, Lambda=args.Lambda, P=args.P, gamma=args.gamma, lam=args.lam,
                 h=args.h)
    engine = args.engine or "builtin"
    model, runs, report = run_experiment(args.duration, args.trajectory, gains, args.substeps,
                                         progress=not args.quiet, channels=args.channels,
                                         engine=engine)
    settings = dict(gains, duration=args.duration, trajectory=args.trajectory,
                    channels=[str(c) for c in args.channels],
                    substeps=args.substeps, model="css_arm", q0=list(PAPER_Q0), engine=engine)
    write_outputs(model, runs, report, args.out, settings)
    keys = [k for k in report["direct"] if k != "wall_time_s"]
    print(f"{'metric':34s} {'direct':>14s} {'composite':>14s}")
    for k in keys:
        print(f"{k:34s} {report['direct'][k]:14.6g} {report['composite'][k]:14.6g}")
    print(f"wrote {args.out}/metrics.json, tracking_errors.png, parameter_estimates.png")
    return 0
