"""The opt-in real-time options of a node process (rcac_ros.nodes.runtime.realtime), in a
child process so that this one keeps its scheduler: the loop thread at the priority asked
for, the threads that were already running one below, a thread started later inheriting the
loop's; a refused option is a warning, not an error."""

import json
import os
import subprocess
import sys
import time

import pytest

CHILD = r"""
import json, os, sys, threading
from rcac_ros.nodes.runtime.realtime import Realtime, RealtimeOptions
stop = threading.Event()
ids = {}
def idle(key):
    ids[key] = threading.get_native_id()
    stop.wait()
before = threading.Thread(target=idle, args=("before",)); before.start()
while "before" not in ids:
    pass
rt = Realtime(RealtimeOptions(priority=int(sys.argv[1])), warn=lambda t: None)
after = threading.Thread(target=idle, args=("after",)); after.start()
while "after" not in ids:
    pass
ids["loop"] = threading.get_native_id()
out = {k: [os.sched_getscheduler(t), os.sched_getparam(t).sched_priority] for k, t in ids.items()}
out["applied"], out["warnings"] = rt.applied, rt.warnings
stop.set(); before.join(); after.join()
print(json.dumps(out))
"""


def _child(priority):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    done = subprocess.run([sys.executable, "-c", CHILD, str(priority)], capture_output=True,
                          text=True, timeout=60, env=env, check=True)
    return json.loads(done.stdout)


def _needs_fifo():
    """Skip unless a process may take SCHED_FIFO here (probed in a child process)."""
    probe = "import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))"
    if subprocess.run([sys.executable, "-c", probe], capture_output=True).returncode != 0:
        pytest.skip("SCHED_FIFO refused here: needs CAP_SYS_NICE or an rtprio limit, which a "
                    "real-time install grants")


def test_priority_applies_to_the_loop_and_one_below_to_the_process_threads():
    _needs_fifo()
    out = _child(30)
    fifo = os.SCHED_FIFO
    assert out["loop"] == [fifo, 30]
    assert out["before"] == [fifo, 29]           # e.g. DDS's threads, the input threads
    assert out["after"] == [fifo, 30]            # started by the loop thread: inherited
    assert out["warnings"] == [] and out["applied"][0].startswith("sched_fifo (priority 30")


def test_lowest_priority_keeps_the_other_threads_at_one():
    _needs_fifo()
    out = _child(1)
    assert out["loop"] == [os.SCHED_FIFO, 1] and out["before"] == [os.SCHED_FIFO, 1]


def test_a_priority_out_of_range_is_a_warning():
    out = _child(1000)
    assert out["applied"] == []
    assert len(out["warnings"]) == 1 and "priority 1000 outside 1..99" in out["warnings"][0]
    assert out["loop"][0] == os.SCHED_OTHER


def _schedulers(pid):
    """``{thread id: (policy, priority)}`` of process ``pid``'s threads."""
    out = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            out[int(tid)] = (os.sched_getscheduler(int(tid)),
                             os.sched_getparam(int(tid)).sched_priority)
        except ProcessLookupError:      # the thread ended meanwhile
            pass
    return out


@pytest.mark.parametrize("module, overrides", [
    ("simulator_node", ("mode:=realtime",)),      # waits for a controller meanwhile
    ("controller_node", ("mode:=timer",)),        # waits for states meanwhile
])
def test_each_node_applies_its_realtime_parameters(module, overrides):
    """Both node processes take ``realtime.priority`` from their parameters: the thread
    that paces them at it, every other thread of the process one below."""
    _needs_fifo()
    from test_nodes_support import ros_domain, start, stop
    with ros_domain():
        proc = start(module, "realtime.priority:=30", *overrides)
        try:
            deadline = time.monotonic() + 120.0
            seen = {}
            while time.monotonic() < deadline and proc.poll() is None:
                seen = _schedulers(proc.pid)
                if seen.get(proc.pid) == (os.SCHED_FIFO, 30):
                    time.sleep(0.5)                 # threads it started since: inherited
                    seen = _schedulers(proc.pid)
                    break
                time.sleep(0.2)
        finally:
            code, out = stop(proc)
    assert seen.get(proc.pid) == (os.SCHED_FIFO, 30), out
    others = {tid: s for tid, s in seen.items() if tid != proc.pid}
    assert others and all(s[0] == os.SCHED_FIFO and s[1] in (29, 30)
                          for s in others.values()), (others, out)
    assert "real-time options: sched_fifo (priority 30" in out
    assert code == 0, out
