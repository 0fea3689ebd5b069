"""The sources of doc/results.md: one JSON file each, its command and its renderer.

To add a source: write a ``render(data) -> str`` (markdown, :mod:`.blocks`) for the tool's
JSON, add a :class:`Source` to :data:`SOURCES` (its command, the JSON file the command
writes inside ``{out}``, the plots it writes there, a title and a paragraph on what it
measures), run ``python -m
rcac_ros.tools.results record NAME`` and ``make results``, and commit the JSON with the page.
"""

import re

from rcac_ros.tools.results.blocks import (
    render_bench_core, render_bench_ros_modes, render_campaign, render_capture, render_compare,
    render_compare_consistency, render_compare_rms, render_consistency_campaign,
    render_delay_margin, render_experiment, render_faults, render_friction, render_friction_ros,
    render_friction_unseen, render_noise, render_noise_sources, render_payload, render_soak,
    render_stall, render_startup, render_timings)


def scalars(runs):
    """A bench's runs without their series (the JSON keeps the figures, the plot the rest)."""
    return [{k: v for k, v in r.items() if not isinstance(v, list)} for r in runs]


def without_bags(metrics):
    """``rcac friction-ros``'s metrics without the paths of its bags (a temporary directory)."""
    return {k: v for k, v in metrics.items() if k != "bags"}


#: the plot of a campaign's report (:func:`campaign_commands`)
CAMPAIGN_PLOTS = ("report.png",)


def campaign_commands(name):
    return [["rcac", "sweep", f"campaigns/{name}.yaml", "--out", "{out}/results", "--quiet"],
            ["rcac", "sweep", "report", "{out}/results", "--json", "{out}/summary.json",
             "--plot", "{out}/report.png"]]


def unseen_commands(suffix=""):
    """The unseen-plant campaigns ``campaigns/friction_<arm><suffix>.yaml`` of the three arms,
    then their paired ratios (doc/campaigns.md "Unseen plants")."""
    arms = ("panda", "ur5", "xarm7")
    return ([["rcac", "sweep", f"campaigns/friction_{arm}{suffix}.yaml", "--out",
              f"{{out}}/{arm}", "--quiet"] for arm in arms]
            + [["python", "-m", "rcac_ros.tools.sweep.paired"]
               + [f"{{out}}/{arm}" for arm in arms] + ["--out", "{out}"]])


# --- the table of sources -------------------------------------------------------------------

class Source:
    """One block of doc/results.md. ``command``: the argv (or a list of argvs, run in turn)
    that writes ``output`` into ``{out}`` (``rcac`` is the venv's); None when a maintenance
    tool writes the JSON itself (``shown`` names it). ``keep``: what of the output is stored
    (default all of it). ``plots``: glob patterns, in ``{out}``, of the figures the command
    draws (kept beside the JSON, in doc/figures, and shown under the block)."""

    def __init__(self, title, about, render, command=None, output=None, shown=None,
                 keep=None, plots=()):
        self.title, self.about, self.render, self.keep = title, about, render, keep
        self.plots = tuple(plots)
        self.command, self.output = command, output
        self.commands = [] if command is None else \
            command if isinstance(command[0], list) else [command]
        self.shown = shown or "; ".join(" ".join(a.replace("{out}", "results/run") for a in c)
                                        for c in self.commands)
        self.anchor = re.sub(r"[^\w\- ]", "", title.lower()).replace(" ", "-")


SOURCES = {
    "experiment": Source(
        "The paper's experiment",
        "Section 4 on the CSS arm for the direct (gamma = 0) and the composite law: the "
        "paper's gains, the velocity reading of the desired motion, `theta_hat(0) = 0` "
        "(doc/design.md §5). Figures of merit of `rcac_ros/tools/runs/metrics.py`.",
        render_experiment, ["rcac", "experiment", "--quiet", "--out", "{out}"], "metrics.json",
        plots=("tracking_errors.png", "parameter_estimates.png")),
    "bench_core": Source(
        "Speed of one step",
        "The step against `pin.rnea` on the same chain, the non-recursive Slotine-Li "
        "(compiled alike), the simulator (RK4) and the law's variants; the CSS arm repeated "
        "to n = 224, the Panda and UR5.",
        render_bench_core, ["rcac", "bench", "core", "--json", "{out}/bench.json"],
        "bench.json"),
    "bench_ros_modes": Source(
        "Timing over ROS, per controller mode",
        "Simulator (real time), controller and a DDS ping (a process echoing a JointState), "
        "per controller mode. What counts: effort period p99 / state period p99 (source "
        "stamps, goal <= 1.1; the controller's own from its diagnostics, the hop left out), "
        "latency p50 / the ping's one-way p50 (doc/tools.md).",
        render_bench_ros_modes, shown="make readme-bench"),
    "startup": Source(
        "Start-up, with and without the compiled kernels",
        "Each a fresh process with an empty numba cache (cold) or the one the cold run filled "
        "(warm): imports, a bad argument, the first effort of the default law and "
        "`channels: [\"all\"]`, the whole warm-up (doc/tools.md).",
        render_startup, ["rcac", "bench", "startup", "--laws", "default,all", "--json",
                         "{out}/startup.json"], "startup.json"),
    "timings": Source(
        "The two make targets",
        "`make demo` and `make test` timed as a new user runs them.",
        render_timings, shown="make readme-timings"),
    "payload": Source(
        "An unknown payload",
        "The Panda with gravity, adapting link 7 from the URDF's values; a 2 kg payload "
        "attached at 5 s. The composite law, the direct law (gamma = 0) and computed torque "
        "with fixed parameters and the same feedback (`rcac payload-demo`).",
        render_payload, ["rcac", "payload-demo", "--quiet", "--out", "{out}"], "metrics.json",
        plots=("payload_summary.png", "link7_estimates.png")),
    "friction": Source(
        "Joint friction and rotor inertia learnt, the last link adapting",
        "The Panda on the built-in simulator, armature 0.1 kg m^2, damping 0.5 N m s/rad, tanh "
        "friction 0.5 N m on every joint; `channels=\"all\"`, `joint_friction=True` (default "
        "gain), `hold_compensation=True`, zero joint estimates (doc/tools.md, "
        "`rcac friction-demo`).",
        render_friction, ["rcac", "friction-demo", "--out", "{out}"], "metrics.json",
        plots=("friction_estimates.png",)),
    "friction_adapt_links": Source(
        "Joint friction and rotor inertia learnt, links adapting",
        "As above, every link adapting too from the URDF's nominal parameters.",
        render_friction, ["rcac", "friction-demo", "--adapt-links", "--out", "{out}"],
        "metrics.json", plots=("friction_estimates.png",)),
    "friction_least_squares": Source(
        "Joint friction and rotor inertia learnt by least squares, links known",
        "As above, no link adapting, the joint terms' least-squares gain (doc/design.md §7).",
        render_friction, ["rcac", "friction-demo", "--links-known", "--friction-adaptation",
                          "least_squares", "--out", "{out}"],
        "metrics.json", plots=("friction_estimates.png",)),
    "compare": Source(
        "Every adaptive law compared",
        "`rcac compare` on the paper's experiment (`paper`) and the payload run (`payload`), "
        "each with its scenario's gains. `ident.`: parameter combinations excited; `consist.`: "
        "links whose final estimates are a physical body; µs/step: in-loop time (noisy).",
        render_compare, ["rcac", "compare", "--duration", "20", "--out", "{out}"],
        "compare.json", plots=("compare_*.png",)),
    "compare_joints": Source(
        "Joint friction and rotor inertia: the Panda on MuJoCo",
        "The `panda_*` scenarios of `rcac compare` on MuJoCo (damping, dry friction as "
        "MuJoCo's friction loss, armature; doc/tools.md, `rcac compare`): friction-blind "
        "laws against the laws with the joint terms (`*_friction`).",
        render_compare_rms, ["rcac", "compare", "--quiet", "--scenarios", "joint_table",
                             "panda_damping_armature", "--out", "{out}"], "compare.json",
        plots=("compare_panda_joints.png", "compare_panda_damping_armature.png")),
    "compare_joints_builtin": Source(
        "Joint friction and rotor inertia: the same plants on the built-in simulator",
        "As above with `--engine builtin`: the package's own dynamics, whose dry friction is "
        "the model's tanh law (inside the laws' model class).",
        render_compare_rms, ["rcac", "compare", "--quiet", "--scenarios", "joint_table",
                             "panda_damping_armature", "--engine", "builtin", "--out",
                             "{out}"], "compare.json", plots=("compare_panda_joints.png",)),
    "channels_paper": Source(
        "Channel sets out of sample: the paper arm",
        "`campaigns/channels_paper.yaml`: the paper arm with the motion scaled 0.5-1.5x, K_D "
        "and P spread; the paper's channel `[1]`, the linear-cost set `4..7` (picked on the "
        "`rcac compare` scenarios) and `\"all\"` (= Slotine-Li), each run drawn anew.",
        render_campaign, campaign_commands("channels_paper"), "summary.json",
        plots=CAMPAIGN_PLOTS),
    "channels_payload": Source(
        "Channel sets out of sample: Panda payloads",
        "`campaigns/channels_payload.yaml`: random Panda payloads (mass 0.2-3 kg, centre of "
        "mass, inertia, motion scale), the same channel sets.",
        render_campaign, campaign_commands("channels_payload"), "summary.json",
        plots=CAMPAIGN_PLOTS),
    "friction_campaign": Source(
        "Joint friction and rotor inertia over a campaign",
        "`campaigns/friction.yaml`: the Panda on MuJoCo with damping, dry friction and "
        "armature drawn per joint over a decade; `composite` (blind) against "
        "`composite_friction`, paired.",
        render_campaign, campaign_commands("friction"), "summary.json",
        plots=CAMPAIGN_PLOTS),
    "friction_unseen": Source(
        "Joint terms on unseen plants",
        "`campaigns/friction_{panda,ur5,xarm7}.yaml`: 70 MuJoCo plants per arm, joint terms "
        "drawn per joint (doc/campaigns.md \"Unseen plants\"); the blind law against "
        "`joint_friction=True` with default gains, paired (the same plant for both).",
        render_friction_unseen, unseen_commands(), "ratios.json", plots=("ratios.png",)),
    "friction_unseen_all": Source(
        "Joint terms on unseen plants, every joint's channel",
        "Other plants (seed 34), `channels: all`: `campaigns/friction_*_all.yaml` "
        "(doc/design.md §7).",
        render_friction_unseen, unseen_commands("_all"), "ratios.json", plots=("ratios.png",)),
    "friction_ros": Source(
        "Joint terms over ROS 2",
        "Both nodes over DDS in lockstep, the paper's arm on MuJoCo with joint friction; the "
        "controller blind, then with `joint_friction: true` alone; a bag per run "
        "(`rcac friction-ros`).",
        render_friction_ros, ["rcac", "friction-ros", "--out", "{out}"], "metrics.json",
        keep=without_bags,
        plots=("friction_ros.png",)),
    "compare_consistency": Source(
        "Physically consistent estimates compared",
        "The natural geometry's laws (`*_natural`: the log-det metric) against the Euclidean "
        "laws from the same start (`*_nat_start`) and from the paper's `theta_hat(0) = 0` "
        "(doc/design.md §8).",
        render_compare_consistency,
        ["rcac", "compare", "--quiet", "--duration", "20", "--laws", "paper", "paper_nat_start",
         "paper_natural", "all", "all_nat_start", "all_natural", "slotine_li",
         "slotine_li_natural", "--out", "{out}"], "compare.json", plots=("compare_*.png",)),
    "consistency_campaign": Source(
        "Physically consistent estimates over a campaign",
        "`campaigns/consistency.yaml`: the Euclidean law, the natural geometry with its "
        "default (barrier) metric and with the log-det metric on the same random draws "
        "(doc/campaigns.md).",
        render_consistency_campaign,
        [["rcac", "sweep", "campaigns/consistency.yaml", "--out", "{out}/results", "--quiet"],
         ["python", "-m", "rcac_ros.tools.sweep.consistency", "{out}/results",
          "{out}/summary.json"]], "summary.json"),
    "noise": Source(
        "Sensor noise over 10 minutes",
        "The paper's experiment with white Gaussian noise on what the controller reads, per "
        "law and variant: `clean` (no noise, the reference), `plain`, `dead zone`, `sigma` "
        "(fixed leakage) and `switching` (doc/tools.md, `rcac bench noise`).",
        render_noise, ["rcac", "bench", "noise", "--out", "{out}"], "noise.json"),
    "noise_sources": Source(
        "Sensor noise: where the drift comes from",
        "The paper law's drift by noise source and by term (`gamma = 0`: the tracking term "
        "alone).",
        render_noise_sources, ["rcac", "bench", "noise", "--sources", "--out", "{out}"],
        "sources.json"),
    "capture": Source(
        "A payload captured over ROS 2",
        "The CSS arm in zero gravity, both nodes over ROS 2 in lockstep; the simulator's "
        "`payload.*` set at run time, the controller not told (`rcac capture-demo`); the "
        "same offline for four laws (their columns: the effort the law asked for, applied "
        "clipped to the preset's limits as in the ROS run), and the default law over payload "
        "masses.",
        render_capture, ["rcac", "capture-demo", "--quiet", "--mass-table", "--out", "{out}"],
        "capture.json", plots=("capture_ros.png", "capture_laws.png")),
    "capture_release": Source(
        "A payload captured and released, the motion slowed",
        "As above with the motion slowed for the payload and `payload.mass: 0` set later.",
        render_capture, ["rcac", "capture-demo", "--quiet", "--slow", "--release", "20",
                         "--out", "{out}"], "capture.json",
        plots=("capture_ros.png", "capture_laws.png")),
    "faults_starved": Source(
        "A starved machine",
        "The nominal and starved cases (two busy processes per core beside the nodes for the "
        "middle third), the controller in timer mode at the paper's K_D (doc/failsafe.md "
        "\"Starved machine\").",
        render_faults, ["rcac", "bench", "faults", "--cases", "nominal,starved", "--duration",
                        "60", "--K_D", "10000", "--json", "{out}/faults.json"], "faults.json",
        keep=scalars),
    "faults_stall": Source(
        "A stalled controller",
        "The controller's process stopped 5 s (SIGSTOP) at a third of the run, the simulator "
        "running on with the last effort; reference: `direct` (doc/failsafe.md \"Stalls\").",
        render_stall, ["rcac", "bench", "faults", "--cases", "direct,stall", "--duration",
                       "30", "--K_D", "10000", "--json", "{out}/faults.json", "--plot",
                       "{out}/faults.png"], "faults.json", keep=scalars, plots=("faults.png",)),
    "soak_loaded": Source(
        "Thirty minutes on a starved machine",
        "`rcac bench soak`'s `direct` case (doc/failsafe.md) for 30 minutes, four busy "
        "processes on the machine throughout.",
        render_soak, ["rcac", "bench", "soak", "30", "--busy", "4", "--K_D", "10000", "--json",
                      "{out}/soak.json", "--plot", "{out}/soak.png"], "soak.json",
        keep=scalars, plots=("soak.png",)),
    "delay_margin": Source(
        "Delay margin per arm",
        "The margin the starvation guard derives at configure from the model and gains "
        "(doc/failsafe.md \"Delay margin per arm\"), checked against the delayed closed loop "
        "on two URDF arms and the CSS arm (`rcac bench delay-margin --check`).",
        render_delay_margin, ["rcac", "bench", "delay-margin", "--check", "--json",
                              "{out}/delay_margin.json"], "delay_margin.json"),
}


def headlines(docs):
    """The README's results lines (at most six), computed from the sources' data."""
    e, b, c = docs["experiment"], docs["bench_core"], docs["compare"]
    comp, direct = e["composite"], e["direct"]
    goals = {**b["ratios"], **b.get("goals", {})}
    p = docs["payload"]
    pa = c["paper"]
    anchor = ("paper_over_pin_rnea_n7" if "paper_over_pin_rnea_n7" in goals
              else "controller_n7_over_pin_rnea_n7")
    same = f"{pa['all']['rms']:.3g}" == f"{pa['slotine_li']['rms']:.3g}"
    j = docs["compare_joints"]["panda_joints"]
    cc = docs["consistency_campaign"]
    nat = cc["by_geometry"]["natural"]
    pair = cc["paired_natural_over_euclidean"]
    lines = [
        f"- **Paper's experiment**: composite RMS tracking error "
        f"{comp['rms_tracking_error']:.3g} rad against {direct['rms_tracking_error']:.3g} for "
        f"direct adaptation; final prediction error {comp['final_abs_prediction_error']:.2g} "
        f"against {direct['final_abs_prediction_error']:.3g} N m "
        "([results](doc/results.md#the-papers-experiment)).",
        f"- **Cost**: one step of the paper's law {b['rows'][0]['controller_us']:.3g} µs at "
        f"n = 7, {goals[anchor]:.2f}x "
        f"Pinocchio's `rnea`; {goals['slotine_li_over_controller_n56']:.0f}x faster than the "
        "non-recursive Slotine-Li law at n = 56 ([results](doc/results.md#speed-of-one-step)).",
        f"- **Unknown payload**: last-second RMS {p['composite']['rms_error_last_window']:.2g} "
        f"rad composite, {p['direct']['rms_error_last_window']:.2g} direct, "
        f"{p['fixed']['rms_error_last_window']:.2g} fixed parameters "
        "([results](doc/results.md#an-unknown-payload)).",
        f"- **Identification power**: `channels=\"all\"` tracks the paper's experiment at "
        f"{pa['all']['rms'] / pa['paper']['rms']:.2f}x the paper law's RMS"
        + (", as the non-recursive Slotine-Li law does" if same else
           f" (Slotine-Li: {pa['slotine_li']['rms'] / pa['paper']['rms']:.2f}x)")
        + " ([results](doc/results.md#every-adaptive-law-compared)).",
        f"- **Joint friction**: on the Panda in MuJoCo with damping, dry friction and armature, "
        f"the friction-aware `all` law tracks at {j['all_friction']['rms']:.2g} rad RMS, the "
        f"friction-blind paper law at {j['paper']['rms']:.2g} "
        "([results](doc/results.md#joint-friction-and-rotor-inertia-the-panda-on-mujoco)).",
        "- **Consistent estimates**: with `geometry=\"natural\"` "
        f"{nat['consistent_every_step_runs']} of {nat['runs']} campaign runs keep every link a "
        "physical body at every step, at "
        f"{pair['rms_ratio_median']:.2f}x the Euclidean law's RMS (median per sample) "
        "([results](doc/results.md#physically-consistent-estimates-over-a-campaign)).",
    ]
    return lines
