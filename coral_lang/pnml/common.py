"""The names both sides of PNML share: the standard's namespace and net type, and the
tool name and version of coral's own ``<toolspecific>`` blocks.

In a module of their own so the reader and the writer agree on them without importing
each other.
"""

from __future__ import annotations

__all__ = ["CORAL_TOOL", "CORAL_TOOL_VERSION", "PNML_NAMESPACE", "PTNET_TYPE"]

PNML_NAMESPACE = "http://www.pnml.org/version-2009/grammar/pnml"
PTNET_TYPE = "http://www.pnml.org/version-2009/grammar/ptnet"
CORAL_TOOL = "coral"
CORAL_TOOL_VERSION = "1"
