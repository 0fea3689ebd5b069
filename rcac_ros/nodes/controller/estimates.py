"""Estimate files: ``theta_hat`` as YAML, and as URDF ``<inertial>`` blocks where consistent.

The controller's ``~/save_estimates`` service writes :func:`save`; its
``initial_estimates`` parameter reads :func:`initial_estimates` (``zero``, ``model`` or the
path of a saved file). Pure: numpy and PyYAML, no rclpy.

From the 13 parameters of one link (eq 13, doc/design.md §2, :data:`PARAMETER_NAMES`) the rigid
body is ``m = t1``, centre of mass ``c = (t2, t3, t4) / m`` and the inertia about the frame
origin ``I_o`` of doc/design.md §2 (the block of the mass matrix M), and by the parallel-axis
theorem the inertia about the centre of mass ``I_c = I_o - m (|c|^2 I3 - c c^T)``. The
13 parameters have 3 more degrees of freedom than a rigid body (``m px^2`` ... appear also
on their own in C), so the URDF block reproduces M exactly and C up to that redundancy.
A link is physically consistent when ``m > 0``, ``I_c`` is positive definite and its
principal moments satisfy the triangle inequalities ``I1 + I2 >= I3``.

With a URDF, the blocks are in its link frames (:func:`urdf_child_links`); otherwise in the
model's link frames ``i`` (z along the joint axis).

With the joint terms (``joint_friction``, doc/design.md §7) each joint's entry also holds
``joint_terms: {armature, damping, friction}``, and the URDF fragment a ``<joint>`` with
``<dynamics damping=".." friction=".."/>`` (URDF has no armature: it stays in the YAML).
"""

import datetime
import os
from xml.sax.saxutils import quoteattr

import numpy as np
import yaml

from rcac_ros.core.model import PARAMETER_NAMES
from rcac_ros.core.pseudo_inertia import default_start
from rcac_ros.errors import ConfigError, read_yaml

#: the ``format`` key of an estimates file
FORMAT = "rcac_ros/estimates 1"

#: relative tolerance of the triangle inequality (a rigid body on the bound is accepted)
TRIANGLE_TOLERANCE = 1e-9


def rigid_body(theta_i):
    """Mass, centre of mass and inertia about it of one link's 13 parameters.

    Returns
    -------
    (m, c, I_c, reason) : float, ndarray (3,), ndarray (3, 3), str or None
        ``reason`` is ``None`` when the link is physically consistent, otherwise one
        sentence saying why not (then ``c`` and ``I_c`` may be meaningless).
    """
    t = np.asarray(theta_i, dtype=float)
    m = float(t[0])
    if not m > 0.0:
        return m, np.zeros(3), np.zeros((3, 3)), f"mass m = {m:.6g} is not > 0"
    c = t[1:4] / m
    I_o = np.array([[t[10] + t[5] + t[6], -t[7], -t[8]],
                    [-t[7], t[11] + t[4] + t[6], -t[9]],
                    [-t[8], -t[9], t[12] + t[4] + t[5]]])
    I_c = I_o - m * (c @ c * np.eye(3) - np.outer(c, c))
    eig = np.linalg.eigvalsh(I_c)
    moments = "[" + ", ".join(f"{e:.6g}" for e in eig) + "]"
    if not eig[0] > 0.0:
        return m, c, I_c, f"inertia about the centre of mass is not positive definite " \
                          f"(principal moments {moments})"
    if eig[0] + eig[1] < eig[2] * (1.0 - TRIANGLE_TOLERANCE):
        return m, c, I_c, f"principal moments {moments} violate the triangle inequality " \
                          "I1 + I2 >= I3"
    return m, c, I_c, None


def inertial_xml(m, c, I_c, indent="    "):
    """One URDF ``<inertial>`` block (origin at the centre of mass, link axes)."""
    f = "{:.9g}".format
    return (f"{indent}<inertial>\n"
            f"{indent}  <origin xyz=\"{f(c[0])} {f(c[1])} {f(c[2])}\" rpy=\"0 0 0\"/>\n"
            f"{indent}  <mass value=\"{f(m)}\"/>\n"
            f"{indent}  <inertia ixx=\"{f(I_c[0, 0])}\" ixy=\"{f(I_c[0, 1])}\" "
            f"ixz=\"{f(I_c[0, 2])}\" iyy=\"{f(I_c[1, 1])}\" iyz=\"{f(I_c[1, 2])}\" "
            f"izz=\"{f(I_c[2, 2])}\"/>\n"
            f"{indent}</inertial>\n")


def urdf_path(path):
    """The URDF fragment written next to an estimates file (``x.yaml`` -> ``x.inertial.urdf``)."""
    root, ext = os.path.splitext(path)
    return (root if ext in (".yaml", ".yml") else path) + ".inertial.urdf"


def save(path, theta, joint_names, model_name="robot", links=None, friction=None):
    """Write the estimates as YAML at ``path`` and the consistent links as a URDF fragment.

    Parameters
    ----------
    path : str
        The YAML file; the fragment goes to :func:`urdf_path` (``<robot>`` with one
        ``<link>`` per consistent link). Parent directories are created.
    theta : array_like (n, 13)
        ``theta_hat``, in the order of ``joint_names``.
    joint_names : sequence of str
    model_name : str
    links : (names, rotations), optional
        From a URDF (:func:`urdf_child_links`): the link moved by each joint and the turn
        ``A`` from the model's frame to that link's; the blocks are then in the URDF link
        frames (a link's fixed children, merged into it by the model, are included).
        Default: ``<joint>_link`` in the model's frames (z = joint axis).
    friction : array_like (n, 3), optional
        The joint estimates (armature, damping, friction), saved too when given.

    Returns
    -------
    (yaml_path, urdf_path, problems) : str, str, list of str
        ``problems``: one ``"link L (joint J): reason"`` per inconsistent link.
    """
    theta = np.asarray(theta, dtype=float)
    names, turns = links if links else ([f"{j}_link" for j in joint_names], None)
    entries, blocks, problems = [], [], []
    for i, joint in enumerate(joint_names):
        entry = {"joint": str(joint), "link": names[i],
                 "theta": [float(v) for v in theta[i]]}
        m, c, I_c, reason = rigid_body(theta[i])
        if turns is not None:               # model frame (z = axis) -> URDF link frame
            c, I_c = turns[i] @ c, turns[i] @ I_c @ turns[i].T
        if reason is None:
            entry["inertial"] = {"mass": m, "com": c.tolist(), "inertia": [
                float(I_c[0, 0]), float(I_c[1, 1]), float(I_c[2, 2]), float(I_c[0, 1]),
                float(I_c[0, 2]), float(I_c[1, 2])]}
            blocks.append(f"  <link name={quoteattr(names[i])}>\n"
                          + inertial_xml(m, c, I_c) + "  </link>\n")
        else:
            entry["inconsistent"] = reason
            problems.append(f"link {names[i]} (joint {joint}): {reason}")
        if friction is not None:
            a, d, f = (float(v) for v in friction[i])
            entry["joint_terms"] = {"armature": a, "damping": d, "friction": f}
            if d >= 0.0 and f >= 0.0:
                blocks.append(f"  <joint name={quoteattr(str(joint))}>\n    <dynamics "
                              f"damping=\"{d:.9g}\" friction=\"{f:.9g}\"/>\n  </joint>\n")
            else:
                problems.append(f"joint {joint}: damping or friction < 0, left out of the "
                                "URDF <dynamics>")
        entries.append(entry)
    doc = {"format": FORMAT, "model": str(model_name),
           "saved": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
           "parameters": list(PARAMETER_NAMES), "links": entries}
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        f.write("# theta_hat of rcac_ros (eq 13 order); 'inertial': the same link as a rigid "
                "body\n")
        yaml.safe_dump(doc, f, sort_keys=False, default_flow_style=None, width=1000)
    fragment = urdf_path(path)
    with open(fragment, "w", encoding="utf-8") as f:
        frame = "the URDF link frames" if turns is not None else \
            "each joint's frame (z = joint axis)"
        f.write("<?xml version=\"1.0\"?>\n<!-- rcac_ros estimates as URDF inertials, in "
                f"{frame}. Inconsistent links left out:"
                + "".join(f"\n     {p}" for p in problems).replace("--", "- -")
                + " -->\n"
                f"<robot name={quoteattr(str(model_name))}>\n" + "".join(blocks)
                + "</robot>\n")
    return path, fragment, problems


def load(path, joint_names, field="initial_estimates"):
    """Read an estimates file written by :func:`save`; ``theta`` (n, 13) in ``joint_names`` order.

    Raises
    ------
    ConfigError
        Naming ``field`` and the file: missing file, wrong format, joints that differ from
        the model's, or values that are not 13 finite numbers per link.
    """
    if not os.path.isfile(path):
        raise ConfigError(f"{field}: no such file {path!r} (or 'zero', 'model')")
    doc = read_yaml(path, f"{field}: {path}")
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ConfigError(f"{field}: {path}: not an estimates file (format: {FORMAT!r})")
    entries = doc.get("links")
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise ConfigError(f"{field}: {path}: 'links' must be a list of mappings")
    by_joint = {str(e.get("joint")): e.get("theta") for e in entries}
    if sorted(by_joint) != sorted(joint_names) or len(entries) != len(joint_names):
        raise ConfigError(f"{field}: {path}: joints {[e.get('joint') for e in entries]} do not "
                          f"match the model's {list(joint_names)}")
    theta = np.zeros((len(joint_names), 13))
    for i, joint in enumerate(joint_names):
        row = by_joint[joint]
        try:
            values = np.array(row, dtype=float)
        except (TypeError, ValueError):
            values = np.zeros(0)
        if values.shape != (13,) or not np.all(np.isfinite(values)):
            raise ConfigError(f"{field}: {path}: joint {joint}: theta must be 13 finite numbers")
        theta[i] = values
    return theta


def load_joint_terms(path, joint_names, field="initial_estimates"):
    """The joint terms (n, 3) of a file written by :func:`save`, or None if it has none.

    Raises
    ------
    ConfigError
        As :func:`load` (it reads the file first), or joint terms that are not three finite
        numbers per joint.
    """
    load(path, joint_names, field)
    doc = read_yaml(path, f"{field}: {path}")
    by_joint = {str(e.get("joint")): e.get("joint_terms") for e in doc["links"]}
    if all(v is None for v in by_joint.values()):
        return None
    out = np.zeros((len(joint_names), 3))
    for i, joint in enumerate(joint_names):
        terms = by_joint[joint]
        try:
            out[i] = [float(terms[k]) for k in ("armature", "damping", "friction")]
        except (TypeError, KeyError, ValueError):
            raise ConfigError(f"{field}: {path}: joint {joint}: joint_terms must hold armature, "
                              "damping and friction") from None
        if not np.all(np.isfinite(out[i])):
            raise ConfigError(f"{field}: {path}: joint {joint}: joint_terms must be finite")
    return out


def initial_joint_terms(spec, model, joint_names=None):
    """The joint estimates (n, 3) for ``initial_estimates``: zero, the model's, or a file's
    (zero if the file has none)."""
    names = list(model.joint_names if joint_names is None else joint_names)
    if spec == "zero":
        return np.zeros((model.n, 3))
    if spec in ("model", "nominal"):
        return model.joint_terms()
    terms = load_joint_terms(spec, names)
    return np.zeros((model.n, 3)) if terms is None else terms


def initial_estimates(spec, model, joint_names=None):
    """The ``initial_estimates`` parameter: ``zero``, ``model``, ``nominal`` (the natural
    geometry's default start, doc/design.md §8) or a saved file's path.

    Returns
    -------
    ndarray (n, 13)
        In the model's joint order (``joint_names`` defaults to ``model.joint_names``).
    """
    names = list(model.joint_names if joint_names is None else joint_names)
    if spec == "zero":
        return np.zeros((model.n, 13))
    if spec == "model":
        return model.theta()
    if spec == "nominal":                        # doc/design.md §8
        return default_start(model.theta())
    if not spec:
        raise ConfigError("initial_estimates: must be 'zero', 'model', 'nominal' or a file "
                          "path")
    return load(spec, names)


def urdf_child_links(urdf, joint_names):
    """The link each joint moves and the turn ``A`` from its frame to the model's (z = axis).

    Read from URDF XML or a URDF file; ``None`` if not a URDF naming every joint.

    Returns
    -------
    (links, rotations) : list of str, list of ndarray (3, 3)
    """
    import types
    import xml.etree.ElementTree as ET
    from rcac_ros.core.urdf import _axis_rotation
    if not urdf:
        return None
    try:
        root = ET.fromstring(urdf) if urdf.lstrip().startswith("<") else ET.parse(urdf).getroot()
    except (ET.ParseError, OSError):
        return None
    joints = {j.get("name"): j for j in root.iter("joint")}
    if any(joints.get(name) is None or joints[name].find("child") is None
           for name in joint_names):
        return None
    links, rotations = [], []
    for name in joint_names:
        axis = joints[name].find("axis")
        xyz = [float(v) for v in axis.get("xyz", "1 0 0").split()] if axis is not None \
            else [1.0, 0.0, 0.0]
        links.append(joints[name].find("child").get("link"))
        rotations.append(_axis_rotation("URDF", types.SimpleNamespace(name=name, axis=xyz)))
    return links, rotations
