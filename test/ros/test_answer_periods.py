"""What the controller adds to its input's jitter, as its diagnostics report it: the p99
period of the states as DDS received them and of the efforts as sent
(``input_period_p99_us``, ``effort_period_p99_us``; nodes/runtime/stats.py)."""

import math

import numpy as np
import pytest

from failsafe_harness import controller, feed, first_answer, session, wait

from rcac_ros.nodes.runtime.stats import PeriodHistogram

MS = 1_000_000


@pytest.mark.parametrize("q", [50, 90, 99, 100])
def test_histogram_percentile_is_the_upper_edge_of_the_exact_ones_bin(q):
    rng = np.random.default_rng(q)
    t = np.cumsum(rng.integers(1 * MS, 4 * MS, 3000))
    hist = PeriodHistogram(bin_ns=10_000, bins=5_000)
    for x in t:
        hist.add(int(x))
    exact = np.percentile(np.diff(t), q, method="inverted_cdf") / 1e3     # nearest rank, µs
    assert hist.count == len(t) - 1
    assert exact <= hist.percentile_us(q) < exact + 10.0


def test_histogram_edges():
    hist = PeriodHistogram(bin_ns=1_000, bins=10)
    assert math.isnan(hist.percentile_us(99))              # no period yet
    hist.add(5_000)
    hist.add(4_000)                                         # backwards: not a period
    assert hist.count == 0
    hist.add(6_500)
    hist.add(60_000)                                        # beyond the last bin
    assert hist.count == 2
    assert hist.percentile_us(50) == 3.0                    # 2.5 µs: bin [2, 3) µs
    assert hist.percentile_us(99) == math.inf
    hist.reset()
    assert hist.count == 0 and math.isnan(hist.percentile_us(50))


def test_the_controller_reports_its_input_and_effort_periods():
    """States every 4 ms with every tenth gap 40 ms: the p99 of both periods is one of the
    40 ms gaps (10 % of them), not a 4 ms one; the band around it is the scheduling of two
    processes on a loaded machine."""
    gaps = [40 if k % 10 == 9 else 4 for k in range(400)]
    stamps = list(np.cumsum([MS] + [g * MS for g in gaps]))
    name = "rcac_controller: control loop"
    with session() as probe, controller(probe):
        first_answer(probe, int(stamps[0]))
        for s, g in zip(stamps[1:], gaps):       # publish, then wait the gap
            feed(probe, [int(s)], period=g * 1e-3)
        assert wait(lambda: len(probe.answers()) >= len(stamps), timeout=20.0)
        assert wait(lambda: int(probe.diagnostics.get(name, {}).get("steps", 0))
                    >= len(stamps), timeout=10.0)
        values = probe.diagnostics[name]
    for key in ("input_period_p99_us", "effort_period_p99_us"):
        p99_ms = float(values[key]) * 1e-3
        assert 30.0 <= p99_ms <= 60.0, (key, values[key])
