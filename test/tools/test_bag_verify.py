"""Corrupt bags give one clear line and a non-zero exit, never silent partial data
(doc/tools.md, "rcac inspect"); ``--recover`` says what it salvaged and lost; ``rcac inspect``
finds the bag in a
parent folder. The bags are written by the package's writer and read back by
rosbags and by ``mcap`` + ``mcap-ros2-support``."""

import functools
import importlib
import os
import sqlite3

import pytest
import yaml
from bagtest_support import bag_file, cli_module, read_mcap_ros2, read_rosbags

from rcac_ros.errors import BagError, ConfigError, CutBagError
from rcac_ros.tools.bags.recover import recover
from rcac_ros.tools.bags.verify import verify
from rcac_ros.tools.bags.writer import BagWriter

N_MSG = 2000


def _main(argv):
    return importlib.import_module(cli_module()).main(argv)


@functools.cache
def _typestore():
    """rosbags' Jazzy typestore, built once (about 17 ms a build: once per message, it was
    most of this file's time)."""
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


def _clock(k):
    ts = _typestore()
    t = ts.types
    msg = t["rosgraph_msgs/msg/Clock"](clock=t["builtin_interfaces/msg/Time"](
        sec=k // 500, nanosec=(k % 500) * 2_000_000))
    return ts.serialize_cdr(msg, "rosgraph_msgs/msg/Clock")


def write_bag(path, storage="mcap", n=N_MSG, flush_every=200, close=True):
    """A bag of ``n`` numbered /clock messages, flushed every ``flush_every`` messages."""
    w = BagWriter(str(path), storage, flush_period=1e9)
    w.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    for k in range(n):
        w.write("/clock", 1_700_000_000_000_000_000 + k * 2_000_000, _clock(k), sequence=k + 1)
        if (k + 1) % flush_every == 0:
            w.flush()
    if close:
        w.close()
    return w


def _err_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_closed_bag_verifies_and_reads_back(tmp_path, storage):
    bag = tmp_path / "bag"
    write_bag(bag, storage)
    report = verify(str(bag))
    assert report.counts == {"/clock": N_MSG}
    data = read_rosbags(str(bag))
    assert len(data["/clock"]) == N_MSG
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["ros_distro"] == "jazzy" and meta["message_count"] == N_MSG
    if storage == "mcap":
        assert "10 chunk CRCs" in report.checks and "data section CRC" in report.checks
        from mcap.reader import make_reader
        with open(bag_file(str(bag)), "rb") as f:
            reader = make_reader(f)
            assert reader.get_header().profile == "ros2"
            summary = reader.get_summary()
            # real CRCs: rosbags writes 0, which readers take as "not computed"
            assert summary.chunk_indexes and all(
                ci.uncompressed_size for ci in summary.chunk_indexes)
        other = read_mcap_ros2(bag_file(str(bag)))
        assert [m.clock.nanosec for _, _, m in other["/clock"][:3]] == [0, 2_000_000, 4_000_000]
    else:
        db = sqlite3.connect(bag_file(str(bag)))
        assert db.execute("SELECT ros_distro FROM schema").fetchall() == [("jazzy",)]
        db.close()


def _chunk_offsets(path):
    from mcap.reader import make_reader
    with open(path, "rb") as f:
        return [(ci.chunk_start_offset, ci.chunk_length)
                for ci in make_reader(f).get_summary().chunk_indexes]


def _damaged_bag(tmp_path, chunk, damage):
    """An mcap bag whose chunk number ``chunk`` (0-based) ``damage(raw, start, length)`` changes
    in the file's bytes; return ``(bag, the chunk's start offset)``."""
    bag = tmp_path / "bag"
    write_bag(bag, "mcap")
    path = bag_file(str(bag))
    start, length = _chunk_offsets(path)[chunk]
    raw = bytearray(open(path, "rb").read())
    damage(raw, start, length)
    open(path, "wb").write(bytes(raw))
    return bag, start


def _flip_byte(raw, start, length):
    raw[start + length - 40] ^= 0xFF         # inside the chunk's compressed data


def _garble_length(raw, start, length):
    raw[start + 1:start + 9] = b"\xff" * 8   # the chunk's record length


def _inspect_fails_then_recover(tmp_path, capsys, chunk, damage, *words):
    """One chunk of ten damaged: ``rcac inspect`` fails in one line holding ``words``, and
    recovery keeps the nine intact chunks (1800 of the 2000 /clock messages).

    Returns the recovery report and the damaged chunk's byte offset.
    """
    bag, start = _damaged_bag(tmp_path, chunk, damage)
    assert _main(["inspect", str(bag)]) == 2
    line = _err_line(capsys)
    assert all(word in line for word in words), line
    report = recover(str(bag))
    assert report.counts == {"/clock": 1800}
    return report, start


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_damaged_bag_is_a_bag_error_not_a_configuration_error(tmp_path, storage):
    """Exceptions by kind: verify raises BagError (CutBagError for an unclosed bag), which a
    handler of configuration errors does not catch."""
    write_bag(tmp_path / "bag", storage, n=400, close=False)
    with pytest.raises(CutBagError) as err:
        verify(str(tmp_path / "bag"))
    assert isinstance(err.value, BagError) and not isinstance(err.value, ConfigError)


def test_flipped_byte_in_a_chunk_is_a_crc_error(tmp_path, capsys):
    report, start = _inspect_fails_then_recover(tmp_path, capsys, 3, _flip_byte,  # 4th chunk
                                                "damaged record", "corrupt")
    # the summary is intact: recovery says what was lost
    assert any(f"the chunk at byte {start} of bag_0.mcap" in item for item in report.lost)
    assert any("200 of the 2000" in item for item in report.lost), report.lost
    ks = [round(m.clock.sec * 500 + m.clock.nanosec / 2e6)
          for _, m in read_rosbags(report.path)["/clock"]]
    assert ks == list(range(600)) + list(range(800, 2000))


def test_payload_corruption_without_compression_is_caught_by_the_crc(tmp_path, capsys):
    bag = tmp_path / "bag"
    w = BagWriter(str(bag), "mcap", flush_period=1e9, compression="none")
    w.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    for k in range(500):
        w.write("/clock", 10**18 + k, _clock(k))
        if k % 100 == 99:
            w.flush()
    w.close()
    path = bag_file(str(bag))
    start, length = _chunk_offsets(path)[2]
    raw = bytearray(open(path, "rb").read())
    raw[start + length - 3] ^= 0x01           # one bit of a message's payload
    open(path, "wb").write(bytes(raw))
    assert _main(["inspect", str(bag)]) == 2
    assert "crc validation failed" in _err_line(capsys)


def test_counts_differ_from_metadata(tmp_path, capsys):
    bag = tmp_path / "bag"
    write_bag(bag, "mcap")
    meta_path = bag / "metadata.yaml"
    meta = yaml.safe_load(meta_path.read_text())
    meta["rosbag2_bagfile_information"]["topics_with_message_count"][0]["message_count"] = 1999
    meta_path.write_text(yaml.safe_dump(meta))
    assert _main(["inspect", str(bag)]) == 2
    assert "/clock holds 2000 messages, metadata.yaml says 1999" in _err_line(capsys)


def test_sqlite_integrity_check(tmp_path, capsys):
    bag = tmp_path / "bag"
    write_bag(bag, "sqlite3")
    path = bag_file(str(bag))
    raw = bytearray(open(path, "rb").read())
    page = 4096
    for i in range(2 * page + 8, 2 * page + 200):    # garble the b-tree of page 3
        raw[i] = 0xA5
    open(path, "wb").write(bytes(raw))
    assert _main(["inspect", str(bag)]) == 2
    line = _err_line(capsys)
    assert "integrity check" in line or "sqlite error" in line, line


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_unclosed_bag_points_to_recover(tmp_path, capsys, storage):
    bag = tmp_path / "bag"
    w = write_bag(bag, storage, close=False)          # as after kill -9: flushed, not closed
    assert _main(["inspect", str(bag)]) == 2
    assert f"run `rcac inspect --recover {bag}`" in _err_line(capsys)
    assert _main(["inspect", "--recover", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "salvaged /clock: 2000" in out
    assert len(read_rosbags(f"{bag}_recovered")["/clock"]) == N_MSG
    if storage == "sqlite3":
        w._db.close()


def test_inspect_finds_the_bag_in_a_parent_folder(tmp_path, capsys):
    write_bag(tmp_path / "run" / "bag", "mcap", n=50, flush_every=50)
    os.makedirs(tmp_path / "run" / "logs")
    assert _main(["inspect", str(tmp_path / "run")]) == 0
    assert "Messages:" in capsys.readouterr().out
    write_bag(tmp_path / "run" / "bag2", "mcap", n=50, flush_every=50)
    assert _main(["inspect", str(tmp_path / "run")]) == 2
    line = _err_line(capsys)
    assert "holds 2 bags (bag, bag2)" in line, line


def test_figures_legend_log_error_and_timing_caption(tmp_path, monkeypatch):
    """efforts.png names the joints, prediction_error.png shows log |E|, and the loop-timing
    figure says which stamps it comes from."""
    import matplotlib.figure
    import numpy as np

    from rcac_ros.tools.bags.inspect import write_plots
    figures = {}

    def capture(fig, path, **kwargs):
        figures[os.path.basename(str(path))] = fig
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", capture)
    t = np.linspace(0.0, 1.0, 50)
    names = [f"j{k}" for k in range(7)]
    series = {"effort": (t, np.ones((50, 7))),
              "prediction_error": (t, np.exp(-5.0 * t) * np.cos(20.0 * t)),
              "prediction_errors": (t, np.column_stack([np.exp(-t), -np.exp(-2.0 * t)]),
                                    ["joint1", "power"]),
              "timing": {"period_ms": np.full(49, 2.0), "latency_ms": np.full(49, 0.3),
                         "unanswered": 0, "clock": "receive"}}
    write_plots(series, str(tmp_path), names=names)
    ax = figures["efforts.png"].axes[0]
    assert [x.get_text() for x in ax.get_legend().get_texts()] == names
    ax = figures["prediction_error.png"].axes[0]
    assert ax.get_yscale() == "log"
    y = ax.get_lines()[0].get_ydata()
    assert np.allclose(y, np.abs(series["prediction_error"][1]))
    ax = figures["prediction_errors.png"].axes[0]      # log |E_c|, one line per channel
    assert ax.get_yscale() == "log"
    assert [x.get_text() for x in ax.get_legend().get_texts()] == ["joint1", "power"]
    assert np.allclose(ax.get_lines()[1].get_ydata(), np.exp(-2.0 * t))
    caption = " ".join(x.get_text() for x in figures["loop_timing.png"].texts)
    assert "receive stamps" in caption and "cluster near 0 ms" in caption


def test_bag_of_a_killed_rosbags_writer_is_recovered(tmp_path, capsys):
    """A recorder (rosbags) killed mid-run leaves complete 1 MiB chunks, no
    footer and no metadata.yaml; inspect says to recover, recover salvages the chunks."""
    import shutil

    import numpy as np
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import get_typestore, Stores
    ts = get_typestore(Stores.ROS2_JAZZY)
    t = ts.types
    src = tmp_path / "live"
    w = Writer(src, version=9, storage_plugin=StoragePlugin.MCAP)
    w.open()
    conn = w.add_connection("/x", "std_msgs/msg/Float64MultiArray", typestore=ts)
    layout = t["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
    for k in range(3000):                      # ~2.3 MB: two complete chunks and a partial one
        msg = t["std_msgs/msg/Float64MultiArray"](layout=layout, data=np.full(91, float(k)))
        w.write(conn, 10**18 + k, ts.serialize_cdr(msg, "std_msgs/msg/Float64MultiArray"))
    w.storage.bio.flush()                      # what the OS has when the process dies
    bag = tmp_path / "bag"
    shutil.copytree(src, bag)                  # the files as a kill -9 leaves them
    w.close()
    assert not (bag / "metadata.yaml").exists()
    assert _main(["inspect", str(bag)]) == 2
    assert f"no metadata.yaml (the recorder was killed?); run `rcac inspect --recover {bag}`" \
        in _err_line(capsys)
    report = recover(str(bag))
    n = report.counts["/x"]
    assert report.chunks == 2 and 0 < n < 3000
    data = read_rosbags(report.path)["/x"]
    assert [m.data[0] for _, m in data] == list(range(n))
    assert verify(report.path).counts == {"/x": n}


def test_garbled_record_length_is_one_line(tmp_path, capsys):
    """A damaged length field (an OverflowError traceback before) is one line too."""
    _inspect_fails_then_recover(tmp_path, capsys, 5, _garble_length,      # the 6th chunk
                                "bag_0.mcap", "corrupt")
