"""Parameters that are wrong, not only invalid (doc/failsafe.md, "parameters").

* :func:`check_params_files` reads every ``--params-file`` of the command line before
  ``rclpy.init`` does, so that a malformed file gives one line naming it (and the CLI
  exit code 2) instead of an RCLError traceback; a key given twice is read as rcl reads it
  and named (:func:`repeated_in`).
* :func:`check_file_params` checks one node's section of a parameters file against the
  table (the tests run it on the shipped ``config/*.yaml``).
* :func:`unknown_parameters` names each given key that no parameter declares, with the
  nearest declared name; :func:`foreign_sections` names the sections of those files
  that address no node of the package.
"""

import difflib
import re

from rcac_ros.errors import ConfigError, read_yaml
from rcac_ros.params import GAINS_PREFIX, TABLE, check, flatten, gain_override

#: parameters every rclpy node declares itself
BUILTIN = frozenset({"use_sim_time", "start_type_description_service"})


def params_files(argv):
    """The paths given to ``--params-file`` in ``argv`` (ROS arguments)."""
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--params-file"]


def load_params_file(path, repeated=None):
    """Parse one parameters file as rcl reads it; return ``{node: {name: value}}``.

    A key given twice in one mapping is read as rcl reads it: two mappings merge, and of two
    values of one type the last is kept. Each value given twice is appended to ``repeated``
    (if given) as ``(path, keys, first value, last value, of two types)``.

    Raises
    ------
    ConfigError
        One line naming the file, and the line and column of a YAML error, or the first
        entry that is not ``NODE: {ros__parameters: {...}}``.
    """
    found = [] if repeated is None else repeated
    data = read_yaml(path, f"params file {path}",
                     load=lambda stream: _load_merging(stream, path, found))
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"params file {path}: expected a mapping of node names, got "
                          f"{type(data).__name__}")
    out = {}
    _sections(path, "", data, out)
    return out


def _load_merging(stream, path, repeated):
    """The document of ``stream`` (PyYAML's safe types), a repeated key merged as rcl does."""
    import yaml
    loader = yaml.SafeLoader(stream)
    try:
        root = loader.get_single_node()
        return None if root is None else _value(loader, root, (), path, repeated)
    finally:
        loader.dispose()


def _value(loader, node, keys, path, repeated, within=()):
    import yaml
    if not isinstance(node, yaml.MappingNode):
        return loader.construct_object(node, deep=True)
    if id(node) in within:
        raise yaml.constructor.ConstructorError(None, None, "an alias of a mapping inside "
                                                "itself (rcl reads no aliases)", node.start_mark)
    within += (id(node),)
    out = {}
    for key_node, value_node in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark,
                "a merge key ('<<'), which rcl does not read", key_node.start_mark)
        if not isinstance(key_node, yaml.ScalarNode):
            raise yaml.constructor.ConstructorError("while constructing a mapping",
                                                    node.start_mark, "found unhashable key",
                                                    key_node.start_mark)
        key = key_node.value                        # rcl's names are the keys' text
        value = _value(loader, value_node, keys + (key,), path, repeated, within)
        if key in out:
            _merge(out, key, value, keys, path, repeated)
        else:
            out[key] = value
    return out


def _kind(value):
    """A value's type as far as a repeat goes: rcl keeps two values of different types (the
    node gets one of them by type, not the last)."""
    if isinstance(value, list):
        return ("array",) + tuple(sorted({type(v).__name__ for v in value}))
    return (type(value).__name__,)


def _merge(mapping, key, value, keys, path, repeated):
    old = mapping[key]
    if isinstance(old, dict) and isinstance(value, dict):
        for k, v in value.items():
            if k in old:
                _merge(old, k, v, keys + (key,), path, repeated)
            else:
                old[k] = v
        return
    repeated.append((path, keys + (key,), old, value, _kind(old) != _kind(value)))
    mapping[key] = value


def repeated_in(repeated, fq_name, skip=frozenset()):
    """``(line, mixed)`` for each value given twice in a section of ``repeated`` (from
    :func:`load_params_file`) that applies to the node ``fq_name``, but for names in
    ``skip``; ``mixed``: the two values are of different types."""
    lines = []
    for path, keys, first, last, mixed in repeated:
        if "ros__parameters" not in keys[:-1]:
            continue
        at = keys.index("ros__parameters")
        section = "/".join(keys[:at])
        name = ".".join(keys[at + 1:])
        if section_applies(section, fq_name) and name not in skip:
            lines.append((f"{path}: {section}: {name!r} is given twice ({first!r}, then "
                          f"{last!r})", mixed))
    return lines


def _sections(path, namespace, mapping, out):
    """The node sections of ``mapping`` into ``out`` (``{"ns/node": {name: value}}``): a
    key holding ``ros__parameters`` is a node; one holding mappings only, a namespace
    (``arm: {rcac_controller: {ros__parameters: ...}}`` is ``arm/rcac_controller``)."""
    for key, section in mapping.items():
        node = f"{namespace}/{key}" if namespace else str(key)
        if isinstance(section, dict) and "ros__parameters" in section:
            params = section["ros__parameters"]
            if not isinstance(params, dict):
                raise ConfigError(f"params file {path}: {node}: expected 'ros__parameters:' "
                                  "holding a mapping")
            beside = [str(k) for k in section if k != "ros__parameters"]
            if beside:
                raise ConfigError(f"params file {path}: {node}: {beside[0]!r} beside "
                                  "'ros__parameters' (every parameter goes under it)")
            out[node] = dict(flatten(params))
        elif isinstance(section, dict) and section \
                and all(isinstance(v, dict) for v in section.values()):
            _sections(path, node, section, out)
        else:
            raise ConfigError(f"params file {path}: {node}: expected 'ros__parameters:' "
                              "holding a mapping")


def check_params_files(argv, repeated=None):
    """Load every ``--params-file`` of ``argv``; return ``{path: {node: params}}`` (the
    values given twice: appended to ``repeated``, :func:`load_params_file`)."""
    return {path: load_params_file(path, repeated) for path in params_files(argv)}


def check_file_params(node, params):
    """Check the ``{name: value}`` of one node's section of a parameters file.

    Nested mappings are flattened (``paper: {period: 20.0}`` is ``paper.period``).
    ``use_sim_time`` and the other parameters rclpy declares itself are allowed.

    Raises
    ------
    ConfigError
        Naming the first unknown parameter or invalid value.
    """
    known = {p.name: p for p in TABLE[node]}
    for name, value in flatten(params):
        if name in BUILTIN:
            continue
        if node == "controller" and name.startswith(GAINS_PREFIX) and name not in known:
            check(gain_override(name), value)       # the joint is checked at start-up
            continue
        if name not in known:
            raise ConfigError(f"{name}: the {node} declares no such parameter")
        check(known[name], value)


def nearest(name, candidates):
    """The candidate nearest to ``name`` (case-insensitive), or ``None``."""
    lower = {c.lower(): c for c in candidates}
    hit = difflib.get_close_matches(name.lower(), list(lower), n=1, cutoff=0.6)
    return lower[hit[0]] if hit else None


def unknown_parameters(given, declared):
    """Given names that no parameter declares, each with the nearest declared name.

    Returns
    -------
    list of (str, str or None)
    """
    known = set(declared) | BUILTIN
    return [(name, nearest(name, known)) for name in sorted(set(given) - known)]


def describe_unknown(unknown, node):
    """One line listing the unknown keys and their suggestions."""
    parts = [f"'{name}'" + (f" (did you mean '{hint}'?)" if hint else "")
             for name, hint in unknown]
    return f"{node}: no parameter declares {', '.join(parts)}"


def node_token(section):
    """The last name of a section (``/arm/rcac_controller`` -> ``rcac_controller``)."""
    return section.strip("/").split("/")[-1]


def section_applies(section, fq_name):
    """Whether a parameters file's section name (``/ns/node``, ``node``, ``/**``, ``/*/node``)
    addresses the node of fully qualified name ``fq_name``, as rcl matches them."""
    tokens = section.strip("/").split("/")
    pattern = "".join("(/[^/]+)*" if t == "**" else "/[^/]+" if t == "*" else "/" + re.escape(t)
                      for t in tokens)
    return re.fullmatch(pattern, fq_name) is not None


def shared_keys(files, fq_name):
    """Keys that a wildcard section applying to the node ``fq_name`` (``/**``, ``/*``) gives
    it and a node of rcac_ros declares: a file shared by the two nodes gives each the other's
    parameters too (the controller's ``gains.<joint>.<gain>`` among them)."""
    declared = {p.name for rows in TABLE.values() for p in rows}
    return {name for sections in files.values() for section, params in sections.items()
            if "*" in node_token(section) and section_applies(section, fq_name)
            for name in params if name in declared or name.startswith(GAINS_PREFIX)}


def unapplied(files, name, fq_name):
    """None if a section of the files applies to the node ``fq_name`` (or none has a section);
    else ``(paths, sections)``: the files, none of whose sections rcl gives the node, and
    those that name it (``name``) in another namespace."""
    paths = [path for path, sections in files.items() if sections]
    sections = [s for path in paths for s in files[path]]
    if not sections or any(section_applies(s, fq_name) for s in sections):
        return None
    return paths, [s for s in sections if node_token(s) == name]


def foreign_sections(files, nodes):
    """Sections of the parameter files that name none of ``nodes`` but one close to it (a
    typo: ``rcac_simulater``); a section of another node of the stack is not one.

    Returns
    -------
    list of (str, str, str)
        ``(path, section, nearest node name)``.
    """
    out = []
    for path, sections in files.items():
        for section in sections:
            name = node_token(section)
            hint = None if "*" in name or name in nodes else nearest(name, nodes)
            if hint is not None:
                out.append((path, section, hint))
    return out
