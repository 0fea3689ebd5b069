"""The direct law with the joint terms (``gamma = 0``, the paper's one channel: the fused
``paper_friction_step``) against Slotine-Li with the joint terms and ``gamma = 0``
(doc/design.md §7): two implementations of eq 24's tracking term, step by step."""

import numpy as np
import pytest

from rcac_ros.core import (RecursiveCompositeController, Simulator, SlotineLiCompositeController,
                           css_arm)
from rcac_ros.core.model import PAPER_Q0


@pytest.mark.parametrize("P_friction", [(0.5, 5.0, 5.0), 50.0])
def test_direct_law_with_joint_terms_equals_slotine_li(P_friction):
    """Closed loops on the CSS arm with gravity and joint friction, from zero joint
    estimates: efforts and estimates (link and joint) equal to 1e-9 at every step."""
    rng = np.random.default_rng(5)
    rigid = css_arm((0.0, 0.0, -9.81))
    model = rigid.replace(armature=rng.uniform(0.05, 0.2, 7), damping=rng.uniform(1.0, 5.0, 7),
                          friction=rng.uniform(0.5, 2.0, 7))
    q0 = np.array(PAPER_Q0)
    amp = rng.uniform(0.2, 0.5, 7)
    traj = lambda t: (q0 + amp * np.sin(2.0 * t), 2.0 * amp * np.cos(2.0 * t),   # noqa: E731
                      -4.0 * amp * np.sin(2.0 * t))
    gains = dict(K_D=300.0, Lambda=5.0, P=1.0, gamma=0.0, joint_friction=True,
                 friction_hat0=np.zeros((7, 3)), P_friction=P_friction,
                 theta_hat0=rigid.theta())
    a = RecursiveCompositeController(model, **gains)
    b = SlotineLiCompositeController(model, **gains)
    sa, sb = Simulator(model, q0=q0), Simulator(model, q0=q0)
    worst = 0.0
    for k in range(1000):
        x = traj(k * 0.002)
        ta, tb = a.step(sa.q, sa.qd, *x), b.step(sb.q, sb.qd, *x)
        for u, v in ((ta, tb), (a.theta_hat, b.theta_hat), (a.friction_hat, b.friction_hat)):
            worst = max(worst, np.max(np.abs(u - v)) / max(np.max(np.abs(v)), 1e-300))
        sa.step(ta)
        sb.step(tb)
    assert worst < 1e-9, worst
    assert np.max(np.abs(b.friction_hat)) > 1e-3            # the joint terms did adapt
