from glob import glob

from setuptools import find_packages, setup

package_name = "rcac_ros"

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
    install_requires=["setuptools", "numpy", "numba", "pyyaml", "matplotlib", "rosbags",
                      "yourdfpy"],
    zip_safe=True,
    maintainer="rcac_ros maintainers",
    maintainer_email="rcac@example.com",
    description="Recursive composite adaptive controller for serial manipulators (ROS 2).",
    license="Apache-2.0",
    extras_require={"test": ["pytest"]},
    entry_points={
        "console_scripts": [
            "rcac = rcac_ros.tools.cli:main",
            "controller = rcac_ros.nodes.controller.node:main",
            "simulator = rcac_ros.nodes.simulator.node:main",
        ],
    },
)
