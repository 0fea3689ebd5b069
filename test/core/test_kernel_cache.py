"""The kernels' cache (rcac_ros/core/_jit.py): keyed on every compiled source, never stale."""

import os
import shutil
import subprocess
import sys

import numpy as np

import rcac_ros
from rcac_ros.core import _jit

PACKAGE = os.path.dirname(os.path.abspath(rcac_ros.__file__))

#: the RNEA of the CSS arm with joint damping, in a process of the copy
RNEA = """
import numpy as np
from rcac_ros.core import css_arm, inverse_dynamics
m = css_arm(); m = m.replace(damping=np.ones(m.n))
print(repr(inverse_dynamics(m, np.full(m.n, 0.1), np.full(m.n, 0.5), np.zeros(m.n)).tolist()))
"""


def rnea_of(copy, cache):
    env = dict(os.environ, PYTHONPATH=str(copy), NUMBA_CACHE_DIR=str(cache))
    out = subprocess.run([sys.executable, "-c", RNEA], cwd=str(copy), env=env,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    return np.array(eval(out.stdout.strip().splitlines()[-1]))


def test_a_change_in_an_inlined_helper_of_another_file_is_seen(tmp_path):
    """The RNEA kernel (rnea.py) inlines the joint friction torque of spatial.py. A copy of
    the package fills a cache; then that helper changes in the copy (one more N m of
    damping torque per joint) and the same cache is used again: the kernel's result changes
    by exactly that, so the old kernel was not loaded (numba alone keys a kernel on its own
    file, rnea.py, unchanged here)."""
    copy = tmp_path / "src"
    shutil.copytree(PACKAGE, copy / "rcac_ros",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    cache = tmp_path / "cache"
    before = rnea_of(copy, cache)
    spatial = copy / "rcac_ros" / "core" / "spatial.py"
    text = spatial.read_text()
    helper = text.index("def joint_friction_torque")
    old = "    return "
    at = text.index(old, helper)
    spatial.write_text(text[:at] + "    return 1.0 + " + text[at + len(old):])
    after = rnea_of(copy, cache)
    np.testing.assert_allclose(after - before, 1.0, rtol=0, atol=1e-9)
    assert len(os.listdir(cache / "rcac_ros")) == 2       # one directory per source digest
    # nothing is written beside the sources (a read-only install works the same)
    beside = [f for _, _, files in os.walk(copy) for f in files if f.endswith((".nbi", ".nbc"))]
    assert not beside, beside


def test_without_numba_cache_dir_the_cache_is_the_users(tmp_path):
    """Without NUMBA_CACHE_DIR the kernels go to $XDG_CACHE_HOME/rcac_ros/numba/<key>, never
    beside the sources: a root-owned install (apt) caches per user."""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "RCAC_CACHE_DIR")}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    code = "from rcac_ros.core import _jit; print(_jit.cache_dir())"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str(tmp_path / "rcac_ros" / "numba" / _jit.SOURCE_KEY)


def test_an_unwritable_cache_falls_back_to_a_keyed_temporary_one(tmp_path):
    """Where the cache directory cannot be made (here NUMBA_CACHE_DIR is a file), the
    kernels go to a keyed directory of the system's temporary directory, never to numba's
    own locations, which key a kernel on its one file and could load a stale one."""
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = dict(os.environ, NUMBA_CACHE_DIR=str(blocked), TMPDIR=str(temp))
    out = subprocess.run([sys.executable, "-c", RNEA], env=env, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    keyed = temp / f"rcac_ros-{os.getuid()}" / _jit.SOURCE_KEY
    cached = [f for _, _, files in os.walk(keyed) for f in files if f.endswith(".nbi")]
    assert cached, f"nothing cached under {keyed}"
    beside = [f for _, _, files in os.walk(PACKAGE) for f in files if f.endswith((".nbi", ".nbc"))]
    assert not beside, beside


def test_the_key_covers_every_compiled_source_and_numba():
    """Every file of the package that holds compiled code is in the key."""
    compiled = set()
    for root, _, files in os.walk(PACKAGE):
        for f in files:
            path = os.path.join(root, f)
            if f.endswith(".py") and "@njit" in open(path).read() or \
                    f.endswith(".py") and "@kernel(" in open(path).read():
                compiled.add(os.path.relpath(path, PACKAGE))
    assert compiled <= set(_jit.KERNEL_SOURCES)
    assert _jit.cache_dir().endswith(_jit.SOURCE_KEY)


def test_building_a_law_compiles_nothing_until_it_is_compiled(tmp_path):
    """Building the controller (checks, packing, choosing its kernel) compiles nothing; its
    compile() compiles the law's kernel and the kernels that kernel calls, nothing else: not
    the general kernel, not Slotine-Li's, and not the natural geometry's steps, whose branch
    the paper's law's entry rules out (numba's compile events, with an empty cache)."""
    code = """
import numpy as np
from numba.core import event
from rcac_ros.core import RecursiveCompositeController, css_arm
with event.install_recorder("numba:compile") as built:
    ctrl = RecursiveCompositeController(css_arm())
with event.install_recorder("numba:compile") as compiled:
    ctrl.compile()
names = sorted({ev.data["dispatcher"].py_func.__name__ for _, ev in compiled.buffer})
print(len(built.buffer), names)
"""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    count, names = out.stdout.strip().splitlines()[-1].split(" ", 1)
    assert count == "0"
    assert "paper_step" in names
    assert "rcac_step_kernel" not in names and "general_law" not in names
    assert "slotine_li_step_kernel" not in names
    assert "natural_gain_rows" not in names and "retract_links" not in names   # pruned
