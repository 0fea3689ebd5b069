"""The operation count is linear in n (O(n)), and the rcac experiment/bench commands run."""

import json
import subprocess
import sys

from rcac_ros.tools.bench.opcount import count_step


def test_recursive_step_operation_count_is_exactly_linear():
    c7, c14, c21 = (count_step("rcac", n) for n in (7, 14, 21))
    for kind in ("mul", "add"):
        assert c21[kind] - c14[kind] == c14[kind] - c7[kind] > 0
    base = count_step("slotine_li", 7)
    assert base["mul"] > 3 * c7["mul"]
    second = count_step("slotine_li", 14)
    assert second["mul"] - base["mul"] > 2 * base["mul"]   # superlinear


def run(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "rcac_ros.tools.cli", *args], capture_output=True,
                          text=True, timeout=timeout)


def test_experiment_command_writes_metrics_and_figures(tmp_path):
    out = run("experiment", "--duration", "1", "--out", str(tmp_path), "--quiet")
    assert out.returncode == 0, out.stderr
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    for law in ("direct", "composite"):
        for key in ("rms_tracking_error", "max_tracking_error", "rms_tracking_error_last_5s",
                    "parameter_error_norm_start", "parameter_error_norm_end",
                    "link7_parameter_error_norm_end", "final_abs_prediction_error",
                    "max_abs_torque"):
            assert metrics[law][key] >= 0.0
    for name in ("tracking_errors.png", "parameter_estimates.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_experiment_rejects_bad_gain_with_one_line(tmp_path):
    out = run("experiment", "--duration", "1", "--out", str(tmp_path), "--K_D", "-5")
    assert out.returncode == 2
    assert out.stderr.splitlines() == [
        "rcac experiment: error: argument --K_D: must be > 0, got '-5'"]


def test_bench_command_json(tmp_path):
    path = tmp_path / "bench.json"
    out = run("bench", "core", "--budget", "0.02", "--json", str(path), timeout=900)
    assert out.returncode == 0, out.stderr
    result = json.loads(path.read_text())
    assert [r["n"] for r in result["rows"][:6]] == [7, 14, 28, 56, 112, 224]
    assert "controller_n224_over_n28" in result["ratios"]
