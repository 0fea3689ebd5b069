"""``rcac sweep report`` and ``rcac sweep rerun``: a campaign's summary, tables and figure,
and one run again, alone (doc/campaigns.md)."""

import json
import os

import numpy as np

from rcac_ros.errors import ConfigError
from rcac_ros.tools.sweep import campaign as cp
from rcac_ros.tools.sweep.store import METRICS, open_results


def load_table(path):
    """``(DataFrame, metadata)`` of a results directory (results and unmerged parts)."""
    store = open_results(path)
    df = store.table().to_pandas()
    campaign = store.campaign()
    return df, {"campaign": campaign, "varied": cp.varied_columns(campaign)}, store


def sensitivity(df, inputs, metric="rms_tracking_error"):
    """Spearman rank correlation of ``metric`` with each numeric input (NaN if constant)."""
    numeric = [c for c in inputs if df[c].dtype.kind in "fiu" and df[c].nunique() > 1]
    if not numeric or len(df) < 3:
        return {}
    corr = df[numeric + [metric]].corr(method="spearman")[metric]
    return {c: float(corr[c]) for c in numeric}


def report(path, worst=10, plot=None, json_path=None):
    """Print the campaign's summary and write its figure (``json_path``: and the summary as
    JSON: runs and divergences per law, each metric's distribution per law, the Spearman
    correlations)."""
    df, meta, store = load_table(path)
    import pandas as pd
    varied = meta["varied"]
    n = len(df)
    expected = cp.run_count(meta["campaign"])
    div = df["diverged"].astype(bool)
    print(f"campaign {meta['campaign']['name']!r}: {n} of {expected} runs, "
          f"{int(div.sum())} diverged ({100.0 * div.mean():.1f} %)")
    if "channels" in varied:      # a law is a law and its channel set
        channels = df["channels"].fillna("").astype(str)
        df["law"] = np.where(channels != "", df["law"] + " " + channels, df["law"])
    laws = sorted(df["law"].unique())
    summary = {"campaign": meta["campaign"]["name"], "runs": n, "expected": expected,
               "diverged": int(div.sum()),
               "per_law": {law: {"runs": int((df["law"] == law).sum()),
                                 "diverged": int(div[df["law"] == law].sum())}
                           for law in laws}}
    w = max(11, *(len(law) for law in laws))
    print("\nfailure rate per law:")
    for law in laws:
        sel = df["law"] == law
        print(f"  {law:{w}s} {int(div[sel].sum()):5d} / {int(sel.sum()):5d}  "
              f"({100.0 * div[sel].mean():.1f} %)")
    print("\nmetric distributions per law (median [5 %, 95 %] max; runs that did not "
          "diverge):")
    for m in METRICS:
        for law in laws:
            v = df.loc[(df["law"] == law) & ~div, m]
            if len(v):
                q = v.quantile([0.5, 0.05, 0.95])
                summary["per_law"][law][m] = {"median": float(q.iloc[0]),
                                              "p5": float(q.iloc[1]),
                                              "p95": float(q.iloc[2]), "max": float(v.max())}
                print(f"  {m:27s} {law:{w}s} {q.iloc[0]:11.4g} [{q.iloc[1]:10.4g}, "
                      f"{q.iloc[2]:10.4g}] {v.max():10.4g}")
    cols = ["run", "law", "status", "t_end", "rms_tracking_error", "max_tracking_error"] + [
        c for c in varied if c != "law"]
    # diverged first, the earliest divergence first; then the largest RMS error
    key = np.where(div, -df["t_end"].to_numpy(), df["rms_tracking_error"].to_numpy())
    order = df.assign(_d=div, _k=key).sort_values(["_d", "_k"], ascending=[False, False],
                                                  na_position="first")
    print(f"\nworst {min(worst, n)} runs (diverged first, earliest first; then by RMS error)"
          "; rerun one with 'rcac sweep rerun RESULTS INDEX':")
    with pd.option_context("display.width", 200, "display.max_columns", 30,
                           "display.float_format", "{:.4g}".format):
        print(order[cols].head(worst).to_string(index=False))
    print("\nsensitivity (Spearman rank correlation) of the RMS error of the runs that did "
          "not diverge, per law, and of divergence (0/1, all runs):")
    ok = df[~div]
    sens = {"all": sensitivity(ok, varied)}
    for law in laws:
        sens[law] = sensitivity(ok[ok["law"] == law], varied)
    if div.any():
        sens["diverged"] = sensitivity(df.assign(_div=div.astype(float)), varied, "_div")
    names = sorted({c for s in sens.values() for c in s}, key=lambda c: -abs(
        sens["all"].get(c, 0.0)))
    cw = max(12, *(len(k) + 2 for k in sens))
    print(f"  {'input':22s}" + "".join(f"{k:>{cw}s}" for k in sens))
    for c in names:
        print(f"  {c:22s}" + "".join(f"{s[c]:{cw}.3f}" if c in s else f"{'-':>{cw}s}"
                                     for s in sens.values()))
    for c in [c for c in varied if df[c].dtype.kind not in "fiu" and c != "law"]:
        medians = ok.groupby(c)["rms_tracking_error"].median()
        print(f"  {c}: median RMS per value: " + ", ".join(
            f"{k or '-'}: {v:.4g}" for k, v in medians.items()))
    summary["sensitivity"] = {k: {c: float(v) for c, v in s.items()} for k, s in sens.items()}
    if json_path:
        with open(json_path, "w", encoding="utf-8") as f:
            json.dump(summary, f, indent=1)
        print(f"wrote {json_path}")
    plot = plot or os.path.join(store.out, "report.png")
    plot_report(df, div, laws, sens["all"], plot)
    print(f"\nwrote {plot}")
    return 0


def plot_report(df, div, laws, sens, path):
    """Four panels: RMS per law, failure rate per law, sensitivity, RMS vs the top input."""
    from rcac_ros.tools.plots import plt, save
    fig, axes = plt.subplots(1, 4, figsize=(22, 4.5))
    ok = df[~div]
    data = [np.clip(ok.loc[ok["law"] == law, "rms_tracking_error"].to_numpy(), 1e-12, None)
            for law in laws]
    axes[0].boxplot(data, tick_labels=laws)
    axes[0].set_yscale("log")
    axes[0].set_title("tracking RMS error per law (rad)")
    rates = [100.0 * div[df["law"] == law].mean() for law in laws]
    axes[1].bar(laws, rates, color="C3")
    axes[1].set_ylim(0.0, max(1.0, 1.1 * max(rates)))     # 0 %: an empty panel, not a gap
    axes[1].set_title("diverged runs per law (%)")
    names = sorted(sens, key=lambda c: abs(sens[c]))
    axes[2].barh(names, [sens[c] for c in names], color="C0")
    axes[2].set_xlim(-1, 1)
    axes[2].set_title("Spearman correlation with RMS error")
    if names:
        top = names[-1]
        for law in laws:
            sel = ok["law"] == law
            axes[3].scatter(ok.loc[sel, top], ok.loc[sel, "rms_tracking_error"], s=8, label=law)
        axes[3].set_yscale("log")
        axes[3].set_xlabel(top)
        axes[3].set_title(f"RMS error vs {top}")
        axes[3].legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    save(fig, path, 100)


# --------------------------------------------------------------------------- rerun

def rerun(path, index, plot=None):
    """Run ``index`` again, alone, in this process; compare with its stored row; plot it."""
    df, meta, store = load_table(path)
    campaign = meta["campaign"]
    if index >= cp.run_count(campaign):
        raise ConfigError(f"INDEX: the campaign has {cp.run_count(campaign)} runs, got {index}")
    row, result = cp.simulate(campaign, index, keep_run=True)
    stored = df[df["run"] == index]
    cells = [f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()]
    print(f"run {index}: " + ", ".join(cells))
    if len(stored):
        old = stored.iloc[0]
        diffs = [abs(row[m] - old[m]) / max(abs(old[m]), 1e-300) for m in METRICS
                 if np.isfinite(old[m])]
        same = all(row[c] == old[c] for c in df.columns
                   if c not in METRICS + cp.TIMING and not (
                       isinstance(row[c], float) and np.isnan(row[c])))
        print(f"stored row: inputs {'identical' if same else 'DIFFER'}, largest relative "
              f"metric difference {max(diffs, default=0.0):.3g}")
    else:
        print("stored row: none (run not in the results yet)")
    from rcac_ros.tools.plots import plt, save
    plot = plot or os.path.join(store.out, f"rerun_{index}.png")
    fig, axes = plt.subplots(1, 3, figsize=(18, 4))
    t = result["t"]
    e = result["q"] - result["q_d"]
    for j in range(e.shape[1]):
        axes[0].plot(t, e[:, j], lw=0.8, label=f"joint {j + 1}")
    axes[0].set_title(f"run {index} ({row['law']}, {row['status']}): q - q_d (rad)")
    axes[0].legend(fontsize=7)
    theta = result["plant"].theta()
    axes[1].semilogy(t, np.linalg.norm((result["theta_hat"] - theta).reshape(len(t), -1),
                                       axis=1))
    axes[1].set_title("||theta_hat - theta||")
    axes[2].plot(t, result["E"], lw=0.8)
    axes[2].set_title("prediction error E")
    for ax in axes:
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
    save(fig, plot, 100)
    print(f"wrote {plot}")
    return 0
