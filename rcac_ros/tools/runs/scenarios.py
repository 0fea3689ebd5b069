"""The scenarios the tools share: the paper's (CSS arm) and the Panda with a payload.

* The paper's Section 4 experiment is the core's: the CSS arm (Table 1, g = 0),
  ``PAPER_Q0``, ``PAPER_GAINS`` and :class:`~rcac_ros.core.PaperTrajectory`.
* The Panda (example-robot-data's URDF, gravity on) tracking sinusoids about its "ready"
  posture, with a payload attached to link 7 (:func:`with_payload`, the gains at its
  scale of :func:`gains_for`); ``rcac payload-demo`` runs it, ``rcac compare`` and the
  ``panda`` model of a campaign use it.
* Which controller class runs a law (:func:`controller`).
"""

import os

import numpy as np

from rcac_ros.core import ConfigError, RecursiveCompositeController, SlotineLiCompositeController
from rcac_ros.core.urdf import model_from_urdf
from rcac_ros.tools.runs.robots import example_robot_urdf

#: The Panda's "ready" posture (rad), the centre of the desired motion.
READY = (0.0, -np.pi / 4, 0.0, -3 * np.pi / 4, 0.0, np.pi / 2, np.pi / 4)
#: Per-joint amplitude (rad) and frequency (Hz) of the desired sinusoids.
AMPLITUDE = (0.3, 0.25, 0.3, 0.3, 0.4, 0.3, 0.5)
FREQUENCY = (0.2, 0.25, 0.3, 0.22, 0.35, 0.28, 0.4)
#: The flange (``panda_link8``) in link 7's frame: ``panda_joint8``'s origin, m.
FLANGE = (0.0, 0.0, 0.107)
#: Expected size of each of the 13 parameters of link 7 (kg, kg m, then kg m^2).
PARAMETER_SCALE = (2.0,) + (0.4,) * 3 + (0.08,) * 9
#: Default gains (:mod:`rcac_ros.tools.demos.payload` says why).
GAINS = dict(kappa=100.0, Lambda=10.0, rho=30.0, gamma=1.0, lam=10.0, h=0.002)
#: The law with adaptation off.
FIXED_P = 1e-12


def find_panda_urdf():
    """example-robot-data's ``panda.urdf``, or None."""
    return example_robot_urdf(os.path.join("panda_description", "urdf", "panda.urdf"))


def load_panda(urdf=None, joint_terms=False):
    """The Panda arm ``panda_link0 -> panda_link8`` with gravity ``(0, 0, -9.81)``.

    Rigid unless ``joint_terms``: the URDF's ``<dynamics damping="0.003">`` is dropped, so
    the payload experiments isolate the payload (joint terms: doc/design.md §7).
    """
    path = urdf or find_panda_urdf()
    if path is None:
        raise ConfigError("urdf: example-robot-data's panda.urdf not found (the 'robots' "
                          "extra: pip install 'rcac_ros[robots]'); pass --urdf")
    model = model_from_urdf(path, tip_link="panda_link8")
    return model if joint_terms else model.replace(damping=0.0, friction=0.0)


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def spatial_inertia(mass, com, inertia):
    """A link's 6x6 spatial inertia about its frame origin, ``[v; w]`` order (doc/design.md §2)."""
    P = _skew(com)
    return np.block([[mass * np.eye(3), -mass * P], [mass * P, inertia - mass * P @ P]])


def with_payload(model, mass=2.0, com_flange=(0.03, -0.02, 0.08), radius=0.05, link=None):
    """``model`` with a solid-sphere payload rigidly attached to its last link.

    Parameters
    ----------
    mass : float
        Payload mass, kg.
    com_flange : array_like (3,)
        Payload centre of mass in the flange frame (:data:`FLANGE` in link 7's axes), m.
    radius : float
        Sphere radius (inertia ``2/5 m r^2``), m.
    link : int, optional
        Index of the link that carries it (default: the last).
    """
    i = model.n - 1 if link is None else int(link)
    c_p = np.asarray(FLANGE, float) + np.asarray(com_flange, float)
    m0, c0, i0 = model.mass[i], model.com[i], model.inertia[i]
    m = m0 + mass
    c = (m0 * c0 + mass * c_p) / m

    def shift(mk, d):
        return mk * (d @ d * np.eye(3) - np.outer(d, d))

    inertia = i0 + shift(m0, c0 - c) + 0.4 * mass * radius ** 2 * np.eye(3) + shift(mass, c_p - c)
    masses, coms, inertias = model.mass.copy(), model.com.copy(), model.inertia.copy()
    masses[i], coms[i], inertias[i] = m, c, inertia
    return model.replace(mass=masses, com=coms, inertia=inertias)


def gains_for(model, kappa, Lambda, rho, gamma, lam, h, adapt_all=False, law="composite"):
    """Controller keyword arguments of one law (:mod:`rcac_ros.tools.demos.payload`)."""
    K_D = np.array([kappa * spatial_inertia(model.mass[i], model.com[i], model.inertia[i])
                    for i in range(model.n)])
    P = np.array([np.eye(13) * FIXED_P] * model.n)
    if law != "fixed":
        scaled = rho * np.diag(np.square(PARAMETER_SCALE))
        P[-1] = scaled
        if adapt_all:
            P[:] = scaled
    return dict(K_D=K_D, Lambda=Lambda, P=P, gamma=gamma if law == "composite" else 0.0,
                lam=lam, h=h, theta_hat0=model.theta())


#: the kind of a law -> the controller class that runs it
CONTROLLERS = {"rcac": RecursiveCompositeController, "slotine_li": SlotineLiCompositeController}


def controller(kind, model, gains):
    """The controller of ``kind`` (a key of :data:`CONTROLLERS`) for ``model``."""
    return CONTROLLERS[kind](model, **gains)
