"""The sources of doc/results.md: one JSON file each, and how each is rendered.

To add a source: write a ``render(data) -> str`` (markdown) for the tool's JSON, add a
:class:`Source` to :data:`SOURCES` (its command, the JSON file the command writes inside
``{out}``, a title and a paragraph on what it measures), run ``python -m
rcac_ros.tools.results record NAME`` and ``make results``, and commit the JSON with the page.
Every function here reads the JSON only: rendering imports neither numba nor rclpy.
"""

import math
import re

from rcac_ros.tools.demos.compare_report import cell, COLUMNS, side_by_side


def fmt(v, digits=3):
    """A number as the docs print it: ``digits`` significant digits, ``-`` for none."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return f"{v:,}".replace(",", " ")
    return f"{v:.{digits}g}"


def pct(v):
    return "-" if v is None else f"{100 * v:.3g} %"


def table(header, rows):
    """A markdown table; a ``|`` inside a cell is escaped."""
    def line(cells):
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"
    return "\n".join([line(header), "|" + " --- |" * len(header), *(line(r) for r in rows)])


def law_table(report, laws, keys=None, digits=4):
    """Rows: the numeric figures of each law's report (or ``keys``); columns: ``laws``."""
    first = report[laws[0]]
    keys = keys or [k for k, v in first.items() if isinstance(v, (int, float)) and
                    not isinstance(v, bool)]
    return table(["figure", *laws], [[k, *(fmt(report[law].get(k), digits) for law in laws)]
                                     for k in keys])


# --- renderers, one per source --------------------------------------------------------------

def render_experiment(d):
    laws = ["direct", "composite"]
    body = law_table(d, laws)
    c, r = d["composite"], d["direct"]
    s = d.get("settings", {})
    body += (f"\n\nSettings: {s.get('duration', '-')} s, reading `{s.get('trajectory', '-')}`, "
             f"K_D {fmt(s.get('K_D'))}, Lambda {fmt(s.get('Lambda'))}, P {fmt(s.get('P'))}, "
             f"gamma {fmt(s.get('gamma'))}, lambda {fmt(s.get('lam'))}, h {fmt(s.get('h'))} s, "
             f"engine `{s.get('engine', '-')}`.\n\n"
             f"Composite over direct: RMS tracking error "
             f"{c['rms_tracking_error'] / r['rms_tracking_error']:.2f}x, over the last 5 s "
             f"{c['rms_tracking_error_last_5s'] / r['rms_tracking_error_last_5s']:.2f}x; final "
             f"prediction error {c['final_abs_prediction_error']:.3g} against "
             f"{r['final_abs_prediction_error']:.3g} N m.")
    return body


#: goal of each ratio of ``rcac bench core`` (doc/tools.md, ``rcac bench core``)
CORE_GOALS = {
    "paper_over_pin_rnea_n7": ("<=", 3.0), "controller_n7_over_pin_rnea_n7": ("<=", 3.0),
    "controller_over_pin_rnea_panda": ("<=", 3.0), "controller_over_pin_rnea_ur5": ("<=", 3.0),
    "controller_n224_over_n28": ("<=", 10.0), "friction_n224_over_n28": ("<=", 10.0),
    "slotine_li_over_controller_n56": (">=", 20.0), "all_over_paper_n7": ("<=", 2.0),
    "all_over_slotine_li_n56": ("<=", 0.1), "friction_over_paper_n7": ("<=", 1.3),
    "barrier_over_paper_closed_loop_n7": ("<=", 1.3),
    "log_det_over_paper_closed_loop_n7": ("<=", 1.3),
}

CORE_COLUMNS = (("controller_us", "paper law"), ("pin_rnea_us", "pin.rnea"),
                ("slotine_li_us", "Slotine-Li"), ("simulator_us", "simulator"),
                ("power_us", "`[1,\"power\"]`"), ("all_us", "`\"all\"`"),
                ("all_explicit_us", "`\"all\"` explicit"), ("least_squares_us", "least squares"),
                ("natural_us", "natural"), ("friction_us", "joint terms"))


def _goal_rows(ratios):
    rows = []
    for key, value in ratios.items():
        goal = CORE_GOALS.get(key)
        if goal is None:
            rows.append([f"`{key}`", f"{value:.3g}", "", ""])
        else:
            op, bound = goal
            met = value <= bound if op == "<=" else value >= bound
            rows.append([f"`{key}`", f"{value:.3g}", f"{op} {bound:g}", "met" if met else
                         "**missed**"])
    return rows


def render_bench_core(d):
    cols = [(k, h) for k, h in CORE_COLUMNS if any(k in r for r in d["rows"])]
    body = ["µs per step, medians over blocks:", "",
            table(["chain", "n", *(h for _, h in cols)],
                  [[r["model"], r["n"], *(fmt(r.get(k), 4) for k, _ in cols)]
                   for r in d["rows"]]),
            "", "Ratios of the medians above:", "",
            table(["ratio", "measured", "goal", ""], _goal_rows(d["ratios"]))]
    if d.get("goals"):
        body += ["", "Cost goals, the two steps timed side by side block by block (median of "
                 "the per-block ratios):", "",
                 table(["ratio", "measured", "goal", ""], _goal_rows(d["goals"]))]
    ops = d.get("operations")
    if ops:
        fit = ops["rcac_all_mul_fit"]
        c7 = ops["rcac_n7"]
        body += ["", "Operations per step, counted on the kernels' own source "
                 "(`rcac_ros/tools/bench/opcount.py`):", "",
                 table(["law", "multiplications (incl. divisions)", "additions"], [
                     ["paper law, n = 7", c7["mul"] + c7["div"], c7["add"]],
                     ["paper law, per link", fmt(ops["rcac_per_link_mul"], 4),
                      fmt(ops["rcac_per_link_add"], 4)],
                     ["the paper's count, per link", ops["paper_per_link"]["mul"],
                      ops["paper_per_link"]["add"]],
                     ["Slotine-Li, n = 7",
                      ops["slotine_li_n7"]["mul"] + ops["slotine_li_n7"]["div"],
                      ops["slotine_li_n7"]["add"]],
                     *([k.replace("rcac_", "").replace("_n7", "") + ", n = 7",
                        ops[k]["mul"] + ops[k]["div"], ops[k]["add"]]
                       for k in ("rcac_all_explicit_n7", "rcac_power_n7",
                                 "rcac_least_squares_n7") if k in ops)]),
                 "", f"`channels=\"all\"`: {fit['n2']:.0f} n^2 {fit['n']:+.0f} n "
                 f"{fit['1']:+.0f} multiplications (fit on n = 7, 14, 21), against the "
                 f"{fit['wang_n2']} n^2 the paper cites for Wang's O(n^2) law."]
    return "\n".join(body)


#: the rows of the ROS timing table (``make readme-bench``): (label, how to format one run)
BENCH_ROS_ROWS = (
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


def render_bench_ros_modes(d):
    cols = list(d["columns"])
    rows = [[label, *(fmt_row(d["columns"][c]) for c in cols)]
            for label, fmt_row in BENCH_ROS_ROWS]
    return d["conditions"] + "\n\n" + table(["", *cols], rows)


#: the sentence of ``make readme-timings``'s figures
TIMINGS_TEMPLATE = ("Measured on {where} on {date} ({cores} cores, Python {python}): "
                    "`make demo` {demo_min:.1f} min ({demo_parts}), `make test` "
                    "{test_min:.1f} min ({tests}).")


def render_timings(d):
    return TIMINGS_TEMPLATE.format(**d)


PAYLOAD_KEYS = ("rms_error_before_jump", "rms_error_first_window_after_jump",
                "rms_error_last_window", "peak_error_norm_after_jump", "link7_mass_true",
                "link7_mass_estimate_end", "link7_mass_relative_error_end",
                "link7_first_moments_relative_error_end", "link7_mass_settling_time_5pct",
                "max_torque_over_effort_limit", "wall_time_s")


def render_startup(d):
    r = d["results"]

    def sec(x, key="seconds"):
        return "-" if x is None or x.get(key) is None else f"{x[key]:.2f} s"
    rows = []
    for name in ("import rcac_ros.core", "import the recursive law (compiles nothing)",
                 "bad argument (rcac experiment --duration -5)",
                 "warm-up (python -m rcac_ros.tools.warm)"):
        if name in r:
            cold = r[name]["cold"]
            rows.append([name, sec(cold), sec(r[name]["warm"]),
                         "-" if cold is None else f"{cold['cpu_seconds']:.1f} s"])
    for key, v in r.items():
        if key.startswith("controller_"):
            law = key[len("controller_"):]
            rows.append([f"controller ({law}): first answer of `~/get_state`",
                         sec(v["cold"], "first_answer_s"), sec(v["warm"], "first_answer_s"),
                         "-"])
            rows.append([f"controller ({law}): first effort", sec(v["cold"], "first_effort_s"),
                         sec(v["warm"], "first_effort_s"), "-"])
    said = [f"`{v['cold']['state_then']}`, \"{v['cold']['diagnostics_then']}\""
            for k, v in r.items() if k.startswith("controller_") and v["cold"]["state_then"]]
    return (table(["", "cold (empty cache)", "warm", "CPU, cold"], rows)
            + f"\n\n{d['cpus']} CPUs, load average {fmt(d['load_average'][0])} at the end. "
            + ("At its first answer the controller said " + said[0] + "." if said else ""))


def render_payload(d):
    laws = [k for k in ("composite", "direct", "fixed") if k in d]
    s = d.get("settings", {})
    keys = [k for k in PAYLOAD_KEYS if k in d[laws[0]]]
    return (law_table(d, laws, keys) + "\n\nRMS of `q - q_d` over all joints (rad) in 1 s "
            f"windows; payload {fmt(s.get('payload_mass'))} kg attached at "
            f"{fmt(s.get('jump'))} s of {fmt(s.get('duration'))} s.")


def render_friction(d):
    rows = [[term, pct(d["worst_relative_error"][term]), pct(d["goals"][term]),
             "met" if d["met"][term] else "**missed**"] for term in d["worst_relative_error"]]
    return (table(["joint term", "worst relative error over the 7 joints", "goal", ""], rows)
            + f"\n\nRMS tracking error {fmt(d['rms_error_rad'])} rad over "
            f"{fmt(d['duration_s'])} s; links {'adapting' if d['adapt_links'] else 'known'}.")


#: the columns of ``rcac compare``'s tables that doc/results.md shows (the JSON has them all)
COMPARE_KEYS = ("rms", "rms_last_5s", "theta_error_end", "us_per_step", "identifiable",
                "consistent_steps", "payload_mass_error")


def render_compare(d):
    """RMS side by side, then per scenario the figures of :data:`COMPARE_KEYS`."""
    report = {k: v for k, v in d.items() if k != "settings"}
    heads = dict(COLUMNS)
    out = ["RMS tracking error (rad):", "", side_by_side(report).rstrip()]
    for name, rows in report.items():
        keys = [k for k in COMPARE_KEYS if any(m.get(k) is not None for m in rows.values())]
        body = []
        for law, m in rows.items():
            cells = [cell(m.get(k), k) for k in keys]
            if m["diverged_at"] is not None:
                cells[0] = f"diverged at {m['diverged_at']:.3f} s"
            body.append([law, *cells])
        out += ["", f"`{name}`:", "", table(["law", *(heads[k] for k in keys)], body)]
    return "\n".join(out)


def render_compare_consistency(d):
    """RMS side by side, then per scenario the consistency figures of every law."""
    report = {k: v for k, v in d.items() if k != "settings"}
    out = [render_compare_rms(d)]
    for name, rows in report.items():
        out += ["", f"`{name}`: share of link-steps whose estimates were a body, smallest "
                "λ_min(Ĵ), payload mass error:", "",
                table(["law", *(f"`{law}`" for law in rows)],
                      [[heads, *(cell(m.get(k), k) for m in rows.values())]
                       for k, heads in (("consistent_steps", "bodies"),
                                        ("lambda_min", "min λ_min(Ĵ)"),
                                        ("payload_mass_error", "payload |m̃|"))
                       if any(m.get(k) is not None for m in rows.values())])]
    return "\n".join(out)


def render_compare_rms(d):
    """RMS tracking error of every law on every scenario, side by side."""
    report = {k: v for k, v in d.items() if k != "settings"}
    return "RMS tracking error (rad):\n\n" + side_by_side(report).rstrip()


def render_consistency_campaign(d):
    geos = list(d["by_geometry"])
    keys = list(d["by_geometry"][geos[0]])
    rows = [[k, *(fmt(d["by_geometry"][g][k], 4) if not isinstance(d["by_geometry"][g][k], list)
                  else (", ".join(map(str, d["by_geometry"][g][k])) or "none") for g in geos)]
            for k in keys]
    out = [f"`{d['campaign']}`, {d['samples']} samples, paired: {fmt(d['paired'])}.", "",
           table(["figure", *geos], rows)]
    for key, paired in d.items():
        if key.startswith("paired_") and isinstance(paired, dict):
            out += ["", f"Per sample, {key[len('paired_'):].replace('_over_', ' over ')}:", "",
                    table(["figure", "value"], [[k, fmt(v, 4)] for k, v in paired.items()])]
    return "\n".join(out)


def render_noise(d):
    s = d["settings"]
    rows = []
    for name, r in d.items():
        if name == "settings":
            continue
        g = r["theta_norm_growth"]
        dev = r.get("deviation")
        rows.append([name, fmt(r["theta_norm"][-1], 4), f"{100 * g['last_half_rise']:+.1f} %",
                     f"{g['exponent']:.2f}", fmt(dev[-1], 4) if dev else "-",
                     pct(r["deviation_weak_share"]["0.0001"]) if "deviation_weak_share" in r
                     else "-", fmt(r["rms_last_minute"]), pct(r["adapting_share"])])
    return (f"{s['duration']:g} s per run, noise sigma {s['sigma_q']:g} rad on q and "
            f"{s['sigma_qd']:g} rad/s on qd; ‖θ‖ of the truth {s['theta_norm_true']:.0f}; "
            f"`sigma`: leakage {s['sigma_fixed']:g}, `switching`: leakage "
            f"{s['sigma_switching']:g} with `leakage_bound` {s['M0_factor']:g} ‖θ_i‖ per link. "
            "\"last half\": the least-squares rise of ‖θ̂‖ over the second half relative to its "
            f"mean there (still growing above {100 * s['growth_tol']:g} %), ~t^a the exponent "
            "fitted there; \"from clean\": ‖θ̂ − θ̂_clean‖ at the end, \"poorly excited\" its "
            "share in the directions excited less than 1e-4 of the most.\n\n"
            + table(["law / variant", "‖θ̂‖ end", "last half", "~t^a", "from clean",
                     "poorly excited", "RMS last min (rad)", "adapting"], rows))


def render_noise_sources(d):
    rows = [[name, fmt(r["sigma_q"]), fmt(r["sigma_qd"]), fmt(r["gamma"]), r["seed"],
             fmt(r["deviation_end"], 4), fmt(r["theta_norm_end"], 4),
             fmt(r["cosine_with_both"], 3)]
            for name, r in d.items() if name != "settings"]
    return (f"The paper law, {d['settings']['duration']:g} s per run; deviation: ‖θ̂ − "
            "θ̂_clean‖ at the end; cosine: of that deviation with the run `both`'s.\n\n"
            + table(["run", "sigma_q", "sigma_qd", "gamma", "seed", "deviation end",
                     "‖θ̂‖ end", "cosine"], rows))


def render_campaign(d):
    """Per law (a law and its channel set): runs, divergences, the distribution of the RMS
    error and the median of the last 5 s and of the final parameter error."""
    rows = []
    for law, r in d["per_law"].items():
        rms = r.get("rms_tracking_error", {})
        rows.append([f"`{law}`", r["runs"], r["diverged"],
                     f"{fmt(rms.get('median'))} [{fmt(rms.get('p5'))}, {fmt(rms.get('p95'))}]",
                     fmt(r.get("rms_tracking_error_last_5s", {}).get("median")),
                     fmt(r.get("parameter_error_norm_end", {}).get("median"))])
    head = f"`{d['campaign']}`: {d['runs']} of {d['expected']} runs, {d['diverged']} diverged."
    header = ["law", "runs", "diverged", "RMS (rad): median [5 %, 95 %]",
              "RMS last 5 s, median", "‖θ̃‖ end, median"]
    return head + "\n\n" + table(header, rows)


def campaign_commands(name):
    return [["rcac", "sweep", f"campaigns/{name}.yaml", "--out", "{out}/results", "--quiet"],
            ["rcac", "sweep", "report", "{out}/results", "--json", "{out}/summary.json",
             "--plot", "{out}/report.png"]]


# --- the table of sources -------------------------------------------------------------------

class Source:
    """One block of doc/results.md. ``command``: the argv (or a list of argvs, run in turn)
    that writes ``output`` into ``{out}`` (``rcac`` is the venv's); None when a maintenance
    tool writes the JSON itself (``shown`` names it)."""

    def __init__(self, title, about, render, command=None, output=None, shown=None):
        self.title, self.about, self.render = title, about, render
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
        render_experiment, ["rcac", "experiment", "--quiet", "--out", "{out}"], "metrics.json"),
    "bench_core": Source(
        "Speed of one step",
        "The controller step against Pinocchio's `pin.rnea` on the same chain, the "
        "non-recursive Slotine-Li baseline (compiled the same way), the simulator (RK4, four "
        "ABA calls) and the recursive law's variants, on the CSS arm repeated to n = 224 and "
        "the Panda and UR5 URDFs.",
        render_bench_core, ["rcac", "bench", "core", "--json", "{out}/bench.json"],
        "bench.json"),
    "bench_ros_modes": Source(
        "Timing over ROS, per controller mode",
        "The simulator (real time, its own 500 Hz deadline loop) and the controller as two "
        "processes, K_D = 1000, with a third process echoing a JointState (a plain DDS ping), "
        "once per controller mode. The rows that count are ratios of two figures of the same "
        "run: effort period p99 over state period p99 (goal <= 1.1) and state→effort latency "
        "p50 over the ping's one-way p50 (doc/nodes.md, \"Timing\").",
        render_bench_ros_modes, shown="make readme-bench"),
    "startup": Source(
        "Start-up, with and without the compiled kernels",
        "Each figure a fresh process with a numba cache of its own, empty (cold: a fresh "
        "install before `rcac warm`) or filled by the cold run (warm): the imports, a bad "
        "argument, the controller node's first answer and first effort for the default law "
        "and the general kernel (`channels: [\"all\"]`), the whole warm-up (doc/tools.md, "
        "`rcac bench startup`).",
        render_startup, ["rcac", "bench", "startup", "--laws", "default,all", "--json",
                         "{out}/startup.json"], "startup.json"),
    "timings": Source(
        "The two make targets",
        "`make demo` and `make test` timed on a fresh clone, as a new user runs them (venv, "
        "install, the one-time compile of the kernels, the run).",
        render_timings, shown="make readme-timings"),
    "payload": Source(
        "An unknown payload",
        "The Panda with gravity, from the URDF's nominal parameters, adapting link 7 only; a "
        "2 kg payload attached in the simulator at 5 s. The composite law, the direct law "
        "(gamma = 0) and a fixed-parameter computed-torque law with the same feedback "
        "(doc/tools.md, `rcac payload-demo`).",
        render_payload, ["rcac", "payload-demo", "--quiet", "--out", "{out}"], "metrics.json"),
    "friction": Source(
        "Joint friction and rotor inertia learnt, links known",
        "The Panda on the built-in simulator with armature 0.1 kg m^2, damping 0.5 N m s/rad "
        "and tanh friction 0.5 N m on every joint, the law `channels=\"all\"` with "
        "`joint_friction=True` from zero joint estimates (doc/tools.md, "
        "`rcac friction-demo`).",
        render_friction, ["rcac", "friction-demo", "--out", "{out}"], "metrics.json"),
    "friction_adapt_links": Source(
        "Joint friction and rotor inertia learnt, links adapting",
        "As above, every link adapting too from the URDF's nominal parameters.",
        render_friction, ["rcac", "friction-demo", "--adapt-links", "--out", "{out}"],
        "metrics.json"),
    "compare": Source(
        "Every adaptive law compared",
        "Every law of `rcac compare` on the paper's experiment (`paper`) and the payload run "
        "(`payload`), each with the scenario's gains. `ident.` counts the parameter "
        "combinations the run excited, `consist.` the links whose final estimates are a "
        "physical body; µs/step is the in-loop time (a noisy figure: the cost ratios are "
        "those of \"Speed of one step\").",
        render_compare, ["rcac", "compare", "--duration", "20", "--out", "{out}"],
        "compare.json"),
    "compare_joints": Source(
        "Joint friction and rotor inertia: the Panda on MuJoCo",
        "The `panda_*` scenarios of `rcac compare` on MuJoCo (damping, dry friction as "
        "MuJoCo's friction loss, armature; doc/tools.md, `rcac compare`): friction-blind "
        "laws against the laws with the joint terms (`*_friction`).",
        render_compare_rms, ["rcac", "compare", "--quiet", "--scenarios", "joint_table",
                             "panda_damping_armature", "--out", "{out}"], "compare.json"),
    "compare_joints_builtin": Source(
        "Joint friction and rotor inertia: the same plants on the built-in simulator",
        "As above with `--engine builtin`: the package's own dynamics, whose dry friction is "
        "the model's tanh law (inside the laws' model class).",
        render_compare_rms, ["rcac", "compare", "--quiet", "--scenarios", "joint_table",
                             "panda_damping_armature", "--engine", "builtin", "--out",
                             "{out}"], "compare.json"),
    "channels_paper": Source(
        "Channel sets out of sample: the paper arm",
        "`campaigns/channels_paper.yaml`: the paper arm with the motion scaled 0.5-1.5x, K_D "
        "and P spread; the paper's channel `[1]`, the linear-cost set `4..7` (picked on the "
        "`rcac compare` scenarios) and `\"all\"` (= Slotine-Li), each run drawn anew.",
        render_campaign, campaign_commands("channels_paper"), "summary.json"),
    "channels_payload": Source(
        "Channel sets out of sample: Panda payloads",
        "`campaigns/channels_payload.yaml`: random Panda payloads (mass 0.2-3 kg, centre of "
        "mass, inertia, motion scale), the same channel sets.",
        render_campaign, campaign_commands("channels_payload"), "summary.json"),
    "friction_campaign": Source(
        "Joint friction and rotor inertia over a campaign",
        "`campaigns/friction.yaml`: the Panda on MuJoCo with damping, dry friction and "
        "armature drawn per joint over a decade; the friction-blind `composite` law against "
        "`composite_friction`, paired (the same joint terms for both laws).",
        render_campaign, campaign_commands("friction"), "summary.json"),
    "compare_consistency": Source(
        "Physically consistent estimates compared",
        "The natural geometry's laws (`*_natural`: the log-det metric) against the Euclidean "
        "laws from the same start (`*_nat_start`) and from the paper's `theta_hat(0) = 0` "
        "(doc/design.md §8).",
        render_compare_consistency,
        ["rcac", "compare", "--quiet", "--duration", "20", "--laws", "paper", "paper_nat_start",
         "paper_natural", "all", "all_nat_start", "all_natural", "slotine_li",
         "slotine_li_natural", "--out", "{out}"], "compare.json"),
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
