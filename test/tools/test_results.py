"""doc/results.md and the README's results lines are what the generator makes of the JSON."""

import json
import os
import shutil
import subprocess
import sys

import pytest

from rcac_ros.tools.results import page
from rcac_ros.tools.results.sources import SOURCES

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_the_committed_page_and_readme_block_are_the_generated_ones():
    assert page.render(check=True) == [], "run `make results` and commit doc/results.md, README.md"


def test_every_source_has_its_json_with_command_date_machine_and_revision():
    for name in SOURCES:
        record = page.read_source(name)["record"]
        assert all(record[k] for k in ("command", "date", "machine", "revision")), name


def copy_sources(tmp_path):
    results = tmp_path / "results"
    shutil.copytree(page.RESULTS_DIR, results)
    readme = tmp_path / "README.md"
    shutil.copy(page.README, readme)
    return str(results), str(readme)


def test_a_changed_figure_makes_the_committed_page_stale(tmp_path):
    results, readme = copy_sources(tmp_path)
    path = os.path.join(results, "experiment.json")
    with open(path, encoding="utf-8") as f:
        doc = json.load(f)
    doc["data"]["composite"]["rms_tracking_error"] *= 1.5
    page.write_source("experiment", doc["data"], doc["record"], results)
    stale = page.render(check=True, results_dir=results, page=page.PAGE, readme=readme)
    assert sorted(stale) == sorted([page.PAGE, readme])      # the table and the headline


def test_a_missing_source_or_a_malformed_block_is_refused(tmp_path):
    results, readme = copy_sources(tmp_path)
    os.remove(os.path.join(results, "payload.json"))
    with pytest.raises(page.SourceError, match="payload.json"):
        page.render_page(results)
    with pytest.raises(page.SourceError):
        page.replace_block("no markers here", "block")
    with pytest.raises(page.SourceError):
        page.replace_block(f"{page.END}\n{page.BEGIN}\n", "block")


def test_a_stored_source_reads_back_equal_with_its_number_lists_on_one_line(tmp_path):
    data = {"a": [1.5, -2e-07, 3], "b": {"c": [[1, 2], [3.25, 4]]}, "d": "x [1, 2]"}
    record = dict(command="c", date="d", machine="m", revision="r")
    page.write_source("experiment", data, record, str(tmp_path))
    with open(os.path.join(tmp_path, "experiment.json"), encoding="utf-8") as f:
        text = f.read()
    assert json.loads(text) == {"record": record, "data": data}
    assert '"a": [1.5, -2e-07, 3]' in text
    with pytest.raises(page.SourceError, match="unknown source"):
        page.write_source("nope", data, record, str(tmp_path))


def test_the_readme_has_at_most_six_headline_lines():
    with open(page.README, encoding="utf-8") as f:
        text = f.read()
    block = text[text.index(page.BEGIN):text.index(page.END)]
    assert 1 <= len(block.splitlines()) - 1 <= 6


def test_rendering_loads_neither_numba_nor_rclpy():
    """`make results` runs with any Python that has the package on its path: rendering reads
    JSON only (the modules a source's renderer imports included)."""
    code = ("import sys; from rcac_ros.tools.results import page; page.render_page(); "
            "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert not {"numba", "rclpy"} & set(out.stdout.split())


def test_every_figure_in_doc_figures_is_a_recorded_source_plot():
    """doc/figures holds the plots that `record` kept from a source's run and nothing copied
    by hand: each file is named by its source's record, and each named file is there."""
    named = set()
    for name in SOURCES:
        for figure in page.read_source(name)["record"].get("figures", []):
            assert os.path.isfile(os.path.join(ROOT, "doc", figure)), (name, figure)
            named.add(os.path.normpath(figure))
    present = {os.path.join("figures", f) for f in os.listdir(page.FIGURES_DIR)} \
        if os.path.isdir(page.FIGURES_DIR) else set()
    assert present <= named, sorted(present - named)


def test_a_run_keeps_its_plots_under_the_source_name_and_drops_the_older_ones(tmp_path):
    run, figures = tmp_path / "run", tmp_path / "doc" / "figures"
    run.mkdir()
    figures.mkdir(parents=True)
    for f in ("compare_paper.png", "compare_payload.png", "other.txt"):
        (run / f).write_bytes(f.encode())
    (figures / "compare_compare_old.png").write_bytes(b"old")
    # another source's, whose name starts like this one's
    (figures / "compare_joints_compare_x.png").write_bytes(b"another source's")
    kept = page.keep_figures("compare", SOURCES["compare"], str(run),
                             ["figures/compare_compare_old.png"], str(figures))
    assert kept == ["figures/compare_compare_paper.png", "figures/compare_compare_payload.png"]
    assert sorted(os.listdir(figures)) == ["compare_compare_paper.png",
                                           "compare_compare_payload.png",
                                           "compare_joints_compare_x.png"]
    assert (figures / "compare_compare_paper.png").read_bytes() == b"compare_paper.png"
    # and the page shows them under the block
    results, _ = copy_sources(tmp_path)
    doc = page.read_source("compare", results)
    doc["record"]["figures"] = kept
    page.write_source("compare", doc["data"], doc["record"], results)
    assert "](figures/compare_compare_paper.png)" in page.render_page(results)
