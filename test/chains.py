"""Shared test helpers: random valid chains and the Pinocchio reference model of a RobotModel.

A plain module, not a conftest: ``test/ros`` has a conftest of its own, and two modules
named ``conftest`` cannot both be imported by name.
"""

import numpy as np
import pytest


def to_pin(model):
    """Build the Pinocchio model of ``model`` (same frames: placement (R_fix, p), then RZ)."""
    pin = pytest.importorskip("pinocchio")
    pm = pin.Model()
    parent = 0
    for i in range(model.n):
        placement = pin.SE3(np.array(model.R_fix[i]), np.array(model.p[i]))
        parent = pm.addJoint(parent, pin.JointModelRZ(), placement, model.joint_names[i])
        inertia = pin.Inertia(float(model.mass[i]), np.array(model.com[i]),
                              np.array(model.inertia[i]))
        pm.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
    pm.gravity.linear = np.array(model.gravity)
    pm.armature = np.array(model.armature)    # used by Pinocchio's RNEA, CRBA and ABA
    return pm


def random_chain(rng, n, gravity=(0.0, 0.0, -9.81)):
    """A random physically valid chain of ``n`` revolute joints."""
    from rcac_ros.core.model import RobotModel, rpy_matrix
    p = rng.uniform(-0.5, 0.5, size=(n, 3))
    R = np.array([rpy_matrix(rng.uniform(-np.pi, np.pi, 3)) for _ in range(n)])
    mass = rng.uniform(0.5, 5.0, n)
    com = rng.uniform(-0.2, 0.2, size=(n, 3))
    inertia = []
    for _ in range(n):
        Q = rpy_matrix(rng.uniform(-np.pi, np.pi, 3))
        a, b = rng.uniform(0.05, 0.5, 2)
        c = rng.uniform(abs(a - b) + 0.01, a + b)      # triangle inequality holds
        inertia.append(Q @ np.diag([a, b, c]) @ Q.T)
    return RobotModel(p, R, mass, com, np.array(inertia), gravity)
