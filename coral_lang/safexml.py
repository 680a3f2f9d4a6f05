"""One hardened XML front end for every XML format coral reads (PNML, MCC queries).

defusedxml's expat driver refuses DTDs, entity declarations and external references
(no billion laughs, no XXE). `SafeExpatParser` keeps those defences and wires expat's
element events straight to a builder: the SAX layer in between would build attribute
objects and locators per element and roughly double the parse time of a large net.
"""

from __future__ import annotations

from typing import Any, Protocol

from defusedxml.expatreader import DefusedExpatParser


class ElementEvents(Protocol):
    """What a builder provides: expat's three element callbacks, and a slot where the
    parser puts the pyexpat object (for line and column numbers)."""

    expat: Any

    def start(self, name: str, attrs: dict[str, str], /) -> None: ...

    def end(self, name: str, /) -> None: ...

    def data(self, content: str, /) -> None: ...


class SafeExpatParser(DefusedExpatParser):  # type: ignore[misc]
    """defusedxml's expat driver with namespaces on (names arrive as ``"uri local"``)
    and its element events sent to ``builder``; the defusing handlers that defusedxml
    installs in `reset` are kept untouched."""

    def __init__(self, builder: ElementEvents) -> None:
        super().__init__(
            namespaceHandling=1, forbid_dtd=True, forbid_entities=True, forbid_external=True
        )
        self._builder = builder

    def reset(self) -> None:
        super().reset()
        expat = self._parser
        expat.buffer_text = True
        expat.namespace_prefixes = False  # names as "uri local", never "uri local prefix"
        expat.StartElementHandler = self._builder.start
        expat.EndElementHandler = self._builder.end
        expat.CharacterDataHandler = self._builder.data
        self._builder.expat = expat
