"""How each source of doc/results.md is rendered: ``render_NAME(data) -> str`` (markdown),
from the JSON alone (rendering imports neither numba nor rclpy), and the helpers they share.
"""


import math

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
            "", "Ratios of the medians above (those the side-by-side goals below repeat left "
            "out):", "",
            table(["ratio", "measured", "goal", ""],
                  _goal_rows({k: v for k, v in d["ratios"].items()
                              if k not in d.get("goals", {})}))]
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
    ("controller's own: sent / received p99",
     lambda r: _f(r.get("own_period_ratio"), 3)),
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
TIMINGS_TEMPLATE = ("On {where}: `make demo` {demo_min:.1f} min ({demo_parts}), `make test` "
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
    links = "no link" if d.get("links_known") else \
        "every link" if d["adapt_links"] else "the last link"
    adaptation = d.get("friction_adaptation", "gradient")
    by = "" if adaptation == "gradient" else f", joint terms by {adaptation.replace('_', ' ')}"
    rows = [[term, pct(d["worst_relative_error"][term]), pct(d["goals"][term]),
             "met" if d["met"][term] else "**missed**"] for term in d["worst_relative_error"]]
    return (table(["joint term", "worst relative error over the 7 joints", "goal", ""], rows)
            + f"\n\nRMS tracking error {fmt(d['rms_error_rad'])} rad over "
            f"{fmt(d['duration_s'])} s; "
            f"{links} adapting{by}.")


#: the columns of ``rcac compare``'s tables that doc/results.md shows (the JSON has them all)
COMPARE_KEYS = ("rms", "rms_last_5s", "theta_error_end", "us_per_step", "identifiable",
                "consistent_steps", "payload_mass_error")


def render_compare(d):
    """Per scenario the figures of :data:`COMPARE_KEYS` for every law."""
    report = {k: v for k, v in d.items() if k != "settings"}
    heads = dict(COLUMNS)
    out = []
    for name, rows in report.items():
        keys = [k for k in COMPARE_KEYS if any(m.get(k) is not None for m in rows.values())]
        body = []
        for law, m in rows.items():
            cells = [cell(m.get(k), k) for k in keys]
            if m["diverged_at"] is not None:
                cells[0] = f"diverged at {m['diverged_at']:.3f} s"
            body.append([law, *cells])
        out += ["", f"`{name}`:", "", table(["law", *(heads[k] for k in keys)], body)]
    return "\n".join(out[1:])


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


def render_friction_unseen(d):
    """Per arm and pooled: the distribution of each plant's aware / blind RMS ratio."""
    rows = [[f"`{name}`", r["plants"], fmt(r["median"]), fmt(r["p90"]), fmt(r["worst"]),
             r["diverged_aware"], r["diverged_blind"], fmt(r["median_blind_rms_rad"])]
            for name, r in d["arms"].items()]
    p = d["pooled"]
    rows.append(["pooled", p["plants"], fmt(p["median"]), fmt(p["p90"]), fmt(p["worst"]),
                 sum(r["diverged_aware"] for r in d["arms"].values()),
                 sum(r["diverged_blind"] for r in d["arms"].values()), "-"])
    header = ["campaign", "plants", "median", "90 %", "worst", "diverged (aware)",
              "diverged (blind)", "blind RMS, median (rad)"]
    goals, met = d["goals"], d["met"]
    word = {True: "met", False: "missed"}
    return (f"{d['ratio']}.\n\n" + table(header, rows) + "\n\n"
            f"Goals: median <= {goals['median']:g} ({word[met['median']]}), worst <= "
            f"{goals['worst']:g} ({word[met['worst']]}), none diverged "
            f"({word[met['none_diverged']]}).")


def render_friction_ros(d):
    """Both runs' RMS tracking error over ROS 2, and the plant's joint terms."""
    rms = d["rms_tracking_error_rad"]
    terms = ", ".join(f"{k} {v:g}" for k, v in d["plant_joint_terms"].items())
    rows = [["friction-blind", fmt(rms["blind"]), "1"],
            ["`joint_friction: true`", fmt(rms["aware"]), fmt(rms["aware"] / rms["blind"])]]
    return (table(["controller", "RMS tracking error (rad)", "/ blind"], rows)
            + f"\n\n{fmt(d['duration_s'])} s per run; the plant's terms on each joint: "
            f"{terms} (SI).")


def render_capture(d):
    """The ROS run and the offline laws at the capture (and the release), the mass table."""
    from rcac_ros.tools.demos.capture_figures import mass_markdown, table as capture_table
    settings = d["settings"]
    columns = dict({"ROS 2 (composite)": d["ros"]} if "ros" in d else {}, **{
        label: run for label, run in d["offline"].items() if run.get("status") == "ok"})
    phases = ["capture"] + (["release"] if settings.get("release_s") is not None else [])
    payload = settings["payload"]
    head = (f"Payload {payload['mass']:g} kg, centre of mass {payload['com']} m in the last "
            f"link's frame, captured at {settings['at_s']:g} s"
            + (f" and released at {settings['release_s']:g} s" if settings.get("release_s")
               else "") + f" of a {settings['duration_s']:g} s run; the paper's motion "
            + ("at full speed" if settings["slowdown"] == 1.0 else
               f"{settings['slowdown']:.2f} times slower") + ".")
    parts = [head] + [capture_table(columns, phase).rstrip() for phase in phases]
    if d.get("mass_table"):
        parts.append("Over payload masses, the default law offline, the motion slowed for each "
                     "(`slowdown`, doc/tools.md `rcac capture-demo`):\n\n"
                     + mass_markdown(d["mass_table"]).rstrip())
    return "\n\n".join(parts)


def render_delay_margin(d):
    """Per arm and gain: the derived margin and the delayed loop at 0, ~0.7 and ~1.5 margins."""
    rows = []
    for r in d["rows"]:
        finals = ", ".join("diverged" if f is None else fmt(f) for f in r["final"])
        rows.append([r["arm"], f"{r['gain_name']} = {r['gain']:g}", fmt(r["margin_ms"]),
                     fmt(r["margin_periods"]), ", ".join(str(x) for x in r["delays"]),
                     fmt(r["start"]), finals, "-" if r["edge_periods"] is None
                     else r["edge_periods"], "holds" if r["holds"] else "FAILS"])
    header = ["arm", "gain", "margin (ms)", "margin (periods)", "delays run (periods)",
              "start error (rad)", "final error per delay (rad)",
              "settles no more from (periods)", "derivation"]
    return (f"A hold at a posture {d['offset_rad']:g} rad off on every joint, "
            f"{d['duration_s']:g} s per delay; the derivation holds if the loop settles at "
            f"{d['within']:g} margin late and not at {d['beyond']:g} margin late.\n\n"
            + table(header, rows))


def render_soak(runs):
    """The soak: tracking (whole run, last fifth), efforts and safe ones, gaps, late ticks,
    memory growth, estimates bounded."""
    rows = [[fmt(r["tracking_rms"]), fmt(r["tracking_rms_last_fifth"]), r["efforts"],
             r["watchdog_efforts"], fmt(r["longest_gap_ms"]), r["gaps_over_2h"],
             f"{r['controller_late_ticks']}/{r['controller_skipped_ticks']}",
             f"{100 * r['memory_growth']:.2f} %",
             fmt(r["theta_max"]), "yes" if r["theta_bounded"] else "no"]
            for r in runs]
    header = ["tracking RMS (rad)", "last fifth (rad)", "efforts", "safe efforts",
              "longest gap (ms)", "gaps > 2 periods", "late/skipped ticks", "RSS growth",
              "max |θ̂|", "estimates bounded"]
    return ("Goal: tracking within 10x the idle `nominal` case of [A starved machine]"
            "(#a-starved-machine); estimates bounded.\n\n" + table(header, rows))


def render_stall(runs):
    """The stall against the direct case: tracking, when control came back and settled,
    the largest estimate."""
    rows = [[r["case"], fmt(r["tracking_rms"]), fmt(r["tracking_rms_last_fifth"]),
             fmt(r.get("control_back_s")), fmt(r.get("settle_s")),
             r.get("controller_watchdog_replans", "-"), fmt(r["theta_max"]),
             "yes" if r["theta_bounded"] else "no", "yes" if r["recovered"] else "no"]
            for r in runs]
    header = ["case", "tracking RMS (rad)", "last fifth (rad)", "control back (s)",
              "within 3x after (s)", "motion restarts", "max |θ̂|", "estimates bounded",
              "recovered"]
    return ("Goal: the law's effort within 1 s of the process running again, tracking within "
            "3x `direct`'s RMS within 5 s (and staying), estimates bounded.\n\n"
            + table(header, rows))


def render_faults(runs):
    """Per case: tracking against the reference (whole run, and in the faulty window), the
    longest gap between efforts, safe efforts, the guard's spells, late ticks."""
    rows = []
    for r in runs:
        rows.append([r["case"], fmt(r["tracking_rms"]), fmt(r["tracking_ratio"]),
                     fmt(r.get("window_ratio")), fmt(r["longest_gap_ms"]),
                     fmt(r.get("plain_loop_gap_ms")), r["watchdog_efforts"],
                     r["controller_starved_spells"], r["controller_delay_worst_ms"],
                     f"{r['controller_late_ticks']}/{r['controller_skipped_ticks']}",
                     "yes" if r["theta_bounded"] else "no", "yes" if r["recovered"] else "no"])
    header = ["case", "tracking RMS (rad)", "x reference", "x reference, loaded third",
              "longest gap (ms)", "plain loop's longest gap (ms)", "safe efforts",
              "starved spells", "worst delay (ms)", "late/skipped ticks", "estimates bounded",
              "recovered"]
    return ("Goal: the starved case tracks within 10x the reference while loaded, estimates "
            "bounded, control recovered (the last fifth within 3x).\n\n" + table(header, rows))
