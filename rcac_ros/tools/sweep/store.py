"""The results directory of a campaign: ``campaign.json``, Parquet part files, one merged
``results.parquet`` (doc/campaigns.md).

Each finished chunk is written at once as a Parquet part file (``DIR/parts/``); at the
end (or on Ctrl-C) the parts are merged into ``DIR/results.parquet``, one row per run,
sorted by ``run``. ``--resume`` skips every run already in the results or the parts.
"""

import glob
import json
import os

import numpy as np

from rcac_ros.errors import ConfigError
from rcac_ros.tools.sweep import campaign as cp

#: the figures of a run among the columns of the results (recorded in results.parquet's
#: metadata), in the order the report lists them
METRICS = ("rms_tracking_error", "max_tracking_error", "rms_tracking_error_last_5s",
           "parameter_error_norm_end", "final_abs_prediction_error", "max_abs_torque",
           "max_effort_ratio")


class Store:
    """A results directory: ``campaign.json``, ``parts/*.parquet``, ``results.parquet``."""

    def __init__(self, out):
        self.out = out
        self.parts = os.path.join(out, "parts")
        self.results = os.path.join(out, "results.parquet")
        self.campaign_file = os.path.join(out, "campaign.json")

    def claim(self, campaign, resume=False):
        """Record ``campaign`` here, or check it is the one already recorded (``resume``)."""
        key = dict(campaign, samples=None)
        if resume and not os.path.exists(self.campaign_file):
            raise ConfigError(f"--resume: no campaign to continue in {self.out} (no "
                              "campaign.json); without --resume a new one starts there")
        if os.path.exists(self.campaign_file):
            if not resume:
                raise ConfigError(f"--out: {self.out} already holds a campaign; pass --resume "
                                  "to continue it, or choose another directory")
            with open(self.campaign_file, encoding="utf-8") as f:
                if dict(json.load(f), samples=None) != json.loads(json.dumps(key)):
                    raise ConfigError(f"--resume: the campaign differs from the one in "
                                      f"{self.campaign_file} (only --samples may change)")
        os.makedirs(self.parts, exist_ok=True)
        write_atomic(self.campaign_file, json.dumps(campaign, indent=1).encode())

    def campaign(self):
        """The recorded campaign."""
        try:
            with open(self.campaign_file, encoding="utf-8") as f:
                return json.load(f)
        except OSError:
            raise ConfigError(f"RESULTS: no campaign.json in {self.out}") from None

    def part_files(self):
        return sorted(glob.glob(os.path.join(self.parts, "part-*.parquet")))

    def done(self):
        """The indices of the finished runs (results and parts)."""
        import pyarrow.parquet as pq
        runs = set()
        for path in self.part_files() + ([self.results] if os.path.exists(self.results)
                                         else []):
            runs.update(pq.read_table(path, columns=["run"]).column("run").to_pylist())
        return runs

    def write(self, rows):
        """One finished chunk: a part file, written atomically."""
        import pyarrow as pa
        import pyarrow.parquet as pq
        path = os.path.join(self.parts, f"part-{rows[0]['run']:07d}-{len(rows)}.parquet")
        tmp = path + ".tmp"
        pq.write_table(pa.Table.from_pylist(rows), tmp)
        os.replace(tmp, path)

    def table(self):
        """Results and parts as one table sorted by ``run`` (ConfigError on a duplicate)."""
        import pyarrow as pa
        import pyarrow.parquet as pq
        tables = [pq.read_table(p) for p in self.part_files()]
        if os.path.exists(self.results):
            tables.insert(0, pq.read_table(self.results).replace_schema_metadata(None))
        if not tables:
            raise ConfigError(f"RESULTS: no results in {self.out}")
        table = pa.concat_tables(tables, promote_options="default").sort_by("run")
        runs = np.asarray(table.column("run"))
        if np.any(np.diff(runs) == 0):
            raise ConfigError(f"RESULTS: run {runs[1:][np.diff(runs) == 0][0]} appears twice")
        return table

    def merge(self):
        """Fold the parts into ``results.parquet`` (atomically), then delete them."""
        import pyarrow.parquet as pq
        parts = self.part_files()
        table = self.table()
        campaign = self.campaign()
        meta = {"campaign": campaign, "varied": cp.varied_columns(campaign),
                "metrics": list(METRICS)}
        table = table.replace_schema_metadata({"rcac_sweep": json.dumps(meta)})
        tmp = self.results + ".tmp"
        pq.write_table(table, tmp)
        os.replace(tmp, self.results)
        for p in parts:
            os.remove(p)
        return table


def write_atomic(path, data):
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def open_results(path):
    """A results directory or its ``results.parquet`` -> its :class:`Store`."""
    out = os.path.dirname(path) if path.endswith(".parquet") else path
    if not os.path.isdir(out):
        raise ConfigError(f"RESULTS: no such directory {out!r}")
    return Store(out or ".")
