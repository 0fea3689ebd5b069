"""``rcac compare``: every adaptive law on the paper's experiment, the panda payload, and the
panda with joint friction and rotor inertia on MuJoCo.

Laws (:data:`LAWS`): computed torque at the nominal parameters (``fixed``), the direct
law (``gamma = 0``), the paper's composite law (joint-1 channel), ``channels="all"`` with
the implicit and the explicit update, the power channel, fixed-m channel sets,
least-squares variants, the non-recursive Slotine-Li law, the direct, paper and
``"all"`` laws with the joint terms (``*_friction``, doc/design.md §7), and the natural
geometry (``*_natural``, doc/design.md §8: estimates that stay physical bodies) with the
Euclidean paper and ``"all"`` laws from the same start (``paper_nat_start``,
``all_nat_start``), and its barrier-plus-quadratic metric (``*_barrier``, on request). Scenarios
(:data:`SCENARIOS`):

- ``paper``: Section 4, the CSS arm (g = 0), paper gains, ``theta_hat(0) = 0``, the
  velocity reading of the desired motion (``rcac experiment``'s run);
- ``payload``: the panda with gravity, a 2 kg payload attached to link 7 at t = 5 s,
  the demo's gains, ``theta_hat(0)`` = the URDF's (``rcac payload-demo``'s run);
- ``panda_joints`` and its variants (:data:`JOINT_PLANTS`): the panda on MuJoCo
  (doc/plants.md) whose joints have viscous damping 0.5 N m s/rad, dry friction 0.5 N m
  (MuJoCo's friction loss) and rotor inertia 0.1 kg m^2 (``panda_joints``: all three;
  ``panda_rigid``, ``panda_damping``, ``panda_friction``, ``panda_armature``,
  ``panda_damping_armature``), the payload demo's motion and gains, every link adapting
  from the URDF's nominal parameters (no payload): a plant outside the laws' rigid-body
  model class. ``--scenarios joint_table`` runs the five rows of the joint-friction blocks
  of doc/results.md.

Every law gets the scenario's gains; a law only changes the channels, the update or the
adaptation gain. Each scenario has its default laws (``--laws`` overrides them all) and
its plant engine (``--engine`` overrides it). Writes ``compare.json``, ``compare.md`` (the
table; with several scenarios, first their RMS side by side), one figure per
scenario (``compare_<scenario>.png``: tracking error, parameter error, last link's mass
estimate, max |E_c| on log scales, the smallest ``lambda_min(J_hat_i)`` over time) and the
identifiability report of each run (the accumulated excitation ``sum h W_i^T W_i`` per
link, and the physical consistency of the final estimates,
:mod:`rcac_ros.core.identifiability`). Per law the table says which share of the
link-steps were consistent (``J(theta_hat_i) > 0``) and the smallest ``lambda_min``.
"""

import argparse
import json
import os

import numpy as np

from rcac_ros.core import PAPER_GAINS, PAPER_Q0, PaperTrajectory, SinusoidTrajectory, css_arm
from rcac_ros.core.law_options import parse_channels
from rcac_ros.errors import RcacError
from rcac_ros.plants import with_joint_terms
from rcac_ros.tools.runs import metrics as measure
from rcac_ros.tools.args import add_engine_argument, output_dir, positive_float
from rcac_ros.tools.runs.closed_loop import closed_loop
from rcac_ros.core.law_options import P_FRICTION as P_FRICTION_DEFAULT
from rcac_ros.tools.demos.compare_report import markdown
from rcac_ros.tools.runs.scenarios import controller, FIXED_P

#: Forgetting rate lambda_0 (1/s) of the least-squares laws (bound: trace(P_i(0)), per link).
LS_FORGETTING = 1.0

#: A law's ``theta_hat0`` that means: the natural geometry's default start (doc/design.md §8)
#: where the scenario gives none.
NATURAL_START = "natural_default"

#: ``P_friction`` of the friction-aware laws: the library's default, each joint's gain scaled
#: from its feedback at the start (doc/design.md §7 "Joint terms without per-arm tuning").
INERTIA_SCALED = P_FRICTION_DEFAULT

#: law -> (controller class, keyword arguments on top of the scenario's gains).
#: "4,6" and "4..7" are the best fixed-m channel sets found by a search over both scenarios
#: (in-sample: [2], [1,2], [2,3], [1,2,3], [2,3,4], [1,2,3,4], [4], [3,4], [4,7], [5,6,7],
#: [2,4,6], [2,3,5,6], [3..7], [2..7], with and without "power").
LAWS = {
    "fixed": ("rcac", dict(P=FIXED_P, gamma=0.0)),
    "direct": ("rcac", dict(gamma=0.0)),
    "paper": ("rcac", {}),
    "all": ("rcac", dict(channels="all")),
    "all_explicit": ("rcac", dict(channels="all", update="explicit")),
    "power": ("rcac", dict(channels="power")),
    "1+power": ("rcac", dict(channels=[1, "power"])),
    "4,6": ("rcac", dict(channels=[4, 6])),
    "4..7": ("rcac", dict(channels=[4, 5, 6, 7])),
    "ls_paper": ("rcac", dict(adaptation="least_squares", forgetting=LS_FORGETTING)),
    "ls_all": ("rcac", dict(channels="all", adaptation="least_squares",
                            forgetting=LS_FORGETTING)),
    "ls_pred_all": ("rcac", dict(channels="all", adaptation="least_squares_prediction",
                                 forgetting=LS_FORGETTING)),
    "ls_pred_4,6": ("rcac", dict(channels=[4, 6], adaptation="least_squares_prediction",
                                 forgetting=LS_FORGETTING)),
    "slotine_li": ("slotine_li", {}),
    "slotine_li_natural": ("slotine_li", dict(geometry="natural", natural_metric="log_det")),
    "slotine_li_barrier": ("slotine_li", dict(geometry="natural", natural_metric="barrier")),
    # doc/design.md §8: estimates kept physically consistent ("*_natural": the log-det
    # metric, "*_barrier": the barrier metric, the default); "paper_nat_start" and
    # "all_nat_start" are the Euclidean laws from the natural geometry's default start (the
    # same start: the paired comparison)
    "paper_nat_start": ("rcac", dict(theta_hat0=NATURAL_START)),
    "all_nat_start": ("rcac", dict(channels="all", theta_hat0=NATURAL_START)),
    "paper_natural": ("rcac", dict(geometry="natural", natural_metric="log_det")),
    "all_natural": ("rcac", dict(channels="all", geometry="natural", natural_metric="log_det")),
    # the barrier-plus-quadratic metric of the natural geometry (doc/design.md §8), the
    # default of geometry="natural": run on request only (not in DEFAULT_LAWS)
    "paper_barrier": ("rcac", dict(geometry="natural", natural_metric="barrier")),
    "all_barrier": ("rcac", dict(channels="all", geometry="natural", natural_metric="barrier")),
    # with the joint terms: on a plant with dry friction the rigid-body natural law's J_hat
    # escapes to infinity (doc/design.md §8, "Unmodelled joint effects"); this one is bounded
    "paper_natural_friction": ("rcac", dict(geometry="natural", natural_metric="log_det",
                                            joint_friction=True, P_friction=INERTIA_SCALED)),
    "paper_barrier_friction": ("rcac", dict(geometry="natural", natural_metric="barrier",
                                            joint_friction=True, P_friction=INERTIA_SCALED)),
    "ls_natural": ("rcac", dict(adaptation="least_squares", forgetting=LS_FORGETTING,
                                geometry="natural")),
    # the joint terms (doc/design.md §7) with the library's default gain, scaled from each
    # joint's feedback: the direct and paper laws adapt them mostly from the tracking term
    # (an explicit step, beta_f = 30 s); "all" from every joint's channel (beta_f = 100 s)
    "direct_friction": ("rcac", dict(gamma=0.0, joint_friction=True,
                                     P_friction=INERTIA_SCALED)),
    "paper_friction": ("rcac", dict(joint_friction=True, P_friction=INERTIA_SCALED)),
    "all_friction": ("rcac", dict(channels="all", joint_friction=True,
                                  P_friction=INERTIA_SCALED)),
}

#: The laws the paper and payload scenarios run by default (every law but ``fixed``, the
#: ``*_friction`` and the ``*_barrier`` ones).
DEFAULT_LAWS = tuple(law for law in LAWS if law != "fixed"
                     and not law.endswith(("_friction", "_barrier")))

#: The laws of the joint-friction scenarios (the rows of doc/results.md's joint-friction
#: blocks); a law added to :data:`LAWS` and to this list joins the table.
JOINT_LAWS = ["fixed", "direct", "paper", "all", "direct_friction", "paper_friction",
              "all_friction"]

#: scenario -> (damping N m s/rad, dry friction N m, armature kg m^2), the same on every joint
#: of the panda on MuJoCo (the friction is MuJoCo's friction loss, doc/plants.md).
JOINT_PLANTS = {
    "panda_joints": (0.5, 0.5, 0.1),
    "panda_rigid": (0.0, 0.0, 0.0),
    "panda_damping": (0.5, 0.0, 0.0),
    "panda_friction": (0.0, 0.5, 0.0),
    "panda_armature": (0.0, 0.0, 0.1),
    "panda_damping_armature": (0.5, 0.0, 0.1),
}

#: Names that stand for several scenarios: the rows of doc/results.md's joint-friction blocks.
GROUPS = {"joint_table": ("panda_rigid", "panda_damping", "panda_friction", "panda_armature",
                          "panda_joints")}


class Scenario:
    """One closed-loop setting: plant(s), desired motion, gains and the true parameters.

    ``model`` is the controllers' model; ``plant`` the true arm (default ``model``),
    ``loaded`` the arm from ``jump`` on; ``engine`` the plant's engine and ``laws`` the laws
    run by default.
    """

    def __init__(self, name, model, gains, trajectory, q0, qd0, loaded=None, jump=None,
                 plant=None, engine="builtin", laws=DEFAULT_LAWS):
        self.name, self.model, self.gains, self.trajectory = name, model, gains, trajectory
        self.q0, self.qd0, self.loaded, self.jump = q0, qd0, loaded, jump
        self.plant = model if plant is None else plant
        self.engine, self.laws = engine, tuple(laws)
        self.theta_end = (loaded or model).theta()


def paper_scenario():
    model = css_arm()
    q0 = np.array(PAPER_Q0)
    return Scenario("paper", model, dict(PAPER_GAINS), PaperTrajectory(q0), q0,
                    np.zeros(model.n))


def payload_scenario():
    from rcac_ros.tools.runs.scenarios import (AMPLITUDE, FREQUENCY, GAINS, READY, gains_for,
                                               load_panda, with_payload)
    model = load_panda()
    traj = SinusoidTrajectory(np.array(READY), AMPLITUDE, FREQUENCY)
    q0, qd0, _ = traj(0.0)
    return Scenario("payload", model, gains_for(model, law="composite", **GAINS), traj, q0,
                    qd0, loaded=with_payload(model), jump=5.0)


def joint_scenario(name):
    """The panda on MuJoCo with the joint terms of :data:`JOINT_PLANTS` ``[name]``."""
    from rcac_ros.tools.runs.scenarios import (AMPLITUDE, FREQUENCY, GAINS, READY, gains_for,
                                               load_panda)
    model = load_panda()
    damping, friction, armature = JOINT_PLANTS[name]
    traj = SinusoidTrajectory(np.array(READY), AMPLITUDE, FREQUENCY)
    q0, qd0, _ = traj(0.0)
    return Scenario(name, model, gains_for(model, law="composite", adapt_all=True, **GAINS),
                    traj, q0, qd0, plant=with_joint_terms(model, damping, friction, armature),
                    engine="mujoco", laws=JOINT_LAWS)


SCENARIOS = {"paper": paper_scenario, "payload": payload_scenario,
             **{name: (lambda name=name: joint_scenario(name)) for name in JOINT_PLANTS}}


def scenario_names(names):
    """``names`` with every group (:data:`GROUPS`) expanded, each scenario once."""
    out = []
    for name in names:
        for one in GROUPS.get(name, (name,)):
            if one not in out:
                out.append(one)
    return out


def friction_gain_for(scenario):
    """``P_friction`` (n, 3) the friction-aware direct and paper laws use on ``scenario``: the
    library's :func:`~rcac_ros.core.joint_friction.feedback_scaled_gain` at its start with
    ``beta_f`` = 30 s (``all_friction``: 100 s, doc/design.md §7)."""
    from rcac_ros.core.joint_friction import feedback_scaled_gain
    return feedback_scaled_gain(scenario.model, np.asarray(scenario.gains["K_D"], float),
                                scenario.q0)


def make_controller(scenario, law, laws=None):
    from rcac_ros.core.pseudo_inertia import default_start
    kind, extra = (laws or LAWS)[law]
    kwargs = dict(scenario.gains, **extra)
    if isinstance(kwargs.get("theta_hat0"), str):
        start = scenario.gains.get("theta_hat0")
        kwargs["theta_hat0"] = default_start(scenario.model.theta()) if start is None else start
    return controller(kind, scenario.model, kwargs)


def run_law(scenario, controller, duration, progress=None, engine=None):
    """Close the loop (:func:`~rcac_ros.tools.runs.closed_loop.closed_loop`) on the scenario.

    The run stops at the first period whose estimates or prediction errors are not finite
    (``check_estimates``). Returns the time series of the table and the figure, one row
    a period and each taken after that period's update: ``t``, ``e`` (``q - q_d``),
    ``theta_error`` (``||theta_hat - theta||``, the true ``theta`` of the plant then in
    use), ``mass_last`` (the last link's mass estimate), ``E`` (``max_c |E_c|``),
    ``lambda_min`` (per link, ``lambda_min(J(theta_hat_i))``, doc/design.md §8); a
    diverged run's last row has no estimates (NaN) and ``diverged_at`` is its time.
    With them ``us_per_step`` (the controller's step alone), ``excitation`` (the
    accumulated ``sum h W^T W`` of a recursive law, else None) and ``theta_end``.
    ``engine`` overrides the scenario's plant engine.
    """
    from rcac_ros.core.identifiability import Excitation
    from rcac_ros.core.pseudo_inertia import lambda_min
    exc = Excitation(scenario.model.n, controller.h) if hasattr(controller, "channels") else None
    events = () if scenario.loaded is None else ((scenario.jump, scenario.loaded),)
    run = closed_loop(controller, scenario.trajectory, duration, plant=scenario.plant,
                      q0=scenario.q0, qd0=scenario.qd0, events=events, check_estimates=True,
                      engine=engine or scenario.engine,
                      observer=None if exc is None else lambda k, ctrl, sim: exc.add(ctrl.W),
                      progress=progress, progress_every=250)
    t = run["t"]
    theta_end = controller.theta_hat
    # the estimates after period k are those before period k + 1, or the final ones
    theta = np.concatenate([run["theta_hat"][1:], theta_end[None]])
    E = np.max(np.abs(run["E"].reshape(len(t), -1)), axis=1)
    diverged = run["status"] != "ok"
    if diverged:                          # the last period's estimates are not finite
        theta[-1], E[-1] = np.nan, np.nan
    truth = np.broadcast_to(scenario.model.theta(), theta.shape).copy()
    if scenario.loaded is not None:                  # closed_loop's event rule
        truth[t >= scenario.jump - 1e-12] = scenario.theta_end
    with np.errstate(all="ignore"):                  # a diverged law's huge estimates
        theta_error = np.array([np.linalg.norm(d) for d in theta - truth])
    with np.errstate(all="ignore"):
        lam = np.full(theta.shape[:2], np.nan)
        ok = np.all(np.isfinite(theta), axis=(1, 2))
        lam[ok] = lambda_min(theta[ok])
    return dict(t=t, e=run["q"] - run["q_d"], theta_error=theta_error,
                mass_last=theta[:, -1, 0], E=E, lambda_min=lam,
                diverged_at=float(t[-1]) if diverged else None,
                us_per_step=run["step_time"] / len(t) * 1e6, excitation=exc,
                theta_end=theta_end)


def metrics(run, scenario, last_seconds=5.0):
    """The table's figures for one run (NaN where a diverged run has no value)."""
    from rcac_ros.core.identifiability import summary
    t, e = run["t"], run["e"]
    ok = np.all(np.isfinite(e), axis=1)
    fig = measure.tracking(t[ok], e[ok], last_seconds) if ok.any() else {}
    out = {
        "rms": fig.get("rms_tracking_error", float("nan")),
        "rms_last_5s": fig.get("rms_tracking_error_last_5s", float("nan")),
        "max_error": fig.get("max_tracking_error", float("nan")),
        "theta_error_start": float(run["theta_error"][0]),
        "theta_error_end": float(np.linalg.norm(run["theta_end"] - scenario.theta_end)),
        "max_abs_E": float(np.nanmax(run["E"])),
        "us_per_step": float(run["us_per_step"]),
        "diverged_at": run["diverged_at"],
    }
    if run["diverged_at"] is not None:
        out["rms_last_5s"] = out["theta_error_end"] = float("nan")
    if scenario.jump is not None:
        after = ok & (t >= scenario.jump)
        out["rms_after_payload"] = measure.rms(e[after]) if after.any() else float("nan")
    lam = run["lambda_min"]
    finite = np.all(np.isfinite(lam), axis=1)
    out["consistent_steps"] = float(np.mean(lam[finite] > 0.0)) if finite.any() else 0.0
    out["consistent_every_step"] = bool(finite.all() and (lam > 0.0).all())
    out["lambda_min"] = float(np.min(lam[finite])) if finite.any() else float("nan")
    out["mass_last_end"] = float(run["mass_last"][ok][-1])
    if scenario.jump is not None:
        est, true = run["theta_end"][-1], scenario.theta_end[-1]
        out["payload_mass_error"] = float(abs(est[0] - true[0]))
        out["payload_first_moment_error"] = float(np.linalg.norm(est[1:4] - true[1:4]))
    out["mass_last_true"] = float(scenario.theta_end[-1, 0])
    if run["excitation"] is not None and run["diverged_at"] is None:
        ident = summary(run["excitation"], run["theta_end"])
        out["identifiable"] = ident["identifiable_combinations_total"]
        out["consistent"] = ident["consistent_links"]
        out["identifiability"] = ident
    return out


def compare(scenarios=("paper", "payload"), laws=None, duration=20.0, progress=True,
            extra_channels=None, engine=None):
    """Run the laws on every scenario: ``{scenario: {law: metrics}}`` and the time series.

    ``laws``: the same laws on every scenario (default: each scenario's own); ``engine``:
    the plant of every scenario (default: each scenario's own); ``scenarios`` may name
    groups (:data:`GROUPS`).
    """
    report, series = {}, {}
    for name in scenario_names(scenarios):
        scenario = SCENARIOS[name]()
        if extra_channels is not None:               # refused before a run, with one line
            parse_channels(extra_channels, scenario.model.n)
        table = {law: LAWS[law] for law in (scenario.laws if laws is None else laws)}
        if extra_channels is not None:
            key = "channels=" + ",".join(str(c) for c in extra_channels)
            table[key] = ("rcac", dict(channels=list(extra_channels)))
        report[name], series[name] = {}, {}
        for law in table:
            ctrl = make_controller(scenario, law, table)
            label = f"{name}: {law:>20s}" if progress else None
            run = run_law(scenario, ctrl, duration, progress=label, engine=engine)
            report[name][law] = metrics(run, scenario)
            series[name][law] = run
    return report, series


def plot(series, report, out_dir):
    """One figure per scenario: |q - q_d|, ||theta_tilde||, last link's mass, max |E_c|, and
    the smallest lambda_min(J_hat_i) over the links (doc/design.md §8)."""
    from rcac_ros.tools.plots import plt, save
    paths = []
    for name, runs in series.items():
        fig, axes = plt.subplots(1, 5, figsize=(30, 5))
        colors = plt.cm.tab20(np.linspace(0.0, 1.0, 20))      # up to 20 laws, all distinct
        for ax in axes:
            ax.set_prop_cycle(color=list(colors))
        for law, r in runs.items():
            t = r["t"]
            err = np.minimum(np.linalg.norm(r["e"], axis=1), 1e3)
            if r["diverged_at"] is not None:      # its estimates would swamp the axes
                law = f"{law} (diverged at {r['diverged_at']:.2f} s)"
            else:
                axes[1].semilogy(t, r["theta_error"], lw=0.9, label=law)
                axes[2].plot(t, r["mass_last"], lw=0.9, label=law)
            axes[0].semilogy(t, err + 1e-12, lw=0.7, label=law)
            axes[3].semilogy(t, np.minimum(r["E"], 1e12) + 1e-16, lw=0.6, label=law)
            axes[4].plot(t, np.min(r["lambda_min"], axis=1), lw=0.8, label=law)
        truth = next(iter(report[name].values())).get("mass_last_true")
        for ax, title in zip(axes, ("|q - q_d| (rad)", "||theta_hat - theta|| (all links)",
                                    "last link's mass estimate (kg)", "max_c |E_c| (N m, W)",
                                    "min_i lambda_min(J_hat_i) (< 0: not a body)")):
            ax.set_title(title)
            ax.set_xlabel("time (s)")
            ax.grid(alpha=0.3)
        if truth is not None:
            axes[2].axhline(truth, color="k", ls="--", lw=0.9, label="true (end)")
        axes[0].set_ylim(1e-7, 1.0)
        axes[3].set_ylim(bottom=1e-12)
        axes[4].set_yscale("symlog", linthresh=1e-6)
        axes[4].axhline(0.0, color="k", lw=0.8)
        axes[0].legend(fontsize=7, ncol=2)
        fig.suptitle(f"rcac compare: {name} scenario")
        path = os.path.join(out_dir, f"compare_{name}.png")
        save(fig, path, 110)
        paths.append(path)
    return paths


def channel_list(text):
    """argparse type: ``1,power`` (joint numbers, ``power``, ``all``); ranges checked later."""
    try:
        return parse_channels(text, None)
    except RcacError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def add_arguments(parser):
    parser.add_argument("--duration", type=positive_float, default=20.0,
                        help="seconds per run (default 20)")
    parser.add_argument("--scenarios", nargs="+", choices=tuple(SCENARIOS) + tuple(GROUPS),
                        default=["paper", "payload"], metavar="SCENARIO",
                        help=f"any of {' '.join(SCENARIOS)}, or {' '.join(GROUPS)} (the rows "
                             "of the joint-friction table) (default paper payload)")
    parser.add_argument("--laws", nargs="+", choices=tuple(LAWS), default=None,
                        metavar="LAW", help=f"any of {' '.join(LAWS)} (default: each "
                                            "scenario's own: every law but fixed on paper and "
                                            f"payload, {' '.join(JOINT_LAWS)} on the panda_* "
                                            "scenarios)")
    add_engine_argument(parser)
    parser.add_argument("--channels", type=channel_list, default=None,
                        help="add a law with these channels, e.g. 1,power")
    parser.add_argument("--out", type=output_dir, default="results/compare",
                        help="output directory")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def command_line(args):
    """The ``rcac compare`` command that reproduces the run (the options that matter)."""
    words = ["rcac compare", f"--duration {args.duration:g}"]
    if list(args.scenarios) != ["paper", "payload"]:
        words.append("--scenarios " + " ".join(args.scenarios))
    if args.laws is not None:
        words.append("--laws " + " ".join(args.laws))
    if args.channels is not None:
        words.append("--channels " + ",".join(str(c) for c in args.channels))
    if args.engine is not None:
        words.append(f"--engine {args.engine}")
    return " ".join(words)


def run(args):
    report, series = compare(args.scenarios, args.laws, args.duration, not args.quiet,
                             args.channels, args.engine)
    os.makedirs(args.out, exist_ok=True)
    ran = {law for rows in report.values() for law in rows}
    settings = dict(duration=args.duration, ls_forgetting=LS_FORGETTING,
                    laws={k: {"controller": LAWS[k][0],
                              "options": {o: str(v) for o, v in LAWS[k][1].items()}}
                          for k in LAWS if k in ran})
    if args.engine is not None:
        settings["engine"] = args.engine
    joints = {name: dict(zip(("damping", "friction", "armature"), JOINT_PLANTS[name]))
              for name in report if name in JOINT_PLANTS}
    if joints:
        settings["joint_terms"] = joints
    with open(os.path.join(args.out, "compare.json"), "w", encoding="utf-8") as f:
        json.dump(dict(report, settings=settings), f, indent=2)
    table = markdown(report)
    with open(os.path.join(args.out, "compare.md"), "w", encoding="utf-8") as f:
        f.write(f"`{command_line(args)}`\n\n{table}")
    plots = plot(series, report, args.out)
    print(table)
    print(f"wrote {args.out}/compare.json, compare.md, "
          + ", ".join(os.path.basename(p) for p in plots))
    return 0
