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
    # a quiet build: no Python warning (a setuptools deprecation...) from setup.py, neither
    # while colcon reads the metadata nor in the build ("--- stderr" on a terminal)
    assert "--- stderr" not in proc.stdout and "Warning" not in proc.stderr, \
        proc.stdout + proc.stderr
    seed_numba_cache(tmp / "install")
    return tmp / "install"


def seed_numba_cache(install):
    """Copy the source tree's numba cache (``__pycache__/*.nbi``, ``*.nbc``: the kernels the
    earlier tests compiled) next to the installed modules. numba keys a cache on its source
    file's modification time and size, which the install keeps (setuptools copies with
    their times): an installed file that differs from the source is compiled again, one that
    does not loads the kernels (the cold compile itself is covered where the core is first
    imported; a second one here took 160 s of the CI run)."""
    site = glob.glob(str(install / "rcac_ros" / "lib" / "python3*" / "site-packages"))
    for cache in glob.glob(os.path.join(ROOT, "rcac_ros", "**", "__pycache__", "*.nb[ic]"),
                           recursive=True):
        rel = os.path.relpath(cache, ROOT)
        target = os.path.join(site[0], rel)
        if os.path.isdir(os.path.dirname(os.path.dirname(target))):
            os.makedirs(os.path.dirname(target), exist_ok=True)
            shutil.copy2(cache, target)


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
    """Both nodes start from the install space, run 0.2 s in lockstep and exit cleanly.

    The install space is a new path for numba's cache, seeded from the source tree's
    (:func:`seed_numba_cache`); a kernel missing there is compiled cold, which took over
    120 s on the loaded 2-core VM (hence the long timeout)."""
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
                                  str(share / "simulator.yaml"), "-p", "duration:=0.2",
                                  "-p", "lockstep_timeout:=5.0"],
                                 env=env, capture_output=True, text=True, timeout=600)
        finally:
            ctrl.send_signal(subprocess.signal.SIGINT)
            try:
                out, _ = ctrl.communicate(timeout=30)
            except subprocess.TimeoutExpired:   # never outlive the domain (the next test's)
                ctrl.kill()
                out, _ = ctrl.communicate()
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


def test_launch_file_is_installed(install):
    launch_file = install / "rcac_ros" / "share" / "rcac_ros" / "launch" / "rcac.launch.py"
    assert launch_file.is_file()
    compile(launch_file.read_text(), str(launch_file), "exec")     # valid Python


def ros_launch():
    """``(launch, launch_ros)``, or skip: neither is a PyPI wheel (test_launch_file.py checks
    the launch file's source without them)."""
    why = ("ROS 2's launch and launch_ros are not installed: an apt install has them "
           "(ros-jazzy-launch-ros), PyPI has no wheel; test_launch_file.py checks the file's "
           "source instead")
    launch = pytest.importorskip("launch", reason=why)
    if not hasattr(launch, "LaunchDescription"):    # the repository's launch/ folder, or
        pytest.skip(why)                            # PyPI's unrelated 'launch'
    launch_ros = pytest.importorskip("launch_ros", reason=why)
    return launch, launch_ros


def test_launch_description(install, monkeypatch):
    """The installed launch file: its arguments, two nodes, the optional recorder."""
    launch, launch_ros = ros_launch()
    from launch.launch_description_sources import get_launch_description_from_python_launch_file
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(install / "rcac_ros"))
    share = install / "rcac_ros" / "share" / "rcac_ros"
    ld = get_launch_description_from_python_launch_file(str(share / "launch" / "rcac.launch.py"))
    args = {a.name: a for a in ld.get_launch_arguments()}
    assert set(args) == {"controller_params", "simulator_params", "simulator", "record", "bag",
                         "use_sim_time"}
    context = launch.LaunchContext()
    defaults = {name: launch.utilities.perform_substitutions(context, a.default_value)
                for name, a in args.items()}
    assert defaults["controller_params"] == str(share / "config" / "controller.yaml")
    assert defaults["simulator_params"] == str(share / "config" / "simulator.yaml")
    assert (defaults["simulator"], defaults["record"]) == ("true", "false")
    nodes = [e for e in ld.entities if isinstance(e, launch_ros.actions.Node)]
    assert len(nodes) == 2
    recorders = [e for e in ld.entities if type(e) is launch.actions.ExecuteProcess]
    assert len(recorders) == 1 and recorders[0].condition is not None


def test_launch_runs_the_nodes_and_the_recorder(install, tmp_path, monkeypatch):
    """``ros2 launch rcac_ros rcac.launch.py record:=true``, run by a LaunchService: the
    simulator runs 0.4 s in lockstep with the controller, the bag holds every step."""
    launch, _ = ros_launch()
    from launch.actions import EmitEvent, IncludeLaunchDescription, RegisterEventHandler
    from launch.event_handlers import OnProcessExit, OnProcessIO
    from launch.events import Shutdown
    from launch.launch_description_sources import PythonLaunchDescriptionSource
    from rosbags.highlevel import AnyReader
    share = install / "rcac_ros" / "share" / "rcac_ros"
    sim_params = tmp_path / "simulator.yaml"
    # the shipped file, 0.4 s, and a start only once the recorder listens too
    sim_params.write_text((share / "config" / "simulator.yaml").read_text().replace(
        "duration: 0.0", "duration: 0.4").replace("min_subscribers: 1", "min_subscribers: 2"))
    assert "duration: 0.4" in sim_params.read_text()
    assert "min_subscribers: 2" in sim_params.read_text()
    bag = tmp_path / "bag"
    text, exits = [], []

    def on_exit(event, _):
        exits.append((event.action.name, event.returncode))
        return [EmitEvent(event=Shutdown())]
    env = env_for(install)
    for key in ("PYTHONPATH", "AMENT_PREFIX_PATH"):
        monkeypatch.setenv(key, env[key])
    with ros_domain():
        service = launch.LaunchService()
        service.include_launch_description(launch.LaunchDescription([
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(str(share / "launch" / "rcac.launch.py")),
                launch_arguments={"simulator_params": str(sim_params), "record": "true",
                                  "bag": str(bag)}.items()),
            RegisterEventHandler(OnProcessIO(
                on_stdout=lambda e: text.append(e.text.decode()),
                on_stderr=lambda e: text.append(e.text.decode()))),
            # the simulator's exit (after its duration) ends the launch: SIGINT to the others
            RegisterEventHandler(OnProcessExit(on_exit=on_exit)),
        ]))
        assert service.run() == 0
    text = "".join(text)
    assert exits[0][0].startswith("simulator") and exits[0][1] == 0, (exits, text[-3000:])
    assert "finished: 200 steps" in text and "lockstep misses 0" in text, text[-3000:]
    # the controller and the recorder stopped cleanly on the launch's SIGINT
    assert all(code == 0 for _, code in exits) and len(exits) == 3, exits
    with AnyReader([bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts.get("/joint_states", 0) >= 200, counts
    assert counts.get("/effort_controller/commands", 0) >= 200, counts
