"""doc/failsafe.md, "parameters": parameters that are wrong, not only invalid (node processes,
real files)."""

import subprocess
import threading

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


def run_node(module, *overrides, params_file=None, until=None, timeout=120.0, ros_args=()):
    """Run a node until it exits, or (``until``) until a line of its output contains
    ``until``, and then stop it; ``timeout`` s at most (generous: a loaded machine). Return
    ``(exit code, or None if it was still running, output)``."""
    with ros_domain():
        proc = subprocess.Popen(node_cmd(module, *overrides, params_file=params_file,
                                         ros_args=ros_args),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                cwd=ROOT)
        lines, seen, ended = [], threading.Event(), threading.Event()

        def read():
            for line in proc.stdout:
                lines.append(line)
                if until is not None and until in line:
                    seen.set()
            ended.set()                 # the output closed: the process is exiting
            seen.set()
        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        try:
            seen.wait(timeout)
            code = proc.wait(timeout=30) if ended.is_set() else proc.poll()
            if proc.poll() is None:
                proc.terminate()
                proc.wait(timeout=30)
        finally:
            if proc.poll() is None:     # never outlive the domain: its next user would see it
                proc.kill()
                proc.wait()
        reader.join(timeout=30)
        return code, "".join(lines)


def test_unknown_keys_are_warned_with_a_suggestion(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text(TYPO)
    code, out = run_node("controller_node", params_file=path,
                         until="active: publishing efforts")
    assert "active: publishing efforts" in out, out
    assert code is None, out                    # still running: a warning, not a refusal
    assert "'K_d' (did you mean 'K_D'?)" in out, out
    assert "'rcac_simulater'" in out and "rcac_simulator" in out, out


def test_unknown_keys_are_refused_when_strict(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text(TYPO)
    code, out = run_node("controller_node", "strict_parameters:=true", params_file=path)
    assert code == 2, out
    errors = [ln for ln in out.splitlines() if "error" in ln]
    assert len(errors) == 1 and "K_d" in errors[0], out


def test_a_file_shared_by_both_nodes_is_not_unknown_to_either(tmp_path):
    """A ``/**`` section holding the two nodes' parameters (one file for a whole launch):
    the simulator's ``dt`` is not an unknown key of the strict controller; a key no node
    declares still is."""
    path = tmp_path / "shared.yaml"
    path.write_text("/**:\n  ros__parameters:\n    rate: 500.0\n    dt: 0.002\n")
    code, out = run_node("controller_node", "strict_parameters:=true", params_file=path,
                         until="active: publishing efforts")
    assert "active: publishing efforts" in out and code is None, out
    assert "no parameter declares" not in out, out
    path.write_text("/**:\n  ros__parameters:\n    dt: 0.002\n    d_t: 0.002\n")
    code, out = run_node("controller_node", "strict_parameters:=true", params_file=path)
    assert code == 2 and "'d_t'" in out and "'dt'" not in out.split("declares", 1)[1], out
    # /* (every node of the root namespace), a number rcl reads as a double (2.5e2)
    path.write_text("/*:\n  ros__parameters:\n    rate: 2.5e2\n    dt: 0.004\n")
    code, out = run_node("controller_node", "strict_parameters:=true", params_file=path,
                         until="active: publishing efforts")
    assert "h=4 ms" in out and code is None, out
    assert "no parameter declares" not in out and "addresses no node" not in out, out


@pytest.mark.parametrize("module, text", [
    ("controller_node", "rcac_controller:\n  ros__parameters:\n    K_D: [1.0\n"),  # unclosed
    ("controller_node", "rcac_controller:\n  ros__parameters:\n\tK_D: 1.0\n"),     # a tab
    ("simulator_node", "rcac_simulator: [1, 2]\n"),       # valid YAML, not a params file
    # an array of mixed types: rcl's refusal, once and without its source location; a key
    # beside ros__parameters: named by the file check
    ("controller_node", "rcac_controller:\n  ros__parameters:\n    gravity: [0.0, 0, -9.8]\n"),
    ("controller_node", "rcac_controller:\n  ros__parameters:\n    rate: 500.0\n  rate: 1\n"),
    ("controller_node", b"\xff\xfe not UTF-8 text"),
    # a merge key, and a mapping inside itself: rcl reads no aliases
    ("controller_node", "base: &b\n  ros__parameters: {rate: 250.0}\nrcac_controller:\n"
                        "  <<: *b\n"),
    ("controller_node", "rcac_controller:\n  ros__parameters: &x\n    rate: 1.0\n    q: *x\n"),
])
def test_malformed_params_yaml_is_one_line_and_exit_2(tmp_path, module, text):
    path = tmp_path / "bad.yaml"
    path.write_bytes(text) if isinstance(text, bytes) else path.write_text(text)
    code, out = run_node(module, params_file=path)
    assert code == 2, out
    assert "Traceback" not in out
    lines = [ln for ln in out.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(path) in lines[0], out


def test_a_file_that_gives_the_node_nothing_is_named(tmp_path):
    """``/ns/rcac_controller`` does not address the node ``/rcac_controller`` (rcl matches the
    fully qualified name): a file none of whose sections applies, or an empty one, would be
    dropped in silence. A file for several arms or a whole stack is not named."""
    from rcac_ros.nodes.runtime.paramcheck import section_applies
    for section, here, in_ns in [("/ns/rcac_controller", False, True),
                                 ("rcac_controller", True, False), ("/**", True, True),
                                 ("/**/rcac_controller", True, True),
                                 ("/*/rcac_controller", False, True), ("/ns/**", False, True)]:
        assert section_applies(section, "/rcac_controller") is here, section
        assert section_applies(section, "/ns/rcac_controller") is in_ns, section
    path = tmp_path / "ns.yaml"
    path.write_text("/ns/rcac_controller:\n  ros__parameters:\n    rate: 250.0\n")
    code, out = run_node("controller_node", params_file=path, until="active: publishing")
    assert (f"{path}: no section applies to this node (/rcac_controller); "
            "/ns/rcac_controller: another namespace") in out, out
    assert "h=2 ms" in out, out                     # the section's rate did not apply
    path.write_text("# rcac_controller:\n#   ros__parameters: {rate: 250.0}\n")
    code, out = run_node("controller_node", params_file=path, until="active: publishing")
    assert f"{path}: an empty parameters file" in out, out
    # one file for two arms, the node started in one of their namespaces: no warning
    path.write_text("/arm1/rcac_controller:\n  ros__parameters:\n    rate: 250.0\n"
                    "arm2:\n  rcac_controller:\n    ros__parameters:\n      rate: 125.0\n")
    code, out = run_node("controller_node", params_file=path, until="active: publishing",
                         ros_args=("-r", "__ns:=/arm1"))
    assert "h=4 ms" in out and "no section applies" not in out, out
    # a renamed node, in a file for the whole stack: its own section, another node's
    path.write_text("ctrl2:\n  ros__parameters:\n    rate: 250.0\n"
                    "robot_state_publisher:\n  ros__parameters:\n    publish_frequency: 20.0\n")
    code, out = run_node("controller_node", params_file=path, until="active: publishing",
                         ros_args=("-r", "__node:=ctrl2"))
    assert "h=4 ms" in out and "addresses no node" not in out, out
    assert "no section applies" not in out, out


def test_an_inert_option_is_named_and_rcl_log_levels_still_apply():
    """An option that acts only with another, given alone, is named once; a log level the
    user gives rcl (``--log-level rcl:=debug``) still reaches it; ``[]`` for a parameter
    without a default leaves it unset."""
    code, out = run_node("controller_node", "forgetting:=0.5", "realtime.cpus:=[]",
                         until="active: publishing", ros_args=("--log-level", "rcl:=debug"))
    assert "active: publishing" in out and code is None, out    # [] without a default: unset
    assert "forgetting: 0.5 changes nothing without adaptation 'least_squares*'" in out, out
    assert "[DEBUG]" in out and "[rcl]" in out, out[:2000]


#: files with a key given twice, and the node section rcl gives ``/rcac_controller``
REPEATED = [
    "rcac_controller:\n  ros__parameters:\n    K_D: 100.0\n    rate: 400.0\n    K_D: 200.0\n",
    # the section twice: rcl merges the two (PyYAML alone would keep the second only)
    "rcac_controller:\n  ros__parameters:\n    K_D: 100.0\n    rate: 400.0\n"
    "rcac_controller:\n  ros__parameters:\n    K_D: 200.0\n",
    # a nested parameter twice
    "rcac_controller:\n  ros__parameters:\n    paper: {period: 20.0, amplitude: 0.5}\n"
    "    paper: {period: 10.0}\n",
    # names are the keys' text: 'on' and 'true' are two (PyYAML reads both as True), 1 and
    # '1' one
    "rcac_controller:\n  ros__parameters:\n    q: {on: 1, true: 2, 1: 3, '1': 4}\n",
]


@pytest.mark.parametrize("text", REPEATED)
def test_a_key_given_twice_is_read_as_rcl_reads_it(tmp_path, text):
    """The file check's view of a file is the node's: compared with what rcl itself gives a
    node (its parameter overrides), and each value given twice is reported once."""
    from rclpy.node import Node
    from test_nodes_support import ros_context
    from rcac_ros.nodes.runtime.paramcheck import load_params_file, repeated_in
    path = tmp_path / "twice.yaml"
    path.write_text(text)
    repeated = []
    ours = load_params_file(str(path), repeated)["rcac_controller"]
    with ros_context() as (ctx, _):
        node = Node("rcac_controller", context=ctx,
                    cli_args=["--ros-args", "--params-file", str(path)],
                    automatically_declare_parameters_from_overrides=True)
        try:
            rcl = {k: p.value for k, p in node.get_parameters_by_prefix("").items()
                   if k not in ("use_sim_time", "start_type_description_service")}
        finally:
            node.destroy_node()
    assert dict(ours) == rcl
    lines = repeated_in(repeated, "/rcac_controller")
    assert len(lines) == 1 and "is given twice" in lines[0][0] and not lines[0][1], lines
    assert repeated_in(repeated, "/other_node") == []


def test_a_key_given_twice_is_named_and_refused_when_strict(tmp_path):
    path = tmp_path / "twice.yaml"
    path.write_text(REPEATED[1])
    code, out = run_node("controller_node", params_file=path, until="active: publishing")
    assert code is None, out
    assert "'K_D' is given twice (100.0, then 200.0); the last is used" in out, out
    code, out = run_node("controller_node", "strict_parameters:=true", params_file=path)
    assert code == 2, out
    errors = [ln for ln in out.splitlines() if "error" in ln]
    assert len(errors) == 1 and "'K_D' is given twice" in errors[0], out
    # of two types, rcl gives the node one by type, not the last: refused, strict or not
    path.write_text("rcac_controller:\n  ros__parameters:\n    K_D: 100.0\n    K_D: '200'\n")
    code, out = run_node("controller_node", params_file=path)
    errors = [ln for ln in out.splitlines() if "error" in ln]
    assert code == 2 and len(errors) == 1 and "of two types" in errors[0], out
    # the simulator's key twice in a section for both nodes is the simulator's to name
    path.write_text("/**:\n  ros__parameters:\n    duration: 1.0\n    duration: 2.0\n")
    code, out = run_node("controller_node", "strict_parameters:=true", params_file=path,
                         until="active: publishing")
    assert code is None and "given twice" not in out, out
