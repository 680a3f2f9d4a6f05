"""PNML (ISO/IEC 15909-2) import and export of place/transition nets.

PNML is how Petri-net tools exchange nets: the Model Checking Contest models, TAPAAL,
GreatSPN and others all read and write it. coral reads the P/T flavour (net type
``http://www.pnml.org/version-2009/grammar/ptnet``) into its one `Net` model, so every
analysis runs on foreign nets unchanged, and writes any `Net` back out so other tools can
check coral's results.

Two modules, one per direction: `coral_lang.pnml.read` (`read_pnml`, `parse_pnml`:
defensive, every fault a `PnmlError` naming the file, line, column, element and id) and
`coral_lang.pnml.write` (`write_pnml`, `to_pnml`: built with ``xml.etree``). The format
notes (what is accepted, what is refused and why) are in ``docs/pnml.md``.

What survives a round trip ``parse_pnml(to_pnml(net))``: places, transitions, arcs with
their weights, initial markings, labels (stripped of surrounding white space) and every
name. Mission-only data (place and transition kinds, capacities, commands, replies,
priorities, resources, spans, final markings, assertions, vehicle, sources) travels in
``<toolspecific tool="coral" version="1">`` blocks that other tools ignore (a ``within``
assertion with its deadline in seconds, ``deadline-s``). Temporal assertions
(``always``, ``eventually``, ``leadsto``, ``ltl``, ``ctl``) are not exported: PNML has
no syntax for their formulas.
"""

from __future__ import annotations

from coral_lang.diagnostics import PnmlError
from coral_lang.pnml.common import CORAL_TOOL, CORAL_TOOL_VERSION, PNML_NAMESPACE, PTNET_TYPE
from coral_lang.pnml.read import parse_pnml, read_pnml
from coral_lang.pnml.write import to_pnml, write_pnml

__all__ = [
    "CORAL_TOOL",
    "CORAL_TOOL_VERSION",
    "PNML_NAMESPACE",
    "PTNET_TYPE",
    "PnmlError",
    "parse_pnml",
    "read_pnml",
    "to_pnml",
    "write_pnml",
]
