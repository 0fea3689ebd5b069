"""Every number on the ``rcac`` command line is checked by the parser: one line, exit code 2."""

import argparse
import os
import subprocess
import sys

import pytest

from rcac_ros.tools import args as checked
from rcac_ros.tools import cli

#: (subcommand, the arguments it needs besides the option, numeric option, a valid value)
NUMERIC_OPTIONS = [
    ("experiment", [], "--duration", "20"),
    ("experiment", [], "--K_D", "1e4"),
    ("experiment", [], "--Lambda", "1"),
    ("experiment", [], "--P", "100"),
    ("experiment", [], "--lam", "10"),
    ("experiment", [], "--h", "0.002"),
    ("experiment", [], "--substeps", "2"),
    ("bench", ["ros"], "--duration", "60"),
    ("bench", ["faults"], "--duration", "60"),
    ("bench", ["noise"], "--duration", "600"),
    ("bench", ["core"], "--budget", "0.3"),
    ("bench", ["ros"], "--K_D", "1e4"),
    ("bench", ["faults"], "--K_D", "1e4"),
    ("bench", ["soak", "5"], "--K_D", "1e4"),
    ("demo", [], "--duration", "20"),
    ("record", [], "--duration", "5"),
    ("inspect", ["some_bag"], "--link", "7"),
    ("payload-demo", [], "--duration", "20"),
    ("payload-demo", [], "--kappa", "100"),
    ("payload-demo", [], "--Lambda", "10"),
    ("payload-demo", [], "--rho", "30"),
    ("payload-demo", [], "--lam", "10"),
    ("payload-demo", [], "--h", "0.002"),
]
#: options where 0 is allowed and a negative number is not
NON_NEGATIVE_OPTIONS = [
    ("experiment", [], "--gamma"),
    ("bench", ["ros"], "--lookahead"),
    ("bench", ["faults"], "--phase-offset"),
    ("payload-demo", [], "--gamma"),
    ("payload-demo", [], "--jump"),
    ("payload-demo", [], "--payload-mass"),
]
INTEGER_OPTIONS = {("experiment", "--substeps"), ("inspect", "--link")}


@pytest.fixture(autouse=True)
def in_tmp(tmp_path, monkeypatch):
    """The defaults of the paths a command writes are checked against the working directory:
    a fresh one, not the checkout."""
    monkeypatch.chdir(tmp_path)


def parse_error(capsys, monkeypatch, argv):
    """Run ``rcac ARGV`` in this process; return (exit code, stderr lines)."""
    monkeypatch.setattr(sys, "argv", ["rcac"])
    with pytest.raises(SystemExit) as stop:
        cli.main(argv)
    return stop.value.code, capsys.readouterr().err.splitlines()


def assert_one_line(code, lines, command, option):
    assert code == 2
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"rcac {command}: error: argument {option}"), lines


def named(command, extra):
    """How the parser names the command: ``bench ros`` for a benchmark, else ``command``."""
    return f"{command} {extra[0]}" if command == "bench" else command


@pytest.mark.parametrize("command,extra,option,good", NUMERIC_OPTIONS)
@pytest.mark.parametrize("bad", ["0", "-5", "nan", "inf", "abc"])
def test_a_non_positive_or_non_numeric_value_stops_at_the_parser(
        capsys, monkeypatch, command, extra, option, good, bad):
    code, lines = parse_error(capsys, monkeypatch, [command, *extra, option, bad])
    assert_one_line(code, lines, named(command, extra), option)


@pytest.mark.parametrize("command,extra,option", NON_NEGATIVE_OPTIONS)
@pytest.mark.parametrize("bad", ["-1", "-1e-9", "nan", "-inf", "x"])
def test_a_negative_value_stops_at_the_parser(capsys, monkeypatch, command, extra, option, bad):
    code, lines = parse_error(capsys, monkeypatch, [command, *extra, option, bad])
    assert_one_line(code, lines, named(command, extra), option)


@pytest.mark.parametrize("command,option", sorted(INTEGER_OPTIONS))
def test_an_integer_option_rejects_a_fraction(capsys, monkeypatch, command, option):
    extra = ["some_bag"] if command == "inspect" else []
    code, lines = parse_error(capsys, monkeypatch, [command, *extra, option, "1.5"])
    assert_one_line(code, lines, command, option)
    assert "expected an integer" in lines[0]


def test_the_payload_centre_of_mass_must_be_finite(capsys, monkeypatch):
    code, lines = parse_error(capsys, monkeypatch,
                              ["payload-demo", "--payload-com", "0", "nan", "0"])
    assert_one_line(code, lines, "payload-demo", "--payload-com")


def subparsers(parser):
    """The parsers below ``parser`` (its subcommands, theirs, ...), and itself."""
    found = [parser]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found += subparsers(sub)
    return found


def subcommand_parsers(command):
    """Every parser of one subcommand (its benchmarks, its forms), built as ``rcac`` does."""
    forms = {"sweep": [["CAMPAIGN"], ["report"], ["rerun"]]}.get(command, [[]])
    return [p for words in forms for p in subparsers(cli.build_parser([command, *words]))
            if p.prog.startswith(f"rcac {command}")]


@pytest.mark.parametrize("command,extra,option,good", NUMERIC_OPTIONS)
def test_valid_values_are_accepted(command, extra, option, good):
    args = cli.build_parser([command]).parse_args([command, *extra, option, good])
    value = getattr(args, option.lstrip("-").replace("-", "_"))
    assert value == float(good)
    assert isinstance(value, int if (command, option) in INTEGER_OPTIONS else float)


@pytest.mark.parametrize("command", sorted(cli.SUBCOMMANDS))
def test_every_numeric_option_of_every_subcommand_is_checked(command):
    """No option is parsed with a bare ``float`` or ``int``; each default passes its own check."""
    parsers = subcommand_parsers(command)
    assert parsers
    actions = [a for p in parsers for a in p._actions]
    for action in actions:
        assert action.type not in (float, int), f"rcac {command} {action.option_strings}"
        if action.type is not None and action.default not in (None, argparse.SUPPRESS):
            defaults = (action.default if isinstance(action.default, (list, tuple))
                        else [action.default])
            for value in defaults:
                # raises if a default breaks its own rule
                action.type(value if isinstance(value, str) else repr(value))


@pytest.mark.parametrize("text", ["1e-300", "0.002", "3", "1e12"])
def test_positive_float_takes_every_finite_positive_number(text):
    assert checked.positive_float(text) == float(text)


def test_zero_is_non_negative_but_not_positive():
    assert checked.non_negative_float("0") == 0.0
    assert checked.non_negative_int("0") == 0
    for fn in (checked.positive_float, checked.positive_int):
        with pytest.raises(argparse.ArgumentTypeError, match="> 0|>= 1"):
            fn("0")


@pytest.mark.parametrize("text", ["1e400", "-1e400", "nan", "NaN"])
def test_overflow_and_nan_are_not_finite(text):
    with pytest.raises(argparse.ArgumentTypeError, match="finite"):
        checked.finite_float(text)


def test_the_payload_must_attach_before_the_end(tmp_path, capsys, monkeypatch):
    """A relation between two options is checked in ``run``: one line naming both."""
    monkeypatch.setattr(sys, "argv", ["rcac"])
    assert cli.main(["payload-demo", "--duration", "3", "--out", str(tmp_path), "--quiet"]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and "--jump" in lines[0] and "--duration 3" in lines[0], lines


@pytest.mark.parametrize("argv", [["experiment", "--duration", "-5"],
                                  ["experiment", "--duration", "0"],
                                  ["payload-demo", "--duration", "-1"]])
def test_the_cases_a_new_user_hit(argv):
    """As typed in a shell: no traceback, one line naming --duration, exit 2."""
    out = subprocess.run([sys.executable, "-m", "rcac_ros.tools.cli", *argv],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.splitlines() == [
        f"rcac {argv[0]}: error: argument --duration: must be > 0, got '{argv[2]}'"]
    assert out.stdout == ""


#: (words before the option, option): every path the commands write, with what the parser
#: needs besides it
OUTPUT_OPTIONS = [
    (["experiment"], "--out"), (["demo"], "--out"), (["capture-demo"], "--out"),
    (["payload-demo"], "--out"), (["friction-demo"], "--out"), (["friction-ros"], "--out"),
    (["compare"], "--out"), (["record"], "--out"), (["sweep", "c.yaml"], "--out"),
    (["sweep", "report", "r"], "--json"), (["sweep", "report", "r"], "--plot"),
    (["sweep", "rerun", "r", "3"], "--plot"), (["bench", "core"], "--json"),
    (["bench", "ros"], "--json"), (["bench", "faults"], "--json"),
    (["bench", "faults"], "--plot"), (["bench", "soak", "5"], "--json"),
    (["bench", "soak", "5"], "--plot"), (["bench", "delay-margin"], "--json"),
    (["bench", "delay-margin"], "--plot"), (["bench", "noise"], "--out"),
    (["bench", "startup"], "--json"), (["inspect", "bag"], "--plots"),
    (["inspect", "bag"], "--recover-out"),
]
WRITES = ("--out", "--json", "--plot", "--plots", "--recover-out")


@pytest.mark.parametrize("command", sorted(cli.SUBCOMMANDS))
def test_every_path_a_command_writes_is_checked_by_the_parser(command):
    """Each ``--out``, ``--json``, ``--plot`` of every form is an ``output_dir`` or
    ``output_file``, and is in :data:`OUTPUT_OPTIONS` (the test below)."""
    listed = {(words[0], words[1] if words[0] == "bench" else None, option)
              for words, option in OUTPUT_OPTIONS}
    for parser in subcommand_parsers(command):
        for action in parser._actions:
            for option in set(action.option_strings) & set(WRITES):
                assert action.type in (checked.output_dir, checked.output_file), \
                    f"{parser.prog} {option}"
                bench = parser.prog.split()[2] if command == "bench" else None
                assert (command, bench, option) in listed, f"{parser.prog} {option}"


@pytest.mark.parametrize("words,option", OUTPUT_OPTIONS,
                         ids=[" ".join(w + [o]) for w, o in OUTPUT_OPTIONS])
def test_a_path_that_cannot_be_written_stops_at_the_parser(capsys, monkeypatch, tmp_path,
                                                           words, option):
    (tmp_path / "afile").write_text("")
    code, lines = parse_error(capsys, monkeypatch,
                              [*words, option, str(tmp_path / "afile" / "x")])
    name = " ".join(words[:2]) if words[0] == "bench" or words[1:2] in (["report"], ["rerun"]) \
        else words[0]
    assert_one_line(code, lines, name, option)
    assert f"not a directory: '{tmp_path / 'afile'}'" in lines[0]


def test_output_dir_and_output_file_refuse_what_they_cannot_write(tmp_path):
    (tmp_path / "afile").write_text("")
    for check in (checked.output_dir, checked.output_file):
        with pytest.raises(argparse.ArgumentTypeError, match="an empty path"):
            check("")
    (tmp_path / "ro").write_text("")
    os.chmod(tmp_path / "ro", 0o444)
    if not os.access(tmp_path / "ro", os.W_OK):     # (root may write a read-only file)
        with pytest.raises(argparse.ArgumentTypeError, match="not writable"):
            checked.output_file(str(tmp_path / "ro"))
    with pytest.raises(argparse.ArgumentTypeError, match="exists and is not a directory"):
        checked.output_dir(str(tmp_path / "afile"))
    with pytest.raises(argparse.ArgumentTypeError, match="a directory"):
        checked.output_file(str(tmp_path))
    if os.path.isdir("/proc/self"):     # Linux: no entry can be made in /proc, even by root
        with pytest.raises(argparse.ArgumentTypeError, match="cannot write in '/proc'"):
            checked.output_dir("/proc/rcac/out")
        with pytest.raises(argparse.ArgumentTypeError, match="cannot write in '/proc'"):
            checked.output_file("/proc/rcac.json")


def test_a_writable_path_is_returned_and_nothing_is_left_behind(tmp_path):
    out = str(tmp_path / "new" / "dir")
    assert checked.output_dir(out) == out
    assert checked.output_file(str(tmp_path / "r.json")) == str(tmp_path / "r.json")
    assert checked.output_dir(str(tmp_path)) == str(tmp_path)
    assert os.listdir(tmp_path) == []
    assert checked.output_file(os.devnull) == os.devnull      # an existing writable file


def test_the_directory_of_a_file_to_write_is_made_before_the_command_runs(tmp_path):
    """``--json new/dir/x.json``: the directory is made by ``rcac``, not left to the writer
    at the end of the run."""
    path = tmp_path / "new" / "dir" / "margins.json"
    args = cli.build_parser(["bench", "delay-margin"]).parse_args(
        ["bench", "delay-margin", "--check", "--json", str(path)])
    cli.make_output_dirs(args)
    assert (tmp_path / "new" / "dir").is_dir() and not path.exists()


def test_a_run_whose_history_cannot_fit_in_memory_is_refused_before_it_starts():
    from rcac_ros.errors import ConfigError
    from rcac_ros.tools.runs.closed_loop import available_memory, check_history
    check_history(10, 8, available=80)              # exactly fits
    free = available_memory()
    assert free is None or free > 0
    with pytest.raises(ConfigError, match="duration: 11 steps keep .* GiB of history"):
        check_history(11, 8, available=80)


def test_a_control_period_longer_than_the_run_is_refused(capsys, monkeypatch, tmp_path):
    monkeypatch.setattr(sys, "argv", ["rcac"])
    code = cli.main(["experiment", "--h", "5", "--duration", "0.01", "--quiet",
                     "--out", str(tmp_path)])
    lines = capsys.readouterr().err.splitlines()
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith("rcac experiment: error: --h: the control period (5 s)"), lines
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("bad", ["", "bad name!", "1arm", "arm//ctrl", "arm/", "a-b"])
def test_a_node_name_ros_would_refuse_stops_at_the_parser(capsys, monkeypatch, bad):
    code, lines = parse_error(capsys, monkeypatch, ["record", "--controller-node", bad])
    assert_one_line(code, lines, "record", "--controller-node")
    assert "not a ROS node name" in lines[0]


@pytest.mark.parametrize("good,name", [("rcac_controller", "rcac_controller"),
                                       ("arm/rcac_controller", "arm/rcac_controller"),
                                       ("/arm/_c2", "arm/_c2")])
def test_a_node_name_with_its_namespace_is_accepted(good, name):
    assert checked.node_name(good) == name
