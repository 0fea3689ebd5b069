"""Estimate files: YAML round trip, URDF inertials checked by Pinocchio, inconsistent links."""

import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from chains import random_chain

from rcac_ros.core.model import css_arm
from rcac_ros.core.urdf import model_from_urdf
from rcac_ros.nodes.controller.estimates import (initial_estimates, load, rigid_body, save,
                                                 urdf_child_links, urdf_path)

URDF_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "three_link.urdf")
with open(URDF_PATH, encoding="utf-8") as _f:
    URDF = _f.read()


def test_rigid_body_recovers_mass_com_and_inertia():
    model = random_chain(np.random.default_rng(4), 5)
    for i, row in enumerate(model.theta()):
        m, c, I_c, reason = rigid_body(row)
        assert reason is None
        assert m == pytest.approx(model.mass[i], rel=1e-14)
        np.testing.assert_allclose(c, model.com[i], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(I_c, model.inertia[i], rtol=1e-10, atol=1e-12)


def test_saved_urdf_inertials_match_the_original_in_pinocchio(tmp_path):
    """The fragment's <inertial> blocks, put into the URDF in place of the originals, give
    Pinocchio the same bodies (an independent URDF parser and inertia algebra)."""
    pin = pytest.importorskip("pinocchio")
    model = model_from_urdf(URDF)
    _, fragment, problems = save(str(tmp_path / "est.yaml"), model.theta(), model.joint_names,
                                 model.name, links=urdf_child_links(URDF, model.joint_names))
    assert problems == []
    blocks = {link.get("name"): link.find("inertial") for link in ET.parse(fragment).getroot()}
    assert sorted(blocks) == ["fore", "hand", "upper"]
    robot = ET.fromstring(URDF)
    for link in robot.findall("link"):
        if link.get("name") in blocks:
            link.remove(link.find("inertial"))
            link.append(blocks[link.get("name")])
    original = pin.buildModelFromXML(URDF)
    rebuilt = pin.buildModelFromXML(ET.tostring(robot, encoding="unicode"))
    for j in range(1, original.njoints):
        a, b = original.inertias[j], rebuilt.inertias[j]
        assert b.mass == pytest.approx(a.mass, rel=1e-8)
        np.testing.assert_allclose(b.lever, a.lever, atol=1e-8)
        np.testing.assert_allclose(b.inertia, a.inertia, atol=1e-8)


def test_yaml_round_trip_and_initial_estimates(tmp_path):
    model = random_chain(np.random.default_rng(6), 4)
    theta = np.random.default_rng(7).normal(size=(4, 13))
    path, _, _ = save(str(tmp_path / "sub" / "est.yaml"), theta, model.joint_names)
    np.testing.assert_array_equal(load(path, model.joint_names), theta)
    np.testing.assert_array_equal(initial_estimates(path, model), theta)
    np.testing.assert_array_equal(initial_estimates("model", model), model.theta())
    np.testing.assert_array_equal(initial_estimates("zero", model), np.zeros((4, 13)))
    # saved in another joint order, read back in the model's
    order = [2, 0, 3, 1]
    path2, _, _ = save(str(tmp_path / "perm.yaml"), theta[order],
                       [model.joint_names[k] for k in order])
    np.testing.assert_array_equal(load(path2, model.joint_names), theta)


def test_inconsistent_links_are_named_with_the_reason(tmp_path):
    model = css_arm()
    theta = model.theta()
    theta[1, 0] = -2.0                      # joint2's link: negative mass
    theta[3, 10] = -50.0                    # joint4's link: Ixx < 0
    path, fragment, problems = save(str(tmp_path / "e.yaml"), theta, model.joint_names)
    text = "\n".join(problems)
    assert "joint2" in text and "mass m = -2 is not > 0" in text
    assert "joint4" in text and "not positive definite" in text
    # the paper's own Table 1 (diag[2 2 200]) is no real rigid body either
    assert "triangle inequality" in text
    links = [link.get("name") for link in ET.parse(fragment).getroot()]
    assert "joint2_link" not in links and "joint4_link" not in links
    assert urdf_path(path) == fragment


@pytest.mark.parametrize("content, text", [
    (None, "no such file"),
    ("format: other\n", "not an estimates file"),
    ("format: rcac_ros/estimates 1\nlinks:\n- {joint: a, theta: [1]}\n", "do not match"),
])
def test_bad_estimate_files_name_the_parameter(tmp_path, content, text):
    from rcac_ros.errors import ConfigError
    path = tmp_path / "bad.yaml"
    if content is not None:
        path.write_text(content)
    with pytest.raises(ConfigError) as err:
        initial_estimates(str(path), css_arm())
    assert str(err.value).startswith("initial_estimates:") and text in str(err.value)
    assert "\n" not in str(err.value)


def test_natural_geometry_exports_every_link_and_pinocchio_accepts_them(tmp_path):
    """doc/design.md §8: after a payload run with geometry="natural", save() exports every
    link, and the panda URDF with those inertials loads in Pinocchio with every pseudo-
    inertia positive definite (the Euclidean law's run, for contrast, leaves link 7 out)."""
    pin = pytest.importorskip("pinocchio")
    from rcac_ros.core import RecursiveCompositeController
    from rcac_ros.tools.demos.compare import payload_scenario, run_law
    from rcac_ros.tools.runs.scenarios import find_panda_urdf
    urdf = find_panda_urdf()
    if urdf is None:
        pytest.skip("example-robot-data's panda.urdf not found")
    scen = payload_scenario()
    scen.jump = 0.5                                   # the payload half a second in
    ctrl = RecursiveCompositeController(scen.model, **dict(scen.gains, geometry="natural"))
    run_law(scen, ctrl, 3.0)
    names = scen.model.joint_names
    _, fragment, problems = save(str(tmp_path / "est.yaml"), ctrl.theta_hat, names, "panda",
                                 urdf_child_links(urdf, names))
    assert problems == []
    exported = {link.get("name"): link.find("inertial")
                for link in ET.parse(fragment).getroot().findall("link")}
    assert len(exported) == len(names)
    root = ET.parse(urdf).getroot()
    for link in root.findall("link"):
        if link.get("name") in exported:
            link.remove(link.find("inertial"))
            link.append(exported[link.get("name")])
    model = pin.buildModelFromXML(ET.tostring(root, encoding="unicode"))
    for j in range(1, model.njoints):
        J = model.inertias[j].toPseudoInertia().toMatrix()
        assert np.linalg.eigvalsh(J)[0] > 0.0, model.names[j]


def test_joint_terms_saved_restored_and_exported(tmp_path):
    """The joint estimates (doc/design.md §7) round-trip through the YAML, and the URDF
    fragment's <dynamics>, put into the URDF, are what model_from_urdf and Pinocchio read."""
    from rcac_ros.nodes.controller.estimates import initial_joint_terms, load_joint_terms
    pin = pytest.importorskip("pinocchio")
    model = model_from_urdf(URDF)
    friction = np.array([[0.1, 0.5, 0.3], [0.2, 0.7, 0.4], [0.05, 0.2, 0.1]])
    path, fragment, problems = save(str(tmp_path / "est.yaml"), model.theta(),
                                    model.joint_names, model.name,
                                    urdf_child_links(URDF, model.joint_names), friction=friction)
    assert problems == []
    np.testing.assert_array_equal(load_joint_terms(path, model.joint_names), friction)
    np.testing.assert_array_equal(initial_joint_terms(path, model), friction)
    np.testing.assert_array_equal(load(path, model.joint_names), model.theta())
    dynamics = {j.get("name"): j.find("dynamics") for j in ET.parse(fragment).getroot()
                if j.tag == "joint"}
    assert sorted(dynamics) == sorted(model.joint_names)
    robot = ET.fromstring(URDF)
    for joint in robot.findall("joint"):
        if joint.get("name") in dynamics:
            old = joint.find("dynamics")
            if old is not None:
                joint.remove(old)
            joint.append(dynamics[joint.get("name")])
    text = ET.tostring(robot, encoding="unicode")
    back = model_from_urdf(text, armature=friction[:, 0])
    np.testing.assert_allclose(back.joint_terms(), friction, rtol=1e-9)
    pm = pin.buildModelFromXML(text)
    np.testing.assert_allclose(pm.damping, friction[:, 1], rtol=1e-9)
    np.testing.assert_allclose(pm.friction, friction[:, 2], rtol=1e-9)
    # a file without joint terms: none (zero initial joint estimates)
    plain, _, _ = save(str(tmp_path / "plain.yaml"), model.theta(), model.joint_names)
    assert load_joint_terms(plain, model.joint_names) is None
    np.testing.assert_array_equal(initial_joint_terms(plain, model), np.zeros((3, 3)))
    np.testing.assert_array_equal(initial_joint_terms("model", model), model.joint_terms())
