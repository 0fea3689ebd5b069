"""The garbage collector around the loop (nodes/gcwatch.py): start-up objects frozen, so a
full collection walks only what came after; every collection timed; the node reports it."""

import gc

from failsafe_harness import controller, first_answer, session, wait

from rcac_ros.nodes import gcwatch


def test_freeze_leaves_a_full_collection_only_the_new_objects():
    import rcac_ros.nodes.controller_node  # noqa: F401  (a node process's start-up objects)
    try:
        tracked = len(gc.get_objects())     # what a full collection walks
        gcwatch.freeze_startup()
        assert gc.get_freeze_count() > 0.9 * tracked - 1000
        kept = [[i] for i in range(1000)]   # made after start-up: still collectable
        assert 1000 <= len(gc.get_objects()) < 0.05 * tracked
    finally:
        gcwatch.unfreeze()
    assert gc.get_freeze_count() == 0 and len(gc.get_objects()) > 0.9 * tracked
    del kept


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


def test_the_node_process_freezes_and_reports_its_collections():
    with session() as probe, controller(probe):
        first_answer(probe, 0)
        name = "rcac_controller: control loop"
        assert wait(lambda: "gc_frozen_objects" in probe.diagnostics.get(name, {}),
                    timeout=30.0)
        values = probe.diagnostics[name]
        assert int(values["gc_frozen_objects"]) > 10000
        # (the steady loop allocates almost no tracked objects: collections are rare, and
        # test_watch_times_each_collection checks their timing)
        assert float(values["gc_pause_max_ms"]) >= 0.0
        assert int(values["gc_full_collections"]) >= 0
