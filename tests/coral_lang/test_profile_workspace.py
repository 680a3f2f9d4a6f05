"""The optional ``workspace`` of a vehicle profile: the outline coral-run's plots draw."""

from __future__ import annotations

import pytest

from coral_lang.diagnostics import ProfileError
from coral_lang.profile import Workspace, load_bundled_profile, load_profile, parse_profile
from tests.conftest import EXAMPLES

HEAD = """vehicle: BOT
commands:
  GO: {kind: action, replies: [done]}
"""


def test_romeo_declares_the_pool_of_the_paper() -> None:
    assert load_bundled_profile("ROMEO").workspace == Workspace(0.0, 12.0, 0.0, 8.0)


@pytest.mark.parametrize("file", ["minnow.yaml", "glider.yaml", "usv.yaml"])
def test_a_profile_without_a_workspace_still_loads(file: str) -> None:
    assert load_profile(EXAMPLES / "profiles" / file).workspace is None


def test_a_workspace_is_read_in_metres() -> None:
    profile = parse_profile(HEAD + "workspace: {x: [-5, 20.5], y: [0, 3]}\n")
    assert profile.workspace == Workspace(-5.0, 20.5, 0.0, 3.0)


@pytest.mark.parametrize(
    ("workspace", "where", "message"),
    [
        ("[0, 12]", "workspace", "expected a mapping, got a list"),
        ("{x: [0, 12]}", "workspace", "missing required field 'y'"),
        ("{x: [0, 12], y: [0, 8], z: [0, 4]}", "workspace.z", "unknown field 'z'"),
        ("{x: [0, 12, 14], y: [0, 8]}", "workspace.x", r"expected \[min, max\] in metres, got 3"),
        ("{x: [0, 12], y: 8}", "workspace.y", "expected a list, got a number"),
        ("{x: [0, twelve], y: [0, 8]}", r"workspace.x\[1\]", "expected a number, got text"),
        ("{x: [12, 0], y: [0, 8]}", "workspace.x", "min 12 must be below max 0"),
        ("{x: [0, 12], y: [3, 3]}", "workspace.y", "min 3 must be below max 3"),
        ("{x: [0, .inf], y: [0, 8]}", r"workspace.x\[1\]", "expected a finite number"),
    ],
)
def test_a_bad_workspace_is_refused_naming_the_field(
    workspace: str, where: str, message: str
) -> None:
    with pytest.raises(ProfileError, match=rf"bot.yaml:4:\d+: {where}: .*{message}"):
        parse_profile(HEAD + f"workspace: {workspace}\n", "bot.yaml")
