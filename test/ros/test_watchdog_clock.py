"""The watchdog's clock across threads (module docstring of ``nodes/safety/watchdog.py``,
doc/failsafe.md "Watchdog clock"): in timer mode the state input's side thread hands each
valid state over as one immutable snapshot with its arrival time, and the control thread
reads the state and the time the watchdog judges from that one object.

The test hammers the hand-over: a side thread reads states as fast as it can while the
control thread takes them and asks the real :class:`Watchdog` whether the state is stale, with
the interpreter switching threads every microsecond. Each state's positions encode its stamp;
a hand-over made of several assignments (a position of one state beside the stamp or the
arrival time of another) fails the checks of a snapshot, and an arrival time read apart from
its state goes backwards or stops matching the snapshot's.
"""

import sys
import threading
import time

import numpy as np

from test_nodes_support import ros_context
from test_state_input_threads import state, state_input, Watchdog as RecordingWatchdog

from rcac_ros.nodes.safety.state_guards import SafeStop, StampGate  # noqa: E402
from rcac_ros.nodes.safety.watchdog import Watchdog  # noqa: E402

#: states the side thread reads
COUNT = 20_000
#: ns between two stamps: far below the steady time a read takes, so the stamp gate never
#: refuses one as ahead of the clock
STEP_NS = 1_000


def test_the_watchdog_reads_each_state_and_its_arrival_from_one_snapshot():
    with ros_context() as (ctx, _):
        node, states, warnings = state_input(ctx, StampGate(), RecordingWatchdog(),
                                             lambda: None)
        watchdog = Watchdog(stop=SafeStop(), send_safe_effort=lambda: None,
                            state_received=lambda: states.received, state_timeout=1.0,
                            lockstep=False, log=None, stepped=lambda: True,
                            filters_missed=lambda: None, replan=lambda held: None)
        messages = [state(k * STEP_NS, [k * 1e-3, -k * 1e-3]) for k in range(1, COUNT + 1)]
        done = threading.Event()

        def side():
            for msg in messages:
                states._on_state(msg)
            done.set()

        interval = sys.getswitchinterval()
        sys.setswitchinterval(1e-6)
        reader = threading.Thread(target=side)
        try:
            reader.start()
            while states.latest is None:
                time.sleep(0)
            takes, last_received, last_stamp = 0, 0, 0
            while not done.is_set():
                sample = states.take()
                # the snapshot is one state: its positions, stamp and arrival belong together
                k = round(sample.stamp / STEP_NS)
                assert sample.stamp == k * STEP_NS
                np.testing.assert_array_equal(sample.q, [k * 1e-3, -k * 1e-3])
                assert sample.received >= last_received and sample.stamp >= last_stamp
                last_received, last_stamp = sample.received, sample.stamp
                # the watchdog's reading of the time: the same snapshot or a newer one
                received = states.received
                assert received >= sample.received
                assert not watchdog.state_is_stale()
                takes += 1
        finally:
            sys.setswitchinterval(interval)
            reader.join(60.0)
            states.close()
            node.destroy_node()
        assert not reader.is_alive() and warnings == []
        assert states.latest.stamp == COUNT * STEP_NS
        assert takes > 100, takes           # the two threads did interleave
