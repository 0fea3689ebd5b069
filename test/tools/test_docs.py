"""The documentation's references resolve: design-note citations, links, no outside notes."""

import os
import re
import subprocess

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CITATION = re.compile(r"doc/design\.md §(\d+)(?:-(\d+))?")
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


def tracked(*suffixes):
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    if out.returncode != 0:            # not a git checkout (an sdist): walk the tree
        return sorted(os.path.relpath(os.path.join(d, f), ROOT)
                      for d, _, files in os.walk(ROOT) if "/." not in d
                      for f in files if f.endswith(suffixes))
    return [p for p in out.stdout.split() if p.endswith(suffixes)]


def read(path):
    with open(os.path.join(ROOT, path), encoding="utf-8") as f:
        return f.read()


def test_every_design_citation_names_a_section_of_doc_design():
    sections = set(re.findall(r"^## §(\d+) ", read("doc/design.md"), re.MULTILINE))
    cited = 0
    for path in tracked(".py", ".yaml", ".md", ".xml"):
        for first, last in CITATION.findall(read(path)):
            for n in range(int(first), int(last or first) + 1):
                assert str(n) in sections, f"{path}: doc/design.md §{n} does not exist"
            cited += 1
    assert cited >= 15


def test_no_reference_to_notes_outside_the_repository():
    me = os.path.relpath(os.path.abspath(__file__), ROOT)
    for path in tracked(".py", ".yaml", ".md", ".xml", ".cfg", ".txt"):
        if path != me:
            text = read(path)
            assert "NOTES.md" not in text and "ROS_NOTES" not in text, path


def test_every_relative_link_of_the_docs_resolves():
    for path in tracked(".md"):
        for target in LINK.findall(read(path)):
            if "://" not in target and not target.startswith("mailto:"):
                where = os.path.normpath(os.path.join(ROOT, os.path.dirname(path), target))
                assert os.path.exists(where), f"{path}: broken link {target}"


#: words about how the package was made, not about what it does; an upstream project's
#: ``owner/repo#n`` is a citation and does not match
PROCESS_WORDS = re.compile(
    r"\bstops? \d+|\bissues? \d+|\bthis release\b|(?<![.\w])today\b(?!\()|\(no time\)|"
    r"\b(?:other|this|that|these) sessions?\b|\bthrowaway\b|\bsince stop\b",
    re.IGNORECASE)
PRODUCT = ("README.md", "doc/", "rcac_ros/", "test/", "config/", "launch/")


def test_no_words_about_how_the_package_was_made():
    me = os.path.relpath(os.path.abspath(__file__), ROOT)
    found = []
    for path in tracked(".py", ".md", ".yaml", ".xml", ".cfg", ".txt", ".json"):
        if path != me and path.startswith(PRODUCT):
            for n, line in enumerate(read(path).splitlines(), 1):
                found += [f"{path}:{n}: {m.group(0)!r}" for m in PROCESS_WORDS.finditer(line)]
    assert not found, "\n".join(found)


@pytest.mark.parametrize("text", ["since stop 28", "Stop 27 measured", "goal of issue 17",
                                  "measured today", "in this release", "(no time)",
                                  "while other sessions ran", "a throwaway script"])
def test_the_process_words_are_caught(text):
    assert PROCESS_WORDS.search(text)


@pytest.mark.parametrize("text", ["eProsima/Fast-DDS#6535", "datetime.date.today()",
                                  "each in its own session", "Stop the nodes, then restart"])
def test_citations_and_code_are_not_process_words(text):
    assert not PROCESS_WORDS.search(text)


def slug(heading):
    """GitHub's anchor of a markdown heading: lower case, punctuation dropped, '-' for ' '."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_every_anchor_of_a_relative_link_names_a_heading():
    anchors = {}
    for path in tracked(".md"):
        text = re.sub(r"```.*?```", "", read(path), flags=re.DOTALL)
        anchors[path] = {slug(h) for h in re.findall(r"^#+ (.*)$", text, re.MULTILINE)}
    checked = 0
    for path in anchors:
        for target, anchor in re.findall(r"\]\(([^)#\s]*)#([^)\s]+)\)", read(path)):
            where = os.path.normpath(os.path.join(os.path.dirname(path), target)) if target \
                else path
            if where in anchors:
                assert anchor in anchors[where], f"{path}: no heading for {target}#{anchor}"
                checked += 1
    assert checked >= 20


def test_the_readme_is_a_first_screen_not_a_report():
    """README.md stays short (12 KB): results go to doc/results.md, reference to doc/."""
    assert len(read("README.md").encode("utf-8")) <= 12 * 1024
