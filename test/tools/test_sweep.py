"""rcac sweep without Dask: the closed loop against a plain reference loop, campaign files,
reproducibility, the command line's errors, Ctrl-C and --resume."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from rcac_ros.tools import cli
from rcac_ros.core import PAPER_Q0, PaperTrajectory, RcacError, RecursiveCompositeController, \
    Simulator, SinusoidTrajectory, css_arm
from rcac_ros.tools.sweep import campaign as cp
from rcac_ros.tools.runs.closed_loop import attach_payload, closed_loop, run_metrics

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

#: A small campaign on the paper's arm: 20 runs of 0.5 s, every kind of distribution.
SMALL = {
    "name": "small", "seed": 11, "samples": 10,
    "scenario": {"model": "css_arm", "duration": 0.5},
    "vary": {"law": {"grid": ["direct", "composite"]},
             "K_D": {"loguniform": {"low": 5e3, "high": 2e4}},
             "P": {"normal": {"mean": 100.0, "std": 30.0, "low": 10.0}},
             "noise_q": {"uniform": {"low": 0.0, "high": 1e-5}},
             "delay": {"choice": [0, 1, 3]},
             "payload_mass": {"uniform": {"low": 0.0, "high": 100.0}},
             "payload_com": {"normal": {"mean": [0.0, 0.5, 1.0], "std": 0.1}},
             "estimate_error": {"uniform": {"low": 0.0, "high": 0.3}}},
}


class Recorder:
    """Wraps a controller and keeps what it was given (the measured state)."""

    def __init__(self, ctrl):
        self.ctrl, self.seen = ctrl, []

    def __getattr__(self, name):
        return getattr(self.ctrl, name)

    def step(self, q, qd, *desired):
        self.seen.append((np.array(q), np.array(qd)))
        return self.ctrl.step(q, qd, *desired)


def reference_loop(controller, trajectory, duration, plant, q0, qd0, grasp=None, substeps=1):
    """The closed loop written out from core calls alone: the reference closed_loop must meet.

    ``grasp = (time, loaded)``: from the first period at ``t >= time`` the plant is ``loaded``.
    Returns ``q`` (true, before the step), ``q_d``, ``tau``, ``theta_hat`` (before the step)
    and ``E`` (after it), one row a period.
    """
    h = controller.h
    sim = Simulator(plant, dt=h, q0=q0, qd0=qd0, substeps=substeps)
    rows = {key: [] for key in ("q", "q_d", "tau", "theta_hat", "E")}
    for k in range(int(round(duration / h)) + 1):
        if grasp is not None and k * h >= grasp[0] - 1e-12 and sim.model is plant:
            q, qd = sim.q, sim.qd
            sim = Simulator(grasp[1], dt=h, q0=q, qd0=qd, substeps=substeps)
        q_d, qd_d, qdd_d = trajectory(k * h)
        rows["q"].append(sim.q.copy())
        rows["q_d"].append(q_d)
        rows["theta_hat"].append(controller.theta_hat.copy())
        rows["tau"].append(controller.step(sim.q, sim.qd, q_d, qd_d, qdd_d))
        rows["E"].append(np.array(controller.E))
        sim.step(rows["tau"][-1])
        controller.set_applied_torque(sim.applied)
    return {key: np.array(v) for key, v in rows.items()}


def test_experiment_runs_the_reference_loop():
    """rcac experiment's runs (closed_loop from PAPER_Q0 at rest) are the reference loop's."""
    from rcac_ros.core import PAPER_GAINS
    from rcac_ros.tools.demos.experiment import run_experiment
    model = css_arm()
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0, reading="position")          # a large initial error
    _, runs, report = run_experiment(0.6, "position", substeps=2, progress=False,
                                     channels=("all",))
    for law, gamma in (("direct", 0.0), ("composite", PAPER_GAINS["gamma"])):
        ctrl = RecursiveCompositeController(model, **dict(PAPER_GAINS, gamma=gamma),
                                            channels=("all",))
        ref = reference_loop(ctrl, traj, 0.6, model, q0, np.zeros(7), substeps=2)
        assert runs[law]["E"].shape == (301, 7)
        for key in ref:
            np.testing.assert_array_equal(runs[law][key], ref[key], err_msg=f"{law} {key}")
        assert runs[law]["status"] == "ok"


def test_payload_grasp_is_the_reference_loops():
    """closed_loop's plant event is the grasp of the reference loop, state carried over."""
    from rcac_ros.tools.runs.scenarios import gains_for, with_payload
    model = css_arm(gravity=(0.0, 0.0, -9.81))
    loaded = with_payload(model, 50.0, (0.1, -0.2, 0.3), 0.2)
    traj = SinusoidTrajectory(np.array(PAPER_Q0), 0.1, 0.3)
    gains = gains_for(model, kappa=50.0, Lambda=5.0, rho=10.0, gamma=1.0, lam=10.0, h=0.002)
    q0, qd0, _ = traj(0.0)
    ref = reference_loop(RecursiveCompositeController(model, **gains), traj, 0.4, model, q0,
                         qd0, grasp=(0.2, loaded))
    new = closed_loop(RecursiveCompositeController(model, **gains), traj, 0.4,
                      events=((0.2, loaded),))
    for key in ref:
        np.testing.assert_array_equal(new[key], ref[key], err_msg=key)
    assert new["plant"] is loaded
    # the grasp matters: without it the runs part after t = 0.2 s
    free = closed_loop(RecursiveCompositeController(model, **gains), traj, 0.4)
    np.testing.assert_array_equal(free["tau"][:101], ref["tau"][:101])
    assert np.abs(free["tau"][101:] - ref["tau"][101:]).max() > 1.0


def test_payload_demo_runs_the_reference_loop():
    """rcac payload-demo's run (closed_loop with the grasp event) is the reference loop's."""
    from rcac_ros.tools.demos.payload import run_demo
    from rcac_ros.tools.runs.scenarios import (AMPLITUDE, FREQUENCY, find_panda_urdf, GAINS,
                                               gains_for, READY)
    if find_panda_urdf() is None:
        pytest.skip("example-robot-data's panda.urdf not installed")
    model, loaded, runs, _ = run_demo(0.4, 0.2, progress=False, laws=("composite",))
    traj = SinusoidTrajectory(np.array(READY), AMPLITUDE, FREQUENCY)
    q0, qd0, _ = traj(0.0)
    ctrl = RecursiveCompositeController(model, **gains_for(model, law="composite", **GAINS))
    ref = reference_loop(ctrl, traj, 0.4, model, q0, qd0, grasp=(0.2, loaded))
    for key in ref:
        np.testing.assert_array_equal(runs["composite"][key], ref[key], err_msg=key)


def test_attach_payload_matches_parallel_axis():
    """Parameter additivity (attach_payload) against payload-demo's parallel-axis sums."""
    from rcac_ros.tools.runs.scenarios import FLANGE, with_payload
    model = css_arm()
    for mass, com, radius in ((2.0, (0.03, -0.02, 0.08), 0.05), (80.0, (1.0, 0.5, -0.3), 0.4)):
        ref = with_payload(model, mass, com, radius)
        got = attach_payload(model, mass, np.add(FLANGE, com), 0.4 * mass * radius ** 2 *
                             np.eye(3))
        np.testing.assert_allclose(got.mass, ref.mass, rtol=1e-14)
        np.testing.assert_allclose(got.com, ref.com, atol=1e-14)
        np.testing.assert_allclose(got.inertia, ref.inertia, atol=1e-12)


def test_delay_and_noise_reach_the_controller():
    """The controller sees the true state of ``delay`` periods earlier plus N(0, sigma)."""
    model = css_arm()
    traj = PaperTrajectory(np.array(PAPER_Q0))
    rec = Recorder(RecursiveCompositeController(model))
    run = closed_loop(rec, traj, 2.0, delay=3)
    seen = np.array([s[0] for s in rec.seen])
    np.testing.assert_array_equal(seen[3:], run["q"][:-3])
    np.testing.assert_array_equal(seen[:3], np.repeat(run["q"][:1], 3, axis=0))
    rec = Recorder(RecursiveCompositeController(model))
    run = closed_loop(rec, traj, 2.0, noise_q=1e-3, noise_qd=[2e-3] * 7,
                      rng=np.random.default_rng(5))
    dq = np.array([s[0] for s in rec.seen]) - run["q"]
    dqd = np.array([s[1] for s in rec.seen]) - run["qd"]
    for d, sigma in ((dq, 1e-3), (dqd, 2e-3)):                 # 7007 samples each
        assert abs(d.std() / sigma - 1.0) < 0.03 and abs(d.mean()) < 0.05 * sigma
    assert abs(np.corrcoef(dq.ravel(), dqd.ravel())[0, 1]) < 0.05


def test_divergence_stops_the_run():
    """A gain far beyond stability: the run stops at the error limit and says so."""
    model = css_arm()
    traj = PaperTrajectory(np.array(PAPER_Q0), reading="position")
    run = closed_loop(RecursiveCompositeController(model, K_D=1e4, Lambda=1e4), traj, 2.0,
                      q0=np.array(PAPER_Q0), error_limit=0.5)
    m = run_metrics(run)
    assert m["diverged"] and m["status"] in ("error_limit", "nonfinite")
    assert m["t_end"] < 2.0 and len(run["t"]) < 1001


def test_strict_raises_what_the_controller_raises(tmp_path, capsys):
    """NaN/Inf: a campaign's run ends "nonfinite"; strict (rcac experiment) raises, one line."""
    from rcac_ros.core import InputError
    model = css_arm()
    traj = PaperTrajectory(np.array(PAPER_Q0), reading="position")
    gains = dict(h=0.05, Lambda=100.0)                        # unstable at this period

    run = closed_loop(RecursiveCompositeController(model, **gains), traj, 3.0)
    assert run["status"] == "nonfinite" and len(run["t"]) < 61
    with pytest.raises(InputError, match="contains NaN or Inf"):
        closed_loop(RecursiveCompositeController(model, **gains), traj, 3.0, strict=True)
    out = tmp_path / "experiment"
    assert cli.main(["experiment", "--duration", "3", "--h", "0.05", "--Lambda", "100",
                     "--trajectory", "position", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "contains NaN or Inf" in err, err
    assert not out.exists()


def test_check_estimates_stops_where_the_reference_loops_estimates_blow_up():
    """check_estimates (rcac compare): the run ends at the reference loop's first period whose
    updated theta_hat or E is not finite; the observer sees every period before it."""
    model = css_arm()
    traj = PaperTrajectory(np.array(PAPER_Q0), reading="position")
    gains = dict(h=0.02, Lambda=100.0)                        # unstable at this period
    ctrl = RecursiveCompositeController(model, **gains)
    q0, qd0, _ = traj(0.0)
    with np.errstate(all="ignore"):
        ref = reference_loop(ctrl, traj, 0.22, model, q0, qd0)      # periods 0..11
    # the estimates after period k: those before period k + 1, the last ones at the end
    after = np.concatenate([ref["theta_hat"][1:], ctrl.theta_hat[None]])
    finite = np.all(np.isfinite(after), axis=(1, 2)) & np.all(np.isfinite(ref["E"]), axis=1)
    assert finite[:-1].all() and not finite[-1]      # they blow up in the last period

    seen = []
    t0 = time.perf_counter()
    run = closed_loop(RecursiveCompositeController(model, **gains), traj, 3.0,
                      check_estimates=True,
                      observer=lambda k, c, sim: seen.append((k, c.theta_hat, sim.model)))
    elapsed = time.perf_counter() - t0
    assert run["status"] == "nonfinite" and len(run["t"]) == len(finite)
    for key in ref:
        np.testing.assert_array_equal(run[key], ref[key], err_msg=key)
    assert [k for k, _, _ in seen] == list(range(len(finite) - 1))
    np.testing.assert_array_equal([th for _, th, _ in seen], after[:-1])
    assert all(plant is model for _, _, plant in seen)
    assert 0.0 < run["step_time"] < elapsed
    # without the check the run goes on until the non-finite estimates reach the torque
    plain = closed_loop(RecursiveCompositeController(model, **gains), traj, 3.0)
    assert plain["status"] == "nonfinite" and len(plain["t"]) > len(finite)
    with pytest.raises(RcacError, match="theta_hat or E is not finite"):
        closed_loop(RecursiveCompositeController(model, **gains), traj, 3.0,
                    check_estimates=True, strict=True)


def test_runs_reproducible_from_campaign_and_index():
    """Run i's inputs and row do not depend on what ran before it."""
    c = cp.validate(SMALL)
    assert cp.run_count(c) == 20
    forward = [cp.sample(c, i) for i in range(20)]
    assert [cp.sample(c, i) for i in reversed(range(20))] == forward[::-1]
    assert {s["law"] for s in forward[0::2]} == {"direct"}        # grid cell = i % 2
    assert len({s["K_D"] for s in forward}) == 20
    a = cp.simulate(c, 7)
    cp.simulate(c, 3)
    b = cp.simulate(c, 7)
    for k in cp.TIMING:
        a.pop(k), b.pop(k)
    assert a == b
    # the payload really is in the plant: the row's parameter error is against it
    inputs, ctrl, kw = cp.setup(c, 7)
    assert kw["plant"].mass[-1] == pytest.approx(css_arm().mass[-1] + inputs["payload_mass"])


def test_shipped_campaigns_validate_and_build():
    for name, model, runs in (("robustness", "css_arm", 400), ("payload", "panda", 300)):
        c = cp.load(os.path.join(ROOT, "campaigns", f"{name}.yaml"))
        assert c["scenario"]["model"] == model and cp.run_count(c) == runs
        if model == "panda":
            from rcac_ros.tools.runs.scenarios import find_panda_urdf
            if find_panda_urdf() is None:
                pytest.skip("example-robot-data's panda.urdf not installed")
        inputs, ctrl, kw = cp.setup(c, 0)
        assert ctrl.h == 0.002


@pytest.mark.parametrize("change, key", [
    (lambda d: d.update(colour="red"), "colour: unknown key"),
    (lambda d: d["scenario"].update(modle="css_arm"), "scenario.modle: unknown key"),
    (lambda d: d["vary"].update(K_D={"normal": {"mean": 1e4, "std": -1.0}}),
     "vary.K_D.normal.std: must be >= 0"),
    (lambda d: d["vary"].update(delay={"grid": []}), "vary.delay.grid: empty list"),
    (lambda d: d.update(samples="ten"), "samples: expected a number"),
    (lambda d: d["vary"].update(noise_q={"gaussian": {"mean": 0, "std": 1}}),
     "vary.noise_q.gaussian: unknown distribution"),
    (lambda d: d["vary"].update(delay={"uniform": {"low": 0, "high": 3}}),
     "vary.delay.uniform: delay takes choice or grid"),
    (lambda d: d["vary"].update(payload_com={"choice": [[0, 0]]}),
     "vary.payload_com.choice[0]: expected a list of 3 numbers"),
    (lambda d: d["vary"].update(law={"choice": ["pid"]}), "vary.law.choice[0]: expected one"),
    (lambda d: d["scenario"]["gains"].update(P=[1, 2]), "scenario.gains.P: expected a number"),
])
def test_bad_campaign_one_line_exit_2(tmp_path, capsys, change, key):
    doc = yaml.safe_load(yaml.safe_dump(dict(SMALL, scenario=dict(SMALL["scenario"],
                                                                  gains={"K_D": 1e4}))))
    change(doc)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert cli.main(["sweep", str(path), "--out", str(tmp_path / "out"), "--workers", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"rcac sweep: error: {key}"), err
    assert not (tmp_path / "out").exists()


def test_bad_yaml_and_bad_numbers(tmp_path, capsys):
    path = tmp_path / "broken.yaml"
    path.write_text("seed: [1, 2\n")
    assert cli.main(["sweep", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not valid YAML" in err
    for args in (["--samples", "0"], ["--duration", "-1"], ["--workers", "x"],
                 ["--scheduler", "localhost"]):
        with pytest.raises(SystemExit) as exc:
            cli.main(["sweep", str(path), "--out", "o"] + args)
        assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        cli.main(["sweep", "rerun", "results", "-3"])
    assert exc.value.code == 2


def assert_same_row(got, ref):
    """Numbers equal to 1e-12 (relative), everything else equal."""
    for k, v in ref.items():
        if isinstance(v, float):
            assert got[k] == pytest.approx(v, rel=1e-12, abs=0.0, nan_ok=True), k
        else:
            assert got[k] == v, k


def rows(path):
    t = pq.read_table(path).drop(list(cp.TIMING)).to_pandas()
    return t.sort_values("run").reset_index(drop=True)


def test_ctrl_c_keeps_runs_and_resume_completes(tmp_path):
    """SIGINT mid-campaign keeps the finished runs; --resume runs the rest once each."""
    doc = dict(SMALL, samples=15, scenario=dict(SMALL["scenario"], duration=3.0))
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(doc))
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [sys.executable, "-m", "rcac_ros.tools.cli", "sweep", str(path), "--out", str(out),
           "--workers", "0", "--quiet"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 600          # generous: a loaded machine
    while len(list((out / "parts").glob("*.parquet"))) < 5 and proc.poll() is None:
        assert time.monotonic() < deadline, "fewer than 5 runs finished in 600 s"
        time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()[1]     # interrupted mid-campaign
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    kept = rows(out / "results.parquet")
    assert 5 <= len(kept) < 30 and "--resume continues" in err
    again = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert again.returncode == 2 and "--resume" in again.stderr       # never silently appends
    done = subprocess.run(cmd + ["--resume"], env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    full = rows(out / "results.parquet")
    assert list(full["run"]) == list(range(30))
    assert not list((out / "parts").glob("*"))
    # the kept runs were not rerun, and every row is the one run i gives alone
    c = cp.load(path)
    for i in (0, 29):
        ref = cp.simulate(c, i)
        for k in cp.TIMING:
            ref.pop(k)
        assert_same_row(full.iloc[i].to_dict(), ref)
    pd = pytest.importorskip("pandas")
    pd.testing.assert_frame_equal(full.iloc[kept["run"]].reset_index(drop=True), kept)


def test_report_and_rerun(tmp_path, capsys):
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(SMALL))
    out = tmp_path / "out"
    assert cli.main(["sweep", str(path), "--out", str(out), "--workers", "0", "--quiet"]) == 0
    capsys.readouterr()
    assert cli.main(["sweep", "report", str(out / "results.parquet"), "--worst", "3"]) == 0
    text = capsys.readouterr().out
    assert "20 of 20 runs" in text and "Spearman" in text and "K_D" in text
    assert (out / "report.png").stat().st_size > 10000
    df = rows(out / "results.parquet")
    # the sensitivity printed is the rank correlation (an independent computation: numpy ranks)
    ok = df[~df["diverged"]]
    rank = lambda v: np.argsort(np.argsort(v))  # noqa: E731
    rho = np.corrcoef(rank(ok["K_D"].to_numpy()), rank(ok["rms_tracking_error"].to_numpy()))[0, 1]
    line = next(s for s in text.splitlines() if s.strip().startswith("K_D "))
    assert float(line.split()[1]) == pytest.approx(rho, abs=1e-3)
    assert cli.main(["sweep", "rerun", str(out), "13"]) == 0
    text = capsys.readouterr().out
    assert "inputs identical, largest relative metric difference 0" in text
    assert (out / "rerun_13.png").exists()
    assert cli.main(["sweep", "rerun", str(out), "20"]) == 2


def test_channels_reach_the_controller_when_given(tmp_path, capsys):
    """``channels`` is passed to the recursive law only when the campaign gives it."""
    import inspect
    doc = dict(SMALL, samples=1, vary={"channels": {"grid": [[1], "all"]}})
    c = cp.validate(doc)
    assert [cp.sample(c, i)["channels"] for i in range(2)] == [[1], "all"]
    assert cp.validate(SMALL)["scenario"]["fixed"]["channels"] is None   # not passed
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(doc))
    code = cli.main(["sweep", str(path), "--out", str(tmp_path / "o"), "--workers", "0",
                     "--quiet"])
    if "channels" in inspect.signature(RecursiveCompositeController).parameters:
        assert code == 0
        assert cp.setup(c, 1)[1].channels == tuple(range(1, 8))
        df = rows(tmp_path / "o" / "results.parquet")
        assert df["channels"].tolist() == ['[1]', '"all"']
        # the report takes each channel set as a law of its own (one run each: the median is
        # that run's value)
        capsys.readouterr()
        assert cli.main(["sweep", "report", str(tmp_path / "o")]) == 0
        text = capsys.readouterr().out
        for ch, rms in zip(df["channels"], df["rms_tracking_error"]):
            label = f"composite {ch}"
            assert f"  {label} " in text.split("metric distributions")[0]   # failure rate
            line = next(x for x in text.splitlines()
                        if x.split()[:1] == ["rms_tracking_error"] and f" {label} " in x)
            assert float(line.split(label)[1].split()[0]) == pytest.approx(rms, rel=1e-3)
    else:                                   # a controller without channels: one clear line
        assert code == 2
        assert capsys.readouterr().err.startswith("rcac sweep: error: channels: this "
                                                  "controller does not take channels")


def test_friction_campaign_pairs_the_joint_terms_across_laws():
    """campaigns/friction.yaml (doc/design.md §7): both laws of a sample see the same plant
    joint terms, drawn per joint within the decade; composite_friction has the joint
    estimates, composite has not; the plant carries the terms."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    campaign = cp.load(os.path.join(root, "campaigns", "friction.yaml"))
    assert cp.run_count(campaign) == 2 * campaign["samples"]
    a, b, c = cp.sample(campaign, 0), cp.sample(campaign, 1), cp.sample(campaign, 2)
    assert {a["law"], b["law"]} == {"composite", "composite_friction"}
    for q in cp.PAIRED:
        assert a[q] == b[q] and a[q] != c[q]
    assert all(0.1 <= v <= 1.0 for v in a["joint_friction"])
    assert all(0.02 <= v <= 0.2 for v in a["joint_armature"])
    inputs, ctrl, kwargs = cp.setup(campaign, 1)
    np.testing.assert_array_equal(kwargs["plant"].damping, inputs["joint_damping"])
    np.testing.assert_array_equal(kwargs["plant"].armature, inputs["joint_armature"])
    assert ctrl.joint_friction == (inputs["law"] == "composite_friction")
    row = cp.input_columns(inputs)
    assert row["joint_friction_7"] == inputs["joint_friction"][6]


def test_paired_campaign_gives_every_grid_cell_the_same_draws():
    """``paired: true`` (doc/campaigns.md): the three geometries of a sample of
    campaigns/consistency.yaml get the same start and payload, the next sample others; the
    same file unpaired draws each run anew (the runs of one sample then differ)."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    path = os.path.join(root, "campaigns", "consistency.yaml")
    paired = cp.load(path)
    assert paired["paired"] and cp.run_count(paired) == 3 * paired["samples"]
    a, b, c = cp.sample(paired, 0), cp.sample(paired, 1), cp.sample(paired, 3)
    assert [a["geometry"], b["geometry"], cp.sample(paired, 2)["geometry"]] == \
        ["euclidean", "natural", "natural_log_det"]
    assert dict(a, geometry=None) == dict(b, geometry=None) == \
        dict(cp.sample(paired, 2), geometry=None)
    assert a["payload_mass"] != c["payload_mass"] and a["start_com_shift"] != c["start_com_shift"]
    doc = yaml.safe_load(open(path, encoding="utf-8"))
    doc.pop("paired")
    unpaired = cp.validate(doc)
    assert "paired" not in unpaired                       # the default: older results resume
    u0, u1 = cp.sample(unpaired, 0), cp.sample(unpaired, 1)
    assert u0 == a and u1["payload_mass"] != u0["payload_mass"]
    with pytest.raises(RcacError, match="^paired: expected true or false"):
        cp.validate(dict(doc, paired="yes"))
    from rcac_ros.tools.runs.scenarios import find_panda_urdf
    if find_panda_urdf() is None:
        pytest.skip("example-robot-data's panda.urdf not installed")
    (_, ctrl_a, kw_a), (_, ctrl_b, kw_b) = cp.setup(paired, 0), cp.setup(paired, 1)
    np.testing.assert_array_equal(kw_a["theta_hat0"], kw_b["theta_hat0"])
    np.testing.assert_array_equal(kw_a["events"][0][1].theta(), kw_b["events"][0][1].theta())
    assert {ctrl_a.geometry, ctrl_b.geometry} == {"euclidean", "natural"}


def test_the_natural_geometries_build_their_metric():
    """campaigns/consistency.yaml: ``natural`` (the default metric) and ``natural_barrier``
    build the natural law with the barrier metric and the campaign's ``barrier_c``,
    ``natural_log_det`` the log-det metric; the Slotine-Li law the same."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    three = cp.load(os.path.join(root, "campaigns", "consistency.yaml"))
    runs = [cp.sample(three, k) for k in range(3)]
    from rcac_ros.tools.runs.scenarios import find_panda_urdf
    if find_panda_urdf() is None:
        pytest.skip("example-robot-data's panda.urdf not installed")
    _, ctrl, _ = cp.setup(three, 1)
    assert (ctrl.geometry, ctrl.natural_metric, ctrl.barrier_c) == ("natural", "barrier", 1000.0)
    _, ctrl, _ = cp.setup(three, 2)
    assert (ctrl.geometry, ctrl.natural_metric, ctrl.barrier_c) == ("natural", "log_det", None)
    panda = cp.nominal_model("panda")
    ctrl = cp.controller_for(three, dict(runs[1], geometry="natural_barrier", barrier_c=30.0),
                             panda)
    assert (ctrl.natural_metric, ctrl.barrier_c) == ("barrier", 30.0)
    for geometry, metric, c in (("natural", "barrier", 30.0),
                                ("natural_log_det", "log_det", None)):
        ctrl = cp.controller_for(three, dict(runs[1], geometry=geometry, law="slotine_li",
                                             barrier_c=30.0), panda)
        assert (type(ctrl).__name__, ctrl.natural_metric, ctrl.barrier_c) == \
            ("SlotineLiCompositeController", metric, c)


def test_resume_into_a_directory_without_a_campaign_is_refused(tmp_path):
    """A mistyped --out with --resume would start a whole new campaign unnoticed."""
    from rcac_ros.errors import ConfigError
    from rcac_ros.tools.sweep.store import Store
    store = Store(str(tmp_path / "typo"))
    with pytest.raises(ConfigError, match="--resume: no campaign to continue in"):
        store.claim({"seed": 1}, resume=True)
    assert not os.path.exists(tmp_path / "typo")
    store.claim({"seed": 1})                            # a new campaign starts there
    store.claim({"seed": 1}, resume=True)               # and is then continued


def test_a_scheduler_that_refuses_the_connection_is_refused_before_the_directory(
        tmp_path, capsys):
    """A closed port: one line naming --scheduler, and no results directory claimed (Dask's
    client alone would retry the port for its whole timeout)."""
    import socket
    with socket.socket() as s:                          # a port nobody listens on now
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "out"
    code = cli.main(["sweep", os.path.join(ROOT, "campaigns", "channels_paper.yaml"),
                     "--out", str(out), "--scheduler", f"tcp://127.0.0.1:{port}"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith(
        f"rcac sweep: error: --scheduler: cannot connect to tcp://127.0.0.1:{port}"), err
    assert not out.exists()
