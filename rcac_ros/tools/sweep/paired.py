"""Paired ratios of a law grid: each plant's friction-aware RMS over its friction-blind RMS.

The campaigns ``campaigns/friction_{panda,ur5,xarm7}.yaml`` (doc/campaigns.md, "Unseen plants")
run, on the same drawn plant (``paired: true``), the friction-blind recursive composite law
and the one with the joint terms at their default gain. This reads their results and writes
the distribution of ``rms(composite_friction) / rms(composite)`` per arm and pooled: a JSON
summary (median, 90th percentile, worst, divergences) and a figure::

    python -m rcac_ros.tools.sweep.paired results/friction_panda results/friction_ur5 \\
        results/friction_xarm7 --out results/friction_unseen
"""

import argparse
import json
import os

import numpy as np

from rcac_ros.tools.args import output_dir
from rcac_ros.tools.sweep.report import load_table

#: the grid's laws: (reference, compared)
BLIND, AWARE = "composite", "composite_friction"
#: the goals of the comparison on unseen plants: median and worst ratio
GOALS = {"median": 0.05, "worst": 0.2}


def ratios(path):
    """``(name, ratio per plant, diverged aware, diverged blind, median blind RMS)`` of one
    results directory."""
    df, meta, _ = load_table(path)
    cells = len(set(df["law"]))
    df = df.assign(plant=df["run"] // cells)
    blind = df[df["law"] == BLIND].set_index("plant")
    aware = df[df["law"] == AWARE].set_index("plant")
    both = blind.index.intersection(aware.index)
    r = (aware.loc[both, "rms_tracking_error"] / blind.loc[both, "rms_tracking_error"])
    return (meta["campaign"]["name"], r.to_numpy(dtype=float),
            int(aware.loc[both, "diverged"].astype(bool).sum()),
            int(blind.loc[both, "diverged"].astype(bool).sum()),
            float(blind.loc[both, "rms_tracking_error"].median()))


def summary(r):
    """Median, 90th percentile and worst of the ratios."""
    return {"plants": int(r.size), "median": float(np.median(r)),
            "p90": float(np.percentile(r, 90)), "worst": float(np.max(r))}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", help="results directories of the campaigns")
    parser.add_argument("--out", type=output_dir, default="results/friction_unseen",
                        help="output directory")
    args = parser.parse_args(argv)
    rows, every = {}, []
    for path in args.results:
        name, r, div_aware, div_blind, blind_rms = ratios(path)
        rows[name] = dict(summary(r), diverged_aware=div_aware, diverged_blind=div_blind,
                          median_blind_rms_rad=blind_rms)
        every.append((name, r))
    pooled = np.concatenate([r for _, r in every])
    out = {"ratio": "rms(friction-aware) / rms(friction-blind), same plant",
           "goals": GOALS, "arms": rows, "pooled": summary(pooled)}
    out["met"] = {"median": out["pooled"]["median"] <= GOALS["median"],
                  "worst": out["pooled"]["worst"] <= GOALS["worst"],
                  "none_diverged": all(v["diverged_aware"] == 0 for v in rows.values())}
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "ratios.json"), "w", encoding="utf-8") as f:
        json.dump(out, f, indent=2)
    from rcac_ros.tools.plots import plt
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    ax.boxplot([r for _, r in every] + [pooled], whis=(0, 100))
    ax.set_xticks(range(1, len(every) + 2), [n for n, _ in every] + ["pooled"])
    for k, (_, r) in enumerate(every + [("pooled", pooled)]):
        x = np.random.default_rng(k).uniform(-0.15, 0.15, r.size) + k + 1
        ax.plot(x, r, ".", ms=3, alpha=0.5)
    for goal, ls in ((GOALS["median"], "--"), (GOALS["worst"], ":")):
        ax.axhline(goal, color="k", ls=ls, lw=0.8)
    ax.set_ylabel("RMS aware / RMS blind (same plant)")
    ax.set_title("Joint terms at their default gain on unseen MuJoCo plants")
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "ratios.png"), dpi=110)
    plt.close(fig)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
