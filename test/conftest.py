"""The tests' root: ``test/`` is on ``sys.path`` (pytest's prepend import mode), so the
shared helpers import as ``from chains import random_chain, to_pin``.

``make test`` runs the suite with pytest-xdist (``-n 3 --dist loadgroup``): most tests wait
on processes, DDS and timeouts far more than they compute, so three workers overlap the waits
on 2 cores. The ROS tests take a unique DDS domain each (``domain_coordinator``). A module
that builds a module-scoped fixture (a colcon install, a payload-demo run) runs on one worker
as a group (:data:`GROUPED`), so the fixture is built once; the tests that compare a
process's timing with the machine's (:data:`TIMING`) run one after another on one worker,
never beside each other.
"""

import os

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))

#: timing against the machine's own: one group, so never two of them at once
TIMING = {
    "ros/test_failsafe_flood.py",       # effort gaps against an idle sleeper's
    "ros/test_failsafe_starved.py",     # must start unstarved; SIGSTOP every 30 ms
    "ros/test_freeze_causes.py",        # starved by SIGSTOP, then not
    "ros/test_realtime.py",             # SCHED_FIFO threads
    "ros/test_nodes_pacing.py",         # the timer loop's deadlines
}
#: module-scoped fixtures: the module's tests on one worker
GROUPED = {
    "ros/test_colcon.py",
    "tools/test_payload_demo.py",
}


def _relative(item):
    return os.path.relpath(str(item.path), HERE).replace(os.sep, "/")


def pytest_collection_modifyitems(config, items):
    for item in items:
        rel = _relative(item)
        if rel in TIMING:
            item.add_marker(pytest.mark.xdist_group("timing"))
        elif rel in GROUPED:
            item.add_marker(pytest.mark.xdist_group(rel))


def pytest_configure(config):
    """Under xdist, the control_msgs subset is built once here, before the workers import
    test/ros/conftest.py (each would otherwise build it at the same time)."""
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        import sys
        sys.path.insert(0, os.path.join(HERE, "ros"))
        import interface_build
        interface_build.use_in_tests()
