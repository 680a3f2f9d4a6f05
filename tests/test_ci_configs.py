"""The CI and pre-commit configurations we publish: valid YAML that runs real commands."""

from __future__ import annotations

import importlib
import re
import shlex
import tomllib
from typing import Any

import pytest
import yaml

from analysis.cli import build_lint_parser, build_parser
from tests.conftest import REPO

CI_DOC = (REPO / "docs" / "ci.md").read_text()
BLOCKS = re.findall(r"^```yaml\n(.*?)^```", CI_DOC, re.S | re.M)
HOOKS = REPO / ".pre-commit-hooks.yaml"


def _commands(node: Any, key: str = "") -> list[str]:
    """The coral-check command lines of a YAML document: GitHub's ``run`` steps and
    GitLab's ``script`` lines (hooks' ``entry`` get their files from pre-commit)."""
    if isinstance(node, dict):
        return [c for k, value in node.items() for c in _commands(value, str(k))]
    if isinstance(node, list):
        return [c for value in node for c in _commands(value, key)]
    if key in ("run", "script") and str(node).startswith("coral-check "):
        return [str(node)]
    return []


def test_the_page_has_the_four_configurations() -> None:
    assert len(BLOCKS) == 4
    documents = [yaml.safe_load(block) for block in BLOCKS]
    github, gitlab, remote, local = documents
    steps = github["jobs"]["coral-check"]["steps"]
    uploads = [
        s for s in steps if str(s.get("uses", "")).startswith("github/codeql-action/upload-sarif@")
    ]
    assert uploads and uploads[0]["with"]["sarif_file"] == "coral-check.sarif"
    assert github["jobs"]["coral-check"]["permissions"]["security-events"] == "write"
    assert any("--format sarif -o coral-check.sarif" in str(s.get("run", "")) for s in steps)
    assert gitlab["coral-check"]["allow_failure"] == {"exit_codes": [3]}
    assert gitlab["coral-check"]["artifacts"]["paths"] == ["coral-check.html", "coral-check.json"]
    assert remote["repos"][0]["hooks"][0]["id"] == "coral-check"
    assert local["repos"][0]["hooks"][0]["entry"] == "coral-check lint"


@pytest.mark.parametrize("block", BLOCKS, ids=["github", "gitlab", "pre-commit", "local"])
def test_every_documented_command_line_parses(block: str) -> None:
    commands = _commands(yaml.safe_load(block))
    assert commands or "hooks" in block
    for command in commands:
        words = shlex.split(command.split("||")[0])[1:]
        if words[:1] == ["lint"]:
            args = build_lint_parser().parse_args(words[1:])
        else:
            args = build_parser().parse_args(words)
        for file in args.files:
            assert (REPO / file).is_file(), f"{command}: no {file} in this repository"


@pytest.mark.parametrize(
    ("hook_id", "entry"),
    [("coral-check", "coral-check lint"), ("coral-check-fmt", "coral-check fmt --check")],
)
def test_each_hook_runs_on_missions_through_a_real_console_script(hook_id: str, entry: str) -> None:
    hooks = {hook["id"]: hook for hook in yaml.safe_load(HOOKS.read_text())}
    hook = hooks[hook_id]
    assert hook["language"] == "python" and hook["entry"] == entry
    pattern = re.compile(hook["files"])
    assert pattern.search("missions/pool.coral") and not pattern.search("pool.coral.bak")
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    module, _, function = scripts[entry.split()[0]].partition(":")
    assert callable(getattr(importlib.import_module(module), function))
    # The entry's arguments (plus a file, as pre-commit adds them) parse as a command.
    from analysis.cli import build_parser

    args = build_parser().parse_args([*entry.split()[1:], "missions/pool.coral"])
    assert args.command == entry.split()[1]
