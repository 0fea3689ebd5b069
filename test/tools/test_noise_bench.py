"""``rcac bench noise``: the dead-zone sizing rule, the growth criterion, its options."""

import sys
from statistics import NormalDist

import numpy as np
import pytest

from rcac_ros.core import css_arm
from rcac_ros.tools import cli
from rcac_ros.tools.bench import noise as noise_bench


@pytest.mark.parametrize("n,steps", [(1, 1000), (7, 300_000)])
def test_the_dead_zone_is_crossed_by_noise_alone_about_once_per_run(n, steps):
    """``P(max_j |N(0, 1)| > k)`` over n independent joints, the exact probability
    ``1 - (1 - 2 (1 - Phi(k)))^n``, is one over the number of steps (to first order)."""
    k = noise_bench.dead_zone_factor(n, steps)
    p = 1.0 - (1.0 - 2.0 * (1.0 - NormalDist().cdf(k))) ** n
    assert p * steps == pytest.approx(1.0, rel=1e-3)


def test_the_noise_of_s_combines_both_sensors():
    """``s_j = qd_j - qd_rj`` carries the qd noise plus Lambda_j times the q noise."""
    lam = np.array([1.0, 3.0])
    want = np.sqrt(noise_bench.SIGMA_QD ** 2 + 9.0 * noise_bench.SIGMA_Q ** 2)
    assert noise_bench.s_noise(lam) == pytest.approx(want, rel=1e-12)


def test_growth_tells_a_drift_from_a_bounded_series():
    t = np.arange(600.0)
    rng = np.random.default_rng(0)
    assert noise_bench.growth(100.0 + t)["still_growing"]                  # linear drift
    assert noise_bench.growth(np.sqrt(1.0 + t))["still_growing"]           # random walk
    assert noise_bench.growth(3.0 * (1.0 + t))["exponent"] == pytest.approx(1.0, rel=1e-9)
    assert noise_bench.growth(np.sqrt(1.0 + t))["exponent"] == pytest.approx(0.5, rel=1e-9)
    settled = 50.0 * (1.0 - np.exp(-t / 30.0)) + rng.normal(0.0, 0.5, t.size)
    assert not noise_bench.growth(settled)["still_growing"]
    assert noise_bench.growth(settled)["max_ratio"] == pytest.approx(1.0, abs=0.05)
    assert noise_bench.growth([1.0, 2.0, 3.0])["still_growing"] is None      # too short


def test_each_variant_runs_with_its_options():
    """Four seconds of each variant: the options reach the controller (the dead zone holds
    adaptation back, the switching leakage's radius is per link), with a deviation from
    the clean run for every noisy variant."""
    model = css_arm()
    clean, hats = noise_bench.run_law(model, [1], 4.0, "clean")
    assert clean["options"] == {} and clean["adapting_share"] == 1.0
    for variant in noise_bench.VARIANTS[1:]:
        r, _ = noise_bench.run_law(model, [1], 4.0, variant, clean=hats)
        assert len(r["deviation"]) == 4 and r["deviation"][-1] > 0.0
        if variant == "dead zone":
            assert r["adapting_share"] < 1.0 and r["options"]["dead_zone_s"] > 0.0
        if variant == "switching":
            assert len(r["options"]["leakage_bound"]) == model.n


@pytest.mark.parametrize("option,value", [("--laws", "paper;4,5"),
                                          ("--variants", "plain,deadzone")])
def test_an_unknown_law_or_variant_stops_at_the_parser(capsys, monkeypatch, option, value):
    monkeypatch.setattr(sys, "argv", ["rcac"])
    with pytest.raises(SystemExit) as stop:
        cli.main(["bench", "noise", option, value])
    lines = capsys.readouterr().err.splitlines()
    assert stop.value.code == 2 and len(lines) == 1
    assert lines[0].startswith(f"rcac bench noise: error: argument {option}: unknown")


def test_weak_share_splits_a_deviation_by_excitation():
    """A deviation along a direction the motion never excited counts as weak, one along an
    excited direction does not, and a mix splits by squared norm."""
    rng = np.random.default_rng(1)
    V, _ = np.linalg.qr(rng.normal(size=(13, 13)))
    w = np.r_[np.zeros(3), 1e-2 * np.ones(2), np.logspace(0, 3, 8)]   # 3 null, 2 poor
    sigma = np.array([V @ np.diag(w) @ V.T] * 2)
    null, poor, strong = V[:, 0], V[:, 3], V[:, -1]
    share = noise_bench.weak_share(sigma, np.array([null, null]))
    assert share == pytest.approx({"1e-08": 1.0, "0.0001": 1.0})
    share = noise_bench.weak_share(sigma, np.array([poor, 2.0 * strong]))
    assert share == pytest.approx({"1e-08": 0.0, "0.0001": 0.2}, abs=1e-12)


def test_noise_sources_writes_its_report(tmp_path):
    """Four seconds of ``rcac bench noise --sources``: each case against the clean run of its own
    gamma, the cosine of the reference case with itself 1, the JSON and the plot."""
    report = noise_bench.run_noise_sources(4.0, str(tmp_path))
    assert set(report) == set(noise_bench.SOURCES)
    assert report["both"]["cosine_with_both"] == pytest.approx(1.0, rel=1e-12)
    assert report["both, gamma = 0"]["gamma"] == 0.0
    assert all(len(r["deviation"]) == 4 for r in report.values())
    assert (tmp_path / "sources.json").exists() and (tmp_path / "sources.png").exists()


def test_growth_of_a_run_too_short_to_judge_has_every_key():
    """Under 4 per-second samples nothing is assessed, and the report still has its fields."""
    g = noise_bench.growth([1.0, 2.0, 3.0])
    assert g.keys() == noise_bench.growth(np.arange(1.0, 9.0)).keys()
    assert g["still_growing"] is None and np.isnan(g["exponent"])
