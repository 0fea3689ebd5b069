"""rcac sweep on real Dask clusters: a ``dask scheduler`` and two ``dask worker`` processes
started here on localhost, a LocalCluster, and this process alone give the same rows; a
worker killed mid-campaign loses and duplicates nothing."""

import json
import os
import signal
import subprocess
import sys
import time

import pyarrow.parquet as pq
import pytest
import yaml

pytest.importorskip("distributed")

from rcac_ros.tools.sweep import campaign as cp  # noqa: E402
from rcac_ros.tools.sweep.engine import execute  # noqa: E402
from rcac_ros.tools.sweep.store import Store  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ENV = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))

#: 20 runs of the paper's arm, 2 laws x 10 draws, noise, delay, payload, gains.
CAMPAIGN = {
    "name": "dask20", "seed": 3, "samples": 10,
    "scenario": {"model": "css_arm", "duration": 2.0},
    "vary": {"law": {"grid": ["direct", "composite"]},
             "K_D": {"loguniform": {"low": 5e3, "high": 2e4}},
             "gamma": {"uniform": {"low": 0.05, "high": 0.5}},
             "noise_q": {"uniform": {"low": 0.0, "high": 1e-5}},
             "noise_qd": {"uniform": {"low": 0.0, "high": 1e-4}},
             "delay": {"choice": [0, 2]},
             "payload_mass": {"uniform": {"low": 0.0, "high": 100.0}},
             "estimate_error": {"uniform": {"low": 0.0, "high": 0.3}}},
}


class DaskCluster:
    """``dask scheduler`` + ``dask worker`` processes on localhost (random free ports)."""

    def __init__(self, tmp, workers=2):
        self.file = str(tmp / "scheduler.json")
        dask = [sys.executable, "-m", "dask"]
        self.scheduler = self.spawn(dask + ["scheduler", "--host", "127.0.0.1", "--port", "0",
                                            "--no-dashboard", "--scheduler-file", self.file])
        self.address = self.read_address(time.monotonic() + 60)
        self.workers = [self.spawn(dask + ["worker", self.address, "--nthreads", "1",
                                           "--nworkers", "1", "--no-dashboard",
                                           "--name", f"w{k}", "--host", "127.0.0.1"])
                        for k in range(workers)]
        from distributed import Client
        with Client(self.address, timeout="30s") as client:
            client.wait_for_workers(workers, timeout=90)

    def read_address(self, deadline):
        """The scheduler's address from its file, once the scheduler has written all of it."""
        while True:
            try:
                with open(self.file, encoding="utf-8") as f:
                    return json.load(f)["address"]
            except (OSError, ValueError, KeyError):
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    @staticmethod
    def spawn(cmd):
        # own session: a kill reaches the nanny and its worker process together
        return subprocess.Popen(cmd, env=ENV, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True)

    @staticmethod
    def kill(proc, sig=signal.SIGKILL):
        if proc.poll() is None:
            os.killpg(proc.pid, sig)
        proc.wait(timeout=30)

    def close(self):
        for p in self.workers + [self.scheduler]:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in self.workers + [self.scheduler]:
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.kill(p)


@pytest.fixture
def cluster(tmp_path):
    c = DaskCluster(tmp_path)
    yield c
    c.close()


def table(path):
    return pq.read_table(path).drop(list(cp.TIMING)).to_pandas()


def assert_same_tables(a, b):
    """Same runs, same columns; numbers equal to 1e-12 (relative), the rest equal."""
    pd = pytest.importorskip("pandas")
    assert list(a.columns) == list(b.columns)
    assert list(a["run"]) == list(b["run"])
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-12, atol=0.0)


def test_real_cluster_localcluster_and_serial_give_the_same_rows(tmp_path, cluster):
    campaign = cp.validate(CAMPAIGN)
    assert cp.run_count(campaign) == 20
    outs = {}
    for name, kwargs in (("serial", dict(workers=0)), ("local", dict(workers=2)),
                         ("real", dict(scheduler=cluster.address))):
        store = Store(str(tmp_path / name))
        store.claim(campaign)
        assert execute(campaign, store, chunk=3, progress=False, **kwargs) == 20
        store.merge()
        outs[name] = table(store.results)
    assert list(outs["serial"]["run"]) == list(range(20))
    assert outs["serial"]["law"].tolist() == ["direct", "composite"] * 10
    assert_same_tables(outs["local"], outs["serial"])
    assert_same_tables(outs["real"], outs["serial"])


def test_killed_worker_loses_and_duplicates_nothing(tmp_path, cluster):
    """SIGKILL one worker (nanny included) mid-campaign: all 20 runs, each once."""
    doc = dict(CAMPAIGN, scenario=dict(CAMPAIGN["scenario"], duration=12.0))
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(doc))
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "rcac_ros.tools.cli", "sweep", str(path),
                             "--out", str(out), "--scheduler", cluster.address, "--chunk", "1"],
                            env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while len(list((out / "parts").glob("*.parquet"))) < 4 and time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    finished_before_kill = len(list((out / "parts").glob("*.parquet")))
    cluster.kill(cluster.workers[0])
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    assert finished_before_kill < 20                         # the kill was mid-campaign
    got = table(out / "results.parquet")
    assert list(got["run"]) == list(range(20))               # none lost, none twice
    campaign = cp.load(path)
    for i in (0, 7, 19):                                     # and each is the run itself
        ref = cp.simulate(campaign, i)
        for k in cp.TIMING:
            ref.pop(k)
        row = got.iloc[i].to_dict()
        for k, v in ref.items():
            assert row[k] == (pytest.approx(v, rel=1e-12) if isinstance(v, float) else v), k
    assert "Dask dashboard" in stderr and "20 runs in" in stdout


def test_bench_reports_what_it_measured(tmp_path, capsys):
    """--bench on a tiny campaign: its figures are consistent with one another."""
    from rcac_ros.tools import cli
    assert cli.main(["sweep", "--bench", "--samples", "4", "--duration", "0.2", "--out",
                     str(tmp_path)]) == 0
    text = capsys.readouterr().out
    figures = json.loads((tmp_path / "bench.json").read_text())
    assert figures["runs"] == 4 and figures["duration_s"] == 0.2
    for key in ("w1", "w2", "w1_chunk1"):
        f = figures[key]
        assert f["runs_per_s"] == pytest.approx(4 / f["wall_s"])
        assert max(f["rounds_runs_per_s"]) == pytest.approx(f["runs_per_s"])
    assert figures["efficiency_2_workers"] == pytest.approx(
        figures["w2"]["runs_per_s"] / (2 * figures["w1"]["runs_per_s"]))
    assert f"{100 * figures['efficiency_2_workers']:.1f} %" in text
