"""Link profiles, under their old name: they moved to `coral_lang.linkprofile`.

A link profile is plain data that timed analysis reads as well as the emulator, and
``analysis`` may import ``coral_lang`` only, so the module lives there now. This one
keeps every existing ``from runtime.linkprofile import ...`` working; new code imports
from ``coral_lang.linkprofile``.
"""

from __future__ import annotations

from coral_lang.linkprofile import (
    ANALYSIS_FRAME_BYTES,
    BUILTIN_PROFILES,
    LinkProfile,
    LinkProfileError,
    load_link_profile,
    parse_link_profile,
)

__all__ = [
    "ANALYSIS_FRAME_BYTES",
    "BUILTIN_PROFILES",
    "LinkProfile",
    "LinkProfileError",
    "load_link_profile",
    "parse_link_profile",
]
