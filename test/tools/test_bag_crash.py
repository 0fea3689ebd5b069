"""Recordings survive a crash (doc/tools.md, "rcac record"): ``kill -9`` of ``rcac record`` loses
only what its last flush did not cover, for mcap and sqlite3; ``rcac inspect`` says to use
``--recover``, which salvages the bag; a recorder that joins late records every message sent
after its subscriptions matched."""

import bisect
import re
import signal
import time

import pytest
import yaml
from bagtest_support import (bag_file, clock_k, Publisher, rcac, read_mcap_ros2, read_rosbags,
                             Recorder, wait_for)
from bagtest_support import ros_env  # noqa: F401 - a fixture


def flushed_count(bag, topic="/clock"):
    """``topic``'s message count in the bag's ``metadata.yaml``, which the recorder rewrites at
    every flush (0 while there is none, or while it is being rewritten)."""
    try:
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())
        return next(t["message_count"] for t in
                    meta["rosbag2_bagfile_information"]["topics_with_message_count"]
                    if t["topic_metadata"]["name"] == topic)
    except (OSError, yaml.YAMLError, TypeError, KeyError, StopIteration):
        return 0


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_sigkill_loses_only_what_was_not_flushed(tmp_path, ros_env, storage):  # noqa: F811
    """``kill -9`` while messages stream in: every message of the last flush the recorder
    announced (its ``metadata.yaml`` counts) is salvaged, without a gap. (The time a flush
    covers is the recorder's flush period of running time: a loaded machine that holds the
    recorder delays its flushes, so the bound is counted in messages, not seconds.)"""
    bag = tmp_path / "bag"
    pub = Publisher(ros_env["_DOMAIN"])
    rec = Recorder(tmp_path, ros_env, "--out", str(bag), "--storage", storage)
    try:
        wait_for(pub.matched, 60, "the recorder subscribes", rec)
        pub.start()
        wait_for(lambda: len(pub.sent) >= 1500, 300, "1500 messages sent", rec)
        # still streaming: a flush that covers the first 1500, then the kill
        wait_for(lambda: flushed_count(bag) >= 1500, 300, "a flush of 1500 messages", rec)
        flushed = flushed_count(bag)
        kill_ns = time.time_ns()
        rec.proc.send_signal(signal.SIGKILL)
        rec.proc.wait(10)
        pub.stop()
    finally:
        rec.stop()
        pub.close()
    sent = pub.sent

    # the cut bag: inspect names the problem in one line and points to --recover
    res = rcac("inspect", str(bag), env=ros_env)
    assert res.returncode == 2, res.stdout + res.stderr
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and f"rcac inspect --recover {bag}" in err[0], res.stderr

    res = rcac("inspect", "--recover", str(bag), env=ros_env)
    assert res.returncode == 0, res.stdout + res.stderr
    recovered = f"{bag}_recovered"
    assert f"recovered {bag} into {recovered}" in res.stdout
    assert "salvaged /clock" in res.stdout and "lost:" in res.stdout

    # read back by two libraries (mcap) or rosbags (sqlite3)
    data = read_rosbags(recovered)
    ks = [clock_k(m) for _, m in data["/clock"]]
    if storage == "mcap":
        other = read_mcap_ros2(bag_file(recovered))
        assert [clock_k(m) for _, _, m in other["/clock"]] == ks
    assert ks == list(range(ks[0], ks[-1] + 1)), "a gap in the salvaged messages"
    before_kill = [k for k, t in enumerate(sent) if t <= kill_ns]
    lost = [k for k in before_kill if k > ks[-1]]
    lost_s = 1e-9 * (kill_ns - sent[ks[-1]])
    print(f"{storage}: salvaged {len(ks)} /clock messages ({flushed} flushed), lost "
          f"{len(lost)} sent before the kill, the last {lost_s:.3f} s")
    assert ks[0] == 0 and len(ks) >= flushed, (ks[0], len(ks), flushed)
    # the recovered bag is closed and verifies
    res = rcac("inspect", recovered, env=ros_env)
    assert res.returncode == 0, res.stderr
    assert "/clock" in res.stdout


def test_late_recorder_records_within_1s_of_discovery(tmp_path, ros_env):  # noqa: F811
    """The publishers run first; the recorder joins, prints when each topic's publisher was
    discovered and its first message arrived, and records every message sent once its
    subscriptions matched on both sides (reliable topics: nothing after the match is lost,
    however slow a loaded machine makes the recorder; the delay in seconds is printed, not
    bounded)."""
    bag = tmp_path / "bag"
    pub = Publisher(ros_env["_DOMAIN"])
    pub.start()
    wait_for(lambda: len(pub.sent) >= 500, 300, "500 messages sent before the recorder")
    rec = Recorder(tmp_path, ros_env, "--out", str(bag), "--duration", "4")
    try:
        wait_for(pub.matched, 90, "the recorder subscribes", rec)
        matched_k = len(pub.sent)     # every message from here on was sent after the match
        assert rec.proc.wait(90) == 0, rec.output()
        pub.stop()
    finally:
        rec.stop()
        pub.close()
    out = rec.output()
    pattern = re.compile(r"first message on (\S+) at ([\d.]+) s \(its publisher matched at "
                         r"([\d.]+) s\)")
    firsts = {m.group(1): (float(m.group(2)), float(m.group(2)) - float(m.group(3)))
              for m in pattern.finditer(out)}
    assert {"/clock", "/joint_states"} <= set(firsts), out
    for topic in ("/clock", "/joint_states"):
        at, after = firsts[topic]
        print(f"late recorder: {topic} first message {at:.3f} s after start, {after:.3f} s "
              "after discovery")
    data = read_rosbags(str(bag))
    ks = [clock_k(m) for _, m in data["/clock"]]
    states = [int(m.position[0]) for _, m in data["/joint_states"]]
    for topic, got in (("/clock", ks), ("/joint_states", states)):
        # DDS matches each side on its own: the recorder's side matched at the latest
        # `after` s before its first message's receive stamp (both on that clock, the match
        # taken when its callback ran, printed to 1 ms each); a message published once both
        # sides had matched is recorded. sent[k] is taken just after message k is published.
        reader_ns = data[topic][0][0] - firsts[topic][1] * 1e9 + 1e6
        both_k = max(matched_k, bisect.bisect_right(pub.sent, reader_ns) + 1)
        assert got[0] <= both_k, (topic, got[0], matched_k, both_k)
        assert got == list(range(got[0], got[0] + len(got))), f"{topic}: a gap"
    first_ns = data["/joint_states"][0][0]
    print(f"late recorder: first joint state {1e-9 * (first_ns - rec.started_ns):.3f} s after "
          "the process was started")
    assert len(data["/joint_states"]) > 100
