"""doc/ is a reference of bounded size that still names every command, option, topic and
service: the size bound and the completeness checks together keep a shorter text whole."""

import argparse
import glob
import os
import re

from rcac_ros import topics
from rcac_ros.tools import cli
from rcac_ros.tools.sweep.commands import ACTIONS

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DOCS = sorted(glob.glob(os.path.join(ROOT, "doc", "*.md")))


def read(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


def options(parser, words):
    """``(command, --option)`` of ``parser`` and its subparsers (help not suppressed)."""
    out = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out |= options(sub, words + [name])
        elif action.help != argparse.SUPPRESS:
            out.update((" ".join(words), o) for o in action.option_strings
                       if o.startswith("--") and o != "--help")
    return out


def every_option():
    forms = [[name] for name in cli.SUBCOMMANDS] + [["sweep", a] for a in ACTIONS]
    found = set()
    for form in forms:
        sub = next(a for a in cli.build_parser(form)._actions
                   if isinstance(a, argparse._SubParsersAction))
        found |= options(sub.choices[form[0]], ["rcac"] + form)
    return found


def test_doc_stays_under_150_kb():
    """The reference, generated pages included, in at most 150 KB of Markdown."""
    size = sum(os.path.getsize(p) for p in DOCS)
    assert size <= 150 * 1000, f"doc/*.md is {size / 1000:.1f} KB"


def test_every_subcommand_and_option_is_documented():
    docs = "".join(read(p) for p in DOCS)
    found = every_option()
    assert len(found) > 100            # the parser was walked, not an empty set
    missing = sorted(f"{command} {option}" for command, option in found
                     if option not in docs)
    missing += [f"rcac {name}" for name in cli.SUBCOMMANDS if f"rcac {name}" not in docs]
    assert not missing, "undocumented: " + ", ".join(missing)


def test_every_topic_and_service_is_in_the_nodes_page():
    nodes = read(os.path.join(ROOT, "doc", "nodes.md"))
    names = {v for k, v in vars(topics).items() if k.isupper() and isinstance(v, str)
             and not k.endswith("_NODE")}
    for path in glob.glob(os.path.join(ROOT, "rcac_ros", "nodes", "**", "*.py"),
                          recursive=True):
        names.update(re.findall(r'"(~/[a-z_]+)"', read(path)))
    assert {"~/set_adaptation", "~/follow_joint_trajectory", "joint_states"} <= names
    missing = sorted(n for n in names if n not in nodes)
    assert not missing, "not in doc/nodes.md: " + ", ".join(missing)
