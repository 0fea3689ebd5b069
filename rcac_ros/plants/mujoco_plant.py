"""The arm in MuJoCo: an independent plant with the simulator's interface (doc/plants.md).

:func:`mjcf` writes the MJCF of a :class:`~rcac_ros.core.model.RobotModel`: one body per
link, nested, placed by ``p_i`` and ``R_fix_i`` (doc/design.md §1), a hinge about its own
z axis, the link's mass, centre of mass and full inertia, the model's gravity, and per joint
``damping`` -> ``dof_damping`` (a passive force ``-d qd``), ``armature`` ->
``dof_armature`` (added to the diagonal of the mass matrix) and ``friction`` ->
``dof_frictionloss``: MuJoCo's dry friction, a soft constraint ``|f| <= friction`` solved
with the dynamics, not the model's smooth Coulomb law (doc/plants.md explains the
difference). No joint range, no contact: the built-in simulator has neither.

:class:`MujocoPlant` steps that model as :class:`rcac_ros.core.simulator.Simulator` steps
its own: the torque, clipped to the effort limit, held over ``dt`` (``qfrc_applied``),
``substeps`` MuJoCo steps of ``dt / substeps`` each, RK4 by default. With the friction
loss at zero the two plants integrate the same equations with the same scheme; they
differ only by rounding (test/plants/test_mujoco_plant.py).

MuJoCo is imported here only: :func:`require_mujoco` turns its absence into a one-line
:class:`~rcac_ros.errors.DependencyError`.
"""

import numpy as np

from rcac_ros.core.payload import Payload, with_payload
from rcac_ros.core.simulator import effort_limits, held_torque, initial_state, plant_period
from rcac_ros.errors import ConfigError, DependencyError, ModelError

#: MJCF names of MuJoCo's integrators (``option/@integrator``); RK4 is the built-in one's.
INTEGRATORS = ("RK4", "Euler", "implicit", "implicitfast")

#: The joint terms a model may carry (per joint, default zero) and MuJoCo's name for each.
JOINT_TERMS = (("damping", "damping"), ("armature", "armature"), ("friction", "frictionloss"))


def require_mujoco():
    """The ``mujoco`` module, or :class:`DependencyError` in one line saying how to get it."""
    try:
        import mujoco
    except ImportError:
        raise DependencyError("engine mujoco: the 'mujoco' package is not installed "
                              "(pip install mujoco==4.0.0, or the extra rcac_ros[mujoco])"
                              ) from None
    return mujoco


def joint_terms(model):
    """``{"damping": (n,), "armature": (n,), "friction": (n,)}`` of ``model``.

    The model's per-joint viscous damping (N m s/rad), reflected rotor inertia (kg m^2) and
    dry friction (N m) (doc/design.md §7). MuJoCo has no ``friction_velocity``: its dry
    friction is a constraint, not the model's ``tanh`` (doc/plants.md).
    """
    return {name: np.asarray(getattr(model, name), dtype=float) for name, _ in JOINT_TERMS}


def _num(x):
    """A float as MJCF text that reads back bit for bit."""
    return repr(float(x))


def _nums(values):
    return " ".join(_num(v) for v in np.ravel(values))


def _quat(R):
    """Unit quaternion ``(w, x, y, z)`` of the rotation matrix ``R`` (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    k = int(np.argmax([tr, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = (0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s)
    elif k == 1:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = ((R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s)
    elif k == 2:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = ((R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s)
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = ((R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s)
    q = np.array(q)
    return q / np.linalg.norm(q)


def _breaks_triangle(I):
    """True if the principal moments of ``I`` violate ``I1 + I2 >= I3`` (MuJoCo refuses them)."""
    e = np.linalg.eigvalsh(I)
    return e[0] + e[1] < e[2]


def mjcf(model, dt=0.002, integrator="RK4"):
    """The MJCF text of ``model`` (see the module docstring).

    Parameters
    ----------
    model : RobotModel
    dt : float
        MuJoCo's ``timestep``, s.
    integrator : str
        One of :data:`INTEGRATORS`.

    Notes
    -----
    MuJoCo's compiler refuses a body inertia whose principal moments break the triangle
    inequality; the CSS arm's Table 1 (``diag[2 2 200]``) does. Such a model is written
    with ``balanceinertia="true"`` and :class:`MujocoPlant` puts the true inertias back
    into the compiled model (MuJoCo's dynamics never check the inequality).
    """
    terms = joint_terms(model)
    balance = any(_breaks_triangle(model.inertia[i]) for i in range(model.n))
    lines = [f'<mujoco model="{model.name}">',
             '  <compiler angle="radian" autolimits="true" inertiafromgeom="false"'
             f' balanceinertia="{str(balance).lower()}"/>',
             f'  <option timestep="{_num(dt)}" integrator="{integrator}"'
             f' gravity="{_nums(model.gravity)}">',
             '    <flag contact="disable"/>',
             '  </option>',
             '  <worldbody>']
    indent = "    "
    for i in range(model.n):
        I = model.inertia[i]
        full = (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
        joint = (f'<joint name="{model.joint_names[i]}" type="hinge" axis="0 0 1"'
                 f' limited="false"')
        for name, mj_name in JOINT_TERMS:
            joint += f' {mj_name}="{_num(terms[name][i])}"'
        lines += [f'{indent}<body name="link{i + 1}" pos="{_nums(model.p[i])}"'
                  f' quat="{_nums(_quat(model.R_fix[i]))}">',
                  f'{indent}  {joint}/>',
                  f'{indent}  <inertial pos="{_nums(model.com[i])}" mass="{_num(model.mass[i])}"'
                  f' fullinertia="{_nums(full)}"/>']
        indent += "  "
    for _ in range(model.n):
        indent = indent[:-2]
        lines.append(f"{indent}</body>")
    lines += ["  </worldbody>", "</mujoco>"]
    return "\n".join(lines) + "\n"


class MujocoPlant:
    """A serial arm in MuJoCo with the interface of :class:`~rcac_ros.core.simulator.Simulator`.

    Parameters
    ----------
    model : RobotModel
        The true plant: its links, gravity and (if it has them) per-joint ``damping``,
        ``armature`` and ``friction`` (the last becomes MuJoCo's friction loss).
    dt : float
        Period over which one torque is held, s (default 2 ms).
    q0, qd0 : array_like (n,), optional
        Initial state (default zero).
    substeps : int
        MuJoCo steps per period (``timestep = dt / substeps``; default 1).
    effort_limit : float or array_like (n,), optional
        Torques are clipped to +-effort_limit (default: the model's ``effort_limit``).
    integrator : str
        MuJoCo's integrator, one of :data:`INTEGRATORS` (default ``"RK4"``, the built-in
        simulator's scheme).

    Attributes
    ----------
    mj_model, mj_data : mujoco.MjModel, mujoco.MjData
        The compiled model and its state (``qpos`` = ``q``, ``qvel`` = ``qd``).
    xml : str
        The MJCF it was compiled from.

    Raises
    ------
    DependencyError
        If ``mujoco`` is not installed.
    InputError, ConfigError
        A bad period, substep count, effort limit, initial state or integrator.
    ModelError
        If MuJoCo refuses the generated model (the message is MuJoCo's first line).
    """

    def __init__(self, model, dt=0.002, q0=None, qd0=None, substeps=1, effort_limit=None,
                 integrator="RK4"):
        mujoco = require_mujoco()
        self.model = model
        self.base_model = model             # the arm without a payload
        self.payload = Payload()
        self.dt, self.substeps = plant_period(dt, substeps)
        if integrator not in INTEGRATORS:
            raise ConfigError(f"integrator: expected one of {', '.join(INTEGRATORS)}, "
                              f"got {integrator!r}")
        self.integrator = integrator
        self.effort_limit = effort_limits(model, effort_limit)
        self.xml = mjcf(model, self.dt / self.substeps, integrator)
        try:
            self.mj_model = mujoco.MjModel.from_xml_string(self.xml)
        except ValueError as err:
            raise ModelError(f"mujoco: {str(err).splitlines()[0]}") from None
        self.mj_data = mujoco.MjData(self.mj_model)
        if "balanceinertia=\"true\"" in self.xml:
            self._restore_inertias(mujoco)
        self._step = mujoco.mj_step
        self._forward = mujoco.mj_forward
        self._reset_data = mujoco.mj_resetData
        self.read_from_urdf = False   # from_urdf(): MuJoCo read the file's frames
        self.reset(q0, qd0)

    def _restore_inertias(self, mujoco):
        """Put the model's principal inertias back into the compiled model (see :func:`mjcf`).

        MuJoCo stores each body's inertia as principal moments ``body_inertia`` about axes
        ``body_iquat`` (in the body frame); the eigen-decomposition ``I = Q diag(d) Q^T``
        gives both (``Q`` made a proper rotation).
        """
        for i in range(self.model.n):
            self._set_inertia(i + 1, self.model.inertia[i])
        mujoco.mj_setConst(self.mj_model, self.mj_data)

    def _set_inertia(self, body, I):
        d, Q = np.linalg.eigh(I)
        if np.linalg.det(Q) < 0.0:
            Q[:, 0] = -Q[:, 0]
        self.mj_model.body_inertia[body] = d
        self.mj_model.body_iquat[body] = _quat(Q)

    def set_payload(self, payload):
        """As :meth:`rcac_ros.core.simulator.Simulator.set_payload`: the last body's mass,
        centre of mass (``body_ipos``) and inertia (principal moments ``body_inertia`` about
        the axes ``body_iquat``) become the link's and the payload's together
        (:func:`rcac_ros.core.payload.combine`), from the next step on; the state is kept.

        MuJoCo's dynamics read these fields at every step; the constants derived from them
        (``body_subtreemass``, ``dof_invweight0``, ...) are recomputed by ``mj_setConst``,
        which works on ``mj_data`` at ``qpos0``: the state is saved and put back.

        Raises
        ------
        ConfigError
            On a plant MuJoCo read from a URDF (:meth:`from_urdf`): its last body's frame is
            the file's link frame, not the model's.
        """
        if self.read_from_urdf:
            raise ConfigError("payload: not available on a plant MuJoCo read from a URDF")
        mujoco = require_mujoco()
        loaded = with_payload(self.base_model, payload)
        n = loaded.n
        body = n                            # body 0 is the world
        self.mj_model.body_mass[body] = loaded.mass[n - 1]
        self.mj_model.body_ipos[body] = loaded.com[n - 1]
        self._set_inertia(body, loaded.inertia[n - 1])
        # the compiler's shortcuts for an inertial frame on the body's: they may hold no more
        self.mj_model.body_sameframe[body] = 0
        self.mj_model.body_simple[body] = 0
        data = self.mj_data
        qpos, qvel, act, time = data.qpos.copy(), data.qvel.copy(), data.act.copy(), data.time
        mujoco.mj_setConst(self.mj_model, data)
        data.qpos[:], data.qvel[:], data.act[:], data.time = qpos, qvel, act, time
        self._forward(self.mj_model, data)
        self.model = loaded
        self.payload = payload

    @property
    def q(self):
        """Joint positions, rad (a copy)."""
        return self.mj_data.qpos.copy()

    @property
    def qd(self):
        """Joint velocities, rad/s (a copy)."""
        return self.mj_data.qvel.copy()

    def reset(self, q0=None, qd0=None, t=0.0):
        """Set the state (default zero) and the time."""
        n = self.model.n
        q, qd = initial_state(n, q0, qd0)
        self._reset_data(self.mj_model, self.mj_data)
        self.mj_data.qpos[:] = q
        self.mj_data.qvel[:] = qd
        self._forward(self.mj_model, self.mj_data)
        self.t = float(t)
        self.applied = np.zeros(n)          # the torque held over the last step, after clipping

    def step(self, tau):
        """As :meth:`rcac_ros.core.simulator.Simulator.step`, integrated by MuJoCo: hold
        ``tau`` (clipped, left in ``applied``) for ``dt``; the new ``(q, qd)``; an
        :class:`InputError` leaves the state untouched."""
        self.applied = held_torque(tau, self.effort_limit)
        self.mj_data.qfrc_applied[:] = self.applied
        for _ in range(self.substeps):
            self._step(self.mj_model, self.mj_data)
        self.t += self.dt
        return self.q, self.qd

    @classmethod
    def from_urdf(cls, path, model, **kwargs):
        """The plant read by MuJoCo's own URDF parser (an independent reading of the file).

        Parameters
        ----------
        path : str
            The URDF the :class:`RobotModel` ``model`` was loaded from
            (:func:`rcac_ros.core.urdf.model_from_urdf`).
        model : RobotModel
            Its chain: the joints MuJoCo keeps, in order, are ``model.joint_names``; every
            other joint of the file is locked (made fixed, at its zero), as the loader
            merges them; meshes are dropped (no contact). Its gravity and joint terms go
            into the MuJoCo model too; the inertial data are the file's, as MuJoCo reads
            them. MuJoCo's world is the URDF's root link: the chain's ``base_link`` must be
            the root (or fixed to it without a rotation), as ``model.gravity`` is taken in
            that frame.
        **kwargs
            As the constructor.
        """
        return _from_urdf(cls, path, model, kwargs)


def _urdf_for_mujoco(path, keep):
    """The URDF text with every joint not in ``keep`` fixed and no visual/collision."""
    import xml.etree.ElementTree as ET
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as err:
        raise ConfigError(f"{path}: cannot read the URDF ({err})") from None
    for link in root.findall("link"):
        for tag in ("visual", "collision"):
            for child in link.findall(tag):
                link.remove(child)
    for joint in root.findall("joint"):
        if joint.get("name") not in keep and joint.get("type") != "fixed":
            joint.set("type", "fixed")
            for tag in ("limit", "mimic", "dynamics", "axis", "safety_controller"):
                for child in joint.findall(tag):
                    joint.remove(child)
    for child in root.findall("mujoco"):
        root.remove(child)
    return ET.tostring(root, encoding="unicode")


def _from_urdf(cls, path, model, kwargs):
    mujoco = require_mujoco()
    plant = cls(model, **kwargs)                 # the checks, the generated model's options
    text = _urdf_for_mujoco(path, set(model.joint_names))
    try:
        spec = mujoco.MjSpec.from_string(text)
    except ValueError as err:
        raise ModelError(f"mujoco: {str(err).splitlines()[0]}") from None
    spec.option.timestep = plant.dt / plant.substeps
    spec.option.integrator = getattr(mujoco.mjtIntegrator,
                                     {"RK4": "mjINT_RK4", "Euler": "mjINT_EULER",
                                      "implicit": "mjINT_IMPLICIT",
                                      "implicitfast": "mjINT_IMPLICITFAST"}[plant.integrator])
    spec.option.gravity = np.asarray(model.gravity, dtype=float)
    spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    terms = joint_terms(model)
    names = list(model.joint_names)
    for joint in spec.joints:
        if joint.name in names:
            i = names.index(joint.name)
            joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
            joint.damping = [float(terms["damping"][i]), 0.0, 0.0]     # (linear, polynomial)
            joint.armature = float(terms["armature"][i])
            joint.frictionloss = float(terms["friction"][i])
    try:
        mj_model = spec.compile()
    except ValueError as err:
        raise ModelError(f"mujoco: {str(err).splitlines()[0]}") from None
    got = [mj_model.joint(j).name for j in range(mj_model.njnt)]
    if got != names:
        raise ConfigError(f"{path}: MuJoCo's joints {got} are not the chain's {names}")
    plant.mj_model = mj_model
    plant.mj_data = mujoco.MjData(mj_model)
    plant.xml = spec.to_xml()
    plant.read_from_urdf = True
    plant.reset()
    return plant
