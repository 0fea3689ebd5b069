"""The tables of ``rcac compare``: ``compare.md`` and doc/results.md's comparison blocks.

Reads the report (a dict per scenario, per law, of the figures of
:func:`rcac_ros.tools.demos.compare.metrics`) only: no numba, no rclpy.
"""

import math

#: (key of a law's figures, column header) of the tables
COLUMNS = (("rms", "RMS (rad)"), ("rms_last_5s", "RMS last 5 s"), ("max_error", "max err"),
           ("theta_error_end", "‖θ̃‖ end"), ("max_abs_E", "max |E|"),
           ("us_per_step", "µs/step"), ("identifiable", "ident."), ("consistent", "consist."),
           ("consistent_steps", "consist. all steps"), ("lambda_min", "min λ_min(Ĵ)"),
           ("payload_mass_error", "payload |m̃|"), ("payload_first_moment_error", "payload ‖h̃‖"))


def cell(v, key):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    if key in ("identifiable", "consistent"):
        return str(v)
    if key == "us_per_step":
        return f"{v:.1f}"
    if key == "consistent_steps":
        return f"{100 * v:.4g} %"
    return f"{v:.3g}"


def side_by_side(report):
    """The RMS tracking error (rad) of every law (columns) on every scenario (rows)."""
    laws = []
    for rows in report.values():
        laws += [law for law in rows if law not in laws]
    lines = ["| scenario | " + " | ".join(laws) + " |", "|---|" + "---:|" * len(laws)]
    for name, rows in report.items():
        cells = []
        for law in laws:
            m = rows.get(law)
            cells.append("" if m is None else "diverged" if m["diverged_at"] is not None
                         else cell(m["rms"], "rms"))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def markdown(report, n_links=None):
    """The table, one section per scenario (with several, first their RMS side by side)."""
    lines = []
    if len(report) > 1:
        lines += ["### RMS tracking error (rad)\n", side_by_side(report)]
    for name, rows in report.items():
        lines.append(f"### {name}\n")
        lines.append("| law | " + " | ".join(h for _, h in COLUMNS) + " |")
        lines.append("|---|" + "---:|" * len(COLUMNS))
        for law, m in rows.items():
            cells = [cell(m.get(k), k) for k, _ in COLUMNS]
            if m["diverged_at"] is not None:
                cells[0] = f"diverged at {m['diverged_at']:.3f} s"
            lines.append(f"| {law} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)
