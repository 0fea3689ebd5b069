"""A payload held by the last link: checks, and the loaded link against closed forms and
Pinocchio's composition of inertias; both plants carry it from the next step on.

References: two point masses and a solid box cut in two (textbook inertias), Pinocchio's
``Inertia.__add__``, the linearity of eq 13 in (mass, first moment, inertia about the
origin), and MuJoCo's own dynamics for the MuJoCo plant.
"""

import numpy as np
import pytest
from chains import needs_mujoco

from rcac_ros.core import Simulator, css_arm
from rcac_ros.core.payload import (Payload, arm_reach, check_payload, combine, inertia_matrix,
                                   inertia_values, with_payload)
from rcac_ros.errors import ConfigError


def test_two_point_masses_make_the_reduced_mass_inertia():
    """Masses m1 at the origin and m2 at (L, 0, 0): centre of mass m2 L / (m1 + m2) on x, and
    about it Iyy = Izz = m1 m2 L^2 / (m1 + m2) (the reduced mass times L^2), Ixx = 0."""
    m1, m2, L = 3.0, 5.0, 2.0
    m, c, I = combine(m1, np.zeros(3), np.zeros((3, 3)), Payload(m2, (L, 0.0, 0.0)))
    assert m == m1 + m2
    np.testing.assert_allclose(c, [m2 * L / (m1 + m2), 0.0, 0.0], rtol=1e-15)
    mu = m1 * m2 / (m1 + m2) * L * L
    np.testing.assert_allclose(I, np.diag([0.0, mu, mu]), rtol=0.0, atol=1e-12 * mu)


def box(m, a, b, c):
    """A solid box's inertia about its centre, sides a, b, c along x, y, z."""
    return m / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def test_two_halves_of_a_box_make_the_box():
    """A box cut across x into halves (mass m/2, side a/2, centres at -a/4 and +a/4): one the
    link, the other the payload; together the whole box about its centre."""
    m, a, b, c = 8.0, 2.0, 0.6, 0.4
    half = box(m / 2, a / 2, b, c)
    centre = np.array([1.0, -0.5, 0.3])            # the box's centre in the link frame
    step = np.array([a / 4, 0.0, 0.0])
    payload = Payload(m / 2, centre + step, inertia_values(half))
    got_m, got_c, got_I = combine(m / 2, centre - step, half, payload)
    assert got_m == pytest.approx(m)
    np.testing.assert_allclose(got_c, centre, rtol=0, atol=1e-15)
    np.testing.assert_allclose(got_I, box(m, a, b, c), rtol=0, atol=1e-12)


def random_body(rng, scale=1.0):
    """A random physical body: mass, centre of mass, inertia about it (a random rotation of
    principal moments that satisfy the triangle inequalities)."""
    m = rng.uniform(0.5, 20.0) * scale
    c = rng.uniform(-1.0, 1.0, 3)
    d = rng.uniform(0.1, 1.0, 3)
    d[2] = rng.uniform(abs(d[0] - d[1]), d[0] + d[1])          # a real mass distribution
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return m, c, Q @ np.diag(d * scale) @ Q.T


def test_the_loaded_link_equals_pinocchios_sum_of_inertias():
    pin = pytest.importorskip("pinocchio")
    rng = np.random.default_rng(7)
    for _ in range(20):
        link, load = random_body(rng), random_body(rng, scale=rng.uniform(0.1, 100.0))
        m, c, I = combine(*link, Payload(*load))
        ref = pin.Inertia(link[0], link[1], link[2]) + pin.Inertia(load[0], load[1], load[2])
        assert m == pytest.approx(ref.mass, rel=1e-14)
        np.testing.assert_allclose(c, ref.lever, rtol=0, atol=1e-13)
        np.testing.assert_allclose(I, ref.inertia, rtol=0, atol=1e-11 * np.abs(ref.inertia).max())


def standard(theta):
    """The 10 standard parameters (mass, first moment, inertia about the frame's origin) of
    the 13 of eq 13: ``I_o,aa = theta[10 + a]`` plus the two other ``m c_k^2``."""
    m_c2 = theta[4:7]
    diag = theta[10:13] + m_c2.sum() - m_c2
    return np.concatenate([theta[:4], diag, -theta[7:10]])


def test_the_loaded_model_adds_the_payloads_standard_parameters():
    """Mass, first moment and the inertia about the link's origin are additive: the loaded
    last link's are the link's plus the payload's; the other links are unchanged."""
    model = css_arm()
    rng = np.random.default_rng(3)
    m, c, I = random_body(rng, scale=50.0)
    payload = Payload(m, c, I)
    loaded = with_payload(model, payload)
    np.testing.assert_allclose(standard(loaded.theta()[-1]),
                               standard(model.theta()[-1]) + standard(payload.theta()),
                               rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(loaded.theta()[:-1], model.theta()[:-1])
    assert with_payload(model, Payload()) is model          # mass 0: nothing held


@pytest.mark.parametrize("mass, com, inertia, start", [
    (-1.0, (0, 0, 0), (0,) * 6, "payload.mass: must be >= 0"),
    (float("nan"), (0, 0, 0), (0,) * 6, "payload.mass: must be finite"),
    (float("inf"), (0, 0, 0), (0,) * 6, "payload.mass: must be finite"),
    (1.0, (0, 0), (0,) * 6, "payload.com: expected 3 values"),
    (1.0, (0, float("nan"), 0), (0,) * 6, "payload.com: contains NaN"),
    (1.0, (0, 0, 50.0), (0,) * 6, "payload.com: 50 m from the last link's frame, beyond"),
    (1.0, (0, 0, 0), (1, 1, 1), "payload.inertia: expected 6 values"),
    (1.0, (0, 0, 0), (1, 1, -1, 0, 0, 0), "payload.inertia: not a body, a principal moment"),
    (1.0, (0, 0, 0), (1, 1, 3, 0, 0, 0), "payload.inertia: not a body, principal moments"),
    (1.0, (0, 0, 0), (1, 1, 1, 2, 0, 0), "payload.inertia: not a body"),
    (1.0, (0, 0, 0), (1, 1, float("inf"), 0, 0, 0), "payload.inertia: contains NaN"),
])
def test_a_bad_payload_is_refused_in_one_line_naming_the_field(mass, com, inertia, start):
    with pytest.raises(ConfigError) as err:
        check_payload(mass, com, inertia, reach=10.0)
    text = str(err.value)
    assert text.startswith(start), text
    assert "\n" not in text


def test_a_point_mass_and_a_flat_plate_are_bodies():
    """A point mass (no inertia) and a thin plate (I3 = I1 + I2, the triangle's edge) pass."""
    check_payload(1.0, (0, 0, 0), (0,) * 6)
    check_payload(2.0, (0, 0, 1.0), inertia_values(box(2.0, 1.0, 0.5, 0.0)))
    np.testing.assert_array_equal(inertia_matrix((1, 2, 3, 4, 5, 6)),
                                  [[1, 4, 5], [4, 2, 6], [5, 6, 3]])


def test_the_reach_is_the_arms_length():
    model = css_arm()
    lengths = sum(np.linalg.norm(p) for p in model.p) + np.linalg.norm(model.com[-1])
    assert arm_reach(model) == pytest.approx(lengths)


def run(plant, taus, payload_at, payload):
    qs = []
    for k, tau in enumerate(taus):
        if k == payload_at:
            plant.set_payload(payload)
        qs.append(plant.step(tau)[0].copy())
    return np.array(qs)


def test_the_simulator_holds_the_payload_from_the_next_step_and_releases_it():
    """From the step after set_payload the plant is the loaded arm (a fresh Simulator of the
    loaded model, started from the same state); mass 0 gives back the arm without it."""
    model = css_arm()
    rng = np.random.default_rng(1)
    taus = rng.normal(size=(100, model.n)) * 50.0
    payload = Payload(1000.0, (0.2, 0.5, 1.5), (50.0, 60.0, 70.0, 1.0, 2.0, 3.0))
    sim = Simulator(model, q0=np.full(model.n, 0.3))
    before = run(sim, taus[:40], None, None)
    sim.set_payload(payload)
    assert sim.model.mass[-1] == model.mass[-1] + 1000.0
    ref = Simulator(with_payload(model, payload), q0=sim.q, qd0=sim.qd)
    for tau in taus[40:70]:
        np.testing.assert_array_equal(sim.step(tau)[0], ref.step(tau)[0])
    sim.set_payload(Payload())
    assert sim.model is model and not sim.payload.attached
    back = Simulator(model, q0=sim.q, qd0=sim.qd)
    for tau in taus[70:]:
        np.testing.assert_array_equal(sim.step(tau)[0], back.step(tau)[0])
    assert np.all(np.isfinite(before))


@needs_mujoco
def test_the_mujoco_plant_holds_the_same_payload_as_the_builtin_simulator():
    """MuJoCo's own dynamics with the edited last body against the built-in simulator of the
    loaded model: the same 1 s of torques, capture at 0.2 s and release at 0.6 s, agree to
    the open-loop tolerance of the two plants (test/plants/test_mujoco_plant.py)."""
    from rcac_ros.plants.mujoco_plant import MujocoPlant
    model = css_arm()
    rng = np.random.default_rng(2)
    taus = rng.normal(size=(500, model.n)) * 1000.0
    payload = Payload(1000.0, (0.2, 0.5, 1.5), (50.0, 60.0, 70.0, 1.0, 2.0, 3.0))
    q0 = rng.uniform(-1.0, 1.0, model.n)
    a = Simulator(model, q0=q0, effort_limit=np.inf)
    b = MujocoPlant(model, q0=q0, effort_limit=np.inf)
    gap, travel = 0.0, 0.0
    for k, tau in enumerate(taus):
        if k in (100, 300):
            for plant in (a, b):
                plant.set_payload(payload if k == 100 else Payload())
        qa, qb = a.step(tau)[0], b.step(tau)[0]
        gap = max(gap, np.abs(qa - qb).max())
        travel = max(travel, np.abs(qa - q0).max())
    # the payload changed the motion: the arm without it, same torques, ends elsewhere
    c = Simulator(model, q0=q0, effort_limit=np.inf)
    for tau in taus:
        c.step(tau)
    assert np.abs(c.q - a.q).max() > 1e-3
    assert travel > 0.1
    assert gap < 1e-6                  # the open-loop tolerance of test_mujoco_plant.py
    assert b.mj_model.body_mass[-1] == model.mass[-1]        # released
