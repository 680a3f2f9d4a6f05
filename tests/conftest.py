"""Shared test configuration: deterministic hypothesis, paths to vendored data."""

from __future__ import annotations

import functools
import gzip
import hashlib
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from analysis.signing import SigningKey, TrustStore, generate_key_files, load_signing_key

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
# HYPOTHESIS_PROFILE=explore to search with fresh randomness locally; `make check` (the
# inner loop) uses "fast": the same derandomized search, a fifth of the examples.
settings.register_profile(
    "ci", derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile("fast", settings.get_profile("ci"), max_examples=20)
settings.register_profile("explore", deadline=None, max_examples=1000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@dataclass(frozen=True)
class TestKey:
    """A signing key pair made for this test session, as a verifier and an operator
    would hold it: the private key file, the ``.pub`` file, and the store trusting it."""

    __test__ = False  # not a test class, whatever its name

    private: Path
    public: Path
    key: SigningKey
    trusted: TrustStore


@functools.cache
def session_signing_key() -> TestKey:
    """One key pair per test process (each pytest-xdist worker makes its own), in a
    temporary folder: tests sign certificates with it and trust it with
    ``--trusted-keys``, instead of running with the signature check weakened."""
    folder = Path(tempfile.mkdtemp(prefix="coral-test-key-"))
    private = folder / "test-signing.key"
    public = generate_key_files(private, "coral tests")
    return TestKey(
        private,
        Path(public.source),
        load_signing_key(private),
        TrustStore.of([public], public.source),
    )


@pytest.fixture(scope="session")
def signing_key() -> TestKey:
    """The session's signing key pair (`session_signing_key`)."""
    return session_signing_key()


BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def required_program(names: tuple[str, ...], install: str) -> str:
    """The first of ``names`` on the PATH, for a test that needs an outside program
    (``.ci/run`` installs each): skipped on a developer's machine without it, a failure
    under CI, where a missing program must not hide a test."""
    for name in names:
        found = shutil.which(name)
        if found:
            return found
    message = f"{names[0]} is not installed ({install})"
    if os.environ.get("CI"):
        pytest.fail(f"{message}; CI must run the tests that need it")
    pytest.skip(message)


@pytest.fixture(scope="session")
def chromium() -> str:
    """The headless browser for the HTML report and watch page tests."""
    return required_program(BROWSERS, "apt-get install chromium")


@pytest.fixture(scope="session")
def patch_program() -> str:
    """``patch``, which must apply what ``coral-check fmt --diff`` prints."""
    return required_program(("patch",), "apt-get install patch")
