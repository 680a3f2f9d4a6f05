"""Stable diagnostic codes. A code never changes meaning once released.

``docs/rules.md`` documents each; a test pins that every code used is listed here.
"""

from __future__ import annotations

CODES: dict[str, str] = {
    "CORAL001": "syntax error",
    "CORAL002": "unknown name (place, constant or transition)",
    "CORAL003": "duplicate declaration",
    "CORAL004": "include failed (missing file, cycle, or different mission header)",
    "CORAL005": "bad value (wrong kind of constant, negative tokens, zero weight)",
    "CORAL006": "vehicle profile not found or system name mismatch",
    "CORAL007": "missing mission header",
    "CORAL008": "temporal property outside its logic (or an atom it cannot use)",
    "CORAL009": "unknown requirement",
    "CORAL010": "operator input misused (signalled, given tokens or a capacity, too many)",
    "CORAL011": "mission part header wrong (mission missing or not including the part, "
    "names itself or another part, misplaced or malformed)",
    "CORAL101": "unknown command",
    "CORAL102": "parameter count wrong, parameter missing, unknown or given twice",
    "CORAL103": "parameter type wrong",
    "CORAL104": "parameter unit wrong",
    "CORAL105": "parameter out of range",
    "CORAL106": "reply kind not handled",
    "CORAL107": "reply kind not produced by this command",
    "CORAL108": "reply kind mapped twice",
}
