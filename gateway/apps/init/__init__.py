"""``wheelgate init``'s pure core: a commented configuration made from a shipped example.

* :mod:`gateway.apps.init.shipped` reads the files shipped with the package (the examples of
  the repository's ``config/``, installed as ``gateway.examples``, and the systemd unit);
* :mod:`gateway.apps.init.annotated` reads a configuration's YAML with its comments and writes
  it back;
* :mod:`gateway.apps.init.nodes` reads a ``wheelgate scan --json`` output and gives its nodes to
  the controllers;
* :mod:`gateway.apps.init.notes` holds what ``init`` adds: what each block means, what to
  measure and fill in;
* :mod:`gateway.apps.init.plan` applies the choices (example, driver, scan) and makes the text.

The edge, which reads the scan, checks and writes the files, is
:mod:`gateway.cli.commands.init`.
"""

from __future__ import annotations

from gateway.apps.init.nodes import Assignment, FoundNode, parse_scan
from gateway.apps.init.plan import Chosen, Written, choose, describe, generate

__all__ = ["Assignment", "Chosen", "FoundNode", "Written", "choose", "describe", "generate",
           "parse_scan"]
