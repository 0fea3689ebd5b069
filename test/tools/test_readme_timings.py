"""The README's timings block is the generated one (its form, not its numbers)."""

import os

import pytest

from rcac_ros.tools import readme_timings as rt

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FIELDS = dict(where="this checkout", date="2031-01-02", cores=8, python="3.12.1", demo_min=0.52,
              demo_parts="the venv as it was, 20 s simulated in 24 s, plots", test_min=12.04,
              tests="240 passed, 3 skipped, 1 xfailed")


def readme():
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
        return f.read()


def test_the_readme_holds_one_well_formed_timings_block():
    fields = rt.read_block(readme())
    assert fields["where"] in ("a clean clone", "this checkout")
    assert fields["demo_min"] > 0 and fields["test_min"] > 0
    # the block reads back to itself: it is exactly what the tool writes
    text = readme()
    block = text[text.index(rt.BEGIN):text.index(rt.END) + len(rt.END)]
    assert rt.render(fields) == block


def test_the_block_is_replaced_and_the_rest_kept():
    text = f"# title\n\nbefore\n\n{rt.render(FIELDS)}\n\nafter {rt.END[:4]}\n"
    new = rt.replace_block(text, dict(FIELDS, demo_min=2.0))
    assert rt.read_block(new)["demo_min"] == 2.0
    assert new.startswith("# title\n\nbefore\n\n") and new.endswith("\n\nafter <!--\n")
    assert all(len(line) <= 99 for line in new.splitlines())


@pytest.mark.parametrize("broken", [
    lambda b: b.replace(rt.END, ""),                                   # no end marker
    lambda b: b + "\n" + b,                                            # two blocks
    lambda b: b.replace("`make test`", "make test"),                   # edited by hand
    lambda b: rt.END + "\n" + b.replace(rt.END, ""),                   # end before start
])
def test_a_malformed_block_is_refused(broken):
    with pytest.raises(rt.BlockError):
        rt.read_block(broken(rt.render(FIELDS)))


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
