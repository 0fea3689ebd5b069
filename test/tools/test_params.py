"""The parameter table: the shipped parameter files, the generated doc, the checks."""

import os

import pytest
import yaml

from rcac_ros import params, params_doc
from rcac_ros.nodes.runtime import paramcheck
from rcac_ros.errors import ConfigError

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SECTIONS = {"controller": "rcac_controller", "simulator": "rcac_simulator"}


def shipped(node):
    with open(os.path.join(ROOT, "config", f"{node}.yaml"), encoding="utf-8") as f:
        return yaml.safe_load(f)[SECTIONS[node]]["ros__parameters"]


@pytest.mark.parametrize("node", sorted(SECTIONS))
def test_shipped_parameter_files_pass_the_check(node):
    paramcheck.check_file_params(node, shipped(node))


@pytest.mark.parametrize("node", sorted(SECTIONS))
def test_shipped_parameter_files_restate_the_defaults(node):
    """What a file sets and the table defaults agree (the files reproduce the paper)."""
    flat = dict(params.flatten(shipped(node)))
    for name, value in flat.items():
        row = params.row(node, name)
        if row.default is not None:
            assert params.check(row, value) == row.default, name   # arrays: tuples


@pytest.mark.parametrize("node, name, value, words", [
    ("controller", "K_D", 10000, "wrong type"),             # YAML integer for a double
    ("controller", "K_DD", 1.0, "no such parameter"),
    ("controller", "mode", "fast", "'lockstep' or 'timer'"),
    ("controller", "lambda", 0.0, "must be > 0"),
    ("controller", "gamma", -1.0, "out of range"),
    ("controller", "state_timeout", float("nan"), "finite"),
    ("controller", "effort_limit", [1.0, -1.0], "every value must be > 0"),
    ("simulator", "gravity", [0.0, 9.81], "expected 3 values"),
    ("simulator", "substeps", 0, "out of range"),
    ("simulator", "q0", [0.0, float("inf")], "NaN or Inf"),
])
def test_a_bad_entry_is_refused_naming_it(node, name, value, words):
    section = dict(shipped(node))
    section[name] = value
    with pytest.raises(ConfigError) as err:
        paramcheck.check_file_params(node, section)
    assert str(err.value).startswith(name + ":"), str(err.value)
    assert words in str(err.value)


def test_nested_names_are_checked():
    section = dict(shipped("controller"))
    section["paper"] = dict(section["paper"], period=0.0)
    with pytest.raises(ConfigError, match=r"^paper\.period: must be > 0"):
        paramcheck.check_file_params("controller", section)


def test_every_default_passes_its_own_check():
    for node, rows in params.TABLE.items():
        names = [p.name for p in rows]
        assert len(names) == len(set(names)), node
        for p in rows:
            assert p.type in params.TYPES
            assert params.check(p, p.default) == p.default, (node, p.name)


def test_per_joint_broadcasts_one_value_and_refuses_a_wrong_count():
    assert params.per_joint("q0", [0.5], 3, None).tolist() == [0.5, 0.5, 0.5]
    assert params.per_joint("q0", None, 2, 0.0).tolist() == [0.0, 0.0]
    assert params.per_joint("q0", None, 2, None) is None
    with pytest.raises(ConfigError, match=r"^q0: expected 1 or 3 values"):
        params.per_joint("q0", [0.0, 1.0], 3, None)


def test_doc_table_is_the_generated_one():
    with open(os.path.join(ROOT, "doc", "parameters.md"), encoding="utf-8") as f:
        assert f.read() == params_doc.document(), \
            "doc/parameters.md is stale: python -m rcac_ros.params_doc > doc/parameters.md"


@pytest.mark.parametrize("name, valid", [
    ("~", True), ("~/robot_description", True), ("/robot_description", True),
    ("robot_description", True), ("_private/x", True), ("{node}/robot_description", True),
    ("~/{node}", True), ("/{namespace}/x_1", True), ("a!", False), ("1abc", False),
    ("/a//b", False), ("/a/", False), ("bad topic", False), ("{other}/x", False),
])
def test_a_topic_name_is_checked_as_ros_names_it(name, valid):
    """``description_topic``: ROS 2's topic names, private ones and substitutions included."""
    row = next(p for p in params.CONTROLLER if p.name == "description_topic")
    if valid:
        assert params.check(row, name) == name
    else:
        with pytest.raises(ConfigError, match="is not a valid topic name"):
            params.check(row, name)
