"""``rcac sweep report --json``: the summary it writes is the results table's own figures."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from rcac_ros.tools import cli

CAMPAIGN = {
    "name": "tiny", "seed": 5, "samples": 6,
    "scenario": {"model": "css_arm", "duration": 0.3},
    "vary": {"law": {"grid": ["direct", "composite"]},
             "K_D": {"loguniform": {"low": 5e3, "high": 2e4}}},
}


def test_the_json_summary_holds_each_laws_runs_and_quantiles(tmp_path, capsys):
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(CAMPAIGN))
    out = tmp_path / "out"
    assert cli.main(["sweep", str(path), "--out", str(out), "--workers", "0", "--quiet"]) == 0
    summary_path = tmp_path / "summary.json"
    assert cli.main(["sweep", "report", str(out), "--json", str(summary_path),
                     "--plot", str(tmp_path / "r.png")]) == 0
    capsys.readouterr()
    summary = json.loads(summary_path.read_text())
    df = pq.read_table(out / "results.parquet").to_pandas()
    assert (summary["campaign"], summary["runs"], summary["expected"]) == ("tiny", 12, 12)
    assert summary["diverged"] == int(df["diverged"].sum())
    for law in ("direct", "composite"):
        sel = df[(df["law"] == law) & ~df["diverged"]]["rms_tracking_error"].to_numpy()
        got = summary["per_law"][law]
        assert got["runs"] == int((df["law"] == law).sum())
        # numpy's quantiles with linear interpolation, as pandas' default: the same numbers
        rms = got["rms_tracking_error"]
        assert rms["median"] == pytest.approx(np.quantile(sel, 0.5), rel=1e-12)
        assert rms["p5"] == pytest.approx(np.quantile(sel, 0.05), rel=1e-12)
        assert rms["p95"] == pytest.approx(np.quantile(sel, 0.95), rel=1e-12)
        assert rms["max"] == pytest.approx(sel.max(), rel=1e-12)
    assert "K_D" in summary["sensitivity"]["all"]
