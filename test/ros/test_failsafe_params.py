"""doc/failsafe.md, "parameters": parameters that are wrong, not only invalid (node processes,
real files)."""

import subprocess

import pytest

from failsafe_harness import node_cmd, ROOT, ros_domain

TYPO = """rcac_controller:
  ros__parameters:
    K_d: 100.0
    rate: 500.0
rcac_simulater:
  ros__parameters:
    dt: 0.002
"""


def run_node(module, *overrides, params_file=None, timeout=8.0):
    """Run a node for ``timeout`` s at most; return ``(exit code or None, output)``."""
    with ros_domain():
        proc = subprocess.Popen(node_cmd(module, *overrides, params_file=params_file),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                cwd=ROOT)
        try:
            out, _ = proc.communicate(timeout=timeout)
            return proc.returncode, out
        except subprocess.TimeoutExpired:
            proc.terminate()
            out, _ = proc.communicate(timeout=30)
            return None, out


def test_unknown_keys_are_warned_with_a_suggestion(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text(TYPO)
    code, out = run_node("controller_node", params_file=path)
    assert code is None, out                    # still running: a warning, not a refusal
    assert "'K_d' (did you mean 'K_D'?)" in out, out
    assert "'rcac_simulater'" in out and "rcac_simulator" in out, out


def test_unknown_keys_are_refused_when_strict(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text(TYPO)
    code, out = run_node("controller_node", "strict_parameters:=true", params_file=path,
                         timeout=60.0)
    assert code == 2, out
    errors = [ln for ln in out.splitlines() if "error" in ln]
    assert len(errors) == 1 and "K_d" in errors[0], out


@pytest.mark.parametrize("module, text", [
    ("controller_node", "rcac_controller:\n  ros__parameters:\n    K_D: [1.0\n"),  # unclosed
    ("controller_node", "rcac_controller:\n  ros__parameters:\n\tK_D: 1.0\n"),     # a tab
    ("simulator_node", "rcac_simulator: [1, 2]\n"),       # valid YAML, not a params file
])
def test_malformed_params_yaml_is_one_line_and_exit_2(tmp_path, module, text):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    code, out = run_node(module, params_file=path, timeout=60.0)
    assert code == 2, out
    assert "Traceback" not in out
    lines = [ln for ln in out.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(path) in lines[0], out
