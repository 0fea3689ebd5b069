"""``launch/rcac.launch.py`` read as source, without ROS 2's ``launch`` (no PyPI wheel).

Where ``launch`` and ``launch_ros`` are installed (apt), ``test_colcon.py`` also evaluates
the description and runs it. Here the file's syntax tree is checked against what it must
agree with in this package: the arguments it declares and documents, the node names the
parameter files are keyed by, the console scripts it starts, and the ``rcac`` sub-command
of its recorder. Nothing is imported from the launch file.
"""

import ast
import os
import re
import subprocess
import sys

import yaml

from rcac_ros import topics

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LAUNCH = os.path.join(ROOT, "launch", "rcac.launch.py")


def calls(tree, name):
    """Every call of ``name(...)`` in ``tree``, as ``(positional args, {keyword: node})``."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == name:
            out.append((node.args, {k.arg: k.value for k in node.keywords}))
    return out


def literal(node):
    return ast.literal_eval(node)


def configuration(node):
    """The argument name of ``LaunchConfiguration("name")``, else ``None``."""
    if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "LaunchConfiguration":
        return literal(node.args[0])
    return None


def tree():
    with open(LAUNCH, encoding="utf-8") as f:
        return ast.parse(f.read(), LAUNCH)


def declared(t):
    """``{name: default}`` of the DeclareLaunchArgument calls (default as source text)."""
    return {literal(args[0]): ast.unparse(kw["default_value"]) for args, kw in
            calls(t, "DeclareLaunchArgument")}


def test_arguments_are_the_documented_ones_and_each_is_used():
    t = tree()
    args = declared(t)
    assert set(args) == {"controller_params", "simulator_params", "simulator", "record", "bag",
                         "use_sim_time"}
    assert (args["simulator"], args["record"], args["bag"], args["use_sim_time"]) == \
        ("'true'", "'false'", "'rcac_bag'", "'false'")
    # the installed parameter files, by the package's share directory
    assert args["controller_params"] == "os.path.join(config, 'controller.yaml')"
    assert args["simulator_params"] == "os.path.join(config, 'simulator.yaml')"
    used = {configuration(n) for n in ast.walk(t)} - {None}
    assert used == set(args)            # no argument unused, none used undeclared
    doc = ast.get_docstring(t)
    for name in args:                   # the module docstring documents each argument
        assert f"``{name}``" in doc, name
    with open(os.path.join(ROOT, "doc", "install.md"), encoding="utf-8") as f:
        install = f.read()
    section = install[install.index("`launch/rcac.launch.py` takes these arguments"):]
    section = section[:section.index("\n\n", section.index("- `use_sim_time`"))]
    assert set(re.findall(r"`(\w+)`", section)) >= set(args)


def test_nodes_are_the_package_scripts_with_parameter_files_keyed_by_their_names():
    t = tree()
    nodes = {}
    for _, kw in calls(t, "Node"):
        assert ast.unparse(kw["package"]) == "PACKAGE"
        nodes[literal(kw["name"])] = (literal(kw["executable"]), kw)
    assert set(nodes) == {topics.CONTROLLER_NODE, topics.SIMULATOR_NODE}
    assert nodes[topics.CONTROLLER_NODE][0] == "controller"
    assert nodes[topics.SIMULATOR_NODE][0] == "simulator"
    package = [literal(a.value) for a in ast.walk(t) if isinstance(a, ast.Assign)
               and getattr(a.targets[0], "id", None) == "PACKAGE"]
    assert package == ["rcac_ros"]
    # the executables are the package's console scripts (installed to lib/rcac_ros)
    with open(os.path.join(ROOT, "setup.py"), encoding="utf-8") as f:
        scripts = re.findall(r'"(\w+) = rcac_ros\.', f.read())
    assert {"controller", "simulator", "rcac"} <= set(scripts)
    for name, (exe, kw) in nodes.items():
        params = kw["parameters"]
        assert isinstance(params, ast.List)
        assert configuration(params.elts[0]) == f"{exe}_params"
        assert ast.unparse(params.elts[1]) == "sim_time"
        # a parameter file keyed by another node name would be ignored without a word
        with open(os.path.join(ROOT, "config", f"{exe}.yaml"), encoding="utf-8") as f:
            assert list(yaml.safe_load(f)) == [name]
    # only the simulator is optional (simulator:=false drives a real arm)
    sim_condition = nodes[topics.SIMULATOR_NODE][1]["condition"]
    assert configuration(sim_condition.args[0]) == "simulator"
    assert "condition" not in nodes[topics.CONTROLLER_NODE][1]


def test_recorder_is_rcac_record_when_record_is_true():
    t = tree()
    (_, kw), = calls(t, "ExecuteProcess")
    cmd = kw["cmd"].elts
    exe = cmd[0]
    assert getattr(exe.func, "id", None) == "ExecutableInPackage"
    assert literal(exe.args[0]) == "rcac" and ast.unparse(exe.args[1]) == "PACKAGE"
    assert [literal(c) for c in cmd[1:3]] == ["record", "--out"]
    assert configuration(cmd[3]) == "bag"
    assert configuration(kw["condition"].args[0]) == "record"
    # the sub-command exists and takes --out: the rcac script's main, as setup.py names it
    with open(os.path.join(ROOT, "setup.py"), encoding="utf-8") as f:
        module, func = re.search(r'"rcac = ([\w.]+):(\w+)"', f.read()).groups()
    code = f"import {module} as m; m.{func}(['record', '--help'])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert "--out" in out.stdout
