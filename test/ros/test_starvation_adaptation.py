"""The two reasons that freeze the adaptation of eq 24 (``nodes/controller/freeze.py``,
doc/failsafe.md "Starved machine"): the operator's ``~/set_adaptation`` and the starvation
guard each hold their own, and the law is frozen while either holds, whichever order they
come in. The guard runs on a steady clock of the test's; whether the law is frozen is read
from the estimates themselves (a step that would adapt leaves ``theta_hat`` unchanged)."""

import types

import numpy as np
import pytest

from std_srvs.srv import SetBool

from rcac_ros.core import RecursiveCompositeController, css_arm
from rcac_ros.core.model import PAPER_GAINS, PAPER_Q0
from rcac_ros.nodes.controller import starvation
from rcac_ros.nodes.controller.freeze import AdaptationFreeze
from rcac_ros.nodes.controller.estimate_services import EstimateServices
from rcac_ros.nodes.controller.starvation import Starvation

H = PAPER_GAINS["h"]
H_NS = round(H * 1e9)


class Logger:
    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(text)

    warning = info


class Machine:
    """A controller node's parts that the guard and the service use, on a fake clock."""

    def __init__(self, monkeypatch):
        model = css_arm()
        gains = {k: v for k, v in PAPER_GAINS.items() if k != "h"}
        ctrl = RecursiveCompositeController(model, h=H, **gains)
        self.log = Logger()
        self.ctrl, adaptation = ctrl, AdaptationFreeze(ctrl)
        self.received = 0           # steady ns of the state a step uses
        self.now = 10 ** 12
        monkeypatch.setattr(starvation, "time",
                            types.SimpleNamespace(monotonic_ns=lambda: self.now))
        self.guard = Starvation({"starvation.delay_margin": None,
                                 "starvation.recover_after": 0.1,
                                 "starvation.min_scale": 0.02},
                                ctrl=ctrl, adaptation=adaptation, h=H, q0=None,
                                state_received=lambda: self.received, log=self.log)
        self.guard.prepare()        # the node's warm-up thread does this after compiling
        host = types.SimpleNamespace(create_service=lambda *args: None)     # no ROS here
        self.services = EstimateServices(
            host, ctrl=ctrl, adaptation=adaptation, model=model, theta0=ctrl.theta_hat,
            friction0=None, initial="zero", urdf_links=None, estimates_file=lambda: "",
            log=self.log)
        self.q = np.array(PAPER_Q0)

    def run(self, seconds, age):
        """Control steps every period on states ``age`` s old; the guard's events."""
        events = []
        for _ in range(round(seconds / H)):
            self.now += H_NS
            self.received = self.now - round(age * 1e9)
            starved = self.guard.guard.starved
            self.guard.step()
            if self.guard.guard.starved != starved:
                events.append("starved" if not starved else "recovered")
        return events

    def starve(self):
        assert self.run(0.2, 0.05) == ["starved"]

    def recover(self):
        assert self.run(1.0, 0.0) == ["recovered"]

    def set_adaptation(self, on):
        response = self.services._set_adaptation(SetBool.Request(data=on),
                                                 SetBool.Response())
        assert response.success
        return response.message

    def learns(self):
        """A step off the desired motion changes the estimates (the law adapts)."""
        ctrl = self.ctrl
        before = ctrl.theta_hat.copy()
        for _ in range(3):
            ctrl.step(self.q, np.zeros(7), self.q + 0.1, np.ones(7), np.ones(7))
        return not np.array_equal(ctrl.theta_hat, before)


@pytest.fixture
def machine(monkeypatch):
    return Machine(monkeypatch)


def test_starvation_alone_freezes_and_its_recovery_resumes(machine):
    assert machine.learns()
    machine.starve()
    assert not machine.learns() and machine.ctrl.K_D_scale < 1.0
    machine.recover()
    assert machine.learns() and machine.ctrl.K_D_scale == 1.0
    assert machine.log.lines[-1].startswith("starvation over: nominal K_D and adaptation again")


def test_a_user_freeze_during_starvation_outlasts_the_recovery(machine):
    machine.starve()
    assert machine.set_adaptation(False).startswith("adaptation frozen")
    machine.recover()
    assert not machine.learns()                     # still the user's freeze
    assert "adaptation still frozen (by set_adaptation)" in machine.log.lines[-1]
    assert machine.set_adaptation(True) == "adaptation resumed"
    assert machine.learns()


def test_a_user_resume_during_starvation_waits_for_the_recovery(machine):
    machine.set_adaptation(False)
    machine.starve()
    message = machine.set_adaptation(True)
    assert "still frozen by the starvation guard" in message
    assert not machine.learns()                     # the guard's freeze holds
    machine.recover()
    assert machine.learns()


def test_a_user_freeze_before_starvation_outlasts_the_recovery(machine):
    machine.set_adaptation(False)
    machine.starve()
    machine.recover()
    assert not machine.learns()
    machine.set_adaptation(True)
    assert machine.learns()
