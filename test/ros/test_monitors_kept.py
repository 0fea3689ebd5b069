"""The controller's monitor topics are transient local (nodes/runtime/base.py, ``QOS_KEPT``):
``rcac record`` started after the controller has answered states still records the monitors
published before it matched, as a late reader of a transient-local writer gets its history.
(DDS matches each side on its own: a writer that has not yet matched a reader whose side
already sees it drops what it publishes meanwhile; the history closes that window.)"""

import os
import signal
import subprocess
import sys

from failsafe_harness import controller, first_answer, session, wait

from rcac_ros import topics

ESTIMATES = topics.resolve(topics.PARAMETER_ESTIMATES)


def read_bag(path):
    """topic -> message count, through rosbags."""
    from rosbags.rosbag2 import Reader
    with Reader(path) as reader:
        return {c.topic: c.msgcount for c in reader.connections}


def test_a_recorder_started_late_gets_the_monitors_sent_before(tmp_path):
    bag = tmp_path / "bag"
    stamps = [(k + 1) * 2_000_000 for k in range(20)]
    with session() as probe, controller(probe):
        for t_ns in stamps:                 # 20 answers, each with its monitors
            first_answer(probe, t_ns)
        rec = subprocess.Popen([sys.executable, "-m", "rcac_ros.tools.cli", "record", "--out",
                                str(bag), "--duration", "3"], env=dict(os.environ),
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            out, _ = rec.communicate(timeout=120)
        finally:
            if rec.poll() is None:
                rec.send_signal(signal.SIGINT)
                rec.wait(30)
        assert wait(lambda: len(probe.answers()) >= len(stamps), timeout=5.0)
    assert rec.returncode == 0, out
    # every monitor message of the 20 steps was published before the recorder existed
    assert read_bag(str(bag)).get(ESTIMATES, 0) == len(stamps), out
