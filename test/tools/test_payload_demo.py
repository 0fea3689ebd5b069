"""The payload demo: adaptive laws recover from an unknown payload, the fixed law does not."""

import json

import numpy as np
import pytest

from rcac_ros.tools.runs import scenarios
from rcac_ros.tools.demos import payload as demo

pin = pytest.importorskip("pinocchio")
pytestmark = pytest.mark.skipif(scenarios.find_panda_urdf() is None,
                                reason="example-robot-data's panda.urdf not installed")

JUMP, DURATION, WINDOW = 1.0, 4.0, 1.0


@pytest.fixture(scope="module")
def short_run():
    model, loaded, runs, report = demo.run_demo(DURATION, JUMP, progress=False)
    return model, loaded, runs


def rms(run, start, stop):
    sel = (run["t"] >= start) & (run["t"] < stop)
    return float(np.sqrt(np.mean((run["q"][sel] - run["q_d"][sel]) ** 2)))


def test_payload_is_a_rigid_body_sum(short_run):
    model, loaded, _ = short_run
    # independent reference: Pinocchio's inertia algebra (sum of two bodies about their com)
    c_p = np.array(scenarios.FLANGE) + [0.03, -0.02, 0.08]
    ref = (pin.Inertia(model.mass[-1], model.com[-1], model.inertia[-1])
           + pin.Inertia(2.0, c_p, 0.4 * 2.0 * 0.05 ** 2 * np.eye(3)))
    assert loaded.mass[-1] == pytest.approx(ref.mass, rel=1e-14)
    np.testing.assert_allclose(loaded.com[-1], ref.lever, rtol=0, atol=1e-14)
    np.testing.assert_allclose(loaded.inertia[-1], ref.inertia, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(loaded.theta()[:-1], model.theta()[:-1])


def test_adaptive_laws_recover_and_the_fixed_law_does_not(short_run):
    model, loaded, runs = short_run
    before = {law: rms(r, JUMP - WINDOW, JUMP) for law, r in runs.items()}
    first = {law: rms(r, JUMP, JUMP + WINDOW) for law, r in runs.items()}
    last = {law: rms(r, DURATION - WINDOW, DURATION + 1) for law, r in runs.items()}
    # with the true (nominal) parameters, every law tracks closely before the jump
    assert max(before.values()) < 1e-4, before
    # the payload throws the fixed law off for good
    assert last["fixed"] > 100 * before["fixed"], (before, last)
    assert last["fixed"] > 0.3 * first["fixed"], (first, last)
    for law in ("composite", "direct"):
        assert last[law] < 0.5 * first[law], (law, first, last)
        assert last[law] < 0.1 * last["fixed"], (law, last)


def test_estimates_find_the_payload(short_run):
    model, loaded, runs = short_run
    truth, nominal = loaded.theta()[-1], model.theta()[-1]
    # P = 1e-12 I: the fixed law keeps its nominal estimates (to round-off)
    fixed = runs["fixed"]["theta_hat"][:, -1]
    np.testing.assert_allclose(fixed, np.broadcast_to(nominal, fixed.shape), rtol=0, atol=1e-9)
    for law in ("composite", "direct"):
        assert runs[law]["theta_hat"][-1, -1, 0] == pytest.approx(truth[0], rel=0.05)
    # the composite law pins down the first moments much better than the direct one
    err = {law: np.linalg.norm(runs[law]["theta_hat"][-1, -1, 1:4] - truth[1:4])
           for law in ("composite", "direct")}
    assert err["composite"] < 0.5 * err["direct"], err


def test_cli_writes_metrics_and_figures(tmp_path):
    from rcac_ros.tools.cli import main
    out = tmp_path / "payload"
    code = main(["payload-demo", "--duration", "1.5", "--jump", "0.5", "--out", str(out),
                 "--quiet"])
    assert code == 0
    report = json.loads((out / "metrics.json").read_text())
    assert set(report) == {"composite", "direct", "fixed", "settings"}
    assert report["composite"]["link7_mass_true"] == pytest.approx(
        report["composite"]["link7_mass_nominal"] + 2.0)
    for name in ("tracking_errors.png", "payload_summary.png", "link7_estimates.png"):
        assert (out / name).stat().st_size > 1000


def test_cli_rejects_a_jump_after_the_end(tmp_path):
    from rcac_ros.tools.cli import main
    assert main(["payload-demo", "--duration", "1", "--jump", "2", "--out",
                 str(tmp_path), "--quiet"]) == 2
