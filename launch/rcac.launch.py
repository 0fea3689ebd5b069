"""Simulator, controller and, optionally, a bag recorder (``ros2 launch rcac_ros rcac.launch.py``).

Arguments (``name:=value``):

* ``controller_params``, ``simulator_params``: parameter files (default: the installed
  ``share/rcac_ros/config/controller.yaml`` and ``simulator.yaml``);
* ``simulator``: ``true`` (default) or ``false`` to drive a real arm (or another simulator)
  with the controller alone;
* ``record``: ``true`` to run ``rcac record`` beside them (default ``false``), into ``bag``
  (default ``rcac_bag``, a directory that must not exist yet);
* ``use_sim_time``: passed to both nodes (default ``false``).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.substitutions import ExecutableInPackage

PACKAGE = "rcac_ros"


def generate_launch_description():
    """The launch description: two nodes and an optional ``rcac record`` process."""
    config = os.path.join(get_package_share_directory(PACKAGE), "config")
    sim_time = {"use_sim_time": LaunchConfiguration("use_sim_time")}
    return LaunchDescription([
        DeclareLaunchArgument("controller_params",
                              default_value=os.path.join(config, "controller.yaml"),
                              description="parameter file of the controller node"),
        DeclareLaunchArgument("simulator_params",
                              default_value=os.path.join(config, "simulator.yaml"),
                              description="parameter file of the simulator node"),
        DeclareLaunchArgument("simulator", default_value="true",
                              description="start the simulator node"),
        DeclareLaunchArgument("record", default_value="false",
                              description="record the package's topics with 'rcac record'"),
        DeclareLaunchArgument("bag", default_value="rcac_bag",
                              description="bag directory of the recorder (must not exist)"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="use_sim_time of both nodes"),
        Node(package=PACKAGE, executable="simulator", name="rcac_simulator", output="screen",
             parameters=[LaunchConfiguration("simulator_params"), sim_time],
             condition=IfCondition(LaunchConfiguration("simulator"))),
        Node(package=PACKAGE, executable="controller", name="rcac_controller",
             output="screen", parameters=[LaunchConfiguration("controller_params"), sim_time]),
        ExecuteProcess(cmd=[ExecutableInPackage("rcac", PACKAGE), "record", "--out",
                            LaunchConfiguration("bag")],
                       name="rcac_record", output="screen", sigterm_timeout="10",
                       condition=IfCondition(LaunchConfiguration("record"))),
    ])
