"""``doc/parameters.md``: the parameter tables of :mod:`rcac_ros.params`, in Markdown
(``python -m rcac_ros.params_doc > doc/parameters.md``)."""

import math
import sys

from rcac_ros.params import TABLE


def _cell(value):
    if value is None:
        return "unset"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"`{value!r}`" if value == "" else f"`{value}`"
    return repr(value)      # doubles keep their decimal point


def _range(p):
    if p.choices:
        return " \\| ".join(f"`{c}`" for c in p.choices)
    if p.lo is None:
        return ""
    left = "(" if p.strict else "["
    number = str if p.type == "integer" else (lambda x: f"{x:g}")
    hi = "inf" if p.hi is None or p.hi == math.inf else number(p.hi)
    text = f"{left}{number(p.lo)}, {hi}]"
    return text + (" each" if p.type.endswith("_array") else "")


def _row(p):
    kind = p.type + (" (1 or n)" if p.per_joint else "")
    return (f"| `{p.name}` | {kind} | {_cell(p.default)} | {_range(p)} | "
            f"{'' if p.read_only else 'yes'} | {p.description} |")


def shared():
    """The Markdown rows both nodes declare alike, in the controller's order."""
    simulator = set(map(_row, TABLE["simulator"]))
    return [row for row in map(_row, TABLE["controller"]) if row in simulator]


def markdown(rows):
    """The Markdown table of parameter ``rows`` (:func:`_row`)."""
    return "\n".join(["| name | type | default | range | settable | description |",
                      "| --- | --- | --- | --- | --- | --- |"] + rows)


def document():
    """The whole of ``doc/parameters.md``."""
    parts = ["# Node parameters", "",
             "Generated from `rcac_ros/params.py` by `python -m rcac_ros.params_doc > "
             "doc/parameters.md`; do not edit by hand.",
             "Ranges are inclusive, `(` excludes the bound; doubles must be written with a "
             "decimal point in a YAML file. Settable parameters can be changed with "
             "`ros2 param set` while the node runs; the others are read once at start-up (the "
             "managed controller: at each configure). The controller also takes per-joint "
             "gain overrides `gains.<joint>.<K_D|Lambda|P>` (doubles; see doc/nodes.md)."]
    common = shared()
    parts += ["", "## both nodes", "", "Each node declares its own.", "", markdown(common)]
    for node, config in (("controller", "controller.yaml"), ("simulator", "simulator.yaml")):
        parts += ["", f"## {node} (`ros2 run rcac_ros {node}`, `config/{config}`)", "",
                  markdown([r for r in map(_row, TABLE[node]) if r not in common])]
    return "\n".join(parts) + "\n"


def main():
    """Print ``doc/parameters.md``."""
    sys.stdout.write(document())
    return 0


if __name__ == "__main__":
    sys.exit(main())
