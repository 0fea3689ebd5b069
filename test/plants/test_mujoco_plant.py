"""The MuJoCo plant against the built-in simulator, a closed form and MuJoCo's own URDF reading.

Independent references: MuJoCo's integrator and dynamics (its CRB/ABA-free solver, its own
URDF parser), an RK4 transcription of ``(M + diag(armature)) qdd = tau - damping qd - h``
built on the package's Pinocchio-checked ``mass_matrix`` and ``inverse_dynamics``, and the
textbook behaviour of dry friction (stick below the breakaway torque, ``(tau - F) / I``
above it).
"""

import copy
import os
import subprocess
import sys

import numpy as np
import pytest
from chains import needs_mujoco

from rcac_ros.core import (InputError, ModelError, RobotModel, Simulator, css_arm,
                           inverse_dynamics, mass_matrix)
from rcac_ros.core.urdf import model_from_urdf
from rcac_ros.errors import ConfigError, DependencyError
from rcac_ros.plants import ENGINES, check_engine, make_plant
from rcac_ros.tools.runs.robots import example_robot_urdf

from rcac_ros.plants.mujoco_plant import MujocoPlant, mjcf

try:
    import mujoco
except ImportError:                  # the tests that use it are marked needs_mujoco
    mujoco = None

PANDA = example_robot_urdf(os.path.join("panda_description", "urdf", "panda.urdf"))
UR5 = example_robot_urdf(os.path.join("ur_description", "urdf", "ur5_robot.urdf"))
needs_robots = pytest.mark.skipif(PANDA is None or UR5 is None,
                                  reason="example-robot-data not installed")
#: the agreement asked of the two plants over 1 s of open-loop torques, rad
TOL = 1e-6


def robots():
    out = [("css g=0", lambda: css_arm()), ("css g", lambda: css_arm((0.0, 0.0, -9.81)))]
    if PANDA is not None and UR5 is not None:
        out += [("panda", lambda: model_from_urdf(PANDA, tip_link="panda_link8")),
                ("ur5", lambda: model_from_urdf(UR5))]
    return out


def open_loop(model, seconds=1.0, seed=1):
    """A start state and torques of the size of each arm's gravity load, one per 2 ms."""
    rng = np.random.default_rng(seed)
    n = model.n
    q0, qd0 = rng.uniform(-1.0, 1.0, n), rng.uniform(-0.5, 0.5, n)
    scale = np.abs(inverse_dynamics(model, q0, np.zeros(n), np.zeros(n))) + \
        np.abs(mass_matrix(model, q0)).sum(axis=1)
    taus = rng.normal(size=(int(round(seconds / 0.002)), n)) * scale
    return q0, qd0, taus


def worst_gap(a, b, taus):
    """max over the run of ``|q_a - q_b|`` and of ``|qd_a - qd_b|``, and how far the arm went."""
    gap_q = gap_qd = travel = 0.0
    q0 = a.q.copy()
    for tau in taus:
        qa, qda = a.step(tau)
        qb, qdb = b.step(tau)
        gap_q = max(gap_q, np.abs(qa - qb).max())
        gap_qd = max(gap_qd, np.abs(qda - qdb).max())
        travel = max(travel, np.abs(qa - q0).max())
    return gap_q, gap_qd, travel


@pytest.mark.parametrize("label,build", robots(), ids=[r[0] for r in robots()])
@needs_mujoco
def test_open_loop_equals_the_builtin_simulator(label, build):
    model = build()
    q0, qd0, taus = open_loop(model)
    a = Simulator(model, q0=q0, qd0=qd0, effort_limit=np.inf)
    b = MujocoPlant(model, q0=q0, qd0=qd0, effort_limit=np.inf)
    gap_q, gap_qd, travel = worst_gap(a, b, taus)
    print(label, "gap q", gap_q, "gap qd", gap_qd, "travel", travel)
    assert travel > 0.3                 # the arm really moved
    assert gap_q < TOL and gap_qd < 100 * TOL
    assert b.t == pytest.approx(1.0) and a.t == pytest.approx(b.t)


@needs_robots
@pytest.mark.parametrize("which", ["panda", "ur5"])
@needs_mujoco
def test_mujocos_own_urdf_reading_gives_the_same_arm(which):
    """MuJoCo's URDF parser (fingers locked, meshes dropped) against the package's loader."""
    path = PANDA if which == "panda" else UR5
    model = model_from_urdf(path, tip_link="panda_link8" if which == "panda" else None)
    q0, qd0, taus = open_loop(model, seed=2)
    a = Simulator(model, q0=q0, qd0=qd0, effort_limit=np.inf)
    b = MujocoPlant.from_urdf(path, model, effort_limit=np.inf)
    b.reset(q0, qd0)
    assert b.mj_model.nv == model.n and b.mj_model.body_mass.sum() == pytest.approx(
        model.mass.sum(), rel=1e-12)
    gap_q, _, travel = worst_gap(a, b, taus)
    assert travel > 0.3 and gap_q < TOL


def with_terms(model, **terms):
    """``model`` with per-joint ``damping``/``armature``/``friction`` (default zero)."""
    return model.replace(**{k: np.asarray(terms.get(k, np.zeros(model.n)), float)
                            for k in ("damping", "armature", "friction")})


def reference_rk4(rigid, damping, armature, q, qd, taus, h=0.002):
    """Classical RK4 of ``(M(q) + diag(armature)) qdd = tau - damping qd - h(q, qd)``."""
    n = rigid.n

    def acc(q, qd, tau):
        bias = inverse_dynamics(rigid, q, qd, np.zeros(n))
        return np.linalg.solve(mass_matrix(rigid, q) + np.diag(armature),
                               tau - damping * qd - bias)

    out = []
    for tau in taus:
        k1q, k1v = qd, acc(q, qd, tau)
        k2q, k2v = qd + 0.5 * h * k1v, acc(q + 0.5 * h * k1q, qd + 0.5 * h * k1v, tau)
        k3q, k3v = qd + 0.5 * h * k2v, acc(q + 0.5 * h * k2q, qd + 0.5 * h * k2v, tau)
        k4q, k4v = qd + h * k3v, acc(q + h * k3q, qd + h * k3v, tau)
        q = q + h / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q)
        qd = qd + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        out.append(q)
    return np.array(out)


@needs_robots
@needs_mujoco
def test_damping_and_armature_follow_their_equation():
    # rigid: the URDF's own <dynamics damping> removed (the reference adds the terms itself)
    rigid = with_terms(model_from_urdf(PANDA, tip_link="panda_link8"))
    damping, armature = np.linspace(0.2, 1.0, 7), np.linspace(0.3, 0.05, 7)
    model = with_terms(rigid, damping=damping, armature=armature)
    q0, qd0, taus = open_loop(rigid, seconds=0.4, seed=3)
    plant = MujocoPlant(model, q0=q0, qd0=qd0, effort_limit=np.inf)
    assert np.array_equal(plant.mj_model.dof_damping, damping)
    assert np.array_equal(plant.mj_model.dof_armature, armature)
    ref = reference_rk4(rigid, damping, armature, q0, qd0, taus)
    got = np.array([plant.step(tau)[0] for tau in taus])
    rigid_plant = MujocoPlant(rigid, q0=q0, qd0=qd0, effort_limit=np.inf)
    rigid_q = np.array([rigid_plant.step(tau)[0] for tau in taus])
    assert np.abs(rigid_q - ref).max() > 1e-2          # the terms matter on this run
    assert np.abs(got - ref).max() < TOL


@needs_robots
@pytest.mark.parametrize("which", ["panda", "ur5"])
@needs_mujoco
def test_damping_and_armature_equal_the_builtin_simulator(which):
    rigid = model_from_urdf(PANDA, tip_link="panda_link8") if which == "panda" \
        else model_from_urdf(UR5)
    n = rigid.n
    model = rigid.replace(damping=np.full(n, 0.5), armature=np.full(n, 0.1))
    q0, qd0, taus = open_loop(rigid, seed=4)
    a = Simulator(model, q0=q0, qd0=qd0, effort_limit=np.inf)
    b = MujocoPlant(model, q0=q0, qd0=qd0, effort_limit=np.inf)
    gap_q, _, travel = worst_gap(a, b, taus)
    print(which, "damping + armature: gap q", gap_q, "travel", travel)
    assert travel > 0.3 and gap_q < TOL
    # dry friction: the model's tanh law and MuJoCo's friction loss differ by design
    # (doc/plants.md), by far more than rounding
    model = model.replace(friction=np.full(n, 0.5))
    a = Simulator(model, q0=q0, qd0=qd0, effort_limit=np.inf)
    b = MujocoPlant(model, q0=q0, qd0=qd0, effort_limit=np.inf)
    gap_q, _, _ = worst_gap(a, b, taus)
    print(which, "+ friction 0.5: gap q", gap_q)
    assert gap_q > 1e-3


def pendulum(friction):
    """One link about a vertical axis (no gravity torque): ``I = 0.1 + 2 * 0.5^2`` kg m^2."""
    model = RobotModel([[0.0, 0.0, 0.0]], [np.eye(3)], [2.0], [[0.5, 0.0, 0.0]],
                       [np.diag([0.1, 0.1, 0.1])], gravity=(0.0, 0.0, -9.81))
    return with_terms(model, friction=np.array([friction])), 0.1 + 2.0 * 0.25


@needs_mujoco
def test_friction_loss_sticks_below_breakaway_and_slides_above():
    """Dry friction F: below F the joint (nearly) sticks, above it ``qdd = (tau - F) / I``.

    MuJoCo's friction loss is a soft constraint: below breakaway the joint creeps at a small
    velocity proportional to the torque (doc/plants.md), far below the free motion.
    """
    F = 0.5
    free_model, inertia = pendulum(0.0)
    model, _ = pendulum(F)
    for ratio in (0.5, 0.9):
        plant = MujocoPlant(model)
        free = MujocoPlant(free_model)
        for _ in range(500):
            plant.step([ratio * F])
            free.step([ratio * F])
        assert 0.0 < plant.qd[0] < 1e-2 * free.qd[0]          # creeps, in the torque's sense
    for ratio in (1.5, 4.0):
        plant = MujocoPlant(model)
        for _ in range(500):
            plant.step([-ratio * F])
        assert plant.qd[0] == pytest.approx(-(ratio - 1.0) * F / inertia * 1.0, rel=1e-6)


@needs_mujoco
def test_the_interface_of_the_simulator():
    model = css_arm()
    plant = MujocoPlant(model, q0=np.full(7, 0.1), effort_limit=10.0)
    free = MujocoPlant(model, q0=np.full(7, 0.1))
    plant.step(np.full(7, 1e4))
    free.step(np.full(7, 10.0))
    assert np.array_equal(plant.applied, np.full(7, 10.0))
    assert np.array_equal(plant.q, free.q) and np.array_equal(plant.qd, free.qd)
    q = plant.q
    with pytest.raises(InputError, match="tau: contains NaN"):
        plant.step(np.full(7, np.nan))
    with pytest.raises(InputError, match="tau: expected shape"):
        plant.step(np.zeros(6))
    assert np.array_equal(q, plant.q) and plant.t == pytest.approx(0.002)
    plant.reset(np.ones(7), np.full(7, 2.0), t=3.0)
    assert np.array_equal(plant.q, np.ones(7)) and np.array_equal(plant.qd, np.full(7, 2.0))
    assert plant.t == 3.0 and not plant.applied.any()
    returned = plant.step(np.zeros(7))
    returned[0][:] = 99.0                               # a copy, as the simulator's
    assert not np.any(plant.q == 99.0)
    for bad, match in ((dict(dt=0.0), "dt"), (dict(substeps=1.5), "substeps"),
                       (dict(effort_limit=-1.0), "effort_limit"),
                       (dict(q0=np.zeros(3)), "q0"), (dict(integrator="verlet"), "integrator")):
        with pytest.raises((InputError, ConfigError), match=match):
            MujocoPlant(model, **bad)


@needs_mujoco
def test_substeps_refine_the_step():
    """``substeps`` MuJoCo steps of ``dt / substeps``: RK4 converges at 4th order to the
    built-in simulator with as many substeps."""
    model = css_arm((0.0, 0.0, -9.81))
    q0 = np.linspace(-1.0, 1.0, 7)
    tau = np.linspace(-300.0, 300.0, 7)

    def final(cls, substeps):
        plant = cls(model, dt=0.05, q0=q0, substeps=substeps)
        for _ in range(10):
            plant.step(tau)
        return plant.q

    for substeps in (1, 4):
        assert np.abs(final(MujocoPlant, substeps) - final(Simulator, substeps)).max() < 1e-9
    ref = final(MujocoPlant, 64)
    e1 = np.abs(final(MujocoPlant, 4) - ref).max()
    e2 = np.abs(final(MujocoPlant, 8) - ref).max()
    assert 12.0 < e1 / e2 < 20.0


@needs_mujoco
def test_the_css_arm_keeps_its_table_1_inertias():
    """Table 1 breaks the triangle inequality MuJoCo's compiler checks: the MJCF balances
    them, the plant puts the true ones back (principal moments and axes)."""
    model = css_arm()
    plant = MujocoPlant(model)
    assert 'balanceinertia="true"' in plant.xml
    for i in range(model.n):
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, plant.mj_model.body_iquat[i + 1])
        R = R.reshape(3, 3)
        back = R @ np.diag(plant.mj_model.body_inertia[i + 1]) @ R.T
        assert np.allclose(back, model.inertia[i], rtol=0, atol=1e-12 * model.inertia[i].max())


@needs_mujoco
def test_the_mjcf_is_a_standalone_model(tmp_path):
    """The generated MJCF loads in MuJoCo by itself (e.g. in its viewer), names included."""
    model = css_arm((0.0, 0.0, -9.81))
    path = tmp_path / "css.xml"
    path.write_text(mjcf(model))
    loaded = mujoco.MjModel.from_xml_path(str(path))
    assert [loaded.joint(j).name for j in range(loaded.njnt)] == list(model.joint_names)
    assert np.array_equal(loaded.opt.gravity, model.gravity)
    assert loaded.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4


@needs_mujoco
def test_a_model_mujoco_refuses_is_one_line():
    model = css_arm()
    broken = copy.copy(model)
    broken.mass = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0])     # past the model's checks
    with pytest.raises(ModelError, match="^mujoco: ") as err:
        MujocoPlant(broken)
    assert "\n" not in str(err.value)


def test_engines():
    assert ENGINES[0] == "builtin" and check_engine("mujoco") == "mujoco"
    for bad in ("MuJoCo", "", None, 3):
        with pytest.raises(ConfigError, match="^engine: expected one of builtin, mujoco"):
            check_engine(bad)
    assert isinstance(make_plant(css_arm(), "builtin", dt=0.001), Simulator)


@needs_mujoco
def test_make_plant_builds_the_mujoco_plant():
    assert isinstance(make_plant(css_arm(), "mujoco", dt=0.001), MujocoPlant)


def test_without_mujoco_the_core_imports_and_the_engine_says_so_in_one_line(tmp_path):
    """A ``mujoco`` that cannot be imported: the core and the builtin plant work, the mujoco
    engine raises DependencyError naming the package."""
    (tmp_path / "mujoco.py").write_text("raise ImportError('no mujoco here')\n")
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    code = ("import sys\n"
            "from rcac_ros.core import css_arm\n"
            "from rcac_ros.plants import make_plant\n"
            "from rcac_ros.errors import DependencyError\n"
            "make_plant(css_arm(), 'builtin').step([0.0] * 7)\n"
            "assert 'mujoco' not in sys.modules\n"
            "try:\n"
            "    make_plant(css_arm(), 'mujoco')\n"
            "except DependencyError as err:\n"
            "    print(err)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), root]))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("engine mujoco: the 'mujoco' package is not installed")
    assert out.stdout.count("\n") == 1
    assert issubclass(DependencyError, ImportError)
