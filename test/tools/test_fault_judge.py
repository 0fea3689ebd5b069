"""The fault bench's verdicts (``rcac bench faults``): each case against its reference."""

import pytest

from rcac_ros.tools.bench.faults import CASES, format_table, judge


def run(case, rms, **more):
    r = {"case": case, "rate": 500.0, "tracking_rms": rms, "tracking_rms_last_fifth": rms,
         "longest_gap_ms": 5.0, "gaps_over_2h": 0, "theta_bounded": True}
    r.update(more)
    return r


def test_a_case_without_the_relay_is_judged_against_direct_and_one_with_it_against_nominal():
    assert not CASES["starved"].relay and CASES["drops"].relay
    results = [run("nominal", 0.004), run("direct", 0.002), run("drops", 0.010),
               run("starved", 0.010, window_tracking_rms=0.016)]
    judge(results)
    by = {r["case"]: r for r in results}
    assert by["drops"]["reference"] == "nominal" and by["drops"]["tracking_ratio"] == 2.5
    assert by["drops"]["recovered"]                     # 2.5 <= 3
    assert by["starved"]["reference"] == "direct" and by["starved"]["tracking_ratio"] == 5.0
    assert not by["starved"]["recovered"]               # 5 > 3
    assert by["starved"]["window_ratio"] == 8.0 and by["starved"]["window_ok"]     # <= 10
    # without a direct run, the other reference
    results = [run("nominal", 0.004), run("starved", 0.010, window_tracking_rms=0.016)]
    judge(results)
    assert results[1]["reference"] == "nominal" and results[1]["tracking_ratio"] == 2.5


def test_a_flood_case_holds_its_start_and_has_no_tracking_verdict():
    assert CASES["hostile_flood"].controller == {"trajectory": "topic"}
    results = [run("direct", 0.004),
               run("hostile_flood", 0.0, window_safe=0, window_gap_ms=10.0,
                   window_efforts=10000, plain_loop_gap_ms=9.0)]
    judge(results)
    flood = results[1]
    assert flood["tracking_ratio"] is None and flood["recovered"] is None
    assert flood["window_ok"]                           # 10 <= 9 + 2 periods (4 ms)
    line = format_table(results, 0.002).splitlines()[3]
    assert line.split()[:3] == ["hostile_flood", "0", "-"] and " - " in line


@pytest.mark.parametrize("fails", [False, True])
def test_a_loaded_soak_keeps_its_busy_processes_for_the_run_and_stops_them(monkeypatch, fails):
    """``rcac bench soak --busy N``: N busy processes run while the soak runs and are gone
    after it, also when the soak fails."""
    import types

    from rcac_ros.tools.bench import commands
    from rcac_ros.tools.bench import fault_cases
    started = []
    real_start = fault_cases.start_busy
    monkeypatch.setattr(fault_cases, "start_busy",
                        lambda n: started.extend(real_start(n)) or started)

    def soak(args, cases=None, soak_minutes=None):
        assert cases == ("direct",) and soak_minutes == 0.5
        assert len(started) == 3 and all(p.poll() is None for p in started)   # running
        if fails:
            raise RuntimeError("the soak failed")
        return 0
    monkeypatch.setattr(commands, "run_faults", soak)
    args = types.SimpleNamespace(busy=3, minutes=0.5)
    if fails:
        with pytest.raises(RuntimeError):
            commands.run_soak(args)
    else:
        assert commands.run_soak(args) == 0
    assert len(started) == 3 and all(p.poll() is not None for p in started)   # stopped
