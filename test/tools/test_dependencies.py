"""Dependencies are declared once: setup.py names them, the requirements files pin them.

setup.py's ``install_requires`` and extras are the declaration; ``requirements.txt`` and
``requirements-test.txt`` together pin exactly those names (plus the ROS 2 wheels, which
setup.py must not name: they would shadow an apt install, doc/install.md). Every
third-party module the package imports comes from a declared distribution, as the
installed metadata says (an independent reference: the distributions' own file lists).
"""

import ast
import importlib.metadata
import os
import re
import sys

import pytest

from rcac_ros.tools import extras

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

#: imported by the package, not pip-installable: control_msgs is apt-only (doc/install.md)
#: imported, but no PyPI wheel provides the module: control_msgs (built for the tests), and
#: example_robot_data (the apt/robotpkg module; PyPI's example-robot-data ships only the URDFs
#: under its cmeel prefix, which tools/runs/robots.py finds without it: the ``robots`` extra)
NOT_ON_PYPI = {"control_msgs", "example_robot_data"}


def norm(name):
    """PEP 503 normalised distribution name, without extras (``ros-jazzy-rclpy[fastrtps]``)."""
    return re.sub(r"[-_.]+", "-", name.split("[")[0]).lower()


def declared():
    """``(install_requires, extras_require)`` of setup.py, read from its source."""
    tree = ast.parse(open(os.path.join(ROOT, "setup.py"), encoding="utf-8").read())
    found = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name):
            if node.targets[0].id in ("INSTALL_REQUIRES", "EXTRAS_REQUIRE"):
                found[node.targets[0].id] = ast.literal_eval(node.value)
    return found["INSTALL_REQUIRES"], found["EXTRAS_REQUIRE"]


def pins(name):
    """``{normalised name: version}`` of a requirements file (``-r`` lines not followed)."""
    out = {}
    for line in open(os.path.join(ROOT, name), encoding="utf-8"):
        line = line.split("#")[0].strip()
        if not line or line.startswith("-r "):
            continue
        match = re.fullmatch(r"([A-Za-z0-9_.\-\[\]]+)==([\w.]+)", line)
        assert match, f"{name}: not an exact pin: {line!r}"
        assert norm(match[1]) not in out, f"{name}: {match[1]} pinned twice"
        out[norm(match[1])] = match[2]
    return out


def is_ros_wheel(name):
    """``ros-jazzy-*`` as pinned; installed, their distributions are named ``ros-*``."""
    return norm(name).startswith("ros-")


def test_requirements_pin_exactly_what_setup_py_declares():
    install, extra = declared()
    names = {norm(n) for n in install} | {norm(n) for deps in extra.values() for n in deps}
    runtime, test = pins("requirements.txt"), pins("requirements-test.txt")
    assert not set(runtime) & set(test), "pinned in both files"
    pinned = {n for n in {**runtime, **test} if not is_ros_wheel(n)}
    # setuptools: the venv's own (setup.py's ament template names it, nobody pins it)
    assert pinned == names - {"setuptools"}, (
        f"pinned, not declared: {sorted(pinned - names)}; "
        f"declared, not pinned: {sorted(names - {'setuptools'} - pinned)}")
    # install_requires and the extras the runtime commands need are in requirements.txt
    for n in list(install) + extra["bags"] + extra["sweep"]:
        assert norm(n) in runtime or n == "setuptools", f"{n}: not in requirements.txt"


def test_setup_py_names_no_ros_wheel():
    install, extra = declared()
    every = list(install) + [n for deps in extra.values() for n in deps]
    assert not [n for n in every if is_ros_wheel(n) or norm(n) == "rclpy"]
    assert any(is_ros_wheel(n) for n in pins("requirements.txt"))   # they live there


def test_the_extras_of_the_commands_are_setup_py_extras():
    _, extra = declared()
    assert set(extras.EXTRAS) <= set(extra)


def provided_by():
    """``{top-level module: {normalised distribution, ...}}`` of the installed distributions.

    Also the modules a wheel installs below a prefix of its own (cmeel's wheels, ``pin`` and
    ``example-robot-data``: ``cmeel.prefix/lib/pythonX.Y/site-packages/MODULE/...``)."""
    out = {m: {norm(d) for d in dists}
           for m, dists in importlib.metadata.packages_distributions().items()}
    for dist in importlib.metadata.distributions():
        for path in dist.files or ():
            parts = path.parts
            if "site-packages" in parts[:-1] and parts[0] != "..":
                top = parts[parts.index("site-packages") + 1].split(".")[0]
                out.setdefault(top, set()).add(norm(dist.metadata["Name"]))
    return out


@pytest.mark.parametrize("extra", sorted(extras.EXTRAS))
def test_each_extra_provides_the_modules_its_commands_check(extra):
    """extras.EXTRAS[extra] names modules that the extra's distributions install."""
    _, declared_extras = declared()
    mine = {norm(n) for n in declared_extras[extra]}
    where = provided_by()
    for module in extras.EXTRAS[extra]:
        if module not in where:
            pytest.skip(f"{module} not installed here")
        assert where[module] & mine, f"{module} comes from {where[module]}, not [{extra}]"


def third_party_imports():
    """Top-level names of every module the package imports that is not its own or stdlib."""
    found = set()
    for folder, _, files in os.walk(os.path.join(ROOT, "rcac_ros")):
        for name in files:
            if name.endswith(".py"):
                tree = ast.parse(open(os.path.join(folder, name), encoding="utf-8").read())
                for node in ast.walk(tree):
                    if isinstance(node, ast.Import):
                        found.update(a.name.split(".")[0] for a in node.names)
                    elif isinstance(node, ast.ImportFrom) and not node.level:
                        found.add(node.module.split(".")[0])
    return found - set(sys.stdlib_module_names) - {"rcac_ros"}


def test_every_imported_distribution_is_declared():
    install, extra = declared()
    names = {norm(n) for n in install} | {norm(n) for deps in extra.values() for n in deps}
    where = provided_by()
    undeclared = []
    for module in sorted(third_party_imports() - NOT_ON_PYPI):
        dists = where.get(module)
        if not dists:       # not installed here: then an extra the commands check names it
            assert any(module in mods for mods in extras.EXTRAS.values()), module
            continue
        if not (dists & names or any(is_ros_wheel(d) for d in dists)):
            undeclared.append(f"{module} ({', '.join(sorted(dists))})")
    assert not undeclared, f"imported but not declared in setup.py: {undeclared}"


def test_a_missing_extra_is_named_in_one_line(monkeypatch):
    monkeypatch.setitem(extras.EXTRAS, "sweep", ("dask", "no_such_module_rcac"))
    with pytest.raises(extras.DependencyError) as err:
        extras.require("bags", "sweep")
    assert str(err.value) == ("needs the 'sweep' extra (missing no_such_module_rcac): "
                              "pip install 'rcac_ros[sweep]'")
