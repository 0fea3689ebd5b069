"""``rcac payload-demo``: a Panda arm picks up an unknown 2 kg payload.

The Panda (7 joints, gravity on) is loaded from example-robot-data's URDF
(``panda_link0`` -> ``panda_link8``; the hand and the locked fingers are part of
link 7). Every controller starts from the URDF's nominal parameters. At
``t = jump`` a payload (default 2 kg, centre of mass offset from the flange) is
rigidly attached to link 7 in the simulator only: the plant is rebuilt with
``model.replace(...)`` and its state carried over. Three laws with the same
feedback are compared:

- ``composite``: the recursive composite adaptive law (eq 24, ``gamma > 0``);
- ``direct``: the same with ``gamma = 0``;
- ``fixed``: computed torque with ``theta_hat`` fixed at nominal (``P = 1e-12 I``,
  ``gamma = 0``: the same recursion, adaptation off).

Gains at the Panda's scale: ``K_Di = kappa M_i`` (the link's nominal 6x6 spatial
inertia, so the feedback is ``kappa`` rad/s on every link whatever its size;
``K_D = 1e4 I`` suits the 600 kg CSS arm, not 1 kg wrist links at 2 ms), and
``P_7 = rho diag(s)^2`` with ``s`` the expected size of each of the 13
parameters (kg, kg m, kg m^2). Links 1-6 are known (``P = 1e-12 I``) unless
``--adapt-all``. Writes ``metrics.json``, ``tracking_errors.png``,
``payload_summary.png`` and ``link7_estimates.png``.
"""

import json
import os
import time

import numpy as np

from rcac_ros.core import ConfigError, SinusoidTrajectory
from rcac_ros.tools.runs import metrics as measure
from rcac_ros.tools.args import (add_engine_argument, add_gain_arguments, check_period,
                                 existing_file, finite_float, non_negative_float, output_dir,
                                 positive_float)
from rcac_ros.tools.runs.closed_loop import closed_loop
from rcac_ros.tools.runs.scenarios import (AMPLITUDE, FREQUENCY, GAINS, gains_for, load_panda,
                                           READY, with_payload)


def window_rms(run, start, stop):
    """RMS of ``q - q_d`` over all joints for ``start <= t < stop``."""
    return measure.window_rms(run["t"], run["q"] - run["q_d"], start, stop)


def metrics(run, jump, theta_before, theta_after, window=1.0, effort_limit=None):
    """The figures of ``metrics.json`` for one law (doc/results.md, "An unknown payload")."""
    t_end = run["t"][-1]
    e = np.linalg.norm(run["q"] - run["q_d"], axis=1)
    after = run["t"] >= jump
    est = run["theta_hat"][-1, -1]
    first = theta_after[1:4]
    out = {
        "rms_error_before_jump": window_rms(run, max(0.0, jump - window), jump),
        "rms_error_first_window_after_jump": window_rms(run, jump, jump + window),
        "rms_error_last_window": window_rms(run, t_end - window, t_end + 1.0),
        "peak_error_norm_after_jump": float(e[after].max()),
        "link7_mass_true": float(theta_after[0]),
        "link7_mass_nominal": float(theta_before[0]),
        "link7_mass_estimate_end": float(est[0]),
        "link7_mass_relative_error_end": float(abs(est[0] - theta_after[0]) / theta_after[0]),
        "link7_first_moments_true": theta_after[1:4].tolist(),
        "link7_first_moments_estimate_end": est[1:4].tolist(),
        "link7_first_moments_relative_error_end": float(np.linalg.norm(est[1:4] - first)
                                                        / np.linalg.norm(first)),
    }
    if effort_limit is not None:
        out["max_torque_over_effort_limit"] = float(np.max(np.abs(run["tau"]) / effort_limit))
    out["recovery_ratio"] = (out["rms_error_last_window"]
                             / out["rms_error_first_window_after_jump"])
    within = np.abs(run["theta_hat"][:, -1, 0] - theta_after[0]) <= 0.05 * theta_after[0]
    outside = np.nonzero(after & ~within)[0]
    settled = outside[-1] + 1 if outside.size else np.nonzero(after)[0][0]
    out["link7_mass_settling_time_5pct"] = (float(run["t"][settled] - jump)
                                            if settled < len(run["t"]) else None)
    return out


def run_demo(duration=20.0, jump=5.0, payload_mass=2.0, payload_com=(0.03, -0.02, 0.08),
             gains=None, adapt_all=False, urdf=None, progress=True, laws=None,
             engine="builtin"):
    """The three laws on the Panda with a payload attached at ``jump``.

    ``engine``: the plant (``builtin`` or ``mujoco``, doc/plants.md). Returns ``(model,
    loaded, runs, report)``.
    """
    g = dict(GAINS, **(gains or {}))
    model = load_panda(urdf)
    loaded = with_payload(model, payload_mass, payload_com)
    from rcac_ros.core import RecursiveCompositeController   # once the URDF has loaded
    trajectory = SinusoidTrajectory(np.array(READY), AMPLITUDE, FREQUENCY)
    runs, report = {}, {}
    for law in laws or ("composite", "direct", "fixed"):
        ctrl = RecursiveCompositeController(model, **gains_for(model, adapt_all=adapt_all,
                                                               law=law, **g))
        t0 = time.perf_counter()
        runs[law] = closed_loop(ctrl, trajectory, duration, events=((jump, loaded),), strict=True,
                                progress=f"{law:>9s}" if progress else None, progress_every=250,
                                engine=engine)
        report[law] = metrics(runs[law], jump, model.theta()[-1], loaded.theta()[-1],
                              effort_limit=model.effort_limit)
        report[law]["wall_time_s"] = time.perf_counter() - t0
    return model, loaded, runs, report


def write_outputs(model, loaded, runs, report, out_dir, settings, jump):
    """metrics.json and the three figures into ``out_dir``."""
    from rcac_ros.tools.plots import plot_parameter_estimates, plot_tracking_errors, plt, save

    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, "metrics.json"), "w", encoding="utf-8") as f:
        json.dump(dict(report, settings=settings), f, indent=2)
    t = next(iter(runs.values()))["t"]
    plot_tracking_errors(t, {law: r["q"] - r["q_d"] for law, r in runs.items()},
                         os.path.join(out_dir, "tracking_errors.png"), list(model.joint_names),
                         title=f"Panda tracking errors, payload attached at t = {jump:g} s")
    plot_parameter_estimates(t, {law: r["theta_hat"][:, -1] for law, r in runs.items()},
                             loaded.theta()[-1], os.path.join(out_dir, "link7_estimates.png"),
                             link=model.n)
    truth = np.where(t[:, None] >= jump, loaded.theta()[-1], model.theta()[-1])
    fig, axes = plt.subplots(1, 5, figsize=(22, 4))
    for law, r in runs.items():
        axes[0].semilogy(t, np.linalg.norm(r["q"] - r["q_d"], axis=1) + 1e-12, lw=0.8,
                         label=law)
        for k in range(4):
            axes[k + 1].plot(t, r["theta_hat"][:, -1, k], lw=1.0, label=law)
    for k, label in enumerate(("mass m (kg)", "m px (kg m)", "m py (kg m)", "m pz (kg m)")):
        axes[k + 1].plot(t, truth[:, k], "k--", lw=0.9, label="true")
        axes[k + 1].set_title(f"link 7 {label}")
    axes[0].set_title("|q - q_d| (rad)")
    axes[0].set_ylim(bottom=1e-7)
    for ax in axes:
        ax.axvline(jump, color="grey", lw=0.6)
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    save(fig, os.path.join(out_dir, "payload_summary.png"), 110)


def add_arguments(parser):
    parser.add_argument("--duration", type=positive_float, default=20.0,
                        help="seconds (default 20)")
    parser.add_argument("--jump", type=non_negative_float, default=5.0,
                        help="time the payload is attached, s (default 5)")
    parser.add_argument("--payload-mass", type=non_negative_float, default=2.0,
                        help="kg (default 2)")
    parser.add_argument("--payload-com", type=finite_float, nargs=3, default=(0.03, -0.02, 0.08),
                        metavar=("X", "Y", "Z"),
                        help="payload centre of mass in the flange frame, m "
                             "(default 0.03 -0.02 0.08)")
    parser.add_argument("--out", type=output_dir, default="results/payload_demo",
                        help="output directory")
    parser.add_argument("--urdf", type=existing_file, default=None,
                        help="panda.urdf (default: example-robot-data's)")
    add_gain_arguments(parser, GAINS, (
        ("kappa", "link gain K_Di = kappa * M_i (rad/s)"),
        ("Lambda", "Lambda = value * I"),
        ("rho", "adaptation gain P_7 = rho * diag(parameter scale)^2"),
        ("gamma", "prediction-error weight of the composite law"),
        ("lam", "filter bandwidth lambda, rad/s"),
        ("h", "control period, s")))
    parser.add_argument("--adapt-all", action="store_true",
                        help="adapt links 1-6 too (default: only link 7)")
    add_engine_argument(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress line")


def run(args):
    gains = {k: getattr(args, k) for k in GAINS}
    check_period(args.h, args.duration)
    if args.jump >= args.duration:
        raise ConfigError(f"--jump: the payload must attach before the end of the run "
                          f"(--duration {args.duration:g} s), got {args.jump:g} s")
    engine = args.engine or "builtin"
    model, loaded, runs, report = run_demo(args.duration, args.jump, args.payload_mass,
                                           args.payload_com, gains, args.adapt_all, args.urdf,
                                           progress=not args.quiet, engine=engine)
    settings = dict(gains, duration=args.duration, jump=args.jump,
                    payload_mass=args.payload_mass, payload_com_flange=list(args.payload_com),
                    adapt_all=args.adapt_all, model=model.name, tip_link="panda_link8",
                    q_center=list(READY), amplitude=list(AMPLITUDE), frequency=list(FREQUENCY),
                    engine=engine)
    write_outputs(model, loaded, runs, report, args.out, settings, args.jump)
    laws = list(report)
    keys = [k for k in report[laws[0]] if not isinstance(report[laws[0]][k], list)
            and k != "wall_time_s"]
    print(f"{'metric':36s}" + "".join(f"{law:>14s}" for law in laws))
    for k in keys:
        cells = "".join(f"{'-':>14s}" if report[law][k] is None else f"{report[law][k]:14.6g}"
                        for law in laws)
        print(f"{k:36s}{cells}")
    print(f"wrote {args.out}/metrics.json, tracking_errors.png, payload_summary.png, "
          "link7_estimates.png")
    return 0
