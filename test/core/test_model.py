"""RobotModel: the CSS preset, the YAML schema, and the errors of bad descriptions."""

import numpy as np
import pytest

from rcac_ros.core import ConfigError, ModelError, RobotModel, css_arm
from rcac_ros.core.model import rot_x, rot_y

CONFIG = __file__.rsplit("/test/", 1)[0] + "/config/css_arm.yaml"


def test_css_preset_is_table_1():
    m = css_arm()
    assert m.joint_names == tuple(f"joint{i}" for i in range(1, 8))
    assert m.mass.tolist() == [50, 50, 100, 100, 50, 50, 100]
    assert np.allclose(m.p[3], [4.0, 0.0, 0.5]) and np.allclose(m.p[6], [0.0, 0.0, 1.0])
    assert np.allclose(m.R_fix[1], rot_x(-np.pi / 2)) and np.allclose(m.R_fix[6], rot_y(np.pi / 2))
    th = m.theta()[6]                   # link 7: m=100, p_c=(0, .5, 1), I_c = diag(2, 2, 200)
    assert th.tolist() == pytest.approx([100, 0, 50, 100, 0, 25, 100, 0, 0, 50, 2, 2, 200])
    assert np.all(m.gravity == 0.0)


def test_yaml_preset_equals_code_preset_and_round_trips(tmp_path):
    a, b = RobotModel.from_yaml(CONFIG), css_arm()
    for field in ("p", "R_fix", "mass", "com", "inertia", "gravity"):
        assert np.allclose(getattr(a, field), getattr(b, field), atol=1e-15), field
    assert a.joint_names == b.joint_names
    import yaml
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(b.to_dict()))
    c = RobotModel.from_yaml(path)
    assert np.array_equal(c.theta(), b.theta()) and np.array_equal(c.R_fix, b.R_fix)


def test_model_is_immutable():
    m = css_arm()
    with pytest.raises(ValueError):
        m.mass[0] = 1.0
    th = m.theta()
    th[0, 0] = -1.0
    assert m.theta()[0, 0] == 50.0


def test_repeated_chain():
    m = css_arm().repeated(3)
    assert m.n == 21 and m.joint_names[7] == "joint1_1"
    assert np.array_equal(m.theta()[14:], css_arm().theta())


def good():
    return dict(p=[[0, 0, 0]], R_fix=[np.eye(3)], mass=[1.0], com=[[0, 0, 0]],
                inertia=[np.diag([1.0, 1.0, 1.0])])


@pytest.mark.parametrize("change,match", [
    (dict(mass=[0.0]), "mass\\[0\\]: must be > 0"),
    (dict(mass=[-2.0]), "mass\\[0\\]: must be > 0"),
    (dict(mass=[np.nan]), "mass: contains NaN"),
    (dict(p=[[0, 0]]), "p: expected shape"),
    (dict(com=[[0, 0, np.inf]]), "com: contains NaN or Inf"),
    (dict(inertia=[np.diag([1.0, -1.0, 1.0])]), "inertia\\[0\\]: inertia is not positive"),
    (dict(inertia=[[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]]), "inertia\\[0\\]: inertia is not symm"),
    (dict(inertia=[np.diag([1.0, 1.0, 3.0])]), "triangle inequality"),
    (dict(R_fix=[2 * np.eye(3)]), "R_fix\\[0\\]: not a proper rotation"),
    (dict(R_fix=[np.diag([1.0, 1.0, -1.0])]), "R_fix\\[0\\]: not a proper rotation"),
    (dict(joint_names=["a", "b"]), "joint_names"),
    (dict(gravity=[0, 0]), "gravity: expected shape"),
    (dict(effort_limit=[0.0]), "effort_limit"),
    (dict(effort_limit=[1.0, 2.0]), "effort_limit: expected a scalar or 1 values"),
    (dict(velocity_limit=-1.0), "velocity_limit: every entry must be > 0"),
    (dict(position_lower=1.0, position_upper=0.0), "position_lower\\[0\\]: above"),
    (dict(mass="heavy"), "mass: not a numeric array"),
])
def test_bad_model_raises_model_error(change, match):
    with pytest.raises(ModelError, match=match):
        RobotModel(**dict(good(), **change))


def test_triangle_check_can_be_waived():
    """Waived, the inertia that fails the triangle inequality is kept as given (and the waiver
    survives a copy); positive definiteness is still checked."""
    flat = np.diag([1.0, 1.0, 3.0])          # 1 + 1 < 3: no rigid body has it
    m = RobotModel(**dict(good(), inertia=[flat]), check_triangle=False)
    np.testing.assert_array_equal(m.inertia[0], flat)
    assert m.check_triangle is False
    np.testing.assert_array_equal(m.replace(name="copy").inertia[0], flat)
    with pytest.raises(ModelError, match="triangle inequality"):
        m.replace(check_triangle=True)
    with pytest.raises(ModelError, match="inertia is not positive"):
        RobotModel(**dict(good(), inertia=[np.diag([1.0, -1.0, 1.0])]), check_triangle=False)


@pytest.mark.parametrize("text,exc,match", [
    ("links: [", ConfigError, "not valid YAML"),
    ("- 1\n- 2\n", ConfigError, "top level must be a mapping"),
    ("links: []\n", ConfigError, "'links' must be a non-empty list"),
    ("links:\n  - {p: [0, 0, 0], com: [0, 0, 0], inertia: [1, 1, 1]}\n", ConfigError,
     "links\\[0\\].mass: missing"),
    ("links:\n  - {p: [0, 0], mass: 1, com: [0, 0, 0], inertia: [1, 1, 1]}\n", ConfigError,
     "links\\[0\\].p: expected a list of 3"),
    ("links:\n  - {p: [0, 0, 0], mass: one, com: [0, 0, 0], inertia: [1, 1, 1]}\n", ConfigError,
     "links\\[0\\].mass: expected a number"),
    ("links:\n  - {p: [0, 0, 0], mass: 1, com: [0, 0, 0], inertia: [1, 1]}\n", ConfigError,
     "links\\[0\\].inertia"),
    ("links:\n  - {p: [0, 0, 0], mass: 1, com: [0, 0, 0], inertia: [1, 1, 1], colour: red}\n",
     ConfigError, "unknown key"),
    ("links:\n  - {p: [0, 0, 0], mass: 1, com: [0, 0, 0], inertia: [1, 1, 1], rpy: [0, 0, 0],"
     " rpy_deg: [0, 0, 0]}\n", ConfigError, "at most one of"),
    ("links:\n  - {p: [0, 0, 0], mass: -1, com: [0, 0, 0], inertia: [1, 1, 1]}\n", ModelError,
     "mass\\[0\\]: must be > 0"),
])
def test_bad_yaml(tmp_path, text, exc, match):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(exc, match=match):
        RobotModel.from_yaml(path)


def test_missing_yaml_file():
    with pytest.raises(ConfigError, match="cannot read"):
        RobotModel.from_yaml("/nonexistent/model.yaml")


def test_joint_terms_yaml_round_trip_replace_and_repeat(tmp_path):
    """Per-link YAML keys armature, damping, friction and the model-level friction_velocity
    (doc/design.md §7)."""
    import yaml
    m = css_arm().replace(armature=np.arange(7) * 0.1, damping=0.5, friction=[0.2] * 7,
                          friction_velocity=0.05)
    doc = m.to_dict()
    assert doc["friction_velocity"] == 0.05 and "armature" not in doc["links"][0]
    assert doc["links"][1]["armature"] == 0.1 and doc["links"][3]["damping"] == 0.5
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(doc))
    back = RobotModel.from_yaml(path)
    np.testing.assert_array_equal(back.joint_terms(), m.joint_terms())
    np.testing.assert_array_equal(back.joint_terms()[:, 0], np.arange(7) * 0.1)
    assert back.friction_velocity == 0.05
    assert "friction_velocity" not in css_arm().to_dict()
    rep = m.repeated(2)
    np.testing.assert_array_equal(rep.damping, [0.5] * 14)
    assert rep.friction_velocity == 0.05
    kept = m.replace(mass=m.mass * 2.0)
    np.testing.assert_array_equal(kept.joint_terms(), m.joint_terms())
    with pytest.raises(ValueError):
        m.damping[0] = 1.0


@pytest.mark.parametrize("change,match", [
    (dict(armature=[-0.1]), "armature: every entry must be finite and >= 0"),
    (dict(damping=[np.inf]), "damping: every entry must be finite and >= 0"),
    (dict(friction=[1.0, 2.0]), "friction: expected a scalar or 1 values"),
    (dict(friction_velocity=0.0), "friction_velocity: must be > 0"),
    (dict(friction_velocity="slow"), "friction_velocity: expected a number"),
])
def test_bad_joint_terms_raise_model_error(change, match):
    with pytest.raises(ModelError, match=match):
        RobotModel(**dict(good(), **change))


def test_bad_joint_terms_in_yaml(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("links:\n  - {p: [0, 0, 0], mass: 1, com: [0, 0, 0], inertia: [1, 1, 1],"
                    " damping: fast}\n")
    with pytest.raises(ConfigError, match="links\\[0\\].damping: expected a number"):
        RobotModel.from_yaml(path)
    path.write_text("friction_velocity: -1\nlinks:\n  - {p: [0, 0, 0], mass: 1, com: [0, 0, 0],"
                    " inertia: [1, 1, 1], friction: 0.3}\n")
    with pytest.raises(ModelError, match="friction_velocity: must be > 0"):
        RobotModel.from_yaml(path)
