"""Code style: flake8 at 99 columns (the ament_flake8 line length), on the package and tests."""

import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_flake8():
    pytest.importorskip("flake8")
    out = subprocess.run([sys.executable, "-m", "flake8", "rcac_ros", "test", "launch",
                          "setup.py"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
