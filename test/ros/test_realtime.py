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


OTHER_LOOP = r"""
import json, os, threading
from rcac_ros.nodes.runtime.realtime import Realtime, RealtimeOptions
stop, ids = threading.Event(), {}
def idle():
    ids["loop"] = threading.get_native_id()
    stop.wait()
worker = threading.Thread(target=idle); worker.start()
while "loop" not in ids:
    pass
cpu = min(os.sched_getaffinity(0))
rt = Realtime(RealtimeOptions(cpus=[cpu]), warn=lambda t: None, loop_thread=ids["loop"])
out = {"cpu": cpu, "loop": sorted(os.sched_getaffinity(ids["loop"])),
       "caller": sorted(os.sched_getaffinity(0)), "applied": rt.applied}
stop.set(); worker.join()
print(json.dumps(out))
"""


def test_the_loop_thread_named_takes_the_options_not_the_caller():
    """The lockstep controller's step runs in its state input's thread: that thread is
    pinned (and prioritised), not the thread that applies the options."""
    if len(os.sched_getaffinity(0)) < 2:
        pytest.skip("one CPU: pinning changes nothing")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    out = json.loads(subprocess.run([sys.executable, "-c", OTHER_LOOP], capture_output=True,
                                    text=True, timeout=60, env=env, check=True).stdout)
    assert out["loop"] == [out["cpu"]]
    assert len(out["caller"]) >= 2
    assert out["applied"][0].startswith(f"cpu_affinity (CPUs [{out['cpu']}]")


MOVED_LOOP = r"""
import json, os, sys, threading
from rcac_ros.nodes.runtime.realtime import Realtime, RealtimeOptions
stop, ids = threading.Event(), {}
def idle(key):
    ids[key] = threading.get_native_id()
    stop.wait()
first = threading.Thread(target=idle, args=("first",)); first.start()
while "first" not in ids:
    pass
cpu = min(os.sched_getaffinity(0))
rt = Realtime(RealtimeOptions(cpus=[cpu], priority=int(sys.argv[1])), warn=lambda t: None,
              loop_thread=ids["first"])
second = threading.Thread(target=idle, args=("second",)); second.start()
while "second" not in ids:
    pass
rt.move(ids["second"])                   # a node configured again: a new loop thread
out = {k: [sorted(os.sched_getaffinity(t)), os.sched_getparam(t).sched_priority]
       for k, t in ids.items()}
out["cpu"], out["applied"] = cpu, rt.applied
stop.set(); first.join(); second.join()
print(json.dumps(out))
"""


def test_the_options_follow_the_loop_to_its_new_thread():
    """A node configured again makes a new loop thread (lockstep: a new state input): it
    takes the CPUs and the priority, the former loop thread goes one below."""
    if len(os.sched_getaffinity(0)) < 2:
        pytest.skip("one CPU: pinning changes nothing")
    fifo = subprocess.run([sys.executable, "-c", "import os; os.sched_setscheduler(0, "
                           "os.SCHED_FIFO, os.sched_param(1))"], capture_output=True)
    priority = 30 if fifo.returncode == 0 else 0
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    out = json.loads(subprocess.run([sys.executable, "-c", MOVED_LOOP, str(priority)],
                                    capture_output=True, text=True, timeout=60, env=env,
                                    check=True).stdout)
    assert out["second"][0] == [out["cpu"]]
    if priority:
        assert out["second"][1] == 30 and out["first"][1] == 29


def test_a_controller_configured_again_moves_its_options_to_the_new_state_input():
    from test_nodes_support import ros_context, spin_until
    from rcac_ros.nodes.controller.node import ControllerNode

    class Moves:
        def __init__(self):
            self.to = []

        def move(self, thread):
            self.to.append(thread)
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx)
        executor.add_node(node)
        assert spin_until(executor, lambda: node.running)      # (once its kernels are ready)
        node.realtime_applied = moves = Moves()
        first = node.loop_thread
        node.trigger_deactivate()
        node.trigger_cleanup()
        node.trigger_configure()
        assert moves.to == [node.loop_thread] and node.loop_thread not in (None, first)


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


@pytest.mark.parametrize("module, overrides, main_loop", [
    ("simulator_node", ("mode:=realtime",), True),      # waits for a controller meanwhile
    ("controller_node", ("mode:=timer",), True),        # waits for states meanwhile
    ("controller_node", ("mode:=lockstep",), False),    # steps in its state input's thread
])
def test_each_node_applies_its_realtime_parameters(module, overrides, main_loop):
    """Both node processes take ``realtime.priority`` from their parameters: the thread
    that paces them at it (the main thread, or the lockstep controller's state input),
    every other thread of the process one below."""
    _needs_fifo()
    from test_nodes_support import ros_domain, start, stop
    with ros_domain():
        proc = start(module, "realtime.priority:=30", *overrides)
        try:
            deadline = time.monotonic() + 120.0
            seen = {}
            while time.monotonic() < deadline and proc.poll() is None:
                seen = _schedulers(proc.pid)
                if (os.SCHED_FIFO, 30) in seen.values():
                    time.sleep(0.5)                 # threads it started since: inherited
                    seen = _schedulers(proc.pid)
                    break
                time.sleep(0.2)
        finally:
            code, out = stop(proc)
    top = [tid for tid, s in seen.items() if s == (os.SCHED_FIFO, 30)]
    if main_loop:
        assert proc.pid in top, out
    else:
        assert len(top) == 1 and top[0] != proc.pid, (seen, out)
    others = {tid: s for tid, s in seen.items() if tid not in top}
    assert others and all(s[0] == os.SCHED_FIFO and s[1] in (29, 30)
                          for s in others.values()), (others, out)
    assert "real-time options: sched_fifo (priority 30" in out
    assert code == 0, out
