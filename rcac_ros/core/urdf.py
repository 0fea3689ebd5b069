"""Load the serial chain of a URDF into a :class:`~rcac_ros.core.model.RobotModel`.

The URDF is parsed by ``yourdfpy`` (no meshes, no scene graph). The chain runs
from ``base_link`` (default: the root) to ``tip_link`` (default: the end of the
only path of moving joints) and is mapped onto the paper's frames (doc/design.md §1):

- Each revolute or continuous joint ``i`` gets a frame ``F_i = L_i A_i``: the
  URDF frame ``L_i`` of its child link turned by the constant rotation ``A_i``
  that takes z onto the joint axis. Then ``Rot(axis, q) A_i = A_i Rz(q)``, so
  ``p_i``/``R_fix_i`` are the pose of ``F_i`` in ``F_{i-1}`` at ``q = 0`` and the
  joint coordinate ``q_i`` is exactly the URDF one (same sign, same zero).
- Fixed joints on the chain are folded into the poses (before the first moving
  joint: into ``p_1``/``R_fix_1``); the links behind them are merged into the
  preceding moving link (mass, centre of mass, parallel-axis inertia).
- Everything else attached to a moving link (side branches, and everything
  beyond ``tip_link``) is merged rigidly too, with any joint in it locked at
  its zero position, like ``pinocchio.buildReducedModel`` at the neutral
  configuration (e.g. the Panda's gripper fingers). Links attached before the
  first moving joint belong to the fixed base and are ignored.
- Prismatic, floating, planar and mimic joints on the chain are rejected
  (:class:`ConfigError` naming the joint): the controller models revolute chains.
"""

import io
import logging
import math
import os

import numpy as np

from rcac_ros.errors import ConfigError, ModelError
from .model import check_inertia, FRICTION_VELOCITY, RobotModel

#: Joint types that become a degree of freedom of the chain.
MOVING_TYPES = ("revolute", "continuous")

#: Default relative tolerance on the triangle inequality ``I1 + I2 >= I3 (1 - tol)``.
TRIANGLE_TOLERANCE = 1e-2


def model_from_urdf(path_or_xml, base_link=None, tip_link=None, gravity=(0.0, 0.0, -9.81),
                    name=None, triangle_tolerance=TRIANGLE_TOLERANCE, armature=0.0,
                    friction_velocity=FRICTION_VELOCITY):
    """The serial chain ``base_link`` -> ``tip_link`` of a URDF as a :class:`RobotModel`.

    Parameters
    ----------
    path_or_xml : str or os.PathLike
        A URDF file, or the URDF XML itself (a string starting with ``<``).
    base_link : str, optional
        The fixed base of the chain (default: the root link). Gravity is expressed in it.
    tip_link : str, optional
        The last link of the chain (default: the child of the last joint of the
        only path of moving joints; a tree whose moving joints branch needs it).
    gravity : array_like, shape (3,), optional
        Gravity acceleration in the base link's frame (default ``(0, 0, -9.81)``).
    name : str, optional
        Model name (default: the URDF robot name).
    triangle_tolerance : float or None, optional
        Each merged link inertia must satisfy ``I1 + I2 >= (1 - tol) I3`` for its
        principal moments (real URDFs are sometimes a little off); ``None`` turns
        the check off. Positive definiteness is always required. Default 1e-2.
    armature : float or array_like, shape (n,), optional
        Reflected rotor inertia of each moving joint, kg m^2 (URDF has no tag for it;
        default 0). Damping and Coulomb friction come from each joint's
        ``<dynamics damping=".." friction=".."/>`` (doc/design.md §7).
    friction_velocity : float, optional
        ``v_c`` of the smooth Coulomb law (default :data:`~rcac_ros.core.model.FRICTION_VELOCITY`).

    Returns
    -------
    RobotModel
        With ``joint_names`` the URDF joint names base -> tip and the URDF
        effort, velocity and position limits (a missing or zero effort or
        velocity limit means unbounded), and each joint's damping and friction. The
        model's own triangle check is off; this loader applied the tolerant one above.

    Raises
    ------
    ConfigError
        Missing file, malformed XML, unknown or unrelated base/tip link, a branched
        tree without ``tip_link``, a prismatic/floating/planar/mimic joint on the
        chain, or a moving link without mass (the message names the joint or link).
    ModelError
        If a merged link inertia is not physical (not positive definite, or beyond
        the triangle tolerance); the message names the link.
    """
    urdf, source = _load(path_or_xml)
    robot = urdf.robot
    links = {}
    for link in robot.links:
        if link.name in links:
            raise ConfigError(f"{source}: link {link.name!r} is defined twice")
        links[link.name] = link
    parent_joint, children = {}, {name_: [] for name_ in links}
    for joint in robot.joints:
        for end in (joint.parent, joint.child):
            if end not in links:
                raise ConfigError(f"{source}: joint {joint.name!r} refers to unknown link "
                                  f"{end!r}")
        if joint.child in parent_joint:
            raise ConfigError(f"{source}: link {joint.child!r} has two parent joints")
        parent_joint[joint.child] = joint
        children[joint.parent].append(joint)
    roots = [n for n in links if n not in parent_joint]
    if len(roots) != 1:
        raise ConfigError(f"{source}: the URDF must be one tree with one root link, found roots "
                          f"{roots}")
    base = roots[0] if base_link is None else str(base_link)
    if base not in links:
        raise ConfigError(f"{source}: base_link {base!r} is not a link of the URDF")
    tip = _default_tip(source, base, children) if tip_link is None else str(tip_link)
    if tip not in links:
        raise ConfigError(f"{source}: tip_link {tip!r} is not a link of the URDF")
    path = _path(source, base, tip, parent_joint)

    # Classify the chain joints.
    moving = []
    for joint in path:
        if joint.type in MOVING_TYPES:
            if joint.mimic is not None:
                raise ConfigError(f"{source}: joint {joint.name!r} mimics {joint.mimic.joint!r}; "
                                  "coupled joints are not supported on the chain")
            moving.append(joint)
        elif joint.type == "prismatic":
            raise ConfigError(f"{source}: joint {joint.name!r} is prismatic; rcac_ros models "
                              "chains of revolute joints only (choose a base_link/tip_link that "
                              "leaves it out)")
        elif joint.type != "fixed":
            raise ConfigError(f"{source}: joint {joint.name!r} has type {joint.type!r}; only "
                              "revolute, continuous and fixed joints can be on the chain")
    if not moving:
        raise ConfigError(f"{source}: no revolute or continuous joint between {base!r} and "
                          f"{tip!r}")

    # Poses: T accumulates the URDF origins since the previous moving link's frame L.
    n = len(moving)
    p, R_fix, mass, com, inertia = [], [], [], [], []
    A_prev = np.eye(3)
    T = np.eye(4)
    k = 0
    for joint in path:
        T = T @ _origin(joint)
        if joint.type not in MOVING_TYPES:
            continue
        A = _axis_rotation(source, joint)
        # Pose of F_i = L_i A_i in F_{i-1} = L_{i-1} A_{i-1}.
        R_fix.append(A_prev.T @ T[:3, :3] @ A)
        p.append(A_prev.T @ T[:3, 3])
        stop = moving[k + 1].name if k + 1 < n else None
        m, c, inert = _rigid_body(source, joint.child, children, links, stop)
        if m <= 0.0:
            raise ConfigError(f"{source}: link {joint.child!r} (moved by joint {joint.name!r}) "
                              "has no mass: give it an <inertial> with a mass > 0")
        c, inert = A.T @ c, A.T @ inert @ A
        inert = 0.5 * (inert + inert.T)
        try:
            check_inertia(inert, f"link {joint.child!r}", check_triangle=False)
        except ModelError as err:
            raise ModelError(f"{source}: {err}") from None
        _check_triangle(source, joint.child, inert, triangle_tolerance)
        mass.append(m)
        com.append(c)
        inertia.append(inert)
        A_prev, T, k = A, np.eye(4), k + 1

    effort, velocity, lower, upper, damping, friction = [], [], [], [], [], []
    for joint in moving:
        dyn = joint.dynamics
        damping.append(float(getattr(dyn, "damping", None) or 0.0))
        friction.append(float(getattr(dyn, "friction", None) or 0.0))
        lim = joint.limit
        e = getattr(lim, "effort", None)
        v = getattr(lim, "velocity", None)
        effort.append(e if e is not None and e > 0.0 else np.inf)
        velocity.append(v if v is not None and v > 0.0 else np.inf)
        lo = getattr(lim, "lower", None)
        hi = getattr(lim, "upper", None)
        if joint.type == "continuous" or lo is None or hi is None or lo >= hi:
            lo, hi = -np.inf, np.inf
        lower.append(lo)
        upper.append(hi)
    try:
        return RobotModel(np.array(p), np.array(R_fix), np.array(mass), np.array(com),
                          np.array(inertia), gravity=gravity,
                          joint_names=[j.name for j in moving], effort_limit=effort,
                          position_lower=lower, position_upper=upper, velocity_limit=velocity,
                          name=robot.name if name is None else name, check_triangle=False,
                          armature=armature, damping=damping, friction=friction,
                          friction_velocity=friction_velocity)
    except ModelError as err:
        raise ModelError(f"{source}: {err}") from None


# ---------------------------------------------------------------------------- helpers
class _ErrorLog(logging.Handler):
    """Collects the errors yourdfpy logs (it recovers from malformed XML silently)."""

    def __init__(self):
        super().__init__(logging.ERROR)
        self.messages = []

    def emit(self, record):
        self.messages.append(record.getMessage())


def _load(path_or_xml):
    """Parse the URDF with yourdfpy; return ``(urdf, source label)``."""
    if isinstance(path_or_xml, bytes):
        path_or_xml = path_or_xml.decode("utf-8", errors="replace")
    if isinstance(path_or_xml, str) and path_or_xml.lstrip().startswith("<"):
        source = "URDF string"
        stream = io.BytesIO(path_or_xml.encode("utf-8"))
    else:
        try:
            source = os.fspath(path_or_xml)
        except TypeError:
            raise ConfigError(f"path_or_xml: expected a file path or URDF XML, got "
                              f"{type(path_or_xml).__name__}") from None
        if not os.path.isfile(source):
            raise ConfigError(f"{source}: " + ("a directory, not a URDF file"
                                               if os.path.isdir(source) else "no such URDF file"))
        stream = source
    import yourdfpy                         # once the file is known to exist
    logger = logging.getLogger(yourdfpy.urdf.__name__)
    log = _ErrorLog()
    propagate = logger.propagate
    logger.addHandler(log)
    logger.propagate = False
    try:
        urdf = yourdfpy.URDF.load(stream, build_scene_graph=False, load_meshes=False,
                                  build_collision_scene_graph=False,
                                  load_collision_meshes=False)
    except Exception as err:  # yourdfpy/lxml raise many kinds on broken input
        detail = log.messages[0] if log.messages else \
            f"an element lacks its {err.args[0]!r} attribute" if isinstance(err, KeyError) \
            else f"{type(err).__name__}: {err}"
        raise ConfigError(f"{source}: not a valid URDF ({detail})") from None
    finally:
        logger.removeHandler(log)
        logger.propagate = propagate
    if log.messages:
        raise ConfigError(f"{source}: malformed XML ({log.messages[0]})")
    if urdf.robot is None or not urdf.robot.links:
        raise ConfigError(f"{source}: the URDF defines no links")
    for joint in urdf.robot.joints:
        if joint.type is None:
            raise ConfigError(f"{source}: joint {joint.name!r} has no type")
    return urdf, source


def _moving_path_to_leaves(base, children):
    """For each leaf below ``base``: the names of the moving joints on its path."""
    out = {}
    stack = [(base, ())]
    while stack:
        link, seq = stack.pop()
        if not children[link]:
            out[link] = seq
        for joint in children[link]:
            step = seq + (joint.name,) if joint.type != "fixed" else seq
            stack.append((joint.child, step))
    return out


def _default_tip(source, base, children):
    """The child of the last joint of the only path of moving joints below ``base``."""
    paths = _moving_path_to_leaves(base, children)
    longest = max(paths.values(), key=len)
    if any(seq != longest[:len(seq)] for seq in paths.values()):
        leaves = sorted(leaf for leaf, seq in paths.items()
                        if not any(len(o) > len(seq) and o[:len(seq)] == seq
                                   for o in paths.values()))
        raise ConfigError(f"{source}: the kinematic tree below {base!r} branches; choose "
                          f"tip_link, e.g. one of the leaves {leaves}")
    if not longest:
        raise ConfigError(f"{source}: no moving joint below {base!r}")
    joint_by_name = {j.name: j for js in children.values() for j in js}
    return joint_by_name[longest[-1]].child


def _path(source, base, tip, parent_joint):
    """The joints from ``base`` down to ``tip``, base first."""
    path = []
    link = tip
    while link != base:
        joint = parent_joint.get(link)
        if joint is None:
            raise ConfigError(f"{source}: tip_link {tip!r} is not below base_link {base!r}")
        path.append(joint)
        link = joint.parent
    if not path:
        raise ConfigError(f"{source}: base_link and tip_link are both {base!r}")
    return path[::-1]


def _origin(joint):
    """The joint's origin transform (4x4); joints off the chain are locked at zero."""
    return np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float)


def _axis_rotation(source, joint):
    """The rotation ``A`` with ``A @ e_z`` = the joint's unit axis (the smallest such turn)."""
    a = np.asarray(joint.axis if joint.axis is not None else (1.0, 0.0, 0.0), dtype=float)
    norm = np.linalg.norm(a)
    if a.shape != (3,) or not np.isfinite(norm) or norm < 1e-12:
        raise ConfigError(f"{source}: joint {joint.name!r} has an invalid axis {a.tolist()}")
    a = a / norm
    c = a[2]                                    # cos of the angle between z and a
    k = np.array([-a[1], a[0], 0.0])            # z x a
    s = np.linalg.norm(k)                       # sin of that angle
    if s < 1e-12:
        return np.eye(3) if c > 0.0 else np.diag([1.0, -1.0, -1.0])   # Rx(pi) for -z
    k /= s
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    ang = math.atan2(s, c)
    return np.eye(3) + math.sin(ang) * K + (1.0 - math.cos(ang)) * (K @ K)


def _rigid_body(source, root, children, links, stop):
    """Mass, centre of mass and inertia about it (frame of ``root``) of everything rigidly
    attached to ``root``: its subtree, except the subtree of the chain joint ``stop``."""
    bodies = []
    stack = [(root, np.eye(4))]
    while stack:
        name, T = stack.pop()
        inertial = links[name].inertial
        if inertial is not None and inertial.mass is not None and inertial.mass != 0.0:
            m = float(inertial.mass)
            if not m > 0.0:
                raise ConfigError(f"{source}: link {name!r} has mass {m}; must be > 0")
            if inertial.inertia is None:
                raise ConfigError(f"{source}: link {name!r} has a mass but no <inertia>")
            To = T @ (np.eye(4) if inertial.origin is None else inertial.origin)
            R = To[:3, :3]
            bodies.append((m, To[:3, 3], R @ np.asarray(inertial.inertia, float) @ R.T))
        for joint in children[name]:
            if joint.name != stop:
                stack.append((joint.child, T @ _origin(joint)))
    if not bodies:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    m = sum(b[0] for b in bodies)
    c = sum(b[0] * b[1] for b in bodies) / m
    inert = np.zeros((3, 3))
    for mk, ck, ik in bodies:
        d = ck - c
        inert += ik + mk * (d @ d * np.eye(3) - np.outer(d, d))
    return m, c, inert


def _check_triangle(source, link, inert, tol):
    """Principal moments must satisfy ``I1 + I2 >= (1 - tol) I3`` (``tol=None``: no check)."""
    if tol is None:
        return
    eig = np.linalg.eigvalsh(inert)
    if eig[0] + eig[1] < (1.0 - float(tol)) * eig[2]:
        raise ModelError(f"{source}: link {link!r}: principal moments {eig.tolist()} violate the "
                         f"triangle inequality I1 + I2 >= I3 by more than {tol:g} relative "
                         "(pass triangle_tolerance=None to accept it)")
