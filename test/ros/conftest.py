"""The ROS tests' set-up: a control_msgs for the FollowJointTrajectory server where none is.

control_msgs is not a PyPI wheel. Where it does not import, the subset the package uses
(``test/ros/interfaces``) is built once into ``build/test-interfaces/<key>`` by
``interface_build.py`` (about 20 s, then cached) and put first on ``sys.path`` and on
``PYTHONPATH`` for the processes the tests start. An installed control_msgs (apt, or a colcon
workspace on ``PYTHONPATH``) always wins: nothing is built then. See doc/testing.md.

A conftest runs before the test modules of its folder are imported, so
``rcac_ros.nodes.fjt.server`` sees the built package when it first imports.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import interface_build  # noqa: E402

interface_build.use_in_tests()
