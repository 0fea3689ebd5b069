"""A node given a bad parameter or file stops at once and compiles no kernel.

Each node runs in its own process, as ``python -m`` runs it, on an empty
``NUMBA_CACHE_DIR``, with a bad parameter, a missing URDF or a malformed parameters file. It
must exit with code 2 and one line naming the parameter (or the file). The nodes import
numba's modules; a refusal must not compile: no dispatcher of the package has a compiled
signature when the process ends (with an empty cache, a signature could only come from the
compiler), and the cache directory holds no file.
"""

import json
import os
import subprocess
import sys

import pytest

from test_nodes_support import NODE_MODULES, ROOT, ros_domain

#: the node's module run as ``__main__`` with ``sys.argv[2:]``; the last line of stdout
#: names the package's dispatchers that hold a compiled signature
DRIVER = """
import json, runpy, sys
module = sys.argv[1]
sys.argv = [module] + sys.argv[2:]
try:
    runpy.run_module(module, run_name="__main__", alter_sys=True)
    code = 0
except SystemExit as stop:
    code = stop.code
compiled = []
if "numba" in sys.modules:
    from numba.core.dispatcher import Dispatcher
    for name, mod in list(sys.modules.items()):
        if name.startswith("rcac_ros") and mod is not None:
            compiled += [f"{name}.{attr}" for attr, obj in list(vars(mod).items())
                         if isinstance(obj, Dispatcher) and obj.signatures]
print("COMPILED " + json.dumps(sorted(set(compiled))))
sys.exit(code)
"""

#: (node, the arguments after --ros-args, text of the error line); ``{tmp}`` is a fresh
#: directory holding ``bad.yaml``, a parameters file that is not YAML
CASES = [
    ("controller", ["-p", "rate:=-1.0"], "controller: error: rate: value out of range"),
    ("controller", ["-p", "model:={tmp}/no_arm.urdf"],
     "controller: error: model: {tmp}/no_arm.urdf: no such URDF file"),
    # a per-joint gain is the gains reader's to refuse: no warning of an undeclared key first
    ("controller", ["-p", "gains.joint9.K_D:=3.0"],
     "controller: error: gains.joint9.K_D: unknown joint 'joint9'"),
    ("controller", ["--params-file", "{tmp}/bad.yaml"],
     "controller: error: params file {tmp}/bad.yaml: not valid YAML"),
    ("controller", ["-p", "channels:=[]"], "controller: error: channels: empty ([])"),
    ("controller", ["-p", "max_state_bytes:=-1"],
     "controller: error: max_state_bytes: value out of range [0, 2147483647]"),
    ("controller", ["-p", "description_topic:=a!"],
     "controller: error: description_topic: 'a!' is not a valid topic name"),
    ("simulator", ["-p", "description_topic:='{{ns}}/robot_description'"],  # '//robot_...'
     "simulator: error: description_topic: '{{ns}}/robot_description' is not a valid topic "
     "name in /"),
    ("controller", ["-p", "realtime.cpus:=[-1]"],
     "controller: error: realtime.cpus: CPU numbers must be >= 0"),
    ("controller", ["-p", "gains.joint7:=5.0"],
     "controller: error: gains.joint7: expected gains.<joint>.<gain>"),
    ("controller", ["-p", "model:={tmp}"],
     "controller: error: model: '{tmp}' is a directory, not a model file"),
    # rcl's own refusals: its message once, without the line rcl logs before it
    ("controller", ["-p", "mode:="],
     "controller: error: cannot parse parameter override rule: '-p mode:='"),
    ("controller", ["-p", "rate:=250.0", "extra"],
     "controller: error: unknown ROS arguments ['extra']"),
    ("simulator", ["-p", "dt:=-1.0"], "simulator: error: dt: value out of range"),
    ("simulator", ["-p", "dt:=[]"], "simulator: error: dt: empty ([])"),
    ("simulator", ["-p", "model:={tmp}/no_arm.urdf"],
     "simulator: error: model: {tmp}/no_arm.urdf: no such URDF file"),
]


@pytest.mark.parametrize("node,args,text", CASES,
                         ids=[f"{n} {' '.join(a)}" for n, a, _ in CASES])
def test_a_bad_parameter_is_refused_without_compiling(tmp_path, node, args, text):
    tmp = str(tmp_path)
    (tmp_path / "bad.yaml").write_text("rcac_controller: {ros__parameters: [unclosed\n")
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    args = [a.format(tmp=tmp) for a in args]
    with ros_domain():                   # the node's participant stays on its own domain
        env = dict(os.environ, NUMBA_CACHE_DIR=str(cache),
                   PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
        out = subprocess.run([sys.executable, "-c", DRIVER, NODE_MODULES[f"{node}_node"],
                              "--ros-args", *args], cwd=ROOT, env=env, capture_output=True,
                             text=True, timeout=300)
    assert out.returncode == 2, out.stdout + out.stderr
    *printed, last = out.stdout.splitlines()
    lines = [ln for ln in printed + out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and text.format(tmp=tmp) in lines[0], lines
    assert json.loads(last.removeprefix("COMPILED ")) == [], last
    files = [os.path.join(d, f) for d, _, names in os.walk(cache) for f in names]
    assert files == [], f"kernels written to the cache: {files}"
