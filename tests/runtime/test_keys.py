"""The pre-shared key (runtime/keys.py): a key file others can read, and a placeholder key,
are refused with a message that says what to do; a well-made key file is read."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from runtime.keys import KEY_HINT, KeyProblem, load_psk, write_key_file
from runtime.vehicle.cli import main as vehicle_main

GOOD = bytes(range(1, 33))

posix_only = pytest.mark.skipif(os.name != "posix", reason="file modes are POSIX")


def _key_file(folder: Path, mode: int, key: bytes = GOOD) -> Path:
    path = folder / "psk.hex"
    path.write_text(key.hex() + "\n")
    path.chmod(mode)
    return path


@posix_only
@pytest.mark.parametrize("mode", [0o666, 0o644, 0o640, 0o604, 0o620, 0o602, 0o610, 0o601])
def test_a_key_file_group_or_others_may_touch_is_refused(tmp_path: Path, mode: int) -> None:
    path = _key_file(tmp_path, mode)
    with pytest.raises(KeyProblem) as refused:
        load_psk(path, None)
    message = str(refused.value)
    assert str(path) in message and f"chmod 600 {path}" in message
    assert f"{mode:04o}" in message


@posix_only
@settings(max_examples=60, deadline=None)
@given(mode=st.integers(0o400, 0o777))
def test_only_the_owner_bits_decide(tmp_path_factory: pytest.TempPathFactory, mode: int) -> None:
    """Any mode the owner can read: accepted exactly when no group or other bit is set."""
    path = _key_file(tmp_path_factory.mktemp("mode"), mode | stat.S_IRUSR)
    try:
        key = load_psk(path, None)
    except KeyProblem as exc:
        assert mode & 0o077, exc
        assert "chmod 600" in str(exc)
    else:
        assert not mode & 0o077 and key == GOOD


@settings(max_examples=50, deadline=None)
@given(value=st.integers(0, 255), size=st.integers(16, 64))
def test_a_key_of_one_repeated_byte_is_refused(value: int, size: int) -> None:
    with pytest.raises(KeyProblem) as refused:
        load_psk(None, (bytes([value]) * size).hex())
    assert f"all {size} bytes are {value:02x}" in str(refused.value)


def test_degenerate_keys_are_refused_from_the_command_line_and_from_a_file(
    tmp_path: Path,
) -> None:
    with pytest.raises(KeyProblem) as refused:
        load_psk(None, "00" * 16)
    message = str(refused.value)
    assert "--key-hex is degenerate" in message and "all 16 bytes are 00" in message
    assert KEY_HINT in message and "umask 077" in message
    path = _key_file(tmp_path, 0o600, b"\xff" * 32)
    with pytest.raises(KeyProblem, match=r"psk\.hex is degenerate \(all 32 bytes are ff\)"):
        load_psk(path, None)


@settings(max_examples=50, deadline=None)
@given(key=st.binary(min_size=16, max_size=64).filter(lambda k: len(set(k)) > 1))
def test_any_other_key_of_16_bytes_or_more_is_read(key: bytes) -> None:
    assert load_psk(None, key.hex()) == key


def test_write_key_file_makes_a_private_file_that_load_psk_reads(tmp_path: Path) -> None:
    path = tmp_path / "psk.hex"
    write_key_file(path, GOOD)
    if os.name == "posix":
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert load_psk(path, None) == GOOD
    with pytest.raises(FileExistsError):
        write_key_file(path, GOOD)  # never over an existing key


@posix_only
def test_a_key_readable_through_a_symlink_is_judged_by_its_target(tmp_path: Path) -> None:
    target = _key_file(tmp_path, 0o644)
    link = tmp_path / "link.hex"
    link.symlink_to(target)
    with pytest.raises(KeyProblem, match="chmod 600"):
        load_psk(link, None)
    target.chmod(0o600)
    assert load_psk(link, None) == GOOD


@posix_only
def test_coral_vehicle_refuses_an_open_key_file_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _key_file(tmp_path, 0o666)
    code = vehicle_main(["serve", "--vehicle", "ROMEO", "--key-file", str(path)])
    err = capsys.readouterr().err
    assert code == 2
    assert f"chmod 600 {path}" in err and "Traceback" not in err


def test_key_hex_help_says_prefer_key_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert vehicle_main(["serve", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "process list: prefer --key-file" in out
