"""The garbage collector around the loop (nodes/runtime/gcwatch.py): every collection timed,
and the node process reports it in its diagnostics."""

import gc

from failsafe_harness import controller, first_answer, session, wait

from rcac_ros.nodes.runtime import gcwatch


def test_watch_times_each_collection():
    ticks = iter(range(0, 10 ** 6, 7))      # a fake clock: every reading 7 units later
    watch = gcwatch.GcWatch(clock=lambda: next(ticks)).install()
    gc.disable()                            # only the two collections asked for
    try:
        gc.collect(0)
        gc.collect(2)
    finally:
        watch.close()
        gc.enable()
    assert watch.collections == 2 and watch.full == 1
    assert watch.pause_max_s == 7           # one reading at the start, one at the end
    gc.collect(2)
    assert watch.collections == 2 and not watch.active


def test_the_node_process_reports_its_collections():
    with session() as probe, controller(probe):
        first_answer(probe, 0)
        name = "rcac_controller: control loop"
        assert wait(lambda: "gc_pause_max_ms" in probe.diagnostics.get(name, {}),
                    timeout=30.0)
        values = probe.diagnostics[name]
        # (the steady loop allocates almost no tracked objects: collections are rare, and
        # test_watch_times_each_collection checks their timing)
        assert float(values["gc_pause_max_ms"]) >= 0.0
        assert 0 <= int(values["gc_full_collections"]) <= int(values["gc_collections"])
