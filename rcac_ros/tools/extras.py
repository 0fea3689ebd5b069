"""The optional parts of the package (setup.py's extras) a command needs, checked up front.

A command whose extra is missing stops with one line naming the extra and the pip command,
before it imports anything heavy; ``rcac COMMAND --help`` works without it. ROS 2 is not an
extra (its wheels would shadow an apt install, doc/install.md): a command that needs rclpy
says how to get it.
"""

import importlib.util

from rcac_ros.errors import DependencyError

#: extra of setup.py -> the top-level modules it provides (test_dependencies.py checks them
#: against the installed distributions). The ``robots`` extra is not here: example-robot-data
#: installs no importable module (its URDFs sit under its cmeel prefix), and the commands
#: that read them name the extra themselves (``tools/runs/scenarios.load_panda``).
EXTRAS = {
    "bags": ("rosbags", "mcap", "mcap_ros2"),
    "sweep": ("dask", "distributed", "bokeh", "pyarrow", "pandas", "tqdm", "psutil"),
    "pinocchio": ("pinocchio",),
    "mujoco": ("mujoco",),
}

#: not an extra: ROS 2 Jazzy's Python (apt, or the wheels of requirements.txt)
ROS = ("rclpy",)


def missing(modules):
    """The modules of ``modules`` that cannot be found (none is imported)."""
    return [m for m in modules if importlib.util.find_spec(m) is None]


def require(*needs):
    """Raise :class:`DependencyError` naming the first of ``needs`` (extras, or ``"ros"``)
    whose modules are not all installed."""
    for need in needs:
        gone = missing(ROS if need == "ros" else EXTRAS[need])
        if not gone:
            continue
        if need == "ros":
            raise DependencyError(
                "needs ROS 2 Jazzy (rclpy not found): source /opt/ros/jazzy/setup.bash, or "
                "pip install -r requirements.txt (doc/install.md)")
        raise DependencyError(f"needs the '{need}' extra (missing {', '.join(gone)}): "
                              f"pip install 'rcac_ros[{need}]'")
