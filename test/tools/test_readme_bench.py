"""The ROS timing per controller mode: the bench's ratios, and their table in doc/results.md."""

import numpy as np
import pytest

from rcac_ros.tools.results import ros_modes as rb
from rcac_ros.tools.bench.ros import analyse
from rcac_ros.tools.results.page import read_source
from rcac_ros.tools.results.blocks import render_bench_ros_modes


class FakeProbe:
    """The stamps a probe keeps, made up: states and efforts at 500 Hz with jitter."""

    def __init__(self, rng, n=2000, h_ns=2_000_000):
        t = np.arange(n) * h_ns
        src = t + rng.integers(0, 300_000, n)                 # the simulator's jitter
        self.states = [(int(s), int(s + rng.integers(50_000, 150_000))) for s in src]
        eff = t + 400_000 + rng.integers(0, 600_000, n)       # the controller's
        self.efforts = [(int(s), int(s + rng.integers(50_000, 150_000)), False) for s in eff]
        self.ping_rtt = list(rng.integers(200_000, 600_000, 100))
        self.diagnostics = {}


def test_ratios_are_quotients_of_the_same_runs_percentiles():
    probe = FakeProbe(np.random.default_rng(1))
    r = analyse(probe, 4.0, 500.0)
    eff = np.array([e[0] for e in probe.efforts], float)
    st = np.array([s[0] for s in probe.states], float)
    p99 = np.percentile(np.diff(eff) * 1e-6, 99) / np.percentile(np.diff(st) * 1e-6, 99)
    assert r["period_ratio"] == pytest.approx(p99, rel=1e-12)
    # the age of the newest state received before each effort, by brute force
    st_recv = np.array([s[1] for s in probe.states])
    ages = [e[1] - st_recv[st_recv <= e[1]].max() for e in probe.efforts
            if (st_recv <= e[1]).any()]
    assert len(ages) >= len(probe.efforts) - 1
    lat = np.percentile(np.array(ages, float), 50) / \
        np.percentile(0.5 * np.array(probe.ping_rtt, float), 50)
    assert r["latency_ratio"] == pytest.approx(lat, rel=1e-12)
    assert r["meets_ratio_goal"] == (p99 <= 1.1)
    assert r["pings"] == 100


def test_without_pings_the_latency_ratio_is_none():
    probe = FakeProbe(np.random.default_rng(2))
    probe.ping_rtt = []
    r = analyse(probe, 4.0, 500.0)
    assert r["latency_ratio"] is None and r["ping_one_way_p50_ms"] is None
    row = dict(rb.ROWS)["**latency p50 / ping p50**"]
    assert row(r) == "-"


def test_the_table_lists_every_mode_and_row():
    r = analyse(FakeProbe(np.random.default_rng(3)), 4.0, 500.0)
    data = {"conditions": "Measured by hand.", "columns": {c: r for c in rb.MODES}}
    lines = render_bench_ros_modes(data).splitlines()
    assert lines[0] == "Measured by hand."
    assert lines[2] == "|  | " + " | ".join(rb.MODES) + " |"
    assert len(lines) == 4 + len(rb.ROWS)
    ratio_row = next(x for x in lines if x.startswith("| **effort p99 / state p99**"))
    assert ratio_row.count(f"{r['period_ratio']:.2f}") == len(rb.MODES)


def test_the_committed_source_has_every_mode_and_row():
    data = read_source("bench_ros_modes")["data"]
    assert list(data["columns"]) == list(rb.MODES)
    for label, fmt in rb.ROWS:
        assert all(fmt(r) for r in data["columns"].values()), label
