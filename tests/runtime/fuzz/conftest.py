"""Fixtures of the fuzz tests: a vehicle file, a certificate for the pool mission."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.runtime.helpers import approve
from tests.runtime.test_properties import mission


@pytest.fixture
def heading_90(tmp_path: Path) -> Path:
    """A vehicle file: the bundled ROMEO, already facing 90 degrees."""
    path = tmp_path / "heading90.yaml"
    path.write_text("initial:\n  psi_deg: 90.0\n", encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def pool_certificate(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("cert")
    approve(mission("pool").net, folder)
    return folder / "pool_mission.certificate.json"
