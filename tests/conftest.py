"""Shared test configuration: deterministic hypothesis, paths to shared data."""

from __future__ import annotations

import os
from pathlib import Path

from hypothesis import HealthCheck, settings

REPO = Path(__file__).resolve().parent.parent
CONFORMANCE = REPO.parent / "shared" / "conformance"
EXAMPLES = REPO / "examples"

# Deterministic by default: the same examples on every run and machine. Set
# HYPOTHESIS_PROFILE=explore to search with fresh randomness locally.
settings.register_profile(
    "ci", derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile("explore", deadline=None, max_examples=1000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
