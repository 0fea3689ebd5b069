"""``rcac compare``: argument checks, outputs, and the all-channel law equal to Slotine-Li."""

import json
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def rcac(*args):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "rcac_ros.tools.cli", *args], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("args,match", [
    (["--duration", "0"], "--duration: must be > 0"),
    (["--duration", "-5"], "--duration: must be > 0"),
    (["--duration", "nan"], "--duration: must be a finite number"),
    (["--laws", "paper", "best"], "--laws: invalid choice: 'best'"),
    (["--scenarios", "moon"], "--scenarios: invalid choice: 'moon'"),
    (["--channels", "1,x"], "channels: 'x' is not a joint number"),
])
def test_bad_arguments_exit_2_with_one_line(args, match):
    out = rcac("compare", *args)
    assert out.returncode == 2
    assert match in out.stderr and "Traceback" not in out.stderr


def test_experiment_channels_out_of_range_exit_2():
    out = rcac("experiment", "--duration", "0.1", "--channels", "1,8", "--quiet")
    assert out.returncode == 2
    assert "channels: joint 8 is out of range 1..7" in out.stderr


def test_short_compare_writes_the_table_and_all_equals_slotine_li(tmp_path):
    out = rcac("compare", "--duration", "0.5", "--scenarios", "paper", "--quiet",
               "--laws", "direct", "paper", "all", "slotine_li", "--channels", "1,power",
               "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    with open(tmp_path / "compare.json", encoding="utf-8") as f:
        report = json.load(f)["paper"]
    assert set(report) == {"direct", "paper", "all", "slotine_li", "channels=1,power"}
    a, b = report["all"], report["slotine_li"]
    for key in ("rms", "max_error", "theta_error_end", "max_abs_E"):
        assert a[key] == pytest.approx(b[key], rel=1e-9)
    assert a["identifiable"] > report["paper"]["identifiable"]
    table = (tmp_path / "compare.md").read_text(encoding="utf-8")
    assert "| slotine_li |" in table and "rcac compare --duration 0.5" in table
    assert (tmp_path / "compare_paper.png").stat().st_size > 10000
