"""The constant description of a serial chain of revolute joints (the paper's frames).

Conventions (doc/design.md §1): frame ``i`` is frame ``i-1`` translated by
``p[i]`` (expressed in frame ``i-1``), turned by the constant rotation
``R_fix[i]`` and then by ``Rz(q_i)``; so ``iC_{i-1} = (R_fix_i Rz(q_i))^T``.
Each link carries its mass, its centre of mass ``com`` (frame ``i``) and its
inertia ``inertia`` about the centre of mass (link axes, tensor entries as in
URDF). Each joint carries its reflected rotor inertia ``armature``, its viscous
``damping`` and its Coulomb ``friction``, smoothed by ``tanh(qd / friction_velocity)``
(doc/design.md §7).

:class:`RobotModel` is immutable, like Pinocchio's ``Model``; per-step work
lives in the controllers' and the simulator's own state.
"""

import math
import os

import numpy as np

from rcac_ros.errors import ConfigError, ModelError, read_yaml
from ._validate import as_array, joint_values, scalar

#: Names of the 13 inertial parameters of one link, in the paper's order (eq 13, doc/design.md §2).
PARAMETER_NAMES = (
    "m", "m*px", "m*py", "m*pz", "m*px^2", "m*py^2", "m*pz^2",
    "m*px*py-Ixy", "m*px*pz-Ixz", "m*py*pz-Iyz", "Ixx", "Iyy", "Izz",
)


#: v_c of the smooth Coulomb law ``sigma(v) = tanh(v / v_c)``, rad/s (doc/design.md §7).
#: 0.1 rad/s: the Panda's identified friction (Gaz et al., RA-L 2019) saturates at 0.2-0.7 N m
#: with a slope of 0.7-2 N m s/rad at rest, a ratio of 0.1-1 rad/s; and the slope it adds,
#: friction / v_c, keeps the simulator's RK4 at 2 ms stable on the Panda's lightest joint
#: (joint 7, about 0.0055 kg m^2: h * 0.5 / (0.1 * 0.0055) = 1.8 < 2.78) without armature.
FRICTION_VELOCITY = 0.1

#: Names of the three joint parameters, in the order of ``friction_hat`` (doc/design.md §7).
JOINT_PARAMETER_NAMES = ("armature", "damping", "friction")


def rot_x(a):
    """Rotation matrix about x by ``a`` rad."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a):
    """Rotation matrix about y by ``a`` rad."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a):
    """Rotation matrix about z by ``a`` rad."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_matrix(rpy):
    """URDF roll-pitch-yaw: ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    r, p, y = rpy
    return rot_z(y) @ rot_y(p) @ rot_x(r)


def theta_from_inertia(mass, com, inertia):
    """The 13 parameters of eq 13 (doc/design.md §2) from mass, centre of mass, inertia there."""
    m = float(mass)
    px, py, pz = (float(v) for v in com)
    I = np.asarray(inertia, dtype=float)
    return np.array([
        m, m * px, m * py, m * pz, m * px * px, m * py * py, m * pz * pz,
        m * px * py - I[0, 1], m * px * pz - I[0, 2], m * py * pz - I[1, 2],
        I[0, 0], I[1, 1], I[2, 2],
    ])


#: Column offsets of the packed model row: p, R_fix, theta, then armature, damping, friction
#: and the friction velocity v_c at JA, JD, JF, JV (doc/design.md §7).
P0, RF0, TH0, JA, JD, JF, JV, KIN_COLS = 0, 3, 12, 25, 26, 27, 28, 29


def pack_kinematics(model):
    """Pack ``model`` into the (n, 29) row layout the kernels read: p, R_fix, theta, joint terms.

    :class:`RobotModel` calls it once and keeps the result in its
    ``packed`` field (read-only, as the model is immutable).
    """
    buf = np.empty((model.n, KIN_COLS))
    buf[:, P0:P0 + 3] = model.p
    buf[:, RF0:RF0 + 9] = model.R_fix.reshape(model.n, 9)
    buf[:, TH0:TH0 + 13] = model.theta()
    buf[:, JA] = model.armature
    buf[:, JD] = model.damping
    buf[:, JF] = model.friction
    buf[:, JV] = model.friction_velocity
    return buf


class RobotModel:
    """A serial chain of revolute joints, each rotating about its own z axis.

    Parameters
    ----------
    p : array_like, shape (n, 3)
        Origin of frame i in frame i-1 (``i-1 p_i`` of eq 10), metres.
    R_fix : array_like, shape (n, 3, 3)
        Constant rotation of frame i relative to frame i-1, applied before ``Rz(q_i)``.
    mass : array_like, shape (n,)
        Link masses, kg, each > 0.
    com : array_like, shape (n, 3)
        Centre of mass of each link in its own frame, metres.
    inertia : array_like, shape (n, 3, 3)
        Inertia about the centre of mass, link axes, kg m^2: symmetric, positive
        definite, satisfying the triangle inequalities.
    gravity : array_like, shape (3,), optional
        Gravity acceleration in the base frame, m/s^2 (default zero, as in the paper).
    joint_names : sequence of str, optional
        Default ``joint1`` ... ``jointn``.
    effort_limit, position_lower, position_upper, velocity_limit : array_like, shape (n,), optional
        Joint limits (default unbounded). ``effort_limit`` is the default torque limit.
    name : str, optional
    armature : array_like, shape (n,), optional
        Reflected rotor inertia of each joint, kg m^2, added to ``M_ii`` (default 0).
    damping : array_like, shape (n,), optional
        Viscous friction of each joint, N m s/rad: torque ``damping_i qd_i`` (default 0).
    friction : array_like, shape (n,), optional
        Coulomb friction of each joint, N m: torque ``friction_i tanh(qd_i / v_c)`` (default 0).
    friction_velocity : float, optional
        ``v_c`` of the smooth Coulomb law, rad/s, > 0 (default :data:`FRICTION_VELOCITY`).
    check_triangle : bool, optional
        Also require the principal moments to satisfy ``I1 + I2 >= I3`` (default True).
        The paper's own Table 1 violates it (``diag[2 2 200]``), so :func:`css_arm`
        turns it off; positive definiteness is always required.

    Raises
    ------
    ModelError
        On a wrong shape, a NaN/Inf, a mass <= 0, a non-physical inertia, a
        rotation that is not proper orthonormal, duplicate joint names, a negative
        joint term or ``friction_velocity <= 0``.
    """

    def __init__(self, p, R_fix, mass, com, inertia, gravity=(0.0, 0.0, 0.0), joint_names=None,
                 effort_limit=None, position_lower=None, position_upper=None,
                 velocity_limit=None, name="robot", check_triangle=True, armature=None,
                 damping=None, friction=None, friction_velocity=FRICTION_VELOCITY):
        mass = as_array(mass, (None,), "mass", ModelError)
        n = mass.shape[0]
        if n < 1:
            raise ModelError("mass: the chain needs at least one link")
        self.name = str(name)
        self.p = as_array(p, (n, 3), "p", ModelError)
        self.R_fix = as_array(R_fix, (n, 3, 3), "R_fix", ModelError)
        self.mass = mass
        self.com = as_array(com, (n, 3), "com", ModelError)
        self.inertia = as_array(inertia, (n, 3, 3), "inertia", ModelError)
        self.gravity = as_array(gravity, (3,), "gravity", ModelError)
        for i in range(n):
            R = self.R_fix[i]
            if not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0.0:
                raise ModelError(f"R_fix[{i}]: not a proper rotation matrix")
            if mass[i] <= 0.0:
                raise ModelError(f"mass[{i}]: must be > 0, got {mass[i]}")
            check_inertia(self.inertia[i], f"inertia[{i}]", check_triangle)
        if joint_names is None:
            joint_names = [f"joint{i + 1}" for i in range(n)]
        joint_names = tuple(str(s) for s in joint_names)
        if len(joint_names) != n or len(set(joint_names)) != n:
            raise ModelError(f"joint_names: need {n} distinct names, got {list(joint_names)}")
        self.joint_names = joint_names
        self.check_triangle = bool(check_triangle)

        def limits(value, default, label):
            if value is None:
                return np.full(n, default)
            return joint_values(value, n, label, ModelError, finite=False)

        self.effort_limit = limits(effort_limit, np.inf, "effort_limit")
        self.velocity_limit = limits(velocity_limit, np.inf, "velocity_limit")
        self.position_lower = limits(position_lower, -np.inf, "position_lower")
        self.position_upper = limits(position_upper, np.inf, "position_upper")
        for label in ("effort_limit", "velocity_limit"):
            if np.any(getattr(self, label) <= 0.0):
                raise ModelError(f"{label}: every entry must be > 0")
        bad = np.flatnonzero(self.position_lower > self.position_upper)
        if bad.size:
            raise ModelError(f"position_lower[{bad[0]}]: above position_upper[{bad[0]}]")
        for label, value in (("armature", armature), ("damping", damping),
                             ("friction", friction)):
            arr = limits(value, 0.0, label)
            if not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
                raise ModelError(f"{label}: every entry must be finite and >= 0")
            setattr(self, label, arr)
        self.friction_velocity = scalar(friction_velocity, "friction_velocity", ModelError,
                                        minimum=0.0, strict=True)
        self._theta = np.array([theta_from_inertia(self.mass[i], self.com[i], self.inertia[i])
                                for i in range(n)])
        #: (n, 29) the rows the compiled kernels read: p, R_fix, theta, the joint terms
        #: (:func:`pack_kinematics`)
        self.packed = pack_kinematics(self)
        for arr in (self.p, self.R_fix, self.mass, self.com, self.inertia, self.gravity,
                    self.effort_limit, self.velocity_limit, self.position_lower,
                    self.position_upper, self._theta, self.packed, self.armature,
                    self.damping, self.friction):
            arr.setflags(write=False)

    @property
    def n(self):
        """Number of joints (and links)."""
        return self.mass.shape[0]

    def theta(self):
        """The true parameters, shape (n, 13), in the paper's order (:data:`PARAMETER_NAMES`)."""
        return self._theta.copy()

    def joint_terms(self):
        """The joint parameters, shape (n, 3): armature, damping, friction (doc/design.md §7)."""
        return np.column_stack([self.armature, self.damping, self.friction])

    @property
    def has_joint_terms(self):
        """Whether any joint has armature, damping or friction (doc/design.md §7)."""
        return bool(np.any(self.armature) or np.any(self.damping) or np.any(self.friction))

    def replace(self, **changes):
        """A copy of the model with some constructor arguments changed."""
        args = dict(p=self.p, R_fix=self.R_fix, mass=self.mass, com=self.com,
                    inertia=self.inertia, gravity=self.gravity, joint_names=self.joint_names,
                    effort_limit=self.effort_limit, position_lower=self.position_lower,
                    position_upper=self.position_upper, velocity_limit=self.velocity_limit,
                    name=self.name, check_triangle=self.check_triangle,
                    armature=self.armature, damping=self.damping, friction=self.friction,
                    friction_velocity=self.friction_velocity)
        args.update(changes)
        return RobotModel(**args)

    def repeated(self, times):
        """The chain repeated ``times`` times end to end (benchmark chains of n = 7 k)."""
        k = int(times)
        if k < 1:
            raise ModelError(f"times: must be >= 1, got {times}")
        tile = lambda a: np.concatenate([a] * k)  # noqa: E731
        names = [f"{s}_{r}" if k > 1 else s for r in range(k) for s in self.joint_names]
        return RobotModel(tile(self.p), tile(self.R_fix), tile(self.mass), tile(self.com),
                          tile(self.inertia), self.gravity, names, tile(self.effort_limit),
                          tile(self.position_lower), tile(self.position_upper),
                          tile(self.velocity_limit), name=f"{self.name}x{k}",
                          check_triangle=self.check_triangle, armature=tile(self.armature),
                          damping=tile(self.damping), friction=tile(self.friction),
                          friction_velocity=self.friction_velocity)

    def __repr__(self):
        return f"RobotModel(name={self.name!r}, n={self.n}, gravity={self.gravity.tolist()})"

    # ------------------------------------------------------------------ loaders
    @classmethod
    def from_yaml(cls, path):
        """Load a model from the YAML schema documented in ``config/css_arm.yaml``.

        Raises
        ------
        ConfigError
            If the file is missing, is not YAML, or lacks a field; the message names it.
        ModelError
            If the values are not physically valid.
        """
        return cls.from_dict(read_yaml(path), source=os.fspath(path))

    @classmethod
    def from_dict(cls, doc, source="model"):
        """Build a model from the parsed YAML schema (see :meth:`from_yaml`)."""
        if not isinstance(doc, dict):
            raise ConfigError(f"{source}: the top level must be a mapping with 'links'")
        if "robot" in doc and isinstance(doc["robot"], dict):
            doc = doc["robot"]
        links = doc.get("links")
        if not isinstance(links, list) or not links:
            raise ConfigError(f"{source}: 'links' must be a non-empty list")
        fields = {k: [] for k in ("p", "R_fix", "mass", "com", "inertia", "joint_names",
                                  "effort_limit", "position_lower", "position_upper",
                                  "velocity_limit", "armature", "damping", "friction")}
        for i, link in enumerate(links):
            where = f"{source}: links[{i}]"
            if not isinstance(link, dict):
                raise ConfigError(f"{where}: must be a mapping")
            unknown = set(link) - {"joint", "p", "rpy", "rpy_deg", "R_fix", "mass", "com",
                                   "inertia", "effort_limit", "position_lower",
                                   "position_upper", "velocity_limit", "armature", "damping",
                                   "friction"}
            if unknown:
                raise ConfigError(f"{where}: unknown key(s) {sorted(unknown)}")
            for key in ("p", "mass", "com", "inertia"):
                if key not in link:
                    raise ConfigError(f"{where}.{key}: missing")
            fields["joint_names"].append(str(link.get("joint", f"joint{i + 1}")))
            fields["p"].append(_vector(link["p"], 3, f"{where}.p"))
            fields["mass"].append(_scalar(link["mass"], f"{where}.mass"))
            fields["com"].append(_vector(link["com"], 3, f"{where}.com"))
            fields["inertia"].append(_inertia(link["inertia"], f"{where}.inertia"))
            rot_keys = [k for k in ("rpy", "rpy_deg", "R_fix") if k in link]
            if len(rot_keys) > 1:
                raise ConfigError(f"{where}: give at most one of rpy, rpy_deg, R_fix")
            if not rot_keys:
                R = np.eye(3)
            elif rot_keys[0] == "R_fix":
                R = _matrix(link["R_fix"], f"{where}.R_fix")
            else:
                rpy = _vector(link[rot_keys[0]], 3, f"{where}.{rot_keys[0]}")
                R = rpy_matrix(np.radians(rpy) if rot_keys[0] == "rpy_deg" else rpy)
            fields["R_fix"].append(R)
            for key, default in (("effort_limit", np.inf), ("position_lower", -np.inf),
                                 ("position_upper", np.inf), ("velocity_limit", np.inf)):
                fields[key].append(_scalar(link[key], f"{where}.{key}") if key in link
                                   else default)
            for key in JOINT_PARAMETER_NAMES:
                fields[key].append(_scalar(link[key], f"{where}.{key}") if key in link else 0.0)
        gravity = _vector(doc.get("gravity", [0.0, 0.0, 0.0]), 3, f"{source}: gravity")
        triangle = doc.get("check_triangle_inequality", True)
        if not isinstance(triangle, bool):
            raise ConfigError(f"{source}: check_triangle_inequality must be true or false")
        v_c = _scalar(doc.get("friction_velocity", FRICTION_VELOCITY),
                      f"{source}: friction_velocity")
        try:
            return cls(gravity=gravity, name=str(doc.get("name", "robot")),
                       check_triangle=triangle, friction_velocity=v_c, **fields)
        except ModelError as err:
            raise ModelError(f"{source}: {err}") from None

    def to_dict(self):
        """The model in the YAML schema of :meth:`from_yaml` (lossless round trip)."""
        links = []
        for i in range(self.n):
            link = {"joint": self.joint_names[i], "p": self.p[i].tolist(),
                    "R_fix": self.R_fix[i].tolist(), "mass": float(self.mass[i]),
                    "com": self.com[i].tolist(), "inertia": self.inertia[i].tolist()}
            for key in ("effort_limit", "position_lower", "position_upper", "velocity_limit"):
                value = float(getattr(self, key)[i])
                if np.isfinite(value):
                    link[key] = value
            for key in JOINT_PARAMETER_NAMES:
                value = float(getattr(self, key)[i])
                if value != 0.0:
                    link[key] = value
            links.append(link)
        doc = {"name": self.name, "gravity": self.gravity.tolist(),
               "check_triangle_inequality": self.check_triangle, "links": links}
        if self.friction_velocity != FRICTION_VELOCITY:
            doc["friction_velocity"] = self.friction_velocity
        return doc


def check_inertia(I, name, check_triangle=True):
    """Raise :class:`ModelError` unless ``I`` is a physically valid inertia about a centre of mass.

    Valid means symmetric, positive definite, and its principal moments satisfy
    the triangle inequality ``I1 + I2 >= I3`` (a real mass distribution).
    """
    I = np.asarray(I, dtype=float)
    if not np.allclose(I, I.T, rtol=1e-9, atol=1e-12):
        raise ModelError(f"{name}: inertia is not symmetric")
    eig = np.linalg.eigvalsh(I)
    if eig[0] <= 0.0:
        raise ModelError(f"{name}: inertia is not positive definite (eigenvalues {eig.tolist()})")
    tol = 1e-9 * eig[-1]
    if check_triangle and eig[0] + eig[1] < eig[2] - tol:
        raise ModelError(f"{name}: principal moments {eig.tolist()} violate the triangle "
                         "inequality I1 + I2 >= I3")


def _scalar(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{name}: expected a number, got {value!r}")
    return float(value)


def _vector(value, size, name):
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise ConfigError(f"{name}: expected a list of {size} numbers, got {value!r}")
    return np.array([_scalar(v, f"{name}[{k}]") for k, v in enumerate(value)])


def _matrix(value, name):
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ConfigError(f"{name}: expected a 3x3 nested list, got {value!r}")
    return np.array([_vector(row, 3, f"{name}[{k}]") for k, row in enumerate(value)])


def _inertia(value, name):
    """Inertia as [ixx, iyy, izz], [ixx, iyy, izz, ixy, ixz, iyz], or a 3x3 nested list."""
    if isinstance(value, (list, tuple)) and value and isinstance(value[0], (list, tuple)):
        return _matrix(value, name)
    if isinstance(value, (list, tuple)) and len(value) in (3, 6):
        v = _vector(value, len(value), name)
        ixy, ixz, iyz = (v[3], v[4], v[5]) if len(v) == 6 else (0.0, 0.0, 0.0)
        return np.array([[v[0], ixy, ixz], [ixy, v[1], iyz], [ixz, iyz, v[2]]])
    raise ConfigError(f"{name}: expected [ixx, iyy, izz], [ixx, iyy, izz, ixy, ixz, iyz] "
                      f"or a 3x3 list, got {value!r}")


#: The paper's initial position of the CSS arm (Section 4), rad.
PAPER_Q0 = (0.3, math.pi / 2, math.pi / 3, -2 * math.pi / 3, math.pi / 3, math.pi / 2, 0.3)

#: The paper's gains (Section 4) and the filter bandwidth ``lambda`` it leaves open, as keyword
#: arguments of the controllers (``lam`` is the paper's lambda, a Python keyword; the node's
#: parameter is ``lambda``); ``h`` is the control period, s.
PAPER_GAINS = dict(K_D=1e4, Lambda=1.0, P=100.0, gamma=0.1, lam=10.0, h=0.002)

#: Table 1 link lengths a1..a8 (Section 4), metres.
CSS_LENGTHS = dict(a1=0.5, a2=0.5, a3=4.0, a4=0.5, a5=4.0, a6=0.5, a7=0.5, a8=1.0)


def css_arm(gravity=(0.0, 0.0, 0.0)):
    """The Chinese Space Station arm of the paper's Table 1 (7 links, g = 0).

    Figure 2 (the frames) is missing from the text, so the constant rotations
    follow doc/design.md §5: ``R_fix = [I, Rx(-90), I, I, Ry(90), Rx(-90), Ry(90)]``.
    ``config/css_arm.yaml`` holds the same preset in the YAML schema. Table 1's
    inertias (``diag[2 2 200]``) break the triangle inequality of a real body, so
    that check is off for this preset (positive definiteness is still checked).
    """
    a = CSS_LENGTHS
    p = [[0, -a["a1"], 0], [0, a["a2"], 0], [a["a3"], 0, 0], [a["a5"], 0, a["a4"]],
         [0, 0, a["a6"]], [0, 0, a["a7"]], [0, 0, a["a8"]]]
    h = math.pi / 2
    R_fix = [np.eye(3), rot_x(-h), np.eye(3), np.eye(3), rot_y(h), rot_x(-h), rot_y(h)]
    mass = [50, 50, 100, 100, 50, 50, 100]
    com = [[0, -0.1, 0], [0, 0.1, 0], [2, 0, 0], [2, 0, 0.5], [0, 0, 0.5], [0, 0, 0.5],
           [0, 0.5, 1]]
    inertia = [np.diag(d) for d in ([2, 2, 200], [2, 2, 200], [5, 300, 500], [5, 300, 500],
                                    [2, 2, 200], [2, 2, 200], [2, 2, 200])]
    return RobotModel(p, R_fix, mass, com, inertia, gravity, name="css_arm",
                      check_triangle=False)


#: Joint torque limits of the CSS arm preset of the nodes, N m (doc/failsafe.md, "goals"). The
#: paper gives none; these are chosen: about twice the largest torque of its Section 4 run
#: (velocity reading, paper gains, 60 s: peaks 376, 988, 532, 127, 26, 18, 10 N m) for the
#: four arm joints, and 500 N m for the three wrist joints.
CSS_EFFORT_LIMIT = (2000.0, 2000.0, 2000.0, 2000.0, 500.0, 500.0, 500.0)


def css_arm_preset():
    """:func:`css_arm` with the torque limits :data:`CSS_EFFORT_LIMIT` (the nodes' preset)."""
    return css_arm().replace(effort_limit=list(CSS_EFFORT_LIMIT))


#: Model presets by name (the ``model`` parameter of the nodes, ``rcac inspect --model``).
PRESETS = {"css_arm": css_arm_preset}
