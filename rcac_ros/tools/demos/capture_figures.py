"""The figures of a capture (``rcac capture-demo``, :mod:`.capture`): from the tracking error,
the efforts and the last link's estimates of a run, around each event (the capture, the
release); and their Markdown tables. numpy only.
"""

import math

import numpy as np

#: the window before an event whose RMS tracking error is the reference, s
PRE_WINDOW = 5.0
#: the trailing window of the recovery RMS, s, and the factor it must stay within
WINDOW, FACTOR = 1.0, 2.0
#: goals: recovery time (s), last link's mass estimate relative error at the end
GOAL_RECOVERY, GOAL_MASS = 5.0, 0.05
#: s: two times closer than this are one (a bag's stamps, ``sec + 1e-9 nsec``, and an offline
#: loop's ``k h`` round apart), so that both runs cut their windows at the same sample
EPS = 1e-9


# ------------------------------------------------------------------ figures
def norm_rows(x):
    return np.linalg.norm(np.asarray(x, dtype=float), axis=1)


def recovery_time(t, e, t_event, t_end, reference, window=WINDOW, factor=FACTOR):
    """Seconds from ``t_event`` until the RMS of ``e`` over the trailing ``window`` s stays
    within ``factor * reference`` up to ``t_end``; 0 if it never left it, None if it is
    still outside at ``t_end`` or without a reference (no sample before the event)."""
    if not math.isfinite(reference):
        return None
    t = np.asarray(t, dtype=float)
    sq = np.sum(np.square(e), axis=1)
    n = e.shape[1]
    cum = np.concatenate([[0.0], np.cumsum(sq)])
    idx = np.nonzero((t >= t_event - EPS) & (t < t_end - EPS))[0]
    if idx.size == 0:
        return None
    lo = np.searchsorted(t, t[idx] - window + EPS, side="right")
    rms = np.sqrt((cum[idx + 1] - cum[lo]) / (n * (idx + 1 - lo)))
    out = np.nonzero(rms > factor * reference)[0]
    if out.size == 0:
        return 0.0
    last = idx[out[-1]]
    if out[-1] == idx.size - 1:
        return None
    return float(t[last + 1] - t_event)


def figures(track, effort, estimates, t_event, t_end, truth, effort_limit):
    """The figures of one event (a capture or a release).

    Parameters
    ----------
    track : (t (T,), e (T, n))
        Tracking errors ``q - q_d``, rad.
    effort : (t (T,), tau (T, n))
        The controller's efforts, N m.
    estimates : (t (T,), theta_hat_last (T, 13))
        The last link's estimates.
    t_event, t_end : float
        The event and the end of its phase, s.
    truth : ndarray (13,)
        The last link's true parameters after the event.
    effort_limit : ndarray (n,)

    Returns
    -------
    dict
    """
    t, e = (np.asarray(a, dtype=float) for a in track)
    before = (t >= max(0.0, t_event - PRE_WINDOW) - EPS) & (t < t_event - EPS)
    after = (t >= t_event - EPS) & (t < t_end - EPS)
    rms_before = float(np.sqrt(np.mean(np.square(e[before])))) if before.any() else math.nan
    out = {"event_time_s": float(t_event), "phase_end_s": float(t_end),
           "rms_error_before_rad": rms_before,
           "peak_error_norm_after_rad": float(norm_rows(e[after]).max()) if after.any()
           else math.nan,
           "recovery_time_s": recovery_time(t, e, t_event, t_end, rms_before)}
    te, th = (np.asarray(a, dtype=float) for a in estimates)
    last = np.nonzero(te < t_end - EPS)[0]
    est = th[last[-1]] if last.size else th[-1]
    out["mass_true_kg"] = float(truth[0])
    out["mass_estimate_end_kg"] = float(est[0])
    out["mass_relative_error_end"] = _relative(abs(est[0] - truth[0]), abs(truth[0]))
    out["first_moment_true_kg_m"] = truth[1:4].tolist()
    out["first_moment_estimate_end_kg_m"] = est[1:4].tolist()
    out["first_moment_relative_error_end"] = _relative(np.linalg.norm(est[1:4] - truth[1:4]),
                                                       np.linalg.norm(truth[1:4]))
    out.update(effort_figures(effort, effort_limit, t_event, t_end))
    return out


def _relative(error, truth):
    """``error / truth``; NaN where the truth is zero (no relative error is defined)."""
    return float(error / truth) if truth > 0.0 else math.nan


def effort_figures(effort, effort_limit, start, stop):
    """The largest effort over ``[start, stop)`` against the limits, and where a limit is
    first reached (``None`` if never)."""
    t, tau = (np.asarray(a, dtype=float) for a in effort)
    sel = (t >= start - EPS) & (t < stop - EPS)
    if not sel.any():                   # no effort in the phase (a run cut short)
        return {"max_effort_nm": math.nan, "max_effort_over_limit": math.nan,
                "max_effort_joint": None, "max_effort_time_s": None,
                "limit_first_reached_s": None, "limit_first_reached_joint": None,
                "steps_at_limit": 0}
    ratio = np.abs(tau[sel]) / effort_limit
    k, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    at = np.nonzero(np.any(ratio >= 1.0 - 1e-9, axis=1))[0]
    return {"max_effort_nm": float(np.abs(tau[sel]).max()),
            "max_effort_over_limit": float(ratio[k, j]), "max_effort_joint": int(j) + 1,
            "max_effort_time_s": float(t[sel][k]),
            "limit_first_reached_s": float(t[sel][at[0]]) if at.size else None,
            "limit_first_reached_joint": (int(np.argmax(ratio[at[0]] >= 1.0 - 1e-9)) + 1
                                          if at.size else None),
            "steps_at_limit": int(at.size)}


def goals(fig, watchdog_trips=None):
    """Which goals of a capture are met (``True``/``False``; ``None``: not measured)."""
    rec = fig["recovery_time_s"]
    out = {"recovery_within_5s": rec is not None and rec <= GOAL_RECOVERY,
           "mass_estimate_within_5pct": fig["mass_relative_error_end"] <= GOAL_MASS,
           "effort_within_limits": fig["max_effort_over_limit_run"] < 1.0 - 1e-9,
           "no_watchdog_trip": None if watchdog_trips is None else watchdog_trips == 0}
    return out


def phases(at, release, duration):
    """``[(name, start, end)]`` of the run: the capture, and the release if any."""
    out = [("capture", at, release if release is not None else duration + 1e-9)]
    if release is not None:
        out.append(("release", release, duration + 1e-9))
    return out


def all_figures(track, effort, estimates, at, release, duration, arm, loaded, watchdog=None):
    """``{"capture": {...}, "release": {...}}`` with the run's largest effort and goals."""
    run_effort = effort_figures(effort, arm.effort_limit, -1.0, duration + 1.0)
    out = {}
    for name, start, end in phases(at, release, duration):
        model = loaded if name == "capture" else arm
        fig = figures(track, effort, estimates, start, end, model.theta()[-1], arm.effort_limit)
        fig["max_effort_over_limit_run"] = run_effort["max_effort_over_limit"]
        fig["goals"] = goals(fig, watchdog)
        out[name] = fig
    out["run_effort"] = run_effort
    return out


# ------------------------------------------------------------------ text
ROWS = (("rms_error_before_rad", "RMS before (rad)", "{:.3g}"),
        ("peak_error_norm_after_rad", "peak \\|e\\| after (rad)", "{:.3g}"),
        ("recovery_time_s", "recovery (s)", "{:.2f}"),
        ("mass_estimate_end_kg", "m7 estimate end (kg)", "{:.1f}"),
        ("mass_relative_error_end", "m7 rel. error end", "{:.2%}"),
        ("first_moment_relative_error_end", "m7 c7 rel. error end", "{:.2%}"),
        ("max_effort_over_limit", "max \\|tau\\|/limit", "{:.2f}"),
        ("limit_first_reached_s", "limit first reached (s)", "{:.3f}"))


def _cell(v, fmt):
    if v is None:
        return "—" if fmt != "{:.2f}" else "not recovered"
    if isinstance(v, float) and not math.isfinite(v):
        return "—"
    return fmt.format(v)


def table(columns, phase):
    """A Markdown table: a row per figure, a column per run (``{label: all_figures}``)."""
    labels = list(columns)
    lines = ["| " + phase + " | " + " | ".join(labels) + " |",
             "|---|" + "---:|" * len(labels)]
    for key, head, fmt in ROWS:
        cells = [_cell(columns[k][phase].get(key), fmt) for k in labels]
        lines.append(f"| {head} | " + " | ".join(cells) + " |")
    for goal in ("recovery_within_5s", "mass_estimate_within_5pct", "effort_within_limits",
                 "no_watchdog_trip"):
        cells = [{True: "met", False: "missed", None: "—"}[columns[k][phase]["goals"][goal]]
                 for k in labels]
        lines.append(f"| goal {goal} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def mass_markdown(rows):
    lines = ["| payload (t) | slowdown s | desired \\|tau\\|/limit at s = 1 | RMS before (rad) | "
             "peak \\|e\\| after (rad) | recovery (s) | m7 rel. error | m7 c7 rel. error | "
             "max \\|tau\\|/limit | goals met (of recovery, mass, limits) |", "|" + "---:|" * 10]
    short = {"recovery_within_5s": "recovery", "mass_estimate_within_5pct": "mass",
             "effort_within_limits": "limits"}
    for r in rows:
        met = ", ".join(short[k] for k, v in r["goals"].items() if v and k in short) or "none"
        lines.append(
            f"| {r['payload_mass_kg'] / 1000:g} | {r['slowdown']:.2f} | "
            f"{r['desired_effort_over_limit_unslowed']:.2f} | {r['rms_error_before_rad']:.3g} | "
            f"{r['peak_error_norm_after_rad']:.3g} | {_cell(r['recovery_time_s'], '{:.2f}')} | "
            f"{r['mass_relative_error_end']:.2%} | {r['first_moment_relative_error_end']:.2%} | "
            f"{r['max_effort_over_limit']:.2f} | {met} |")
    return "\n".join(lines) + "\n"
