"""``colcon build`` installs ``controller`` and ``simulator`` where ``ros2 run`` looks for them."""

import glob
import os
import shutil
import subprocess
import sys

import pytest

from test_nodes_support import ros_domain

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def colcon():
    here = os.path.join(os.path.dirname(sys.executable), "colcon")
    return here if os.path.exists(here) else shutil.which("colcon")


@pytest.fixture(scope="module")
def install(tmp_path_factory):
    exe = colcon()
    if exe is None:
        pytest.skip("colcon is not installed")
    tmp = tmp_path_factory.mktemp("colcon")
    cmd = [exe, "--log-base", str(tmp / "log"), "build", "--base-paths", ROOT,
           "--build-base", str(tmp / "build"), "--install-base", str(tmp / "install")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=str(tmp))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return tmp / "install"


def env_for(install):
    """What sourcing install/setup.bash gives a Python package: its site-packages first."""
    env = dict(os.environ)
    site = glob.glob(str(install / "rcac_ros" / "lib" / "python3*" / "site-packages"))
    assert site, "no site-packages in the install space"
    env["PYTHONPATH"] = os.pathsep.join([site[0], env.get("PYTHONPATH", "")])
    env["AMENT_PREFIX_PATH"] = str(install / "rcac_ros")
    return env


def test_executables_are_installed(install):
    for name in ("controller", "simulator"):
        path = install / "rcac_ros" / "lib" / "rcac_ros" / name
        assert path.is_file() and os.access(path, os.X_OK), path
    assert (install / "rcac_ros" / "share" / "rcac_ros" / "config" / "controller.yaml").is_file()
    assert (install / "rcac_ros" / "share" / "rcac_ros" / "config" / "simulator.yaml").is_file()


def test_installed_nodes_run(install):
    """Both nodes start from the install space, run 0.2 s in lockstep and exit cleanly."""
    lib = install / "rcac_ros" / "lib" / "rcac_ros"
    share = install / "rcac_ros" / "share" / "rcac_ros" / "config"
    env = env_for(install)
    with ros_domain():
        env["ROS_DOMAIN_ID"] = os.environ["ROS_DOMAIN_ID"]
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        ctrl = subprocess.Popen([str(lib / "controller"), "--ros-args", "--params-file",
                                 str(share / "controller.yaml")], env=env, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        try:
            sim = subprocess.run([str(lib / "simulator"), "--ros-args", "--params-file",
                                  str(share / "simulator.yaml"), "-p", "duration:=0.2"],
                                 env=env, capture_output=True, text=True, timeout=120)
        finally:
            ctrl.send_signal(subprocess.signal.SIGINT)
            out, _ = ctrl.communicate(timeout=30)
    assert sim.returncode == 0, sim.stdout + sim.stderr
    assert "finished: 100 steps" in sim.stderr + sim.stdout
    assert "lockstep misses 0" in sim.stderr + sim.stdout
    assert ctrl.returncode == 0, out


def test_installed_node_refuses_bad_parameter(install):
    lib = install / "rcac_ros" / "lib" / "rcac_ros"
    with ros_domain():
        proc = subprocess.run([str(lib / "controller"), "--ros-args", "-p", "P:=-1.0"],
                              env=env_for(install), capture_output=True, text=True,
                              timeout=120)
    assert proc.returncode == 2
    assert "controller: error: P:" in proc.stderr and "Traceback" not in proc.stderr
