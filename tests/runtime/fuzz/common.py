"""What the fuzz tests share: the two missions, and the command run as a user runs it."""

from __future__ import annotations

import pytest

from runtime import fuzz as fuzz_module
from tests.runtime.test_properties import MISSIONS

RACY = str(MISSIONS["racy"])
POOL = str(MISSIONS["pool"])


def cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``coral-run fuzz ARGV`` through the package's own `main` (``coral-run``'s
    subcommand builds its parser with the same `add_fuzz_arguments`)."""
    code = fuzz_module.main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err
