"""Forward kinematics and mechanical energy (for tests, plots and the energy check)."""

import numpy as np

from ._validate import joint_vectors
from .crba import mass_matrix


def forward_kinematics(model, q):
    """World (base-frame) rotations and origins of every link frame.

    Returns
    -------
    R : ndarray, shape (n, 3, 3)
        ``R[i]`` maps frame-i coordinates to the base frame.
    o : ndarray, shape (n, 3)
        Origin of frame i in the base frame.
    """
    (q,) = joint_vectors(model.n, q=q)
    R = np.empty((model.n, 3, 3))
    o = np.empty((model.n, 3))
    R_prev, o_prev = np.eye(3), np.zeros(3)
    for i in range(model.n):
        c, s = np.cos(q[i]), np.sin(q[i])
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        o[i] = o_prev + R_prev @ model.p[i]
        R[i] = R_prev @ model.R_fix[i] @ Rz
        R_prev, o_prev = R[i], o[i]
    return R, o


def energy(model, q, qd):
    """Kinetic and potential energy ``(T, U)``: ``T = qd^T M qd / 2``, ``U = -sum m_i g . c_i``."""
    (q, qd) = joint_vectors(model.n, q=q, qd=qd)
    kinetic = 0.5 * qd @ mass_matrix(model, q) @ qd
    R, o = forward_kinematics(model, q)
    com_world = o + np.einsum("nij,nj->ni", R, model.com)
    potential = -float(np.sum(model.mass * (com_world @ model.gravity)))
    return float(kinetic), potential
