from glob import glob
import os
import subprocess
import sys

from setuptools import find_packages, setup
from setuptools.command.install import install

package_name = "rcac_ros"

# Every Python dependency, declared once here; requirements.txt pins exactly these names
# (plus the ROS 2 wheels) and requirements-test.txt the "test" extra, checked by
# test/tools/test_dependencies.py. The ROS 2 wheels (ros-jazzy-*) stay out of
# install_requires: on an apt install they would shadow /opt/ros/jazzy (doc/install.md).
INSTALL_REQUIRES = ["setuptools", "numpy", "numba", "PyYAML", "matplotlib", "yourdfpy"]

#: optional parts: ``pip install 'rcac_ros[sweep,bags]'``; a command whose extra is
#: missing says which one (rcac_ros/tools/extras.py)
EXTRAS_REQUIRE = {
    # rcac record, rcac inspect, rcac demo: rosbag2 bags (mcap and sqlite3)
    "bags": ["rosbags", "mcap", "mcap-ros2-support"],
    # rcac sweep: Monte Carlo campaigns on Dask distributed (the dashboard needs bokeh),
    # results in Parquet, the report's tables, the progress bar, worker memory
    "sweep": ["dask", "distributed", "bokeh", "pyarrow", "pandas", "tqdm", "psutil"],
    # the real robot URDFs (the Panda of rcac payload-demo, rcac compare, campaigns)
    "robots": ["example-robot-data"],
    # Pinocchio: rcac bench's reference column, and the tests' independent reference
    "pinocchio": ["pin"],
    # the MuJoCo plant
    "mujoco": ["mujoco"],
    # the tests: the runner (in parallel), scipy (an independent reference), the linter, colcon
    "test": ["pytest", "pytest-xdist", "scipy", "flake8", "colcon-core", "colcon-python-setup-py",
             "colcon-ros"],
}


class InstallThenWarm(install):
    """``setup.py install`` (what ``colcon build`` runs), then the numba kernels compiled into
    the user's cache (``python -m rcac_ros.tools.warm``, keyed on the sources' content, so the
    installed copy finds them): the installed nodes start in seconds. ``RCAC_NO_WARM=1``
    skips it; where it fails (no numba in the build's Python) the kernels compile at the first
    start instead."""

    def run(self):
        super().run()
        if os.environ.get("RCAC_NO_WARM"):
            return
        here = os.path.dirname(os.path.abspath(__file__))
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            p for p in (here, os.environ.get("PYTHONPATH")) if p))
        code = subprocess.call([sys.executable, "-m", "rcac_ros.tools.warm"], cwd=here, env=env)
        if code:
            self.warn("rcac_ros: the kernels were not compiled ahead (python -m "
                      "rcac_ros.tools.warm failed): they compile at the first start")


setup(
    name=package_name,
    cmdclass={"install": InstallThenWarm},
    version="0.1.0",
    packages=find_packages(include=["rcac_ros", "rcac_ros.*"]),
    # the packages sit at the top of the project: said explicitly, an editable install is a
    # plain .pth (setuptools' "simple layout"), without the "Editable installation"
    # BuildBackendWarning of its import-hook strategy
    package_dir={"": "."},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/config/layouts", glob("config/layouts/*")),
    ],
    install_requires=INSTALL_REQUIRES,
    zip_safe=True,
    maintainer="rcac_ros maintainers",
    maintainer_email="rcac@example.com",
    description="Recursive composite adaptive controller for serial manipulators (ROS 2).",
    license="Apache-2.0",
    extras_require=EXTRAS_REQUIRE,
    entry_points={
        "console_scripts": [
            "rcac = rcac_ros.tools.cli:main",
            "controller = rcac_ros.nodes.controller.node:main",
            "simulator = rcac_ros.nodes.simulator.node:main",
        ],
    },
)
