"""``rcac compare``'s friction-aware direct law on the rigid panda (built-in simulator): the
explicit tracking step of the joint terms with the inertia-scaled gain tracks as well as
the friction-blind direct law, where a uniform gain too large for the light wrist joints
does not (doc/design.md §7, "Gain and step")."""

import numpy as np

from rcac_ros.core.crba import mass_matrix
from rcac_ros.tools.demos import compare as C


def rms(scenario, law, **override):
    kind, extra = C.LAWS[law]
    ctrl = C.make_controller(scenario, law, {law: (kind, dict(extra, **override))})
    run = C.run_law(scenario, ctrl, 10.0, engine="builtin")
    return C.metrics(run, scenario)["rms"]


def test_inertia_scaled_gain_is_rho_times_the_joint_inertia():
    scenario = C.SCENARIOS["panda_rigid"]()
    P = C.friction_gain_for(scenario.model, scenario.q0)
    H = mass_matrix(scenario.model, scenario.q0)
    np.testing.assert_allclose(P, C.RHO_FRICTION * np.outer(np.diag(H), np.ones(3)))


def test_direct_friction_tracks_the_rigid_panda_as_the_direct_law():
    scenario = C.SCENARIOS["panda_rigid"]()
    direct = rms(scenario, "direct")
    aware = rms(scenario, "direct_friction")
    # "as well as", a stated tolerance: within a factor 2. On the rigid plant the joint
    # terms' truth is 0 and the inertia-scaled gain keeps the step's bound of §7 (25/s
    # against kappa = 100/s on every joint), so they may not change the accuracy's order.
    assert aware < 2.0 * direct, (aware, direct)
    # the check can fail: the uniform gain of the first table, 300 on every joint, puts
    # h P |Y_f|^2 / H_77 about 10x above the feedback rate on joint 7 (H_77 = 0.0067 kg m^2):
    # the step is unstable, the estimates run away, and the error leaves the tracking regime
    # (three orders of magnitude above the stable law's: not a matter of a factor)
    uniform = rms(scenario, "direct_friction", P_friction=300.0)
    assert uniform > 1000.0 * direct, (uniform, direct)
