"""The per-link 6x13 reference regressor (eqs 13-14, doc/design.md §2) and its companions.

``Y(Vdot_r, V_r, w, g) theta = M Vdot_r + C(w) V_r + G`` with the paper's 13
parameters, ``C`` evaluated at the actual angular velocity ``w``:

    force  = t1 (vdot_r + w x v_r - g) + alpha_r x h - w x (h x w_r)
    moment = h x (vdot_r + w x v_r - g) + I_o alpha_r + w x (I_o w_r)
             + I_o (w x w_r) - (t5 + t6 + t7) (w x w_r)

``Ym(V) = Y(V, 0, w, 0)`` is the regressor of ``M V`` and
``Yc(V) = Y(0, V, w, g)`` that of ``C(w) V + G`` (doc/design.md §4).
"""

import numpy as np
from ._jit import njit

from ._validate import as_array


@njit(cache=True, inline="always")
def motion_terms(vdx, vdy, vdz, alx, aly, alz, vrx, vry, vrz, wrx, wry, wrz, wx, wy, wz,
                 gx, gy, gz):
    """Eq 14's motion terms of one link: ``a = vdot_r + w x v_r - g``, ``c = w x w_r``,
    ``d = alpha_r + c`` and ``w . w_r``, as the 10-tuple ``(a, c, d, w . w_r)``."""
    ax = vdx + wy * vrz - wz * vry - gx
    ay = vdy + wz * vrx - wx * vrz - gy
    az = vdz + wx * vry - wy * vrx - gz
    cx = wy * wrz - wz * wry
    cy = wz * wrx - wx * wrz
    cz = wx * wry - wy * wrx
    ww = wx * wrx + wy * wry + wz * wrz
    return ax, ay, az, cx, cy, cz, alx + cx, aly + cy, alz + cz, ww


@njit(cache=True)
def fill_regressor(Y, k, vdx, vdy, vdz, alx, aly, alz, vrx, vry, vrz, wrx, wry, wrz,
                   wx, wy, wz, gx, gy, gz):
    """Write ``Y(Vdot_r, V_r, w, g)`` (6x13) into ``Y[k]`` (eq 14 made linear in theta)."""
    # a = vdot_r + w x v_r - g ; c = w x w_r ; d = alpha_r + c
    ax, ay, az, cx, cy, cz, dx, dy, dz, ww = motion_terms(
        vdx, vdy, vdz, alx, aly, alz, vrx, vry, vrz, wrx, wry, wrz, wx, wy, wz, gx, gy, gz)
    # column 1: mass
    Y[k, 0, 0] = ax
    Y[k, 1, 0] = ay
    Y[k, 2, 0] = az
    Y[k, 3, 0] = 0.0
    Y[k, 4, 0] = 0.0
    Y[k, 5, 0] = 0.0
    # columns 2-4: first moments h; force = (alpha^x - (w.w_r) I + w_r w^T) h, moment = -a^x h
    Y[k, 0, 1] = wrx * wx - ww
    Y[k, 0, 2] = wrx * wy - alz
    Y[k, 0, 3] = wrx * wz + aly
    Y[k, 1, 1] = wry * wx + alz
    Y[k, 1, 2] = wry * wy - ww
    Y[k, 1, 3] = wry * wz - alx
    Y[k, 2, 1] = wrz * wx - aly
    Y[k, 2, 2] = wrz * wy + alx
    Y[k, 2, 3] = wrz * wz - ww
    Y[k, 3, 1] = 0.0
    Y[k, 3, 2] = az
    Y[k, 3, 3] = -ay
    Y[k, 4, 1] = -az
    Y[k, 4, 2] = 0.0
    Y[k, 4, 3] = ax
    Y[k, 5, 1] = ay
    Y[k, 5, 2] = -ax
    Y[k, 5, 3] = 0.0
    # columns 5-13 act on the moment only: col(E) = E d + w x (E w_r) [- c for t5..t7]
    m11x, m11y, m11z = dx, wrx * wz, -wrx * wy            # t11: E = e_x e_x^T
    m12x, m12y, m12z = -wry * wz, dy, wry * wx            # t12: E = e_y e_y^T
    m13x, m13y, m13z = wrz * wy, -wrz * wx, dz            # t13: E = e_z e_z^T
    for r in range(3):
        for col in range(4, 13):
            Y[k, r, col] = 0.0
    Y[k, 3, 4] = m12x + m13x - cx
    Y[k, 4, 4] = m12y + m13y - cy
    Y[k, 5, 4] = m12z + m13z - cz
    Y[k, 3, 5] = m11x + m13x - cx
    Y[k, 4, 5] = m11y + m13y - cy
    Y[k, 5, 5] = m11z + m13z - cz
    Y[k, 3, 6] = m11x + m12x - cx
    Y[k, 4, 6] = m11y + m12y - cy
    Y[k, 5, 6] = m11z + m12z - cz
    Y[k, 3, 7] = wz * wrx - dy                             # t8: E = -(e_x e_y^T + e_y e_x^T)
    Y[k, 4, 7] = -dx - wz * wry
    Y[k, 5, 7] = wy * wry - wx * wrx
    Y[k, 3, 8] = -dz - wy * wrx                            # t9: E = -(e_x e_z^T + e_z e_x^T)
    Y[k, 4, 8] = wx * wrx - wz * wrz
    Y[k, 5, 8] = wy * wrz - dx
    Y[k, 3, 9] = wz * wrz - wy * wry                       # t10: E = -(e_y e_z^T + e_z e_y^T)
    Y[k, 4, 9] = wx * wry - dz
    Y[k, 5, 9] = -dy - wx * wrz
    Y[k, 3, 10] = m11x
    Y[k, 4, 10] = m11y
    Y[k, 5, 10] = m11z
    Y[k, 3, 11] = m12x
    Y[k, 4, 11] = m12y
    Y[k, 5, 11] = m12z
    Y[k, 3, 12] = m13x
    Y[k, 4, 12] = m13y
    Y[k, 5, 12] = m13z


@njit(cache=True)
def link_wrench(th, o, vdx, vdy, vdz, alx, aly, alz, vx, vy, vz, wx, wy, wz, gx, gy, gz):
    """``M Vdot + C(w) V + G`` of one link from its parameters ``th[o:o+13]`` (eq 13).

    Newton-Euler: :func:`reference_wrench` with ``V_r = V``.
    """
    return reference_wrench(th, o, vdx, vdy, vdz, alx, aly, alz, vx, vy, vz, wx, wy, wz,
                            wx, wy, wz, gx, gy, gz)


def link_regressor(Vdot_r, V_r, w, g=(0.0, 0.0, 0.0)):
    """The reference regressor ``Y_r`` of one link (eq 19b), shape (6, 13).

    Parameters
    ----------
    Vdot_r, V_r : array_like, shape (6,)
        Reference spatial acceleration and velocity ``[linear; angular]``, link frame.
    w : array_like, shape (3,)
        Actual angular velocity of the link (where ``C(w)`` is evaluated).
    g : array_like, shape (3,)
        Gravity acceleration in the link frame.

    Returns
    -------
    ndarray, shape (6, 13)
        ``Y`` with ``Y @ theta == M Vdot_r + C(w) V_r + G`` for any ``theta``.
    """
    Vdot_r = as_array(Vdot_r, (6,), "Vdot_r")
    V_r = as_array(V_r, (6,), "V_r")
    w = as_array(w, (3,), "w")
    g = as_array(g, (3,), "g")
    Y = np.zeros((1, 6, 13))
    fill_regressor(Y, 0, *Vdot_r, *V_r, *w, *g)
    return Y[0]


def mass_regressor(V):
    """``Ym(V)``, shape (6, 13): ``Ym(V) theta = M V`` (doc/design.md §4)."""
    V = as_array(V, (6,), "V")
    return link_regressor(V, np.zeros(6), V[3:])


def coriolis_gravity_regressor(V, g=(0.0, 0.0, 0.0)):
    """``Yc(V)``, shape (6, 13): ``Yc(V) theta = C(w) V + G`` with ``w`` = V's angular part."""
    V = as_array(V, (6,), "V")
    return link_regressor(np.zeros(6), V, V[3:], g)


def link_matrices(theta, w, g=(0.0, 0.0, 0.0)):
    """The blocks of eq 14 (doc/design.md §2) of one link's 13 parameters: ``M``, ``C(w)``, ``G``.

    These are the explicit matrices, used to check the regressor and for the
    Lyapunov function of eq 26.
    """
    th = as_array(theta, (13,), "theta")
    w = as_array(w, (3,), "w")
    g = as_array(g, (3,), "g")
    m, h = th[0], th[1:4]
    P = _skew(h / m)
    W = _skew(w)
    t = th
    I_o = np.array([[t[10] + t[5] + t[6], -t[7], -t[8]],
                    [-t[7], t[11] + t[4] + t[6], -t[9]],
                    [-t[8], -t[9], t[12] + t[4] + t[5]]])
    I_c = I_o + m * P @ P
    M = np.block([[m * np.eye(3), -m * P], [m * P, I_o]])
    C = np.block([[m * W, -m * W @ P], [m * P @ W, W @ I_c + I_c @ W - m * P @ W @ P]])
    G = -np.concatenate([m * g, m * P @ g])
    return M, C, G


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@njit(cache=True)
def inertia_row(ax, ay, az, wx, wy, wz):
    """``d(a^T I_o(theta) w) / d theta_5..13`` as a 9-tuple (I_o of doc/design.md §2)."""
    px = ax * wx
    py = ay * wy
    pz = az * wz
    return (py + pz, px + pz, px + py, -(ax * wy + ay * wx), -(ax * wz + az * wx),
            -(ay * wz + az * wy), px, py, pz)


@njit(cache=True)
def momentum_terms(avx, avy, avz, awx, awy, awz, vx, vy, vz, wx, wy, wz):
    """``a^T Ym(V)`` (13-tuple) without forming Ym: the gradient of ``a^T M(theta) V``.

    ``M V = [m v - h x w; h x v + I_o w]``.
    """
    t = inertia_row(awx, awy, awz, wx, wy, wz)
    return (avx * vx + avy * vy + avz * vz,
            # h . (v x a_w - w x a_v)
            (vy * awz - vz * awy) - (wy * avz - wz * avy),
            (vz * awx - vx * awz) - (wz * avx - wx * avz),
            (vx * awy - vy * awx) - (wx * avy - wy * avx),
            t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8])


@njit(cache=True)
def momentum_row(out, avx, avy, avz, awx, awy, awz, vx, vy, vz, wx, wy, wz):
    """:func:`momentum_terms` written into ``out`` (13)."""
    t = momentum_terms(avx, avy, avz, awx, awy, awz, vx, vy, vz, wx, wy, wz)
    for k in range(13):
        out[k] = t[k]


@njit(cache=True)
def bias_terms(avx, avy, avz, awx, awy, awz, vx, vy, vz, wx, wy, wz, gx, gy, gz):
    """``a^T Yc(V)`` (13-tuple) without forming Yc: the gradient of ``a^T (C(w) V + G)``.

    With ``u = w x v - g``: ``C V + G = [m u - w x (h x w); h x u + w x (I_o w)]``.
    """
    ux = wy * vz - wz * vy - gx
    uy = wz * vx - wx * vz - gy
    uz = wx * vy - wy * vx - gz
    ww = wx * wx + wy * wy + wz * wz
    aw = avx * wx + avy * wy + avz * wz
    # a_w . (w x I_o w) = (a_w x w) . (I_o w)
    t = inertia_row(awy * wz - awz * wy, awz * wx - awx * wz, awx * wy - awy * wx, wx, wy, wz)
    return (avx * ux + avy * uy + avz * uz,
            # h . (u x a_w - (w.w) a_v + (a_v.w) w)
            (uy * awz - uz * awy) - ww * avx + aw * wx,
            (uz * awx - ux * awz) - ww * avy + aw * wy,
            (ux * awy - uy * awx) - ww * avz + aw * wz,
            t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8])


@njit(cache=True)
def bias_row(out, avx, avy, avz, awx, awy, awz, vx, vy, vz, wx, wy, wz, gx, gy, gz):
    """:func:`bias_terms` written into ``out`` (13)."""
    t = bias_terms(avx, avy, avz, awx, awy, awz, vx, vy, vz, wx, wy, wz, gx, gy, gz)
    for k in range(13):
        out[k] = t[k]


@njit(cache=True)
def reference_wrench(th, o, vdx, vdy, vdz, alx, aly, alz, vrx, vry, vrz, wrx, wry, wrz,
                     wx, wy, wz, gx, gy, gz):
    """``Y(Vdot_r, V_r, w, g) theta`` of one link (eq 19b's ``Y_ri theta_hat_i``) without Y.

    With ``a = vdot_r + w x v_r - g`` and ``c = w x w_r``:
    force ``= m a + alpha_r x h - w x (h x w_r)``,
    moment ``= h x a + I_o (alpha_r + c) + w x (I_o w_r) - (t5 + t6 + t7) c``.
    """
    m = th[o]
    hx, hy, hz = th[o + 1], th[o + 2], th[o + 3]
    t5, t6, t7 = th[o + 4], th[o + 5], th[o + 6]
    t8, t9, t10 = th[o + 7], th[o + 8], th[o + 9]
    Ixx = th[o + 10] + t6 + t7
    Iyy = th[o + 11] + t5 + t7
    Izz = th[o + 12] + t5 + t6
    ax, ay, az, cx, cy, cz, dx, dy, dz, ww = motion_terms(
        vdx, vdy, vdz, alx, aly, alz, vrx, vry, vrz, wrx, wry, wrz, wx, wy, wz, gx, gy, gz)
    hw = hx * wx + hy * wy + hz * wz
    # I_o d and I_o w_r
    idx = Ixx * dx - t8 * dy - t9 * dz
    idy = -t8 * dx + Iyy * dy - t10 * dz
    idz = -t9 * dx - t10 * dy + Izz * dz
    irx = Ixx * wrx - t8 * wry - t9 * wrz
    iry = -t8 * wrx + Iyy * wry - t10 * wrz
    irz = -t9 * wrx - t10 * wry + Izz * wrz
    s = t5 + t6 + t7
    # w x (h x w_r) = h (w . w_r) - w_r (w . h)
    fx = m * ax + aly * hz - alz * hy - (hx * ww - wrx * hw)
    fy = m * ay + alz * hx - alx * hz - (hy * ww - wry * hw)
    fz = m * az + alx * hy - aly * hx - (hz * ww - wrz * hw)
    nx = hy * az - hz * ay + idx + wy * irz - wz * iry - s * cx
    ny = hz * ax - hx * az + idy + wz * irx - wx * irz - s * cy
    nz = hx * ay - hy * ax + idz + wx * iry - wy * irx - s * cz
    return fx, fy, fz, nx, ny, nz


@njit(cache=True)
def regressor_terms(svx, svy, svz, swx, swy, swz, vdx, vdy, vdz, alx, aly, alz,
                    vrx, vry, vrz, wrx, wry, wrz, wx, wy, wz, gx, gy, gz):
    """``s^T Y(Vdot_r, V_r, w, g)`` (13-tuple, eq 24's ``Y_ri^T s_i``) without forming Y.

    The gradient in theta of ``s^T`` (the wrench of :func:`reference_wrench`).
    """
    ax, ay, az, cx, cy, cz, dx, dy, dz, ww = motion_terms(
        vdx, vdy, vdz, alx, aly, alz, vrx, vry, vrz, wrx, wry, wrz, wx, wy, wz, gx, gy, gz)
    sw_r = svx * wrx + svy * wry + svz * wrz
    # h . (s_v x alpha_r - (w . w_r) s_v + (s_v . w_r) w + a x s_w)
    # s_w . I_o (alpha_r + c) + (s_w x w) . I_o w_r - (t5 + t6 + t7) s_w . c
    a = inertia_row(swx, swy, swz, dx, dy, dz)
    b = inertia_row(swy * wz - swz * wy, swz * wx - swx * wz, swx * wy - swy * wx,
                    wrx, wry, wrz)
    sc = swx * cx + swy * cy + swz * cz
    return (svx * ax + svy * ay + svz * az,
            (svy * alz - svz * aly) - ww * svx + sw_r * wx + (ay * swz - az * swy),
            (svz * alx - svx * alz) - ww * svy + sw_r * wy + (az * swx - ax * swz),
            (svx * aly - svy * alx) - ww * svz + sw_r * wz + (ax * swy - ay * swx),
            a[0] + b[0] - sc, a[1] + b[1] - sc, a[2] + b[2] - sc, a[3] + b[3], a[4] + b[4],
            a[5] + b[5], a[6] + b[6], a[7] + b[7], a[8] + b[8])


@njit(cache=True)
def regressor_row(out, svx, svy, svz, swx, swy, swz, vdx, vdy, vdz, alx, aly, alz,
                  vrx, vry, vrz, wrx, wry, wrz, wx, wy, wz, gx, gy, gz):
    """:func:`regressor_terms` written into ``out`` (13)."""
    t = regressor_terms(svx, svy, svz, swx, swy, swz, vdx, vdy, vdz, alx, aly, alz,
                        vrx, vry, vrz, wrx, wry, wrz, wx, wy, wz, gx, gy, gz)
    for k in range(13):
        out[k] = t[k]
