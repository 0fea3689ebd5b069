"""A rigid payload held by the last link: its checks and its sum with the link's parameters.

A payload is a rigid body fixed to a link: mass ``m``, centre of mass ``c`` in the link's
frame and inertia ``I_c`` about that centre of mass (link axes). The 13 parameters of eq 13
(doc/design.md §2) are linear in mass, first moment ``m c`` and the inertia about the
frame's origin ``I_o = I_c + m (|c|^2 1 - c c^T)`` (the parallel-axis theorem), so the
loaded link is the link's parameters plus the payload's; its mass, centre of mass and
inertia about the new centre of mass follow from that sum (:func:`combine`).

A physical payload (:func:`check_payload`): a finite mass ``>= 0`` (0: no payload), a
centre of mass within ``reach`` of the link's frame, and an inertia that is symmetric,
positive semi-definite (a point mass has none) and whose principal moments satisfy the
triangle inequalities ``I1 + I2 >= I3``. Every refusal is one line naming the field.
"""

import numpy as np

from rcac_ros.errors import ConfigError

#: The six inertia values of a payload, in the order of its parameter (about the centre of mass).
INERTIA_FIELDS = ("Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")

#: Relative tolerance of the inertia checks (eigenvalues of a symmetric matrix in float64).
INERTIA_TOL = 1e-9


def inertia_matrix(values):
    """The symmetric 3x3 inertia of six values ``Ixx Iyy Izz Ixy Ixz Iyz`` (kg m^2)."""
    xx, yy, zz, xy, xz, yz = (float(v) for v in values)
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def inertia_values(I):
    """The six values ``Ixx Iyy Izz Ixy Ixz Iyz`` of a 3x3 inertia (:func:`inertia_matrix`)."""
    I = np.asarray(I, dtype=float)
    return np.array([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


def arm_reach(model):
    """A model's length, m: the sum of its joint offsets ``|p_i|`` plus the last link's
    ``|com|``, the default bound of a payload's centre of mass (:func:`check_payload`)."""
    return float(np.sum(np.linalg.norm(model.p, axis=1)) + np.linalg.norm(model.com[-1]))


class Payload:
    """A checked rigid payload (see the module docstring).

    Parameters
    ----------
    mass : float
        kg, finite, ``>= 0``; 0 is no payload (the other fields are then not used).
    com : array_like (3,)
        Centre of mass in the carrying link's frame, m.
    inertia : array_like (6,) or (3, 3)
        About the centre of mass, link axes, kg m^2: six values ``Ixx Iyy Izz Ixy Ixz Iyz``
        or the matrix.
    reach : float, optional
        The largest ``|com|`` accepted, m (default: no bound).

    Raises
    ------
    ConfigError
        One line naming ``payload.mass``, ``payload.com`` or ``payload.inertia``.
    """

    def __init__(self, mass=0.0, com=(0.0, 0.0, 0.0), inertia=(0.0,) * 6, reach=None):
        self.mass, self.com, self.inertia = check_payload(mass, com, inertia, reach)

    @property
    def attached(self):
        """Whether there is a payload (mass > 0)."""
        return self.mass > 0.0

    def theta(self):
        """The payload's 13 parameters of eq 13, in the link's frame."""
        from .model import theta_from_inertia
        return theta_from_inertia(self.mass, self.com, self.inertia)

    def as_dict(self):
        """``{"mass", "com", "inertia"}`` as plain floats (inertia: the six values)."""
        return {"mass": self.mass, "com": self.com.tolist(),
                "inertia": inertia_values(self.inertia).tolist()}

    def __eq__(self, other):
        return isinstance(other, Payload) and self.mass == other.mass \
            and np.array_equal(self.com, other.com) and np.array_equal(self.inertia, other.inertia)

    def __repr__(self):
        return (f"Payload(mass={self.mass!r}, com={self.com.tolist()!r}, "
                f"inertia={inertia_values(self.inertia).tolist()!r})")


def _numbers(value, name):
    try:
        return np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: expected numbers, got {value!r}") from None


def check_payload(mass, com, inertia, reach=None):
    """``(mass, com (3,), inertia (3, 3))`` checked (see :class:`Payload`), or
    :class:`ConfigError` in one line naming the field."""
    try:
        m = float(mass)
    except (TypeError, ValueError):
        raise ConfigError(f"payload.mass: expected a number, got {mass!r}") from None
    if not np.isfinite(m):
        raise ConfigError(f"payload.mass: must be finite, got {mass!r}")
    if m < 0.0:
        raise ConfigError(f"payload.mass: must be >= 0 kg (0 releases the payload), got {m:g}")
    c = _numbers(com, "payload.com").ravel()
    if c.shape != (3,):
        raise ConfigError(f"payload.com: expected 3 values (x y z, m), got {c.size}")
    if not np.all(np.isfinite(c)):
        raise ConfigError("payload.com: contains NaN or Inf")
    if reach is not None and np.linalg.norm(c) > reach:
        raise ConfigError(f"payload.com: {np.linalg.norm(c):.6g} m from the last link's frame, "
                          f"beyond the arm's reach of {reach:.6g} m")
    arr = _numbers(inertia, "payload.inertia")
    if arr.shape == (3, 3):
        I = arr
    elif arr.size == 6 and arr.ndim == 1:
        I = inertia_matrix(arr)
    else:
        raise ConfigError(f"payload.inertia: expected 6 values (Ixx Iyy Izz Ixy Ixz Iyz, "
                          f"kg m^2), got {arr.size}")
    if not np.all(np.isfinite(I)):
        raise ConfigError("payload.inertia: contains NaN or Inf")
    if not np.allclose(I, I.T, rtol=INERTIA_TOL, atol=0.0):
        raise ConfigError("payload.inertia: the matrix is not symmetric")
    eig = np.linalg.eigvalsh(I)
    tol = INERTIA_TOL * max(abs(eig[-1]), 0.0)
    if eig[0] < -tol:
        raise ConfigError(f"payload.inertia: not a body, a principal moment is negative "
                          f"(principal moments {[float(f'{e:.6g}') for e in eig]} kg m^2)")
    if eig[0] + eig[1] < eig[2] - tol:
        raise ConfigError(f"payload.inertia: not a body, principal moments "
                          f"{[float(f'{e:.6g}') for e in eig]} kg m^2 break I1 + I2 >= I3")
    return m, c, 0.5 * (I + I.T)


def combine(mass, com, inertia, payload):
    """A link and the payload it holds as one body: ``(mass, com (3,), inertia (3, 3))``.

    Parameters
    ----------
    mass, com, inertia
        The link's: kg, centre of mass in its frame (m), inertia about it (3x3, kg m^2).
    payload : Payload

    Returns
    -------
    tuple
        The loaded link's mass, centre of mass in the link's frame, and inertia about that
        centre of mass: ``m = m_l + m_p``, ``m c = m_l c_l + m_p c_p``,
        ``I_c = I_o,l + I_o,p - m (|c|^2 1 - c c^T)`` with ``I_o`` each body's inertia about
        the frame's origin (parallel-axis theorem). With no payload, the link unchanged.
    """
    m_l = float(mass)
    c_l = np.asarray(com, dtype=float)
    I_l = np.asarray(inertia, dtype=float)
    if not payload.attached:
        return m_l, c_l.copy(), I_l.copy()
    m = m_l + payload.mass
    c = (m_l * c_l + payload.mass * payload.com) / m
    origin = _about_origin(m_l, c_l, I_l) \
        + _about_origin(payload.mass, payload.com, payload.inertia)
    return m, c, origin - _shift(m, c)


def _shift(m, c):
    """``m (|c|^2 1 - c c^T)``: the parallel-axis term of a mass ``m`` at ``c``."""
    return m * (c @ c * np.eye(3) - np.outer(c, c))


def _about_origin(m, c, I_c):
    return I_c + _shift(m, c)


def with_payload(model, payload, link=None):
    """``model`` with ``payload`` held by a link (default the last); ``model`` itself when
    the payload has no mass.

    The model's own checks apply to the loaded link (its ``check_triangle`` setting: the
    paper's CSS arm has it off, as its Table 1 breaks the inequality)."""
    if not payload.attached:
        return model
    i = model.n - 1 if link is None else int(link)
    masses, coms, inertias = model.mass.copy(), model.com.copy(), model.inertia.copy()
    masses[i], coms[i], inertias[i] = combine(model.mass[i], model.com[i], model.inertia[i],
                                              payload)
    return model.replace(mass=masses, com=coms, inertia=inertias)
