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


#: in a fresh process after the warm-up: every law's kernels load, none compiles
AFTER_WARM = """
import numpy as np
from numba.core import event
from rcac_ros.core import RecursiveCompositeController, SlotineLiCompositeController, css_arm
from rcac_ros.core import Simulator, forward_dynamics, inverse_dynamics, mass_matrix
from rcac_ros.nodes.safety.guards import DesiredLimiter, EffortClip
with event.install_recorder("numba:compile") as rec:
    m = css_arm(); z = np.zeros(m.n); q = np.full(m.n, 0.1)
    for cls, variants in ((RecursiveCompositeController, ({}, {"joint_friction": True},
                           {"geometry": "natural"}, {"channels": "all"},
                           {"channels": "all", "joint_friction": True},
                           {"geometry": "natural", "adaptation": "least_squares"})),
                          (SlotineLiCompositeController, ({}, {"joint_friction": True},
                           {"geometry": "natural"}))):
        for kw in variants:
            c = cls(m, **kw)
            c.step(q, z, q, z, z)
            c.set_adaptation(False) if hasattr(c, "set_adaptation") else None
            c.step(q, z, q, z, z)
    Simulator(m, dt=0.002).step(z); forward_dynamics(m, q, z, z)
    inverse_dynamics(m, q, z, z); mass_matrix(m, q)
    DesiredLimiter(0.01, 0.1, 0.002, m.n).warm()
    EffortClip(np.ones(m.n), np.arange(m.n)).warm()
print(len(rec.buffer))
"""


def test_after_the_warm_up_no_law_compiles():
    """The warm-up fills the cache for every law and path (adapting and frozen), so a later
    process loads them all: numba's compiler does not run once (its compile events)."""
    out = run()
    assert out.returncode == 0, out.stdout + out.stderr
    out = subprocess.run([sys.executable, "-c", AFTER_WARM], cwd=ROOT, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "0"


@pytest.mark.parametrize("args, message", [
    (("nonsense",), "unknown group 'nonsense'"),
    (("--jobs", "0"), "argument --jobs: must be an integer >= 1")])
def test_bad_arguments_are_one_line(args, message):
    out = run(*args)
    assert out.returncode == 2
    assert message in out.stderr.strip().splitlines()[-1]
