"""The fault bench's verdicts and its table and plot (:mod:`.faults`)."""

import numpy as np

from rcac_ros.tools.bench.fault_cases import CASES, GOALS


def judge(results):
    """Add the verdicts against the reference and the goals.

    The reference of a case is the run of ``nominal`` (the relay in the loop) or, for a
    case without the relay, of ``direct``, each if it was run (else the other). A case whose
    controller holds its start (``trajectory: topic`` with only the flood's trajectories,
    all refused) has no tracking to compare: its ``tracking_ratio`` and ``recovered`` are
    ``None``.
    """
    runs = {r["case"]: r["tracking_rms"] for r in results if r["case"] in ("nominal", "direct")}
    for r in results:
        spec = CASES[r["case"]]
        order = ("nominal", "direct") if spec.relay else ("direct", "nominal")
        r["reference"] = next((c for c in order if runs.get(c)), None)
        ref = runs.get(r["reference"])
        if spec.controller.get("trajectory") == "topic":
            r["tracking_ratio"] = r["recovered"] = None
            ref = None
        else:
            r["tracking_ratio"] = r["tracking_rms"] / ref if ref and r["tracking_rms"] else None
            last = r["tracking_rms_last_fifth"]
            r["recovered"] = bool(ref and last is not None
                                  and last <= GOALS["tracking_ratio"] * ref)
        if spec.check is not None:
            spec.check(r, ref)
    return results


def _yes_no(flag):
    return "-" if flag is None else "yes" if flag else "NO"


def format_table(results, h):
    head = (f"{'case':<13} {'track RMS (rad)':>15} {'x ref':>9} {'longest gap':>11} "
            f"{'gaps>2h':>7} {'theta ok':>8} {'recovered':>9}  notes")
    lines = [head, "-" * len(head)]
    for r in results:
        ratio = "-" if r["tracking_ratio"] is None else f"{r['tracking_ratio']:.2f}"
        rms = "-" if r["tracking_rms"] is None else f"{r['tracking_rms']:.3g}"
        notes = []
        if r.get("reference") == "direct" and r["case"] != "direct" \
                and r["tracking_ratio"] is not None:
            notes.append("ref: direct")
        if r["case"] == "restart":
            rec = r.get("restart_recovery_s")
            notes.append("control back after " + ("never" if rec is None else f"{rec:.3f} s"))
        if r["case"] == "frozen_clock":
            back, settle = r.get("control_back_s"), r.get("settle_s")
            notes.append("control back after " + ("never" if back is None else f"{back:.3f} s")
                         + "; within 3x nominal after "
                         + ("- (not in the run)" if settle is None else f"{settle:.2f} s"))
        if r.get("dropped"):
            notes.append(f"{r['dropped']} states dropped")
        if r.get("watchdog_efforts"):
            notes.append(f"{r['watchdog_efforts']} safe efforts")
        if "window_efforts" in r:
            notes.append(f"in the faulty third: {r['window_safe']}/{r['window_efforts']} safe, "
                         f"longest gap {r['window_gap_ms']:.1f} ms (plain loop "
                         f"{r.get('plain_loop_gap_ms') or float('nan'):.1f} ms)")
        if r.get("window_ratio") is not None:
            notes.append(f"tracking in it {r['window_ratio']:.2f}x ref")
        if "window_ok" in r:
            notes.append("goal " + ("met" if r["window_ok"] else "NOT met"))
        if "controller_starved_spells" in r:
            notes.append(f"starved spells {r['controller_starved_spells']} (worst delay "
                         f"{r.get('controller_delay_worst_ms', '-')} ms)")
        if "memory_growth" in r:
            notes.append(f"RSS growth {100 * r['memory_growth']:.1f} %")
        if "controller_late_ticks" in r:
            notes.append(f"late/skipped ticks {r['controller_late_ticks']}/"
                         f"{r.get('controller_skipped_ticks', '-')}")
        if "simulator_late_ticks" in r:
            notes.append(f"simulator's {r['simulator_late_ticks']}/"
                         f"{r.get('simulator_skipped_ticks', '-')}")
        lines.append(f"{r['case']:<13} {rms:>15} {ratio:>9} {r['longest_gap_ms']:>8.1f} ms "
                     f"{r['gaps_over_2h']:>7} {'yes' if r['theta_bounded'] else 'NO':>8} "
                     f"{_yes_no(r['recovered']):>9}  {'; '.join(notes)}")
    lines.append(f"goals: tracking <= {GOALS['tracking_ratio']:g}x nominal (drops, jitter, "
                 f"noise); control back within {GOALS['restart_recovery_s']:g} s of a restart "
                 f"or of /clock resuming, tracking within 3x nominal {GOALS['settle_s']:g} s "
                 "after it; "
                 f"no gap > {GOALS['gap_periods'] * h * 1e3:g} ms; hostile flood: no safe "
                 "effort and no gap beyond the plain loop's + 2 periods; starved: tracking "
                 f"<= {GOALS['starved_ratio']:g}x the reference while loaded")
    return "\n".join(lines)


#: s without a tracking sample after which the plot breaks its line (samples every 20 ms)
GAP_S = 0.5


def plot(results, path):
    from rcac_ros.tools.plots import plt
    fig, axes = plt.subplots(len(results), 1, figsize=(9, 2.0 * len(results)), sharex=True,
                             squeeze=False)
    for ax, r in zip(axes[:, 0], results):
        t, e = np.asarray(r["tracking_t_s"], float), np.maximum(r["tracking"], 1e-12)
        cut = np.flatnonzero(np.diff(t) > GAP_S) + 1      # no line across a silence
        ax.semilogy(np.insert(t, cut, np.nan), np.insert(e, cut, np.nan), lw=0.7)
        ax.set_ylabel("|q - q_d| (rad)", fontsize=7)
        ax.set_title(r["case"], fontsize=8, loc="left")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
