"""Both nodes as subprocesses (isolated domain, localhost discovery), against the offline run."""

import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from lockstep_support import (assert_lockstep_states, H, lockstep_run, matched, offline,
                              tracking_probe)
from test_nodes_support import (CONFIG, DEEP, node_cmd, PAPER_Q0, Probe, ROOT, ros_context,
                                ros_domain, spin_until, start, stop)

from std_msgs.msg import Float64MultiArray  # noqa: E402

from rcac_ros.core.model import css_arm  # noqa: E402
from rcac_ros.core.simulator import Simulator  # noqa: E402

DURATION = 3.0


def offline_css(steps, reading="velocity"):
    """The experiment without ROS: the core Simulator under the controller, same settings."""
    return offline(steps, Simulator(css_arm(), dt=H, q0=PAPER_Q0), reading)


def test_lockstep_matches_the_offline_experiment():
    steps = round(DURATION / H)
    ref_q, ref_err, ref_theta = offline_css(steps)
    with ros_context() as (ctx, ex):
        probe = Probe(ctx, record=("states",))
        track, theta = [], []
        subs = [
            probe.create_subscription(Float64MultiArray, "/rcac_controller/tracking_error",
                                      lambda m: track.append(np.array(m.data)), DEEP),
            probe.create_subscription(Float64MultiArray,
                                      "/rcac_controller/parameter_estimates", theta.append,
                                      DEEP)]
        ex.add_node(probe)
        readers, (sim_code, sim_out), (ctrl_code, ctrl_out) = lockstep_run(
            ex, probe, subs, lambda: len(theta) >= steps + 1, f"duration:={DURATION}")
    assert sim_code == 0, sim_out
    assert ctrl_code == 0, ctrl_out
    # an effort for every state, and every state the offline one at the same step
    assert_lockstep_states(probe.states, ref_q, steps, readers, sim_out)
    # the tracking error stays what the offline run gives over the same seconds
    track = np.array(track)
    assert track.shape[1] == 7 and len(track) >= steps
    np.testing.assert_allclose(np.sqrt(np.mean(track[:steps + 1] ** 2, axis=0)),
                               np.sqrt(np.mean(ref_err ** 2, axis=0)), rtol=1e-6)
    # the estimates: documented layout, and the offline values at the end
    last = theta[-1]
    dims = [(d.label, d.size, d.stride) for d in last.layout.dim]
    assert dims == [("link", 7, 91), ("parameter", 13, 13)]
    assert len(last.data) == 91
    np.testing.assert_allclose(np.reshape(last.data, (7, 13)), ref_theta, rtol=1e-6,
                               atol=1e-9)


def test_positions_only_states_still_track():
    """The simulator publishes no velocities: the controller estimates them and still tracks."""
    steps = round(1.0 / H)
    _, ref_err, _ = offline_css(steps)
    with ros_context() as (ctx, ex):
        probe, track, sub = tracking_probe(ctx, ex)
        _, (sim_code, sim_out), _ = lockstep_run(
            ex, probe, [sub], lambda: len(track) >= steps + 1, "duration:=1.0",
            "publish_velocity:=false")
    assert sim_code == 0, sim_out
    assert all(len(m.velocity) == 0 for m in probe.states)
    worst = np.max(np.abs(np.array(track)))
    # the offline error is ~1e-6 rad; a missing velocity would give errors of ~1e-2
    assert worst < 10.0 * np.max(np.abs(ref_err)) + 1e-5, worst


def test_sigint_publishes_one_zero_effort_and_exits_zero():
    with ros_context() as (ctx, ex):
        probe = Probe(ctx)
        ex.add_node(probe)
        ctrl = start("controller_node", "state_timeout:=1.0",
                     params_file=os.path.join(CONFIG, "controller.yaml"))
        try:
            assert spin_until(ex, lambda: probe.pub_state.get_subscription_count() > 0,
                              timeout=60.0)
            matched(ex, [probe.subs["efforts"]])
            for k in range(5):
                answered = lambda: sum("stamp=" in lab for lab, _ in probe.efforts) > k  # noqa
                # re-send while unanswered: the first state can be lost while discovery
                # settles; the controller answers a repeated state without stepping twice
                while not answered():
                    probe.state(k * 2_000_000, PAPER_Q0 + 0.01, np.zeros(7))
                    spin_until(ex, answered, timeout=0.5)
                    assert ctrl.poll() is None
            # (before the first state the watchdog sent zeros; the answers are not zero)
            assert not np.allclose(probe.efforts[-1][1], 0.0)
            n = len(probe.efforts)
            ctrl.send_signal(signal.SIGINT)
            assert spin_until(ex, lambda: any("stamp=" not in lab
                                              for lab, _ in probe.efforts[n:]), timeout=20.0)
            ctrl.wait(timeout=20.0)
        finally:
            code, out = stop(ctrl)
    assert code == 0, out
    # after the signal: exactly one zero effort (answers to re-sent states may still come)
    final = [d for lab, d in probe.efforts[n:] if "stamp=" not in lab]
    assert len(final) == 1
    np.testing.assert_array_equal(final[0], np.zeros(7))
    assert "Traceback" not in out


def test_sigint_in_timer_mode_joins_the_input_threads_and_exits_zero():
    """Timer mode reads its states and trajectories in threads of their own, waiting in rcl:
    a SIGINT must end them before the interpreter exits (a thread still waiting there is
    ended inside C++ code and the process aborts, exit 134)."""
    with ros_context() as (ctx, ex):
        probe = Probe(ctx)
        ex.add_node(probe)
        ctrl = start("controller_node", "mode:=timer", "trajectory:=topic",
                     params_file=os.path.join(CONFIG, "controller.yaml"))
        try:
            matched(ex, [probe.subs["efforts"]])
            assert spin_until(ex, lambda: len(probe.efforts) > 10, timeout=60.0)
            # the input threads have work: states come while the signal arrives
            for k in range(50):
                probe.state(k * 2_000_000, PAPER_Q0, np.zeros(7))
                ex.spin_once(timeout_sec=0.002)
        finally:
            code, out = stop(ctrl)
    assert code == 0, out
    assert "terminate called" not in out and "Traceback" not in out, out


#: the controller's main, with a SIGTERM sent from inside a finalizer once it is active:
#: Python runs the handler there and drops the KeyboardInterrupt it raises
DROPPED_INTERRUPT = """
import os, signal, sys
from rcac_ros.nodes.controller import node as cn
from rcac_ros.nodes.runtime.base import run
class Finalized:
    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        sum(range(1000))
activate = cn.ControllerNode._activate
def activate_then_signal(self):
    activate(self)
    self.create_timer(0.2, Finalized)
cn.ControllerNode._activate = activate_then_signal
sys.exit(run(cn.ControllerNode, "controller", ["controller"]))
"""

#: the same, with the node ending (exit code 1, as after a fault of a side thread) in the
#: callback whose finalizer sends the signal
FINISHED_THEN_DROPPED = DROPPED_INTERRUPT.replace("""    self.create_timer(0.2, Finalized)""", """
    def fail():
        self.exit_code, self.finished = 1, True
        return Finalized()
    self.create_timer(0.2, fail)""")

#: the simulator's main, waiting for a robot description that never comes, with the signal
#: sent from a finalizer as above
WAITING_FOR_DESCRIPTION = """
import os, signal, sys
from rcac_ros.nodes.runtime import description
from rcac_ros.nodes.runtime.base import run
from rcac_ros.nodes.simulator.node import SimulatorNode
class Finalized:
    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        sum(range(1000))
subscribe = description.subscribe_description
def subscribe_then_signal(node, topic, callback):
    node.create_timer(0.5, Finalized)
    return subscribe(node, topic, callback)
description.subscribe_description = subscribe_then_signal
sys.exit(run(SimulatorNode, "simulator",
             ["simulator", "--ros-args", "-p", "description_topic:=/robot_description"]))
"""

#: the controller's main, interrupted (as by SIGTERM) at the end of configure, while the node
#: is being built: its input threads are running, waiting in rcl
INTERRUPT_IN_CONFIGURE = """
import sys
from rcac_ros.nodes.controller import node as cn
from rcac_ros.nodes.runtime.base import run
configure = cn.ControllerNode._configure
def configure_then_interrupt(self, values):
    configure(self, values)
    raise KeyboardInterrupt
cn.ControllerNode._configure = configure_then_interrupt
sys.exit(run(cn.ControllerNode, "controller", ["controller"]))
"""


def run_script(source, timeout=60.0):
    """Run ``source`` in a Python process (isolated domain): ``(exit code or None if it had
    to be killed after ``timeout`` s, output)``."""
    with ros_domain():
        proc = subprocess.Popen([sys.executable, "-c", source], stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, cwd=ROOT)
        try:
            out, _ = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            return None, proc.communicate()[0]
    return proc.returncode, out


def test_an_interrupt_that_python_drops_still_stops_the_node():
    """A signal handled inside a finalizer or a collector callback loses its exception; the
    node must stop all the same (once, with its zero effort), not run on deaf to signals."""
    code, out = run_script(DROPPED_INTERRUPT)
    assert "Exception ignored" in out and "KeyboardInterrupt" in out, out   # it was dropped
    assert code == 0, out
    assert out.count("inactive: one zero effort sent") == 1, out


def test_an_interrupt_that_python_drops_after_the_node_ended_keeps_its_exit_code():
    code, out = run_script(FINISHED_THEN_DROPPED)
    assert "Exception ignored" in out, out
    assert code == 1, out


def test_an_interrupt_that_python_drops_while_waiting_for_the_description_counts():
    code, out = run_script(WAITING_FOR_DESCRIPTION)
    assert "Exception ignored" in out and "waiting for the robot description" in out, out
    assert code == 0, out


def test_an_interrupt_while_configuring_leaves_no_thread_behind():
    """SIGINT/SIGTERM during autostart's configure: the half-built node's input threads are
    joined (a thread left waiting in rcl at exit aborts the process, exit 134)."""
    code, out = run_script(INTERRUPT_IN_CONFIGURE)
    assert "configured:" in out, out
    assert code == 0, out
    assert "terminate called" not in out and "Traceback" not in out, out


@pytest.mark.parametrize("module, text, name", [
    ("controller_node", "    K_D: -5.0\n", "K_D"),
    ("controller_node", "    model: nonsense_arm\n", "model"),
    ("controller_node", "    joints: [joint1, joint2]\n", "joints"),
    ("simulator_node", "    q0: [0.0, 1.0]\n", "q0"),
    ("simulator_node", "    dt: -0.002\n", "dt"),
])
def test_bad_parameter_file_is_refused_cleanly(tmp_path, module, text, name):
    node = "rcac_controller" if module == "controller_node" else "rcac_simulator"
    path = tmp_path / "bad.yaml"
    path.write_text(f"{node}:\n  ros__parameters:\n{text}")
    with ros_domain():
        proc = subprocess.run(node_cmd(module, params_file=path), capture_output=True, text=True,
                              timeout=120, cwd=ROOT)
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr + proc.stdout
    errors = [ln for ln in proc.stderr.splitlines() if "error" in ln]
    assert len(errors) == 1 and f"error: {name}:" in errors[0], proc.stderr


def test_simulator_realtime_mode_paces_on_the_steady_clock():
    """Realtime: free-running at about 1/dt, with no effort (and use_sim_time set).

    The probe offers an effort publisher that never publishes, so the simulator starts
    only once the probe is matched (else its 1 s can pass before the probe subscribes).
    """
    with ros_context() as (ctx, ex):
        probe = Probe(ctx)
        probe.create_publisher(Float64MultiArray, "/effort_controller/commands", DEEP)
        ex.add_node(probe)
        sim = start("simulator_node", "mode:=realtime", "wait_for_controller:=true",
                    "duration:=1.0", "use_sim_time:=true",
                    params_file=os.path.join(CONFIG, "simulator.yaml"))
        try:
            assert spin_until(ex, lambda: sim.poll() is not None, timeout=90.0)
        finally:
            code, out = stop(sim)
    assert code == 0, out
    assert "finished: 500 steps" in out
    # no effort: the arm stays at q0 (g = 0, zero velocity)
    np.testing.assert_allclose(probe.states[-1].position, PAPER_Q0, atol=1e-12)
