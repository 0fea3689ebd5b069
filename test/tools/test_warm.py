"""``python -m rcac_ros.tools.warm``: the kernels compiled into their cache by two processes."""
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run(*args):
    return subprocess.run([sys.executable, "-m", "rcac_ros.tools.warm", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def test_both_groups_run_in_their_processes_and_report():
    out = run()
    assert out.returncode == 0, out.stdout + out.stderr
    lines = out.stdout.splitlines()
    assert any(line.startswith("warm: recursive ready in") for line in lines)
    assert any(line.startswith("warm: others ready in") for line in lines)
    assert lines[-1].startswith("warm: done in")


def test_others_does_not_import_the_recursive_law():
    """The point of the split: the second process must not compile the recursive law's
    general kernels beside the first (they compile when rcac_ros.core's __init__ runs)."""
    code = ("import sys; from rcac_ros.tools.warm import warm_others; warm_others(); "
            "print(sorted(m for m in sys.modules if m.startswith('rcac_ros.core.composite')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "['rcac_ros.core.composite_fused']"


@pytest.mark.parametrize("args, message", [(("nonsense",), "unknown group 'nonsense'"),
                                           (("--jobs", "0"), "--jobs must be at least 1")])
def test_bad_arguments_are_one_line(args, message):
    out = run(*args)
    assert out.returncode == 2
    assert message in out.stderr.strip().splitlines()[-1]
