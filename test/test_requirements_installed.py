"""The tests' requirements are installed (requirements.txt, requirements-test.txt).

Many tests skip without one of them (``pytest.importorskip``, ``skipif``: the package's
extras are optional, and a developer may run a part of the suite with a partial install). A
run with one missing would then pass with that evidence turned into skips; here it fails,
one test per requirement, naming it.
"""

import importlib

import pytest

from rcac_ros.tools.runs.scenarios import find_panda_urdf


@pytest.mark.parametrize("module", [
    "pinocchio",            # the independent reference of the dynamics (extra "pinocchio")
    "mujoco",               # the other plant (extra "mujoco")
    "scipy",                # the tests' ODE solver, matrix exponential and splines
    "pandas",               # campaign results (extra "sweep")
    "rclpy",                # the ROS 2 wheels
    "domain_coordinator",   # a unique DDS domain per ROS test
])
def test_module_is_installed(module):
    importlib.import_module(module)


def test_example_robot_data_has_the_panda():
    assert find_panda_urdf() is not None, "example-robot-data (requirements-test.txt)"
