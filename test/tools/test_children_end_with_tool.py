"""A process a tool starts (a node, a busy loop) ends when the tool ends, however it ends.

A tool killed with ``kill -9`` runs no ``finally``; its nodes would go on publishing on a
domain the next run may take. The parent here starts a child the way the tools do, prints
its pid and is killed with SIGKILL; the child must be gone. A child started with a bare
``Popen`` outlives it, which shows that the parent's death alone would not end it.
"""

import os
import signal
import subprocess
import sys
import time

import pytest

from rcac_ros.tools import launch

pytestmark = pytest.mark.skipif(launch.ends_with_parent() is None,
                                reason="no PR_SET_PDEATHSIG on this system")

#: a tool: starts ``sleep 60`` with ``how`` and prints its pid, then waits to be killed
PARENT = """
import os, subprocess, sys, time
from rcac_ros.tools import launch
how, log = sys.argv[1:3]
cmd = [sys.executable, "-c", "import time; time.sleep(60)"]
if how == "spawn":
    pid = launch.spawn(cmd).pid
elif how == "child":
    pid = launch.Child("sleeper", cmd, dict(os.environ), log).proc.pid
else:
    pid = subprocess.Popen(cmd).pid
print(pid, flush=True)
time.sleep(60)
"""


def started(pid):
    """``pid``'s start time (clock ticks since boot), or None if it does not run (a zombie,
    dead but not yet reaped, counts as ended); with the pid it names one process."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            fields = f.read().split(")")[-1].split()
    except FileNotFoundError:
        return None
    return None if fields[0] == "Z" else fields[19]


def orphan_after_kill(how, tmp_path):
    """Start the parent with ``how``, SIGKILL it, return whether its child still runs 3 s
    later (and end the child if so)."""
    parent = subprocess.Popen([sys.executable, "-c", PARENT, how, str(tmp_path / "child.log")],
                              stdout=subprocess.PIPE, text=True)
    try:
        pid = int(parent.stdout.readline())
        start = started(pid)
        assert start is not None
    finally:
        parent.kill()
        parent.wait()
    end = time.monotonic() + 3.0
    while started(pid) == start and time.monotonic() < end:
        time.sleep(0.05)
    survived = started(pid) == start
    if survived:
        os.kill(pid, signal.SIGKILL)
    return survived


@pytest.mark.parametrize("how", ["spawn", "child"])
def test_a_child_of_a_killed_tool_ends(how, tmp_path):
    assert not orphan_after_kill(how, tmp_path)


def test_without_it_the_child_outlives_a_killed_tool(tmp_path):
    assert orphan_after_kill("popen", tmp_path)
