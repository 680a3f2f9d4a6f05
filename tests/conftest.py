"""Shared test configuration: deterministic hypothesis, paths to vendored data."""

from __future__ import annotations

import gzip
import hashlib
import os
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, settings

REPO = Path(__file__).resolve().parent.parent
EXAMPLES = REPO / "examples"
VENDORED_MCC = REPO / "tests" / "data" / "mcc"
"""The Model Checking Contest data the tests use, copied into the repository with its
provenance (``tests/data/mcc/README.md``), so a plain clone runs every test."""


def _unpacked_conformance() -> Path:
    """A folder laid out as ``shared/conformance`` (``oracle.yaml``, ``pnml/*.pnml``) with
    the vendored nets decompressed, made once per content and reused across runs.

    Files are written to a temporary name and renamed, so pytest-xdist workers that
    import this module at the same time never see a half-written net.
    """
    packed = sorted((VENDORED_MCC / "pnml").glob("*.pnml.gz"))
    digest = hashlib.sha256()
    for path in [VENDORED_MCC / "oracle.yaml", *packed]:
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    root = Path(tempfile.gettempdir()) / f"coral-conformance-{digest.hexdigest()[:16]}"
    (root / "pnml").mkdir(parents=True, exist_ok=True)
    for path in [VENDORED_MCC / "oracle.yaml", *packed]:
        unpacked = path.suffix == ".gz"
        target = root / ("pnml" if unpacked else "") / path.name.removesuffix(".gz")
        if target.exists():
            continue
        data = path.read_bytes()
        partial = target.with_name(f".{target.name}.{os.getpid()}")
        partial.write_bytes(gzip.decompress(data) if unpacked else data)
        partial.replace(target)
    return root


CONFORMANCE = _unpacked_conformance()

# Deterministic by default: the same examples on every run and machine. Set
# HYPOTHESIS_PROFILE=explore to search with fresh randomness locally.
settings.register_profile(
    "ci", derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile("explore", deadline=None, max_examples=1000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
