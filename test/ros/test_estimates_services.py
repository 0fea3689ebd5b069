"""The operator's estimate services (std_srvs) on the running controller, from another process."""

import numpy as np

from test_nodes_support import DEEP, JOINTS, ros_context, spin_until, start, stop

from rclpy.node import Node  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from std_srvs.srv import SetBool, Trigger  # noqa: E402

from rcac_ros.nodes.controller.estimates import load  # noqa: E402

NODE = "/rcac_controller"


class Operator(Node):
    """Calls the controller's services and records its estimates."""

    def __init__(self, context, executor):
        super().__init__("operator", context=context)
        self.ex = executor
        self.theta = []
        self.sub = self.create_subscription(
            Float64MultiArray, f"{NODE}/parameter_estimates",
            lambda m: self.theta.append(np.reshape(m.data, (7, 13))), DEEP)
        self.services_ = {name: self.create_client(kind, f"{NODE}/{name}") for name, kind in (
            ("reset_estimates", Trigger), ("set_adaptation", SetBool),
            ("save_estimates", Trigger))}
        executor.add_node(self)

    def call(self, name, **fields):
        client = self.services_[name]
        assert spin_until(self.ex, client.service_is_ready, timeout=60.0), name
        future = client.call_async(client.srv_type.Request(**fields))
        assert spin_until(self.ex, future.done, timeout=60.0), name
        return future.result()

    def wait_steps(self, count):
        n = len(self.theta)
        assert spin_until(self.ex, lambda: len(self.theta) >= n + count, timeout=60.0)
        return self.theta[n:]

    def wait_still(self, count=50, timeout=60.0):
        """Spin until the last ``count`` estimates received are equal: the estimates sent
        before a freeze, still queued here when a loaded test process lags behind the
        lockstep loop, are drained. Estimates that keep moving never get there."""
        def still():
            last = self.theta[-count:]
            return len(last) == count and all(np.array_equal(t, last[-1]) for t in last)
        return spin_until(self.ex, still, timeout=timeout)


def test_freeze_resume_save_reset_and_restart_from_the_file(tmp_path):
    path = str(tmp_path / "est.yaml")
    with ros_context() as (ctx, ex):
        op = Operator(ctx, ex)
        ctrl = start("controller_node", f"estimates_file:={path}")
        sim = start("simulator_node")
        try:
            assert spin_until(ex, lambda: op.sub.get_publisher_count() > 0, timeout=60.0)
            op.wait_steps(200)
            assert not np.allclose(op.theta[-1], 0.0)        # it adapts
            # freeze: the estimates stop moving, control goes on
            res = op.call("set_adaptation", data=False)
            assert res.success and "frozen" in res.message
            assert op.wait_still()
            frozen = [op.theta[-1]] + op.wait_steps(50)
            assert all(np.array_equal(t, frozen[0]) for t in frozen)
            # save: YAML at estimates_file, the response names it
            res = op.call("save_estimates")
            assert res.success and path in res.message, res.message
            saved = load(path, JOINTS)
            np.testing.assert_array_equal(saved, frozen[0])
            # resume: they move again
            assert op.call("set_adaptation", data=True).success
            assert spin_until(ex, lambda: not np.array_equal(op.theta[-1], frozen[0]),
                              timeout=30.0)
            # reset (while frozen, so nothing moves after it): back to the initial zero
            assert op.call("set_adaptation", data=False).success
            res = op.call("reset_estimates")
            assert res.success, res.message
            assert spin_until(ex, lambda: np.array_equal(op.theta[-1], np.zeros((7, 13))),
                              timeout=30.0)
            np.testing.assert_array_equal(op.wait_steps(20)[-1], np.zeros((7, 13)))
        finally:
            stop(sim)
            code, out = stop(ctrl)
        assert code == 0, out
        # restart from the file (no simulator: nothing steps): the same estimates come back
        again = str(tmp_path / "again.yaml")
        ctrl = start("controller_node", f"initial_estimates:={path}",
                     f"estimates_file:={again}")
        try:
            res = op.call("save_estimates")
            assert res.success and again in res.message, res.message
        finally:
            code, out = stop(ctrl)
    assert code == 0, out
    np.testing.assert_array_equal(load(again, JOINTS), saved)
    assert again.replace(".yaml", ".inertial.urdf") in res.message     # the URDF fragment


def test_joint_terms_published_saved_and_restored(tmp_path):
    """joint_friction: true (doc/design.md §7): ~/friction_estimates (labelled, 7 x 3) moves;
    frozen and saved, the file holds them; a controller started from the file has them."""
    from rcac_ros.nodes.controller.estimates import load_joint_terms
    path = str(tmp_path / "est.yaml")
    with ros_context() as (ctx, ex):
        op = Operator(ctx, ex)
        friction, labels = [], []

        def on_friction(msg):
            labels.append(tuple(d.label for d in msg.layout.dim))
            friction.append(np.reshape(msg.data, (7, 3)))
        op.create_subscription(Float64MultiArray, f"{NODE}/friction_estimates", on_friction,
                               DEEP)
        ctrl = start("controller_node", f"estimates_file:={path}", "joint_friction:=true",
                     "P_friction:=[1.0, 50.0, 50.0]")
        sim = start("simulator_node")
        try:
            ok = spin_until(ex, lambda: len(friction) > 200, timeout=120.0)
            assert ok, (len(op.theta), len(friction), stop(ctrl)[1][-3000:])
            assert labels[-1] == ("joint", "armature,damping,friction")
            assert not np.allclose(friction[-1], 0.0)                  # they adapt from zero
            assert op.call("set_adaptation", data=False).success
            n = len(friction)
            # frozen: the published terms stop moving (the reply may be taken before monitor
            # messages sent ahead of it, on a loaded machine: wait for a still tail)
            assert spin_until(ex, lambda: len(friction) > n + 50
                              and all(np.array_equal(f, friction[-1]) for f in friction[-20:]),
                              timeout=60.0), [np.abs(f - friction[-1]).max()
                                              for f in friction[-20:]]
            held = friction[-1]
            res = op.call("save_estimates")
            assert res.success, res.message
            np.testing.assert_array_equal(load_joint_terms(path, JOINTS), held)
            res = op.call("reset_estimates")
            assert res.success
            assert spin_until(ex, lambda: np.array_equal(friction[-1], np.zeros((7, 3))),
                              timeout=30.0)
        finally:
            stop(sim)
            code, out = stop(ctrl)
        assert code == 0, out
        again = str(tmp_path / "again.yaml")
        ctrl = start("controller_node", f"initial_estimates:={path}", "joint_friction:=true",
                     f"estimates_file:={again}")
        try:
            assert op.call("save_estimates").success
        finally:
            code, out = stop(ctrl)
    assert code == 0, out
    np.testing.assert_array_equal(load_joint_terms(again, JOINTS), held)
    text = open(again.replace(".yaml", ".inertial.urdf"), encoding="utf-8").read()
    assert text.count("<dynamics") == 7
