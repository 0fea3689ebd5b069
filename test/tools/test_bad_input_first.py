"""A bad argument is refused before anything heavy is imported.

Every ``rcac`` subcommand (every benchmark of ``rcac bench``, every form of ``rcac sweep``)
is run in a fresh process, on an empty ``NUMBA_CACHE_DIR``, with a bad argument: a number
out of range, a name it does not know, a missing or malformed file. It must stop with exit
code 2 and one line on stderr naming the argument, with numba, Dask, matplotlib, MuJoCo and
rclpy not imported, and the cache directory still empty. numba not imported means its
compiler cannot have run; the empty directory says that no kernel was written either.
"""

import json
import os
import subprocess
import sys

import pytest

from rcac_ros.tools import cli
from rcac_ros.tools.bench.commands import BENCHMARKS
from rcac_ros.tools.sweep.commands import ACTIONS

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

#: what a bad argument must not import: the compiler, the cluster, the plots, the MuJoCo
#: plant, ROS
HEAVY = ("numba", "dask", "distributed", "matplotlib", "mujoco", "rclpy")

#: ``rcac ARGV`` in this interpreter; its last line of stdout lists the heavy modules loaded
DRIVER = f"""
import json, sys
from rcac_ros.tools.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as stop:
    code = stop.code
print("LOADED " + json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))
sys.exit(code)
"""

#: (argv, text the error line holds); ``{tmp}`` is a fresh directory holding the files
#: below (:func:`files`): ``bad.yaml`` a campaign with a negative duration, ``bad.urdf``
#: malformed XML
CASES = [
    (["experiment", "--duration", "-5"], "argument --duration: must be > 0"),
    (["experiment", "--channels", "torque"], "argument --channels: channels: 'torque'"),
    (["experiment", "--channels", "1,8", "--quiet"], "channels: joint 8 is out of range"),
    (["bench", "startup", "--laws", "nonsense"], "unknown nonsense"),
    (["bench", "core", "--budget", "-1"], "argument --budget: must be > 0"),
    (["bench", "ros", "--duration", "0"], "argument --duration: must be > 0"),
    (["bench", "faults", "--lookahead", "-1"], "argument --lookahead: must be >= 0"),
    (["bench", "faults", "--cases", ""], "argument --cases: an empty name in ''"),
    (["bench", "faults", "--cases", "nominal,bogus"], "argument --cases: unknown bogus"),
    (["bench", "soak", "-5"], "argument MINUTES: must be > 0"),
    (["bench", "delay-margin", "--gains", "-1"], "argument --gains: gains must be > 0"),
    (["bench", "noise", "--laws", "bogus"], "argument --laws: unknown bogus"),
    (["record", "--duration", "-5"], "argument --duration: must be > 0"),
    (["inspect", "some_bag", "--link", "0"], "argument --link: must be an integer >= 1"),
    (["inspect", "{tmp}/no_bag", "--model", "{tmp}/no_model.yaml"],
     "model: {tmp}/no_model.yaml is neither a preset"),
    (["demo", "--duration", "-5"], "argument --duration: must be > 0"),
    (["payload-demo", "--duration", "-5"], "argument --duration: must be > 0"),
    (["payload-demo", "--urdf", "{tmp}/no_panda.urdf"], "argument --urdf: no such file"),
    (["payload-demo", "--urdf", "{tmp}/bad.urdf"], "{tmp}/bad.urdf: malformed XML"),
    (["payload-demo", "--duration", "3", "--jump", "5"], "--jump: the payload must attach"),
    (["friction-demo", "--duration", "-5"], "argument --duration: must be > 0"),
    (["capture-demo", "--mass", "-3"], "argument --mass: must be > 0"),
    (["friction-ros", "--duration", "-1"], "argument --duration: must be > 0"),
    (["warm", "--jobs", "0"], "argument --jobs: must be an integer >= 1"),
    (["warm", "nonsense"], "unknown group 'nonsense'"),
    (["capture-demo", "--at", "50"], "--at: the capture must come before the end of the run"),
    (["sweep", "{tmp}/bad.yaml", "--duration", "-5"], "argument --duration: must be > 0"),
    (["sweep", "{tmp}/missing.yaml", "--out", "{tmp}/out"], "{tmp}/missing.yaml: cannot read"),
    (["sweep", "{tmp}/bad.yaml", "--out", "{tmp}/out"], "scenario.duration: must be > 0"),
    (["sweep", "{tmp}/bad.yaml", "--out", "{tmp}/out", "--scheduler", "localhost"],
     "argument --scheduler: expected tcp://HOST:PORT"),
    (["sweep", "report", "{tmp}/no_results"], "RESULTS: no such directory"),
    (["sweep", "rerun", "{tmp}/no_results", "-1"], "argument index: must be an integer >= 0"),
    (["sweep", "rerun", "{tmp}/no_results", "3"], "RESULTS: no such directory"),
    (["sweep", "--bench", "{tmp}/bad.yaml"], "scenario.duration: must be > 0"),
    (["compare", "--duration", "-5"], "argument --duration: must be > 0"),
    (["compare", "--laws", "best"], "argument --laws: invalid choice: 'best'"),
    (["compare", "--channels", "1,9", "--quiet"], "channels: joint 9 is out of range"),
]


def sweep_form(argv):
    """The form of ``rcac sweep`` that ``argv`` runs: run, report, rerun or --bench."""
    return argv[1] if argv[1] in ACTIONS else "--bench" if "--bench" in argv else "run"


def test_every_subcommand_benchmark_and_sweep_form_has_a_case():
    assert {argv[0] for argv, _ in CASES} == set(cli.SUBCOMMANDS)
    assert {argv[1] for argv, _ in CASES if argv[0] == "bench"} == set(BENCHMARKS)
    assert {sweep_form(argv) for argv, _ in CASES if argv[0] == "sweep"} == \
        {"run", "--bench", *ACTIONS}


@pytest.fixture
def files(tmp_path):
    (tmp_path / "bad.yaml").write_text("seed: 1\nscenario: {model: css_arm, duration: -1}\n")
    (tmp_path / "bad.urdf").write_text('<robot name="panda"><link name="panda_link0"/>\n')
    return str(tmp_path)


@pytest.mark.parametrize("argv,text", CASES, ids=[" ".join(a) for a, _ in CASES])
def test_a_bad_argument_is_refused_before_numba_is_imported(files, tmp_path, argv, text):
    argv = [a.format(tmp=files) for a in argv]
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache),
               PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, "-c", DRIVER, *argv], cwd=str(tmp_path), env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.splitlines()
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith(f"rcac {argv[0]}") and ": error: " in lines[0], lines
    assert text.format(tmp=files) in lines[0], lines
    loaded = json.loads(out.stdout.splitlines()[-1].removeprefix("LOADED "))
    assert loaded == [], f"imported before the refusal: {loaded}"
    assert os.listdir(cache) == [], "the numba cache directory was written"
