"""URDF loading checked against Pinocchio on real robots and on synthetic URDFs."""

import os

import numpy as np
import pytest

from rcac_ros.core import ConfigError, ModelError
from rcac_ros.core.model import rot_x
from rcac_ros.core.rnea import inverse_dynamics
from rcac_ros.core.urdf import model_from_urdf
from rcac_ros.tools.runs.robots import example_robots_dir

pin = pytest.importorskip("pinocchio")

TOL = 1e-9


ROBOTS = example_robots_dir()
PANDA = None if ROBOTS is None else os.path.join(ROBOTS, "panda_description/urdf/panda.urdf")
UR5 = None if ROBOTS is None else os.path.join(ROBOTS, "ur_description/urdf/ur5_robot.urdf")
needs_robots = pytest.mark.skipif(ROBOTS is None, reason="example-robot-data not installed")


def _core(name):
    import rcac_ros.core as core
    fn = getattr(core, name, None)
    if fn is None:
        pytest.skip(f"rcac_ros.core.{name} not available yet")
    return fn


# ---------------------------------------------------------------------- Pinocchio side
def pin_reference(pm, joint_names):
    """Lock every joint of ``pm`` that is not in ``joint_names`` at its neutral position."""
    lock = [pm.getJointId(nm) for nm in list(pm.names)[1:] if nm not in joint_names]
    if lock:
        pm = pin.buildReducedModel(pm, lock, pin.neutral(pm))
    assert list(pm.names)[1:] == list(joint_names)
    assert pm.nv == len(joint_names)
    return pm


def pin_q(pm, q):
    """Pinocchio's configuration of joint angles ``q`` (continuous joints are (cos, sin))."""
    out = []
    for jm, qi in zip(list(pm.joints)[1:], q):
        out += [np.cos(qi), np.sin(qi)] if jm.nq == 2 else [qi]
    return np.array(out)


def rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - b)) / max(np.max(np.abs(b)), 1e-300))


def compare(model, pm, rng, states=20, gravity=True):
    """Max relative errors of inverse dynamics, mass matrix and forward dynamics.

    Pinocchio reads each joint's ``<dynamics damping friction>`` into its model but no
    algorithm of it uses them: the joint friction of doc/design.md §7 is added to its RNEA
    and taken off ABA's torque from Pinocchio's own reading of the URDF.
    """
    if gravity:
        pm.gravity.linear = np.array(model.gravity)
    data = pm.createData()
    mass_matrix = _core("mass_matrix")
    forward_dynamics = _core("forward_dynamics")
    err = dict(inverse_dynamics=0.0, mass_matrix=0.0, forward_dynamics=0.0)
    for _ in range(states):
        q = rng.uniform(-np.pi, np.pi, model.n)
        qd = rng.uniform(-2.0, 2.0, model.n)
        qdd = rng.uniform(-5.0, 5.0, model.n)
        tau = rng.uniform(-10.0, 10.0, model.n)
        pq = pin_q(pm, q)
        tf = pm.damping * qd + pm.friction * np.tanh(qd / model.friction_velocity)
        err["inverse_dynamics"] = max(err["inverse_dynamics"], rel(
            inverse_dynamics(model, q, qd, qdd), pin.rnea(pm, data, pq, qd, qdd) + tf))
        M = pin.crba(pm, data, pq)
        M = np.triu(M) + np.triu(M, 1).T
        err["mass_matrix"] = max(err["mass_matrix"], rel(mass_matrix(model, q), M))
        err["forward_dynamics"] = max(err["forward_dynamics"], rel(
            forward_dynamics(model, q, qd, tau), pin.aba(pm, data, pq, qd, tau - tf)))
    return err


# ---------------------------------------------------------------------- real robots
@needs_robots
def test_panda_arm_matches_pinocchio():
    model = model_from_urdf(PANDA, tip_link="panda_link8")
    assert model.joint_names == tuple(f"panda_joint{k}" for k in range(1, 8))
    np.testing.assert_array_equal(model.effort_limit, [87, 87, 87, 87, 12, 12, 12])
    np.testing.assert_array_equal(model.velocity_limit, [2.175] * 4 + [2.61] * 3)
    assert model.position_lower[3] == -3.0718 and model.position_upper[3] == -0.0698
    np.testing.assert_array_equal(model.gravity, [0.0, 0.0, -9.81])
    # link 7 carries link8 (massless), the hand and the (locked) fingers
    assert model.mass[6] == pytest.approx(0.735522 + 0.73 + 2 * 0.015, rel=1e-12)
    pm = pin_reference(pin.buildModelFromUrdf(PANDA), model.joint_names)
    err = compare(model, pm, np.random.default_rng(1))
    print("panda", err)
    assert max(err.values()) < TOL, err


@needs_robots
def test_ur5_matches_pinocchio():
    model = model_from_urdf(UR5)        # one path of moving joints: the tip is found
    assert model.joint_names == ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                 "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")
    np.testing.assert_array_equal(model.effort_limit, [150, 150, 150, 28, 28, 28])
    pm = pin_reference(pin.buildModelFromUrdf(UR5), model.joint_names)
    err = compare(model, pm, np.random.default_rng(2))
    print("ur5", err)
    assert max(err.values()) < TOL, err


@needs_robots
def test_ur5_from_an_inner_base_link_is_the_arm_with_joint1_locked():
    model = model_from_urdf(UR5, base_link="shoulder_link")
    assert model.joint_names[0] == "shoulder_lift_joint" and model.n == 5
    pm = pin_reference(pin.buildModelFromUrdf(UR5), model.joint_names)
    err = compare(model, pm, np.random.default_rng(3), states=5)
    assert max(err.values()) < TOL, err


@needs_robots
@pytest.mark.parametrize("path", [
    "xarm_description/urdf/xarm7.urdf", "z1_description/urdf/z1.urdf",
    "so_arm_description/urdf/so101.urdf", "kinova_description/robots/kinova.urdf",
    "double_pendulum_description/urdf/double_pendulum_continuous.urdf"])
def test_more_arms_match_pinocchio(path):
    path = os.path.join(ROBOTS, path)
    if not os.path.isfile(path):
        pytest.skip(f"{path} not in this example-robot-data")
    model = model_from_urdf(path)
    pm = pin_reference(pin.buildModelFromUrdf(path), model.joint_names)
    err = compare(model, pm, np.random.default_rng(7), states=5)
    assert max(err.values()) < TOL, err


@needs_robots
def test_panda_without_tip_names_the_branches():
    with pytest.raises(ConfigError, match="panda_leftfinger.*panda_rightfinger"):
        model_from_urdf(PANDA)


@needs_robots
def test_panda_tip_at_link7_or_link8_is_the_same_body():
    a = model_from_urdf(PANDA, tip_link="panda_link7")
    b = model_from_urdf(PANDA, tip_link="panda_link8")
    np.testing.assert_allclose(a.theta(), b.theta(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(a.p, b.p, atol=0)


# ---------------------------------------------------------------------- synthetic URDFs
def inertial(mass, xyz="0 0 0", rpy="0 0 0", ixx=0.02, iyy=0.03, izz=0.04, ixy=0.001, ixz=-0.002,
             iyz=0.003):
    return (f'<inertial><origin xyz="{xyz}" rpy="{rpy}"/><mass value="{mass}"/>'
            f'<inertia ixx="{ixx}" iyy="{iyy}" izz="{izz}" ixy="{ixy}" ixz="{ixz}" '
            f'iyz="{iyz}"/></inertial>')


def link(name, body=""):
    return f'<link name="{name}">{body}</link>'


def joint(name, parent, child, kind="revolute", xyz="0 0 0", rpy="0 0 0", axis="0 0 1",
          limit='<limit effort="50" velocity="3" lower="-2" upper="2"/>', extra=""):
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>'
            f'{limit if kind != "fixed" else ""}{extra}</joint>')


def robot(*parts, name="synthetic"):
    return f'<?xml version="1.0"?><robot name="{name}">{"".join(parts)}</robot>'


#: A chain with non-z axes, a fixed joint with rpy before the first moving joint, a link split
#: in two by a fixed joint, inertial origins with rpy, a fixed side branch and a massless tip.
SKEWED = robot(
    link("world"),
    link("base", inertial(3.0)),
    joint("mount", "world", "base", "fixed", xyz="0.1 -0.2 0.3", rpy="0.3 -0.2 0.7"),
    link("l1", inertial(2.0, "0.05 0.02 0.1", "0.4 0.1 -0.3")),
    joint("j1", "base", "l1", xyz="0 0 0.2", rpy="0.1 0.2 0.3", axis="1 0 0"),
    link("l2", inertial(1.5, "0.2 0 0", "0 0 0", 0.01, 0.05, 0.05, 0, 0, 0)),
    joint("j2", "l1", "l2", xyz="0.1 0.3 0", rpy="-1.0 0.5 0", axis="0 -1 0"),
    link("l2b", inertial(0.7, "0 0.1 0", "1.2 0 0.4")),
    joint("l2_split", "l2", "l2b", "fixed", xyz="0.3 0 0.05", rpy="0 0.6 0"),
    link("l3", inertial(1.2, "0 0 0.15", "0.3 0.3 0.3")),
    joint("j3", "l2b", "l3", xyz="0 0.1 0.2", rpy="0.5 0 1.0", axis="0.6 0 0.8"),
    link("sensor", inertial(0.3, "0.01 0.02 0.03")),
    joint("sensor_mount", "l3", "sensor", "fixed", xyz="0.05 0.05 0", rpy="0 0 1.5"),
    link("l4", inertial(0.9, "0.02 -0.03 0.05", "-0.7 0.2 2.0")),
    joint("j4", "l3", "l4", xyz="0 0 0.25", rpy="0 -0.4 0", axis="0 0 -1"),
    link("tool0"),
    joint("flange", "l4", "tool0", "fixed", xyz="0 0 0.1"),
)


def test_skewed_axes_fixed_joints_and_inertial_rpy_match_pinocchio():
    model = model_from_urdf(SKEWED)
    assert model.joint_names == ("j1", "j2", "j3", "j4")
    assert model.name == "synthetic"
    np.testing.assert_allclose(model.mass, [2.0, 1.5 + 0.7, 1.2 + 0.3, 0.9], rtol=1e-15)
    # every frame turns about its own z: the joint axis is z in the new frames
    pm = pin_reference(pin.buildModelFromXML(SKEWED), model.joint_names)
    err = compare(model, pm, np.random.default_rng(4))
    assert max(err.values()) < TOL, err


def test_gravity_parameter_and_base_frame():
    model = model_from_urdf(SKEWED, gravity=(1.0, 2.0, -3.0))
    np.testing.assert_array_equal(model.gravity, [1.0, 2.0, -3.0])
    pm = pin_reference(pin.buildModelFromXML(SKEWED), model.joint_names)
    err = compare(model, pm, np.random.default_rng(5), states=5)
    assert max(err.values()) < TOL, err
    zero_g = model_from_urdf(SKEWED, gravity=(0.0, 0.0, 0.0))
    q = np.array([0.3, -0.2, 0.5, 1.0])
    tau_g = inverse_dynamics(model, q, np.zeros(4), np.zeros(4))
    assert np.abs(tau_g).max() > 0.1
    np.testing.assert_allclose(inverse_dynamics(zero_g, q, np.zeros(4), np.zeros(4)), 0.0,
                               atol=1e-15)


def test_inertial_rpy_turns_the_inertia_into_link_axes():
    # Rz(90 deg) swaps x and y: diag(1, 2, 3) in the inertial frame is diag(2, 1, 3) in the
    # link frame; the centre of mass is taken as given (link frame).
    xml = robot(link("b"), link("a", inertial(2.0, "0.1 0.2 0.3", "0 0 1.5707963267948966",
                                              1.0, 2.0, 3.0, 0, 0, 0)),
                joint("j", "b", "a"))
    model = model_from_urdf(xml)
    np.testing.assert_allclose(model.inertia[0], np.diag([2.0, 1.0, 3.0]), atol=1e-15)
    np.testing.assert_allclose(model.com[0], [0.1, 0.2, 0.3], atol=0)


def test_fixed_joint_merge_is_the_parallel_axis_theorem():
    # two point-like bodies 1 m apart on x, joined by a fixed joint: m = 3, com at x = 2/3,
    # inertia about the com gains m1 m2 / m d^2 = 2/3 on y and z
    small = dict(ixx=0.01, iyy=0.01, izz=0.01, ixy=0, ixz=0, iyz=0)
    xml = robot(link("b"), link("a", inertial(1.0, **small)), joint("j", "b", "a"),
                link("c", inertial(2.0, **small)),
                joint("weld", "a", "c", "fixed", xyz="1 0 0", rpy="0.3 0.2 0.1"))
    model = model_from_urdf(xml)
    assert model.mass[0] == 3.0
    np.testing.assert_allclose(model.com[0], [2.0 / 3.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(model.inertia[0], np.diag([0.02, 0.02 + 2 / 3, 0.02 + 2 / 3]),
                               atol=1e-15)


def test_axis_rotation_keeps_urdf_joint_coordinates():
    # a joint about -z: q in the model is the URDF q (the tip rotates by -q about base z)
    xml = robot(link("b"), link("a", inertial(1.0, "1 0 0")), joint("j", "b", "a", axis="0 0 -1"))
    model = model_from_urdf(xml, gravity=(0.0, -9.81, 0.0))
    # gravity along -y; com on +x at q: rotated by -q about z -> (cos q, -sin q)
    q = 0.4
    tau = inverse_dynamics(model, [q], [0.0], [0.0])
    # torque about -z needed to hold m g at lever x = cos q: tau_z(base) = m g cos q -> about -z
    assert tau[0] == pytest.approx(-9.81 * np.cos(q), rel=1e-12)
    np.testing.assert_allclose(model.R_fix[0], rot_x(np.pi), atol=1e-15)


def test_limits_continuous_and_missing_effort():
    xml = robot(link("b"), link("a", inertial(1.0)), link("c", inertial(1.0)),
                joint("j1", "b", "a", "continuous", limit='<limit effort="7" velocity="2"/>'),
                joint("j2", "a", "c",
                      limit='<limit effort="0" lower="-1" upper="0.5" velocity="0"/>'))
    model = model_from_urdf(xml)
    np.testing.assert_array_equal(model.effort_limit, [7.0, np.inf])
    np.testing.assert_array_equal(model.velocity_limit, [2.0, np.inf])
    np.testing.assert_array_equal(model.position_lower, [-np.inf, -1.0])
    np.testing.assert_array_equal(model.position_upper, [np.inf, 0.5])


def test_off_chain_moving_joints_are_locked_at_zero():
    # a prismatic finger beside the tip: locked at 0 and merged (like pin.buildReducedModel)
    xml = robot(link("b"), link("a", inertial(1.0)), joint("j", "b", "a"),
                link("f", inertial(0.5, "0 0.1 0")),
                joint("finger", "a", "f", "prismatic", xyz="0.2 0 0", axis="0 1 0"),
                link("tip", inertial(0.2)), joint("j2", "a", "tip", xyz="0 0 0.3"))
    model = model_from_urdf(xml, tip_link="tip")
    assert model.joint_names == ("j", "j2")
    assert model.mass[0] == 1.5
    pm = pin_reference(pin.buildModelFromXML(xml), model.joint_names)
    err = compare(model, pm, np.random.default_rng(6), states=5)
    assert max(err.values()) < TOL, err


# ---------------------------------------------------------------------- errors
def test_prismatic_on_the_chain_is_rejected_by_name():
    xml = robot(link("b"), link("a", inertial(1.0)), link("c", inertial(1.0)),
                joint("j1", "b", "a"), joint("slider", "a", "c", "prismatic"))
    with pytest.raises(ConfigError, match="slider.*prismatic"):
        model_from_urdf(xml)
    # leaving it out with tip_link is fine
    assert model_from_urdf(xml, tip_link="a").joint_names == ("j1",)


def test_floating_and_mimic_on_the_chain_are_rejected():
    xml = robot(link("b"), link("a", inertial(1.0)), joint("free", "b", "a", "floating"))
    with pytest.raises(ConfigError, match="free.*floating"):
        model_from_urdf(xml)
    xml = robot(link("b"), link("a", inertial(1.0)), link("c", inertial(1.0)),
                joint("j1", "b", "a"), joint("j2", "a", "c", extra='<mimic joint="j1"/>'))
    with pytest.raises(ConfigError, match="j2.*mimic"):
        model_from_urdf(xml)


def test_branched_tree_without_tip_names_the_leaves():
    xml = robot(link("b"), link("a", inertial(1.0)), link("left", inertial(1.0)),
                link("right", inertial(1.0)), joint("j", "b", "a"),
                joint("jl", "a", "left"), joint("jr", "a", "right"))
    with pytest.raises(ConfigError, match=r"tip_link.*\['left', 'right'\]"):
        model_from_urdf(xml)
    assert model_from_urdf(xml, tip_link="right").joint_names == ("j", "jr")


def test_missing_inertial_on_a_moving_link_names_it():
    xml = robot(link("b"), link("ghost"), link("c", inertial(1.0)), joint("j1", "b", "ghost"),
                joint("j2", "ghost", "c"))
    with pytest.raises(ConfigError, match="'ghost'.*no mass"):
        model_from_urdf(xml)


def test_bad_inputs_raise_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such URDF file"):
        model_from_urdf(tmp_path / "absent.urdf")
    with pytest.raises(ConfigError, match="URDF"):
        model_from_urdf('<robot name="x"><link name="a"></robot>')         # malformed XML
    bad = tmp_path / "bad.urdf"
    bad.write_text('<robot name="x"><link name="a"><joint></robot')
    with pytest.raises(ConfigError):
        model_from_urdf(bad)
    xml = robot(link("b"), link("a", inertial(1.0)), joint("j", "b", "a"))
    with pytest.raises(ConfigError, match="base_link 'nope'"):
        model_from_urdf(xml, base_link="nope")
    with pytest.raises(ConfigError, match="tip_link 'b' is not below base_link 'a'"):
        model_from_urdf(xml, base_link="a", tip_link="b")
    with pytest.raises(ConfigError, match="no moving joint"):
        model_from_urdf(robot(link("b"), link("a", inertial(1.0)),
                              joint("w", "b", "a", "fixed")))


def test_triangle_inequality_tolerance():
    # principal moments (1, 1, 2.1): 5 % beyond I1 + I2 >= I3
    xml = robot(link("b"), link("a", inertial(1.0, ixx=1.0, iyy=1.0, izz=2.1, ixy=0, ixz=0,
                                              iyz=0)), joint("j", "b", "a"))
    with pytest.raises(ModelError, match="'a'.*triangle"):
        model_from_urdf(xml)
    assert model_from_urdf(xml, triangle_tolerance=0.1).mass[0] == 1.0
    assert model_from_urdf(xml, triangle_tolerance=None).mass[0] == 1.0
    # rounding-size violations (0.5 %) pass by default
    xml = xml.replace('izz="2.1"', 'izz="2.01"')
    assert model_from_urdf(xml).inertia[0][2, 2] == 2.01
    # not positive definite is never accepted
    xml = xml.replace('izz="2.01"', 'izz="-1"')
    with pytest.raises(ModelError, match="'a'.*positive definite"):
        model_from_urdf(xml, triangle_tolerance=None)


def test_from_urdf_reads_a_file(tmp_path):
    path = tmp_path / "skewed.urdf"
    path.write_text(SKEWED)
    a = model_from_urdf(str(path))
    b = model_from_urdf(SKEWED)
    np.testing.assert_array_equal(a.theta(), b.theta())
    np.testing.assert_array_equal(a.R_fix, b.R_fix)
    # the frame of joint 1 puts its x axis on z: p_1 is the folded base offset
    assert not np.allclose(a.R_fix[0], np.eye(3))


# ---------------------------------------------------------------- joint terms (doc/design.md §7)
FRICTIONAL = robot(
    link("base"),
    link("l1", inertial(2.0, "0.1 0 0")),
    joint("j1", "base", "l1", extra='<dynamics damping="0.7" friction="0.25"/>'),
    link("l2", inertial(1.0, "0.1 0 0")),
    joint("j2", "l1", "l2", xyz="0.3 0 0", axis="0 1 0", extra='<dynamics damping="1.5"/>'),
    link("l3", inertial(0.5, "0 0 0.1")),
    joint("j3", "l2", "l3", xyz="0.3 0 0", axis="1 0 0"),
)


def test_joint_dynamics_and_armature_from_urdf():
    model = model_from_urdf(FRICTIONAL, armature=[0.1, 0.2, 0.3], friction_velocity=0.05)
    np.testing.assert_array_equal(model.damping, [0.7, 1.5, 0.0])
    np.testing.assert_array_equal(model.friction, [0.25, 0.0, 0.0])
    np.testing.assert_array_equal(model.armature, [0.1, 0.2, 0.3])
    assert model.friction_velocity == 0.05
    # Pinocchio reads the same <dynamics>; its armature is set by hand (URDF has no tag)
    pm = pin.buildModelFromXML(FRICTIONAL)
    pm.armature = model.armature.copy()
    err = compare(model, pm, np.random.default_rng(5))
    assert max(err.values()) < TOL, err
    scalar = model_from_urdf(FRICTIONAL, armature=0.4)
    np.testing.assert_array_equal(scalar.armature, [0.4] * 3)
    assert model_from_urdf(FRICTIONAL).friction_velocity == 0.1


def test_bad_armature_is_a_model_error():
    with pytest.raises(ModelError, match="armature: every entry must be finite and >= 0"):
        model_from_urdf(FRICTIONAL, armature=-0.1)
    with pytest.raises(ModelError, match="armature: expected a scalar or 3 values"):
        model_from_urdf(FRICTIONAL, armature=[0.1, 0.2])
