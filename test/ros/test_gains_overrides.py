"""Per-joint gain overrides ``gains.<joint>.<gain>`` (parsing; the node test is elsewhere)."""

import numpy as np
import pytest

from rcac_ros.errors import ConfigError
from rcac_ros.nodes.controller.gains import parse_overrides, per_joint_gains

JOINTS = ("shoulder", "elbow", "wrist")
SCALARS = {"K_D": 1e4, "Lambda": 1.0, "P": 100.0}


def test_overrides_replace_the_scalar_for_one_joint_only():
    over = parse_overrides({"gains.wrist.K_D": 2e3, "gains.elbow.Lambda": 3.0,
                            "gains.shoulder.P": 5.0}, JOINTS)
    g = per_joint_gains(SCALARS, over, JOINTS)
    np.testing.assert_array_equal(g["K_D"], np.array([1e4, 1e4, 2e3])[:, None, None] * np.eye(6))
    np.testing.assert_array_equal(g["Lambda"], [1.0, 3.0, 1.0])
    np.testing.assert_array_equal(g["P"], np.array([5.0, 100.0, 100.0])[:, None, None]
                                  * np.eye(13))


@pytest.mark.parametrize("name, value, text", [
    ("gains.wirst.K_D", 2e3, "unknown joint 'wirst'"),
    ("gains.wrist.gamma", 0.1, "unknown per-joint gain 'gamma'"),
    ("gains.wrist.K_D", -1.0, "must be > 0"),
    ("gains.wrist.K_D", 2000, "wrong type"),
    ("gains.K_D", 2e3, "expected gains.<joint>.<gain>"),
])
def test_bad_overrides_are_rejected_in_one_line_naming_them(name, value, text):
    with pytest.raises(ConfigError) as err:
        parse_overrides({name: value}, JOINTS)
    assert str(err.value).startswith(f"{name}: ") and text in str(err.value)
    assert "\n" not in str(err.value)


def test_a_parameters_file_may_hold_gains_overrides():
    from rcac_ros.nodes.runtime.paramcheck import check_file_params
    check_file_params("controller", {"gains": {"joint7": {"K_D": 2.0e3, "P": 10.0}}})
    with pytest.raises(ConfigError) as err:
        check_file_params("controller", {"gains": {"joint7": {"K_D": -1.0}}})
    assert str(err.value).startswith("gains.joint7.K_D:")
