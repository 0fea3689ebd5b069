"""Recordings survive a crash (doc/tools.md, "rcac record"): ``kill -9`` of ``rcac record`` loses
at most the
last second, for mcap and sqlite3; ``rcac inspect`` says to use ``--recover``, which salvages
the bag; a recorder that joins late records within 1 s of discovering the publishers."""

import re
import signal
import time

import pytest
from bagtest_support import (bag_file, clock_k, Publisher, rcac, read_mcap_ros2, read_rosbags,
                             Recorder, wait_for)
from bagtest_support import ros_env  # noqa: F401 - a fixture


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_sigkill_loses_at_most_the_last_second(tmp_path, ros_env, storage):  # noqa: F811
    bag = tmp_path / "bag"
    pub = Publisher(ros_env["_DOMAIN"])
    rec = Recorder(tmp_path, ros_env, "--out", str(bag), "--storage", storage)
    try:
        wait_for(pub.matched, 60, "the recorder subscribes", rec)
        pub.start()
        time.sleep(3.0)                          # 3 s of data, 1500 messages per topic
        kill_ns = time.time_ns()
        rec.proc.send_signal(signal.SIGKILL)
        rec.proc.wait(10)
        time.sleep(0.2)
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
    print(f"{storage}: salvaged {len(ks)} /clock messages, lost {len(lost)} sent before the "
          f"kill, the last {lost_s:.3f} s")
    assert lost_s <= 1.0
    assert len(ks) >= 0.5 * len(before_kill)
    # the recovered bag is closed and verifies
    res = rcac("inspect", recovered, env=ros_env)
    assert res.returncode == 0, res.stderr
    assert "/clock" in res.stdout


def test_late_recorder_records_within_1s_of_discovery(tmp_path, ros_env):  # noqa: F811
    """The publishers run first; the recorder joins, prints when each topic's publisher was
    discovered and its first message arrived; the gap is under 1 s."""
    bag = tmp_path / "bag"
    pub = Publisher(ros_env["_DOMAIN"])
    pub.start()
    time.sleep(1.0)
    rec = Recorder(tmp_path, ros_env, "--out", str(bag), "--duration", "4")
    try:
        assert rec.proc.wait(90) == 0, rec.output()
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
        assert after <= 1.0, out
    data = read_rosbags(str(bag))
    first_ns = data["/joint_states"][0][0]
    print(f"late recorder: first joint state {1e-9 * (first_ns - rec.started_ns):.3f} s after "
          "the process was started")
    assert len(data["/joint_states"]) > 100
