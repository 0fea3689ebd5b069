"""Build the control_msgs subset the package uses, without cmake, for the tests.

control_msgs has no PyPI wheel, so on the pip-only path ``FollowJointTrajectory`` does not
import and the action server cannot be tested. The definitions this package uses are kept
in ``test/ros/interfaces/control_msgs`` (``FollowJointTrajectory.action`` and the two
messages it needs, copied field for field from control_msgs 5.8.0, Jazzy). This module turns
them into an importable ``control_msgs`` Python package with the same generators a colcon
build runs (``rosidl_generator_c``/``_py`` and the ``c``, ``fastrtps_c`` and
``introspection_c`` type supports, all wheels of the venv), compiled with the system C and
C++ compilers against the headers and libraries the ROS wheels install under ``sys.prefix``.
See doc/testing.md ("FollowJointTrajectory without control_msgs").

Result, under ``OUT``: ``python/control_msgs`` (to put on ``sys.path``) and ``lib`` (the
``lib*.so``, found through the modules' RUNPATH: no ``LD_LIBRARY_PATH`` needed). Usage::

    python test/ros/interface_build.py OUT
"""

import contextlib
import hashlib
import importlib.util
import io
import os
import pathlib
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from concurrent.futures import ThreadPoolExecutor

HERE = pathlib.Path(__file__).resolve().parent
SOURCES = HERE / "interfaces"
PACKAGE = "control_msgs"
INTERFACES = ["action/FollowJointTrajectory.action", "msg/JointTolerance.msg",
              "msg/JointComponentTolerance.msg"]
# the interface packages the definitions (and the action's services) refer to
DEPENDS = ["builtin_interfaces", "std_msgs", "geometry_msgs", "trajectory_msgs", "action_msgs",
           "unique_identifier_msgs", "service_msgs"]
TYPESUPPORTS = ["rosidl_typesupport_fastrtps_c", "rosidl_typesupport_introspection_c"]


def cache_key():
    """What the build depends on: the definitions, this file, the interpreter and its venv."""
    h = hashlib.sha256()
    for rel in INTERFACES:
        h.update((SOURCES / PACKAGE / rel).read_bytes())
    h.update(pathlib.Path(__file__).read_bytes())
    h.update(f"{sys.prefix} {sys.version}".encode())
    return h.hexdigest()[:16]


def generate(work):
    """Run the rosidl generators (the wheels' Python API: no cmake, no ``rosidl`` CLI)."""
    before = os.environ.get("AMENT_PREFIX_PATH")
    if not before:                  # the generators find their templates in the ament index
        os.environ["AMENT_PREFIX_PATH"] = sys.prefix
    log = io.StringIO()             # the generators print a line per file: kept for errors
    try:
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            _generate(work)
    except Exception as err:
        raise RuntimeError(f"rosidl generation failed ({err}):\n{log.getvalue()[-3000:]}")
    finally:                        # the tests' environment as it was
        if not before:
            os.environ.pop("AMENT_PREFIX_PATH", None)


def _generate(work):
    from rosidl_generator_c.cli import GenerateC
    from rosidl_generator_py.cli import GeneratePython
    from rosidl_typesupport_c.cli import GenerateCTypesupport
    from rosidl_typesupport_fastrtps_c.cli import GenerateFastRTPSCTypesupport
    from rosidl_typesupport_introspection_c.cli import GenerateIntrospectionCTypesupport

    share = pathlib.Path(sys.prefix) / "share"
    include = [str(share / p) for p in DEPENDS]
    files = [f"{SOURCES / PACKAGE}:{rel}" for rel in INTERFACES]
    for ext in (GenerateC("c"),
                GenerateCTypesupport("typesupport_c", typesupport_implementations=TYPESUPPORTS),
                GenerateFastRTPSCTypesupport("fastrtps_c"),
                GenerateIntrospectionCTypesupport("introspection_c"),
                GeneratePython("py", typesupport_implementations=["rosidl_typesupport_c"]
                               + TYPESUPPORTS)):
        ext.generate(PACKAGE, files, include, output_path=work / ext.name / PACKAGE)


def compile_all(work, out):
    """Compile and link the five libraries and the Python extension, like rosidl's cmake."""
    prefix = pathlib.Path(sys.prefix)
    import numpy
    includes = [f"-I{work / d}" for d in ("c", "typesupport_c", "fastrtps_c",
                                          "introspection_c", "py")]
    includes += [f"-I{prefix / 'include'}"]      # fastcdr: not in a directory of its own
    includes += [f"-I{d}" for d in sorted((prefix / "include").iterdir()) if d.is_dir()]
    includes += [f"-I{sysconfig.get_paths()['include']}", f"-I{numpy.get_include()}"]
    lib = out / "lib"
    lib.mkdir(parents=True)
    objdir = work / "obj"
    objdir.mkdir()

    def sources(ext, suffix):
        return sorted(p for p in (work / ext / PACKAGE).rglob(f"*{suffix}")
                      if "tmp" not in p.relative_to(work / ext).parts)

    def deps(kind):
        return [f"-l{d}__{kind}" for d in DEPENDS]

    def obj(src):
        o = objdir / (src.relative_to(work).as_posix().replace("/", "__") + ".o")
        cc = ["g++", "-std=c++17"] if src.suffix == ".cpp" else ["gcc"]
        run(cc + ["-O1", "-fPIC", "-w", "-c", str(src), "-o", str(o)] + includes)
        return o

    def link(name, objs, libs, where=lib, rpath="$ORIGIN"):
        target = where / name
        run(["g++", "-shared", f"-Wl,-soname,{name}", "-o", str(target)] + [str(o) for o in objs]
            + [f"-L{lib}", f"-L{prefix / 'lib'}", f"-Wl,-rpath,{rpath}"] + libs)
        return target

    all_sources = {kind: sources(ext, suffix) for kind, ext, suffix in (
        ("c", "c", ".c"), ("typesupport_c", "typesupport_c", ".cpp"),
        ("fastrtps_c", "fastrtps_c", ".cpp"), ("introspection_c", "introspection_c", ".c"),
        ("py", "py", "_s.c"))}
    entry_points = sorted((work / "py" / PACKAGE).glob(f"_{PACKAGE}_s.ep.*.c"))
    with ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 2)) as pool:
        objs = {k: list(pool.map(obj, v)) for k, v in all_sources.items()}
        ep_objs = list(pool.map(obj, entry_points))

    gen_c = f"-l{PACKAGE}__rosidl_generator_c"
    link(f"lib{PACKAGE}__rosidl_generator_c.so", objs["c"],
         deps("rosidl_generator_c") + ["-lrosidl_runtime_c", "-lrcutils"])
    link(f"lib{PACKAGE}__rosidl_typesupport_fastrtps_c.so", objs["fastrtps_c"],
         [gen_c] + deps("rosidl_typesupport_fastrtps_c") + deps("rosidl_generator_c")
         + ["-lrosidl_typesupport_fastrtps_c", "-lrosidl_typesupport_fastrtps_cpp",
            "-lfastcdr", "-lrmw", "-lrosidl_runtime_c", "-lrcutils"])
    link(f"lib{PACKAGE}__rosidl_typesupport_introspection_c.so", objs["introspection_c"],
         [gen_c] + deps("rosidl_typesupport_introspection_c") + deps("rosidl_generator_c")
         + ["-lrosidl_typesupport_introspection_c", "-lrosidl_runtime_c"])
    # rosidl_typesupport_c finds the fastrtps and introspection libraries by dlopen of their
    # bare names, which searches LD_LIBRARY_PATH as it was when the process started: a test
    # run cannot extend it for itself. Linked here (NEEDED, found by RUNPATH), they are
    # loaded with this library, and the dlopen by name then returns them.
    link(f"lib{PACKAGE}__rosidl_typesupport_c.so", objs["typesupport_c"],
         [gen_c] + deps("rosidl_typesupport_c")
         + ["-lrosidl_typesupport_c", "-lrosidl_runtime_c", "-lrcutils", "-Wl,--no-as-needed"]
         + [f"-l{PACKAGE}__{t}" for t in TYPESUPPORTS])
    link(f"lib{PACKAGE}__rosidl_generator_py.so", objs["py"],
         [gen_c] + deps("rosidl_generator_py") + deps("rosidl_generator_c")
         + deps("rosidl_typesupport_c") + ["-lrosidl_runtime_c", "-lrcutils"])

    pkg = out / "python" / PACKAGE
    for src in (work / "py" / PACKAGE).rglob("*.py"):
        rel = src.relative_to(work / "py" / PACKAGE)
        if "tmp" not in rel.parts:
            (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, pkg / rel)
    (pkg / "__init__.py").touch()
    for ep, o in zip(entry_points, ep_objs):
        support = ep.name[len(f"_{PACKAGE}_s.ep."):-len(".c")]     # rosidl_typesupport_c ...
        link(f"{PACKAGE}_s__{support}{sysconfig.get_config_var('EXT_SUFFIX')}", [o],
             [f"-l{PACKAGE}__rosidl_generator_py", f"-l{PACKAGE}__{support}", gen_c,
              "-lrmw"], where=pkg, rpath="$ORIGIN/../../lib")


def run(cmd):
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[:4])} ... failed:\n{done.stderr[-3000:]}")


def build(root):
    """Build into ``root/<key>`` unless it is there; return that directory.

    The build goes into a temporary directory renamed into place, so concurrent test runs
    sharing ``root`` never see half a build.
    """
    root = pathlib.Path(root)
    out = root / cache_key()
    if (out / "python" / PACKAGE / "__init__.py").exists():
        return out
    root.mkdir(parents=True, exist_ok=True)
    (root / "COLCON_IGNORE").touch()      # colcon build --base-paths <repo> must not look here
    with tempfile.TemporaryDirectory(dir=root) as tmp:
        tmp = pathlib.Path(tmp)
        generate(tmp / "work")
        compile_all(tmp / "work", tmp / "out")
        try:
            os.rename(tmp / "out", out)
        except OSError:
            if not out.exists():        # else another run finished first: keep its build
                raise
    return out


#: why the test build is not used (``None``: it is, or an installed control_msgs imports)
BUILD_ERROR = None


def use_in_tests():
    """Unless control_msgs is installed, build the subset and put it on the import paths.

    Called by ``test/ros/conftest.py``: first on ``sys.path``, and on ``PYTHONPATH`` for the
    processes the tests start. A failed build is kept in :data:`BUILD_ERROR` (the skip
    reason of the tests that need control_msgs), not raised, unless the environment sets
    ``RCAC_REQUIRE_TEST_INTERFACES=1`` (``.ci/run`` does): there a failed build fails the run
    instead of turning the action server's tests into skips.
    """
    global BUILD_ERROR
    if importlib.util.find_spec(PACKAGE) is not None:
        return                                            # an installed one: it wins
    try:
        out = build(HERE.parent.parent / "build" / "test-interfaces")
    except Exception as err:                              # noqa: BLE001 (the skip reason)
        if os.environ.get("RCAC_REQUIRE_TEST_INTERFACES") == "1":
            raise
        BUILD_ERROR = f"the test build of {PACKAGE} failed: {err}"
        return
    python = str(out / "python")
    sys.path.insert(0, python)
    os.environ["PYTHONPATH"] = os.pathsep.join(
        [python] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: interface_build.py OUT")
    print(build(sys.argv[1]))
