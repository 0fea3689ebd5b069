"""The README's ROS timing table: its ratios, its block, and the bench's ratio figures."""

import os

import numpy as np
import pytest

from rcac_ros.tools import readme_bench as rb
from rcac_ros.tools.bench.ros import analyse


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
    assert "-" in rb.render({"timer": r}, "x").splitlines()[-4]   # the ratio row


def test_block_lists_every_mode_and_replaces_only_itself():
    r = analyse(FakeProbe(np.random.default_rng(3)), 4.0, 500.0)
    results = {c: r for c in rb.MODES}
    block = rb.render(results, "Measured by hand.")
    lines = block.splitlines()
    assert lines[0] == rb.BEGIN and lines[-1] == rb.END and lines[1] == "Measured by hand."
    assert lines[3] == "| | " + " | ".join(rb.MODES) + " |"
    assert len(lines) == 5 + len(rb.ROWS) + 1
    ratio_row = next(x for x in lines if x.startswith("| **effort p99 / state p99**"))
    assert ratio_row.count(f"{r['period_ratio']:.2f}") == len(rb.MODES)
    text = f"before\n{rb.BEGIN}\nold\n{rb.END}\nafter\n"
    new = rb.replace_block(text, block)
    assert new == f"before\n{block}\nafter\n"
    assert rb.replace_block(new, block) == new
    with pytest.raises(rb.BlockError):
        rb.replace_block("no markers", block)
    with pytest.raises(rb.BlockError):
        rb.replace_block(f"{rb.END}\n{rb.BEGIN}\n", block)


def test_readme_has_the_block_as_generated():
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with open(os.path.join(root, "README.md"), encoding="utf-8") as f:
        text = f.read()
    block = text[text.index(rb.BEGIN):text.index(rb.END) + len(rb.END)]
    assert rb.replace_block(text, block) == text
    lines = block.splitlines()
    assert lines[1].startswith("Measured by `make readme-bench` on ")
    assert lines[3] == "| | " + " | ".join(rb.MODES) + " |"
    assert [x.split(" | ")[0] for x in lines[5:-1]] == [f"| {label}" for label, _ in rb.ROWS]
