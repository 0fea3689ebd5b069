"""The package's layout: imports run one way (tools -> nodes -> plants -> core), with no cycle.

The graph is read from the source (every ``import``, module level or inside a function);
the heavy-dependency checks import the modules in a fresh interpreter.
"""

import ast
import collections
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PACKAGE = os.path.join(ROOT, "rcac_ros")

#: rank of each part of the package: a module may import its own rank or a lower one
RANKS = {"errors": 0, "topics": 0, "core": 1, "params": 2, "params_doc": 2, "plants": 2,
         "nodes": 3, "tools": 4}


def modules():
    """``{dotted name: path}`` of every module of the package."""
    out = {}
    for folder, _, files in os.walk(PACKAGE):
        for name in files:
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                rel = os.path.relpath(path, ROOT)[:-3].replace(os.sep, ".")
                out[rel[:-len(".__init__")] if rel.endswith(".__init__") else rel] = path
    return out


def imports(name, path):
    """The modules ``name`` imports (absolute dotted names), anywhere in its source."""
    tree = ast.parse(open(path, encoding="utf-8").read(), path)
    package = name if path.endswith("__init__.py") else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[:len(parts) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def graph():
    """Edges between the package's own modules: ``{module: {imported module, ...}}``."""
    mods = modules()
    return {name: {m for m in imports(name, path) if m in mods and m != name}
            for name, path in mods.items()}


def part(module):
    """``core``, ``nodes``, ``tools``, ``errors``, ... (None for the package itself)."""
    pieces = module.split(".")
    return pieces[1] if len(pieces) > 1 else None


def test_nothing_imports_upward():
    upward = []
    for mod, targets in graph().items():
        if part(mod) is None:
            continue
        for target in targets:
            if part(target) is not None and RANKS[part(target)] > RANKS[part(mod)]:
                upward.append(f"{mod} -> {target}")
    assert not upward, "upward imports:\n" + "\n".join(sorted(upward))


def test_every_part_has_a_rank():
    assert {part(m) for m in modules() if part(m)} <= set(RANKS)


def test_no_import_cycle():
    edges = graph()
    state = collections.defaultdict(int)    # 0 new, 1 on the stack, 2 done
    cycles = []

    def visit(node, stack):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(edges[node]):
            if state[nxt] == 1:
                cycles.append(" -> ".join(stack[stack.index(nxt):] + [nxt]))
            elif state[nxt] == 0:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for node in sorted(edges):
        if state[node] == 0:
            visit(node, [])
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def module_level_imports(name):
    """The package modules ``name`` imports at module level (not inside a function)."""
    path = modules()[name]
    tree = ast.parse(open(path, encoding="utf-8").read(), path)
    top = ast.Module(body=[n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))],
                     type_ignores=[])
    found = set()
    for node in ast.walk(top):
        if isinstance(node, ast.ImportFrom):
            found.add(node.module)
            found.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
    return found


def test_tools_that_must_stay_apart():
    """bench core never imports bench ros (rclpy); bench ros does not need the demo."""
    assert "rcac_ros.tools.bench.ros" not in module_level_imports("rcac_ros.tools.bench.core")
    assert "rcac_ros.tools.demos.demo" not in graph()["rcac_ros.tools.bench.ros"]
    # the child processes and the ROS context live in launch, below demo and record
    for mod in ("rcac_ros.tools.bench.ros", "rcac_ros.tools.bags.record"):
        assert "rcac_ros.tools.demos.demo" not in graph()[mod]


def group(module):
    """``nodes.controller``, ``tools.bags``, ... : the subpackage of a module (or its part)."""
    return ".".join(module.split(".")[1:3])


#: the groups of rcac_ros/nodes: a group never imports the groups listed against it
NODE_GROUPS_APART = {
    "nodes.controller": {"nodes.simulator"},
    "nodes.simulator": {"nodes.controller", "nodes.fjt", "nodes.safety"},
    "nodes.fjt": {"nodes.controller", "nodes.simulator"},
    "nodes.safety": {"nodes.controller", "nodes.simulator", "nodes.fjt"},
    "nodes.runtime": {"nodes.controller", "nodes.simulator", "nodes.fjt"},
    "nodes.msgs": {"nodes.controller", "nodes.simulator", "nodes.fjt", "nodes.safety",
                   "nodes.runtime"},
}

#: the groups of rcac_ros/tools that must not reach into others
TOOL_GROUPS_APART = {
    "tools.bags": {"tools.demos", "tools.sweep", "tools.bench"},
    "tools.sweep": {"tools.bags", "tools.bench"},
    "tools.bench": {"tools.bags", "tools.sweep"},
}


def test_nodes_and_tools_are_grouped_by_job():
    """nodes/ and tools/ hold subpackages by job; their top levels stay small."""
    for name, most in (("nodes", 1), ("tools", 14)):
        top = [f for f in os.listdir(os.path.join(PACKAGE, name)) if f.endswith(".py")]
        assert len(top) <= most, f"rcac_ros/{name}/ holds {sorted(top)}: group them by job"
    assert set(NODE_GROUPS_APART) == {group(m) for m in modules()
                                      if m.startswith("rcac_ros.nodes.")}


@pytest.mark.parametrize("rules", [NODE_GROUPS_APART, TOOL_GROUPS_APART])
def test_groups_keep_apart(rules):
    bad = [f"{mod} -> {target}" for mod, targets in graph().items()
           for target in targets if group(target) in rules.get(group(mod), ())]
    assert not bad, "imports across groups that stay apart:\n" + "\n".join(sorted(bad))


#: the most lines a node module may have (one concern a module, doc/testing.md)
NODE_FILE_LINES = 300


def test_node_files_are_short():
    """Every module of rcac_ros/nodes stays under NODE_FILE_LINES lines: split it along a
    concern (controller/state_input, safety/watchdog, ...) when it grows."""
    folder = os.path.join(PACKAGE, "nodes")
    sizes = {}
    for where, _, files in os.walk(folder):
        for name in sorted(files):
            if name.endswith(".py"):
                path = os.path.join(where, name)
                with open(path, encoding="utf-8") as f:
                    sizes[os.path.relpath(path, folder)] = sum(1 for _ in f)
    assert os.path.join("controller", "node.py") in sizes and len(sizes) > 10  # found
    long = {name: n for name, n in sizes.items() if n >= NODE_FILE_LINES}
    assert not long, f"node modules of {NODE_FILE_LINES} lines or more: {long}"


#: the one module that may read another object's private attributes: rclpy's, that have no
#: public API (each with its reason in its docstring)
PRIVATE_ADAPTER = os.path.join("nodes", "runtime", "rclpy_private.py")
NUMBA_ADAPTER = os.path.join("core", "_jit.py")
#: namedtuple's public methods, underscored so as not to clash with field names
NAMEDTUPLE_API = {"_replace", "_asdict", "_fields", "_make", "_field_defaults"}


def _is_super(node):
    """``super()``: the object itself, as ``self``."""
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
        and node.func.id == "super"


def private_touches(path):
    """``obj._name`` in the source at ``path`` where ``obj`` is not ``self``/``cls``/``super()``
    (a dunder aside), and ``setattr``/``getattr``/``hasattr``/``delattr`` with a string
    naming a private attribute: ``["line: text", ...]``."""
    tree = ast.parse(open(path, encoding="utf-8").read(), path)
    found = []
    for node in ast.walk(tree):
        name = None
        if isinstance(node, ast.Attribute) and not (
                isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")) \
                and not _is_super(node.value):
            name = node.attr
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in ("setattr", "getattr", "hasattr", "delattr") \
                and len(node.args) > 1 and isinstance(node.args[1], ast.Constant) \
                and isinstance(node.args[1].value, str):
            name = node.args[1].value
        if name and name.startswith("_") and not name.startswith("__") \
                and name not in NAMEDTUPLE_API:
            found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def test_no_module_touches_another_objects_private_attributes():
    """A module reads and writes its own objects' private attributes only; what it needs
    of another object is public. The two exceptions are the adapters to a library's
    internals: rclpy's (``nodes/runtime/rclpy_private.py``) and numba's cache and compile
    switch (``core/_jit.py``)."""
    adapters = {PRIVATE_ADAPTER, NUMBA_ADAPTER}
    bad = {os.path.relpath(path, PACKAGE): hits for path in modules().values()
           if (hits := private_touches(path))}
    assert set(bad) == adapters, "private attributes of other objects:\n" + \
        "\n".join(f"{m}:{h}" for m, hits in sorted(bad.items()) if m not in adapters
                  for h in hits)


def test_core_never_imports_rclpy():
    mods = modules()
    bad = [f"{m} imports {t}" for m in mods if part(m) == "core"
           for t in imports(m, mods[m]) if t.split(".")[0] in ("rclpy", "rcl_interfaces")]
    assert not bad, "\n".join(bad)


def test_only_the_plants_import_mujoco():
    """MuJoCo is optional (doc/plants.md): the core never imports it, and outside
    rcac_ros/plants nothing does; the plants import it inside a function only."""
    mods = modules()
    bad = [m for m in mods if part(m) != "plants"
           and any(t.split(".")[0] == "mujoco" for t in imports(m, mods[m]))]
    bad += [m for m in mods if part(m) == "plants"
            and any(t.split(".")[0] == "mujoco" for t in module_level_imports(m))]
    assert not bad, f"modules importing mujoco: {bad}"
    assert "mujoco" not in loaded_after_import("rcac_ros.plants")


def test_main_blocks_do_not_call_the_cli():
    bad = []
    for mod, path in modules().items():
        tree = ast.parse(open(path, encoding="utf-8").read(), path)
        for node in tree.body:
            if isinstance(node, ast.If) and "__main__" in ast.dump(node.test) \
                    and mod != "rcac_ros.tools.cli" and "cli" in ast.dump(node):
                bad.append(mod)
    assert not bad, f"__main__ blocks calling rcac_ros.tools.cli: {bad}"


def loaded_after_import(module):
    """The top-level packages loaded by ``import module`` in a fresh interpreter."""
    code = (f"import sys, {module}; "
            "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    return set(out.stdout.split())


@pytest.mark.parametrize("module", ["rcac_ros.tools.bags.record", "rcac_ros.tools.bags.inspect",
                                    "rcac_ros.tools.bench.commands", "rcac_ros.tools.extras",
                                    "rcac_ros.errors", "rcac_ros.topics", "rcac_ros.tools.cli",
                                    "rcac_ros.params", "rcac_ros.core.law_options",
                                    "rcac_ros.tools.runs.scenarios",
                                    "rcac_ros.tools.sweep.campaign"])
def test_light_modules_do_not_load_numba(module):
    assert "numba" not in loaded_after_import(module)


@pytest.mark.parametrize("module", ["rcac_ros.core", "rcac_ros.tools.demos.experiment",
                                    "rcac_ros.tools.bench.core", "rcac_ros.params"])
def test_offline_modules_do_not_load_rclpy(module):
    assert "rclpy" not in loaded_after_import(module)


def test_every_folder_of_the_package_is_a_regular_package():
    """setup.py's find_packages (and so colcon and pip) installs only folders with __init__."""
    from setuptools import find_packages
    found = set(find_packages(ROOT, exclude=["test", "test.*"]))
    folders = {os.path.relpath(os.path.dirname(path), ROOT).replace(os.sep, ".")
               for path in modules().values()}
    assert folders <= found, f"missing __init__.py: {sorted(folders - found)}"


def test_test_files_have_unique_names():
    seen = collections.defaultdict(list)
    for folder, _, files in os.walk(os.path.join(ROOT, "test")):
        for name in files:
            if name.startswith("test_") and name.endswith(".py"):
                seen[name].append(folder)
    assert not {k: v for k, v in seen.items() if len(v) > 1}
