"""The direct law with the joint terms (``gamma = 0``, the paper's one channel: the fused
``paper_friction_step``) against Slotine-Li with the joint terms and ``gamma = 0``
(doc/design.md §7): two implementations of eq 24's tracking term, step by step."""

import numpy as np
import pytest
from chains import sine_motion, worst_difference

from rcac_ros.core import RecursiveCompositeController, SlotineLiCompositeController, css_arm
from rcac_ros.core.model import PAPER_Q0


@pytest.mark.parametrize("P_friction", [(0.5, 5.0, 5.0), 50.0, "feedback"])
def test_direct_law_with_joint_terms_equals_slotine_li(P_friction):
    """Closed loops on the CSS arm with gravity and joint friction, from zero joint
    estimates: efforts and estimates (link and joint) equal to 1e-9 at every step."""
    rng = np.random.default_rng(5)
    rigid = css_arm((0.0, 0.0, -9.81))
    model = rigid.replace(armature=rng.uniform(0.05, 0.2, 7), damping=rng.uniform(1.0, 5.0, 7),
                          friction=rng.uniform(0.5, 2.0, 7))
    q0 = np.array(PAPER_Q0)
    amp = rng.uniform(0.2, 0.5, 7)
    traj = sine_motion(q0, amp)
    gains = dict(K_D=300.0, Lambda=5.0, P=1.0, gamma=0.0, joint_friction=True,
                 friction_hat0=np.zeros((7, 3)), P_friction=P_friction,
                 theta_hat0=rigid.theta())
    a = RecursiveCompositeController(model, **gains)
    b = SlotineLiCompositeController(model, **gains)
    worst = worst_difference(a, b, model, q0, traj, with_E=False)
    assert worst < 1e-9, worst
    assert np.max(np.abs(b.friction_hat)) > 1e-3            # the joint terms did adapt
