"""The plant engine through the tools: closed_loop, experiment, payload-demo, compare, sweep.

On a rigid arm the MuJoCo plant and the built-in simulator integrate the same equations
(test/plants/test_mujoco_plant.py: 3e-13 rad over 1 s open loop), so every closed loop run on
one engine must give the other's figures; with joint friction and rotor inertia on MuJoCo
the tracking must get worse (the laws cannot represent them, doc/plants.md).
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import yaml
from chains import needs_mujoco

from rcac_ros.core import PAPER_Q0, RecursiveCompositeController, SinusoidTrajectory, css_arm
from rcac_ros.tools import cli
from rcac_ros.tools.runs.closed_loop import closed_loop
from rcac_ros.tools.runs.scenarios import find_panda_urdf, gains_for, with_payload
from rcac_ros.tools.sweep import campaign as cp

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
needs_panda = pytest.mark.skipif(find_panda_urdf() is None,
                                 reason="example-robot-data's panda.urdf not installed")


def rcac(*args, path=()):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [*path, ROOT, os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "rcac_ros.tools.cli", *args], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=600)


@needs_mujoco
def test_closed_loop_with_a_grasp_is_the_same_on_both_engines():
    model = css_arm(gravity=(0.0, 0.0, -9.81))
    loaded = with_payload(model, 50.0, (0.1, -0.2, 0.3), 0.2)
    traj = SinusoidTrajectory(np.array(PAPER_Q0), 0.1, 0.3)
    gains = gains_for(model, kappa=50.0, Lambda=5.0, rho=10.0, gamma=1.0, lam=10.0, h=0.002)
    runs = {engine: closed_loop(RecursiveCompositeController(model, **gains), traj, 0.4,
                                events=((0.2, loaded),), engine=engine)
            for engine in ("builtin", "mujoco")}
    a, b = runs["builtin"], runs["mujoco"]
    assert b["plant"] is loaded and b["status"] == "ok"
    assert np.abs(a["q"] - b["q"]).max() < 1e-9
    assert np.abs(a["tau"] - b["tau"]).max() < 1e-6 * np.abs(a["tau"]).max()
    # the grasp happened on MuJoCo too: without it the torques part
    free = closed_loop(RecursiveCompositeController(model, **gains), traj, 0.4, engine="mujoco")
    assert np.abs(free["tau"][101:] - b["tau"][101:]).max() > 1.0


@needs_mujoco
def test_experiment_on_mujoco_gives_the_builtin_figures(tmp_path):
    figures = {}
    for engine in ("builtin", "mujoco"):
        out = rcac("experiment", "--duration", "0.4", "--quiet", "--engine", engine,
                   "--out", str(tmp_path / engine))
        assert out.returncode == 0, out.stderr
        with open(tmp_path / engine / "metrics.json", encoding="utf-8") as f:
            figures[engine] = json.load(f)
        assert figures[engine]["settings"]["engine"] == engine
    for law in ("direct", "composite"):
        a, b = figures["builtin"][law], figures["mujoco"][law]
        for key in ("rms_tracking_error", "max_tracking_error", "max_abs_torque"):
            assert b[key] == pytest.approx(a[key], rel=1e-6), (law, key)


@needs_mujoco
@needs_panda
def test_payload_demo_on_mujoco_gives_the_builtin_figures(tmp_path):
    figures = {}
    for engine in ("builtin", "mujoco"):
        out = rcac("payload-demo", "--duration", "0.4", "--jump", "0.2", "--quiet",
                   "--engine", engine, "--out", str(tmp_path / engine))
        assert out.returncode == 0, out.stderr
        with open(tmp_path / engine / "metrics.json", encoding="utf-8") as f:
            figures[engine] = json.load(f)
    for law in ("composite", "direct", "fixed"):
        a, b = figures["builtin"][law], figures["mujoco"][law]
        for key in ("rms_error_before_jump", "rms_error_last_window", "link7_mass_estimate_end"):
            assert b[key] == pytest.approx(a[key], rel=1e-6), (law, key)


@needs_mujoco
@needs_panda
def test_compare_joint_scenarios(tmp_path):
    """panda_rigid on MuJoCo is the built-in run; the joint terms make every law worse."""
    reports = {}
    for engine, scenarios in (("builtin", ["panda_rigid"]),
                              (None, ["panda_rigid", "panda_joints"])):
        args = ["compare", "--duration", "0.4", "--quiet", "--laws", "fixed", "paper",
                "--scenarios", *scenarios, "--out", str(tmp_path / str(engine))]
        out = rcac(*args, *(["--engine", engine] if engine else []))
        assert out.returncode == 0, out.stderr
        with open(tmp_path / str(engine) / "compare.json", encoding="utf-8") as f:
            reports[engine] = json.load(f)
    rigid_builtin, on_mujoco = reports["builtin"]["panda_rigid"], reports[None]
    for law in ("fixed", "paper"):
        assert on_mujoco["panda_rigid"][law]["rms"] == pytest.approx(
            rigid_builtin[law]["rms"], rel=1e-6)
        assert on_mujoco["panda_joints"][law]["rms"] > 100 * on_mujoco["panda_rigid"][law]["rms"]
    assert reports[None]["settings"]["joint_terms"]["panda_joints"] == dict(
        damping=0.5, friction=0.5, armature=0.1)
    table = (tmp_path / "None" / "compare.md").read_text(encoding="utf-8")
    assert table.startswith("`rcac compare --duration 0.4 --scenarios panda_rigid panda_joints "
                            "--laws fixed paper`")
    assert "| scenario | fixed | paper |" in table and "| panda_joints |" in table


def test_compare_groups_and_default_laws():
    from rcac_ros.tools.demos import compare
    names = compare.scenario_names(["panda_rigid", "joint_table", "panda_damping_armature"])
    assert names == ["panda_rigid", "panda_damping", "panda_friction", "panda_armature",
                     "panda_joints", "panda_damping_armature"]
    assert "fixed" not in compare.DEFAULT_LAWS and "fixed" in compare.JOINT_LAWS
    assert set(compare.JOINT_LAWS) <= set(compare.LAWS)


def sweep_doc(**scenario):
    return {"name": "engines", "seed": 3, "samples": 2,
            "scenario": {"model": "css_arm", "duration": 0.3, **scenario},
            "vary": {"law": {"grid": ["direct", "composite"]},
                     "payload_mass": {"uniform": {"low": 0.0, "high": 50.0}}}}


@needs_mujoco
def test_sweep_takes_the_engine_as_a_campaign_key():
    builtin, mujoco = cp.validate(sweep_doc()), cp.validate(sweep_doc(engine="mujoco"))
    assert "engine" not in builtin["scenario"]          # the default leaves the record as it was
    assert cp.setup(mujoco, 1)[2]["engine"] == "mujoco"
    for i in range(cp.run_count(builtin)):
        a, b = cp.simulate(builtin, i), cp.simulate(mujoco, i)
        for key in ("rms_tracking_error", "max_tracking_error", "parameter_error_norm_end"):
            assert b[key] == pytest.approx(a[key], rel=1e-6), (i, key)


def test_a_bad_engine_is_one_line(tmp_path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(sweep_doc(engine="bullet")))
    assert cli.main(["sweep", str(path), "--out", str(tmp_path / "out"), "--workers", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("rcac sweep: error: scenario.engine: expected one of builtin, mujoco")
    for command in ("experiment", "payload-demo", "compare"):
        out = rcac(command, "--engine", "bullet")
        assert out.returncode == 2 and "--engine: invalid choice: 'bullet'" in out.stderr


def test_without_mujoco_a_command_says_so_in_one_line(tmp_path):
    (tmp_path / "mujoco.py").write_text("raise ImportError('no mujoco here')\n")
    out = rcac("experiment", "--duration", "0.1", "--quiet", "--engine", "mujoco",
               "--out", str(tmp_path / "o"), path=[str(tmp_path)])
    assert out.returncode == 2
    assert out.stderr == ("rcac experiment: error: engine mujoco: the 'mujoco' package is not "
                          "installed (pip install mujoco==4.0.0, or the extra rcac_ros[mujoco])\n")


def test_friction_aware_laws_track_the_frictional_panda(tmp_path):
    """The laws with joint_friction (doc/design.md §7) on panda_joints with the model's own
    friction law (builtin engine): far better than the friction-blind paper law; on the rigid
    panda they stay at its level."""
    out = rcac("compare", "--duration", "1", "--quiet", "--engine", "builtin", "--laws",
               "paper", "paper_friction", "all_friction", "--scenarios", "panda_joints",
               "panda_rigid", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    with open(tmp_path / "compare.json", encoding="utf-8") as f:
        report = json.load(f)
    joints, rigid = report["panda_joints"], report["panda_rigid"]
    # paper_friction's inertia-scaled joint gain (doc/design.md §7) learns the wrist joints'
    # armature more slowly: 0.30x the paper law over this first second (0.16x over 20 s)
    for law, factor in (("paper_friction", 0.4), ("all_friction", 0.2)):
        assert joints[law]["rms"] < factor * joints["paper"]["rms"], (law, joints)
        assert rigid[law]["rms"] < 5.0 * rigid["paper"]["rms"], (law, rigid)
