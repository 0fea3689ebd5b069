"""The timings of make demo and make test: pytest's counts, the timing of a target, the source."""

import os
import sys

from rcac_ros.tools.results import timings as rt
from rcac_ros.tools.results.blocks import render_timings

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FIELDS = dict(where="this checkout", date="2031-01-02", cores=8, python="3.12.1", demo_min=0.52,
              demo_parts="the venv as it was, 20 s simulated in 24 s, plots", test_min=12.04,
              tests="240 passed, 3 skipped, 1 xfailed")


def test_the_committed_source_renders_the_sentence_of_the_template():
    from rcac_ros.tools.results.page import read_source
    fields = read_source("timings")["data"]
    assert fields["where"] in ("a clean clone", "this checkout")
    assert fields["demo_min"] > 0 and fields["test_min"] > 0
    assert render_timings(fields).endswith(f"({fields['tests']}).")
    assert render_timings(FIELDS) == (
        "On this checkout: `make demo` 0.5 min "
        "(the venv as it was, 20 s simulated in 24 s, plots), `make test` 12.0 min (240 passed, "
        "3 skipped, 1 xfailed).")


def test_pytest_counts_come_from_the_last_summary_line():
    out = ("..... [100%]\n=== 3 passed in 1.00s ===\nmore\n"
           "==== 212 passed, 3 skipped, 2 warnings in 231.52s (0:03:51) ====\n")
    assert rt.pytest_counts(out) == "212 passed, 3 skipped"
    assert rt.pytest_counts("212 passed in 3.1s") == "212 passed"
    assert rt.pytest_counts("no summary") is None


def test_a_target_is_timed_to_its_own_exit_not_to_its_leftovers(tmp_path, capsys):
    """A process the target leaves running (here a 5 s sleep) does not hold the timing open."""
    seconds, output, code = rt.timed(["sh", "-c", "echo one; (sleep 5 &); echo twö; exit 3"],
                                     str(tmp_path), dict(os.environ))
    assert (output.splitlines(), code) == (["one", "twö"], 3)
    assert seconds < 5.0
    assert "] twö" in capsys.readouterr().out      # echoed as it ran


def test_output_written_while_it_is_being_read_is_all_kept(tmp_path, capsys):
    """The target's writes and the echoing reads overlap all the time; no line is lost."""
    script = "import sys\nfor i in range(20000):\n    print(i, flush=True)\n"
    seconds, output, code = rt.timed([sys.executable, "-c", script], str(tmp_path),
                                     dict(os.environ), poll=1e-4)
    assert code == 0
    assert output.splitlines() == [str(i) for i in range(20000)]
