"""coral-check's configuration file: where it is found, what it may say, how the command
line overrides it, and how a bad one is refused (exit 2, file, key, line and column)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from analysis.cli import main
from analysis.config import (
    KEYS,
    Config,
    ConfigError,
    find_config,
    load_config,
    resolve_config,
)
from tests.conftest import EXAMPLES

DEAD = str(EXAMPLES / "faulty" / "dead_transition.coral")


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


# -- finding it -------------------------------------------------------------------------


def test_the_nearest_folder_wins_and_coral_toml_beats_pyproject(tmp_path: Path) -> None:
    deep = tmp_path / "a" / "b" / "c"
    deep.mkdir(parents=True)
    assert find_config(deep) is None or not find_config(deep).is_relative_to(tmp_path)  # type: ignore[union-attr]
    top = _write(tmp_path / "coral.toml", "por = true\n")
    assert find_config(deep) == top
    middle = _write(tmp_path / "a" / "pyproject.toml", "[tool.coral]\nmax-states = 7\n")
    assert find_config(deep) == middle
    _write(tmp_path / "a" / "b" / "pyproject.toml", "[project]\nname = 'x'\n")
    assert find_config(deep) == middle  # no [tool.coral]: not a coral configuration
    beside = _write(tmp_path / "a" / "coral.toml", "max-states = 9\n")
    assert find_config(deep) == beside


def test_explicit_and_disabled(tmp_path: Path) -> None:
    _write(tmp_path / "coral.toml", "max-states = 5\n")
    other = _write(tmp_path / "other.toml", "max-states = 6\n")
    assert resolve_config(None, disabled=False, cwd=tmp_path).max_states == 5
    assert resolve_config(other, disabled=False, cwd=tmp_path).max_states == 6
    assert resolve_config(None, disabled=True, cwd=tmp_path) == Config()
    with pytest.raises(ConfigError, match=r"--config .*missing\.toml: no such file"):
        resolve_config(tmp_path / "missing.toml", disabled=False, cwd=tmp_path)


# -- reading it -------------------------------------------------------------------------


def test_every_key_is_read_and_paths_are_relative_to_the_file(tmp_path: Path) -> None:
    (tmp_path / "lib").mkdir()
    config = load_config(
        _write(
            tmp_path / "coral.toml",
            'select = ["CORAL2"]\nignore = ["coral207"]\nprofile = ["p.yaml"]\n'
            'include-path = ["lib"]\nlink-rtt = 3\nmax-states = 10\ntime-limit = 1.5\n'
            "max-edges = 20\nmax-deadlocks = 2\npor = true\n",
        )
    )
    assert config == Config(
        path=tmp_path / "coral.toml",
        select=("CORAL2",),
        ignore=("CORAL207",),
        profile=(tmp_path / "p.yaml",),
        include_path=(tmp_path / "lib",),
        link_rtt=3.0,
        max_states=10,
        time_limit=1.5,
        max_edges=20,
        max_deadlocks=2,
        por=True,
    )
    assert set(KEYS) == {k.replace("_", "-") for k in vars(config) if k != "path"}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("colour = 1\n", "unknown key 'colour'; known keys: select, ignore"),
        ("max_states = 1\n", "unknown key 'max_states' (keys use dashes)"),
        ("max-states = 0\n", "max-states: must be at least 1, got 0"),
        ("max-states = 1.5\n", "max-states: expected a whole number, got 1.5"),
        ("max-states = true\n", "max-states: expected a whole number, got a boolean"),
        ("time-limit = 0\n", "time-limit: must be more than 0"),
        ("link-rtt = -1\n", "link-rtt: must be 0 or more"),
        ("time-limit = nan\n", "time-limit: expected a number"),
        ('por = "yes"\n', "por: expected true or false, got a string ('yes')"),
        ('select = "CORAL2"\n', "select: expected a list of strings, got a string"),
        ('ignore = ["CORAL2O4"]\n', "ignore: unknown rule code CORAL2O4"),
        ('ignore = ["CORAL001"]\n', "ignore: CORAL001: compile errors cannot be selected"),
        ('select = ["CORAL0"]\n', "select: CORAL0: compile errors cannot be selected"),
        ('include-path = ["nowhere"]\n', "include-path: "),
        ("max-states = \n", "invalid TOML: Invalid value (at line 1, column 14)"),
        (
            "por = true\npor = false\n",
            "invalid TOML: Cannot overwrite a value (at line 2, column 12)",
        ),
    ],
)
def test_a_bad_config_names_the_file_the_key_and_the_place(
    tmp_path: Path, text: str, message: str
) -> None:
    path = _write(tmp_path / "coral.toml", text)
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert str(caught.value).startswith(f"{path}: ")
    assert message in str(caught.value)


def test_pyproject_keys_are_named_with_their_table(tmp_path: Path) -> None:
    path = _write(tmp_path / "pyproject.toml", "[tool.coral]\nfoo = 1\n")
    with pytest.raises(ConfigError, match=r"unknown key 'tool\.coral\.foo'"):
        load_config(path)
    _write(tmp_path / "pyproject.toml", "[tool]\ncoral = 3\n")
    with pytest.raises(ConfigError, match=r"\[tool\.coral\] must be a table"):
        load_config(path)


@given(
    st.dictionaries(st.sampled_from(["max-states", "max-edges", "max-deadlocks"]), st.integers())
)
def test_counts_are_accepted_exactly_when_at_least_1(values: dict[str, int]) -> None:
    from analysis.config import _parse

    if all(v >= 1 for v in values.values()):
        config = _parse(Path("coral.toml"), values, "")
        assert all(getattr(config, k.replace("-", "_")) == v for k, v in values.items())
    else:
        with pytest.raises(ConfigError, match="must be at least 1"):
            _parse(Path("coral.toml"), values, "")


# -- through the command line -----------------------------------------------------------


def _lint_codes(capsys: pytest.CaptureFixture[str], *argv: str) -> set[str]:
    assert main(["lint", "--format", "json", DEAD, *argv]) == 0
    data = json.loads(capsys.readouterr().out)
    return {d["code"] for d in data["files"][0]["diagnostics"]}


def test_the_file_sets_defaults_and_the_command_line_overrides_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    assert _lint_codes(capsys) == {"CORAL204", "CORAL205"}
    _write(tmp_path / "pyproject.toml", '[tool.coral]\nignore = ["CORAL204"]\n')
    assert _lint_codes(capsys) == {"CORAL205"}
    assert _lint_codes(capsys, "--ignore", "CORAL205") == {"CORAL204"}  # replaces the file's
    assert _lint_codes(capsys, "--no-config") == {"CORAL204", "CORAL205"}
    _write(tmp_path / "coral.toml", 'select = ["CORAL204"]\n')  # beside pyproject: wins
    assert _lint_codes(capsys) == {"CORAL204"}
    other = _write(tmp_path / "elsewhere" / "x.toml", 'ignore = ["CORAL2"]\n')
    assert _lint_codes(capsys, "--config", str(other)) == set()


def test_budgets_from_the_file_reach_the_verifier(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    chain = _write(
        tmp_path / "chain.coral",
        "mission chain\nvehicle ROMEO\nplace p0 = 1, p1, p2, p3, p4, p5\nfinal { p5 }\n"
        + "".join(f"transition t{i} wait {{ p{i} }} signal {{ p{i + 1} }}\n" for i in range(5)),
    )
    monkeypatch.chdir(tmp_path)
    _write(tmp_path / "coral.toml", "max-states = 2\n")
    assert main([str(chain), "--no-structure"]) == 3  # the file's budget: inconclusive
    assert main([str(chain), "--no-structure", "--max-states", "100"]) == 0
    capsys.readouterr()


def test_a_bad_config_file_is_exit_2_naming_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    path = _write(tmp_path / "coral.toml", "max-states = [\n")
    for argv in (["lint", DEAD], [DEAD], ["verify", DEAD], ["export", DEAD, "--dot", "-"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"coral-check: error: {path}: invalid TOML: ") and "line 2" in err
    assert main(["lint", DEAD, "--no-config"]) == 0
    capsys.readouterr()
    assert main(["lint", DEAD, "--config", str(tmp_path)]) == 2
    assert "it is a directory" in capsys.readouterr().err


def test_profile_paths_in_the_file_are_relative_to_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _write(tmp_path / "cfg" / "bad.yaml", "vehicle: ROMEO\ncommands: {DEPTH: {kind: taks}}\n")
    _write(tmp_path / "cfg" / "coral.toml", 'profile = ["bad.yaml"]\n')
    monkeypatch.chdir(tmp_path / "cfg")
    assert main(["lint", DEAD]) == 2
    assert "bad.yaml" in capsys.readouterr().err
