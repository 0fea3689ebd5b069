from glob import glob

from setuptools import find_packages, setup

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

setup(
    name=package_name,
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
