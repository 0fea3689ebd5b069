"""The summary of a run of ``campaigns/consistency.yaml`` (doc/design.md §8), as JSON.

Run from the repository root::

    rcac sweep campaigns/consistency.yaml --out results/consistency
    python -m rcac_ros.tools.sweep.consistency results/consistency summary.json
    python -m rcac_ros.tools.results record consistency_campaign --from summary.json \
        --command "..." --date ... --revision ...

Per geometry: runs, consistency and RMS figures. The campaign is paired (``paired: true``,
doc/campaigns.md): runs ``3 s`` to ``3 s + 2`` are sample ``s`` with the three geometries
on the same start and payload, so each natural law's RMS is also compared run by run (the
ratio natural / Euclidean per sample).
"""
import json
import os
import sys

import numpy as np

from rcac_ros.tools.sweep import campaign as cp


def by_geometry(rows):
    """The figures of one geometry's runs (a DataFrame)."""
    rms = rows.rms_tracking_error[rows.status == "ok"]
    return dict(runs=int(len(rows)),
                consistent_every_step_runs=int(rows.consistent_every_step.sum()),
                consistent_link_steps=float(rows.consistent_link_steps.mean()),
                min_lambda_min=float(rows.min_lambda_min.min()),
                rms_median=float(rms.median()), rms_mean=float(rms.mean()),
                rms_p90=float(rms.quantile(0.9)), diverged=int((rows.status != "ok").sum()),
                diverged_runs=[int(r) for r in rows.run[rows.status != "ok"]])


def paired_ratio(frame, cells, geometry="natural"):
    """``geometry`` / Euclidean RMS per sample (diverged runs included: their RMS up to the
    stop)."""
    frame = frame.assign(sample=frame.run // cells)
    e = frame[frame.geometry == "euclidean"].set_index("sample").rms_tracking_error
    n = frame[frame.geometry == geometry].set_index("sample").rms_tracking_error
    r = (n / e).dropna()
    q = np.quantile(r, [0.1, 0.5, 0.9])
    return dict(samples=int(len(r)), rms_ratio_median=float(q[1]), rms_ratio_p10=float(q[0]),
                rms_ratio_p90=float(q[2]), rms_ratio_min=float(r.min()),
                rms_ratio_max=float(r.max()), share_within_1_1=float(np.mean(r <= 1.1)))


def summary(out_dir):
    """The JSON of a results directory (``rcac sweep``'s ``--out``)."""
    import pyarrow.parquet as pq
    with open(os.path.join(out_dir, "campaign.json"), encoding="utf-8") as f:
        campaign = json.load(f)
    frame = pq.read_table(os.path.join(out_dir, "results.parquet")).to_pandas()
    cells = len(cp.grid_cells(campaign))
    geometries = [g for g in cp.GEOMETRIES if (frame.geometry == g).any()]
    data = {"campaign": f"campaigns/{campaign['name']}.yaml", "samples": campaign["samples"],
            "paired": bool(campaign.get("paired", False)),
            "by_geometry": {g: by_geometry(frame[frame.geometry == g]) for g in geometries}}
    for g in geometries[1:]:
        data[f"paired_{g}_over_euclidean"] = paired_ratio(frame, cells, g)
    return data


def main(out_dir, target="campaign_summary.json"):
    data = summary(out_dir)
    with open(target, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=2)
        f.write("\n")
    print(json.dumps(data, indent=2))


if __name__ == "__main__":
    main(*sys.argv[1:3])
