"""doc/results.md, generated: every measured figure of the documentation, with its provenance.

Each source is one JSON file under ``doc/results/``: ``{"record": {...}, "data": ...}``, the
``data`` a tool's own ``--json`` (or ``metrics.json``) output and the ``record`` what made it
(command, date, machine, git revision, wall time). :data:`sources.SOURCES` lists the sources
and how each is rendered; :mod:`.page` records a source and renders the page
(``make results``; ``python -m rcac_ros.tools.results --help``).
"""
