"""Small hostile inputs must cost little and fail cleanly (issue 17).

Each test feeds the front end something a red team used to exhaust memory or time, or
to crash it: huge garbage lines, YAML bombs, 5,000-digit numbers, FIFOs and devices as
files, includes reaching outside the mission's folder. Every one must end in an error
naming the file and position, fast, with bounded output and no traceback. Inputs are
sized so the old behaviour would be visibly slow or large, never so large that a test
allocates much itself.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import pytest

from analysis.cli import main
from coral_lang import diagnostics
from coral_lang.compiler import CompileResult, compile_file, compile_source
from coral_lang.diagnostics import (
    CoralError,
    Diagnostic,
    ProfileError,
    Severity,
    Span,
    render_all,
    source_line,
)
from coral_lang.lexer import MAX_LEXER_ERRORS
from coral_lang.parser import MAX_ERRORS, parse
from coral_lang.pnml import read_pnml
from coral_lang.profile import bundled_profile_path, load_bundled_profile, load_profile
from coral_lang.safefile import UnreadableFile, read_file_bytes, read_text_file
from coral_lang.yamlsource import MAX_YAML_CHARS, load_yaml
from runtime.linkprofile import LinkProfileError, parse_link_profile

HEADER = "mission m\nvehicle ROMEO\n"

BILLION_LAUGHS = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(8)
)
"""About 500 bytes that expand to 9^9 (387 million) strings if aliases are followed."""


def messages(result: CompileResult) -> list[str]:
    return [d.message for d in result.errors]


def rendered(result: CompileResult) -> str:
    return render_all(result.diagnostics, result.sources)


def run_with_timeout(function: object, seconds: float = 10.0) -> object:
    """Run ``function()`` in a daemon thread; fail (not hang) if it takes too long."""
    outcome: dict[str, object] = {}

    def target() -> None:
        try:
            outcome["value"] = function()  # type: ignore[operator]
        except BaseException as exc:  # re-raised below, in the test's thread
            outcome["error"] = exc

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"still running after {seconds} s: it hangs"
    if "error" in outcome:
        raise outcome["error"]  # type: ignore[misc]
    return outcome.get("value")


# -- 1. diagnostics render in linear time, bounded ---------------------------------------


def test_a_40_kb_garbage_line_renders_fast_and_bounded() -> None:
    text = HEADER + "@" * 40_000 + "\n"
    start = time.perf_counter()
    result = compile_source(text, "garbage.coral")
    output = rendered(result)
    assert time.perf_counter() - start < 1.0
    assert len(output) < 2_000
    assert "garbage.coral:3:1: error: unexpected characters '@@@@" in output
    assert "..." in output


def test_scattered_garbage_stops_after_a_bounded_number_of_errors() -> None:
    text = HEADER + "@ " * 20_000 + "\n" + "$\n" * 100_000
    start = time.perf_counter()
    result = compile_source(text, "garbage.coral")
    output = rendered(result)
    assert time.perf_counter() - start < 1.0
    assert MAX_LEXER_ERRORS <= len(result.errors) <= MAX_LEXER_ERRORS + 2
    assert "stopped reading the file here" in output
    assert len(output) < 40_000


def test_a_file_full_of_syntax_errors_stops_the_parser() -> None:
    _, found = parse(HEADER + "place 1\n" * 5_000, "bad.coral")
    assert len(found) == MAX_ERRORS + 1
    assert found[-1].message == f"{len(found) - 1} errors: stopped reading the file here"


def test_each_source_is_split_into_lines_once_however_many_diagnostics() -> None:
    text = "\n".join(f"line {i}" for i in range(100_000))
    spans = [Span("big.coral", 1 + i * 97, 1, 1 + i * 97, 5) for i in range(1_000)]
    found = [Diagnostic(Severity.ERROR, "CORAL001", "x", span) for span in spans]
    diagnostics._line_starts.cache_clear()
    start = time.perf_counter()
    for diagnostic in found:  # one at a time, as the terminal renderer does
        assert f"line {diagnostic.span.line - 1}" in diagnostic.render({"big.coral": text})  # type: ignore[union-attr]
    assert time.perf_counter() - start < 1.0
    assert diagnostics._line_starts.cache_info().misses == 1


def test_render_all_caps_diagnostics_per_file() -> None:
    text = "x\n" * 500
    found = [
        Diagnostic(Severity.ERROR, "CORAL001", "bad", Span(file, i, 1, i, 2))
        for file in ("a.coral", "b.coral")
        for i in range(1, 251)
    ]
    output = render_all(found, {"a.coral": text, "b.coral": text})
    assert output.count("error: bad") == 200
    assert output.endswith(
        "... and 150 more diagnostics in a.coral\n\n... and 150 more diagnostics in b.coral"
    )


def test_a_long_line_is_shown_as_a_window_around_the_column() -> None:
    line = "a" * 20_000 + "XYZ" + "b" * 20_000
    span = Span("f", 1, 20_001, 1, 20_004)
    lines = Diagnostic(Severity.ERROR, "C", "m", span).render({"f": line}).splitlines()
    shown, caret = lines[2], lines[3]
    assert len(shown) < 140 and shown.count("...") == 2
    column = caret.index("^")
    assert shown[column : column + 3] == "XYZ" and caret.endswith("^~~")


@pytest.mark.parametrize("separator", ["\u2028", "\x0c", "\x1c", "\x85", "\r"])
def test_excerpts_count_lines_as_the_lexer_does(separator: str) -> None:
    text = HEADER + f"# note{separator}more\nplace x = @\n"
    result = compile_source(text, "m.coral")
    [error] = result.errors
    assert str(error.span) == "m.coral:4:11"
    assert " 4 | place x = @\n" in rendered(result)
    assert source_line(text, 4) == "place x = @"


def test_control_characters_are_not_echoed_to_the_terminal() -> None:
    result = compile_source(HEADER + "place x = \x1b[31m\n", "m.coral")
    assert "\x1b" not in rendered(result)


# -- 2. YAML: no aliases, no foreign tags, bounded ----------------------------------------


def test_a_billion_laughs_profile_is_refused_fast(tmp_path: Path) -> None:
    path = tmp_path / "bomb.yaml"
    path.write_text(BILLION_LAUGHS, encoding="utf-8")
    start = time.perf_counter()
    with pytest.raises(ProfileError, match=r"bomb\.yaml:1:4: .*anchors \(&a\) are not supported"):
        load_profile(path)
    assert time.perf_counter() - start < 1.0


def test_an_alias_alone_and_a_recursive_alias_are_refused() -> None:
    with pytest.raises(ProfileError, match=r"p\.yaml:1:4: .*anchors \(&x\)"):
        load_yaml("a: &x [*x]\n", "p.yaml")
    with pytest.raises(ProfileError, match=r"p\.yaml:1:4: .*aliases \(\*x\)"):
        load_yaml("a: *x\n", "p.yaml")  # no anchor: libyaml reports the alias itself


@pytest.mark.parametrize(
    ("text", "shown"),
    [
        ("a: !!python/name:os.system x\n", "!!python/name:os.system"),
        ("a: !!python/object/apply:os.system [ls]\n", "!!python/object/apply:os.system"),
        ("a: !float 3\n", "!float"),
        ("a: !!binary aGk=\n", "!!binary"),
    ],
)
def test_tags_other_than_the_standard_ones_are_refused(text: str, shown: str) -> None:
    with pytest.raises(ProfileError) as caught:
        load_yaml(text, "p.yaml")
    assert str(caught.value).startswith("p.yaml:1:4: ")
    assert f"tag '{shown}' is not supported" in str(caught.value)


def test_standard_tags_still_work() -> None:
    assert load_yaml("a: !!str 3\nb: !!int 4\nc: !!float 1\n", "p.yaml").data == {
        "a": "3",
        "b": 4,
        "c": 1.0,
    }


def test_deep_nesting_is_refused_without_recursion() -> None:
    # PyYAML 6.0.4 scans flow collections ahead and stops at 1,000 levels itself, before
    # the loader's own limit is reached; either way the file and position are named.
    deep = (
        r"p\.yaml:1:101: nested deeper than 100 levels"
        r"|p\.yaml:1:1001: not valid YAML: exceeded maximum nesting depth"
    )
    with pytest.raises(ProfileError, match=deep):
        load_yaml("[" * 5_000 + "]" * 5_000, "p.yaml")
    with pytest.raises(ProfileError, match="nested deeper"):
        load_yaml("a:\n" + "".join(f"{' ' * i}- \n" for i in range(1, 200)), "p.yaml")


def test_an_impossible_date_is_an_error_not_a_traceback() -> None:
    with pytest.raises(ProfileError, match=r"p\.yaml:2:7: when: cannot read value '2001-13-45'"):
        load_yaml("a: 1\nwhen: 2001-13-45\n", "p.yaml")


def test_a_too_large_yaml_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ProfileError, match="too large"):
        load_yaml("#" * (MAX_YAML_CHARS + 1), "p.yaml")
    path = tmp_path / "big.yaml"
    path.write_bytes(b"#" * (1024 * 1024 + 1))
    with pytest.raises(ProfileError, match=r"big\.yaml: cannot read profile: too large"):
        load_profile(path)


def test_link_profiles_share_the_yaml_limits() -> None:
    with pytest.raises(LinkProfileError, match=r"link\.yaml:1:4: .*anchors"):
        parse_link_profile(BILLION_LAUGHS, "link.yaml")


# -- 3. numbers too long or too large ------------------------------------------------------


def test_a_5000_digit_integer_is_an_error_at_its_token() -> None:
    result = compile_source(HEADER + "place a = " + "9" * 5_000 + "\n", "n.coral")
    [error] = result.errors
    assert (str(error.span), error.code) == ("n.coral:3:11", "CORAL001")
    assert error.message == "number too long (5000 characters; at most 40)"
    assert len(rendered(result)) < 1_000


@pytest.mark.parametrize(
    ("source", "message"),
    [
        ("place a = 9223372036854775808\n", "number too large: 9223372036854775808"),
        ("const z = 1e400\n", "number out of range: 1e400"),
        ("place a\nassert bound a <= 99999999999999999999\n", "number too large"),
    ],
)
def test_numbers_out_of_range_are_errors(source: str, message: str) -> None:
    result = compile_source(HEADER + source, "n.coral")
    assert any(m.startswith(message) for m in messages(result)), messages(result)


def test_the_largest_whole_number_is_accepted() -> None:
    result = compile_source(HEADER + "place a = 9223372036854775807\n", "n.coral")
    assert not any("number" in m for m in messages(result))


def test_a_unit_conversion_overflowing_to_infinity_is_refused() -> None:
    source = HEADER + "place a, b, c\ntransition t wait { a } action { ROMEO(DEPTH, z = "
    result = compile_source(source + "1.7e308 km) -> { ack: b, error: c } }\n", "n.coral")
    assert any("out of range" in m for m in messages(result)), messages(result)


def test_huge_integers_in_yaml_are_errors() -> None:
    with pytest.raises(ProfileError, match=r"p\.yaml:1:4: a: number too long"):
        load_yaml("a: " + "9" * 5_000 + "\n", "p.yaml")
    with pytest.raises(ProfileError, match=r"p\.yaml:1:4: a: number too large"):
        load_yaml("a: 9223372036854775808\n", "p.yaml")
    with pytest.raises(ProfileError, match=r"number out of range"):
        load_yaml("a: 1.0e+400\n", "p.yaml")


# -- 4. files: regular only, capped, includes stay in the folder --------------------------


def write_mission(folder: Path, body: str, name: str = "m.coral") -> Path:
    path = folder / name
    path.write_text(HEADER + body, encoding="utf-8")
    return path


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_a_fifo_include_is_refused_without_hanging(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe.coral")
    mission = write_mission(tmp_path, 'include "pipe.coral"\n')
    result = run_with_timeout(lambda: compile_file(mission))
    assert isinstance(result, CompileResult)
    assert any("not a regular file (a FIFO)" in m for m in messages(result)), messages(result)
    assert str(result.errors[0].span).endswith("m.coral:3:1")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_a_fifo_as_the_mission_is_refused_without_hanging(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe.coral")
    result = run_with_timeout(lambda: compile_file(tmp_path / "pipe.coral"))
    assert isinstance(result, CompileResult)
    assert any("not a regular file (a FIFO)" in m for m in messages(result))


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="needs /dev/zero")
@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
def test_devices_are_refused_unread(device: str) -> None:
    with pytest.raises(UnreadableFile, match="not a regular file \\(a character device\\)"):
        run_with_timeout(lambda: read_text_file(device, 1024))
    result = run_with_timeout(lambda: compile_file(device))
    assert isinstance(result, CompileResult)
    assert any("not a regular file" in m for m in messages(result))


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="needs /dev/zero")
def test_a_symlink_to_a_device_inside_the_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "zero.coral").symlink_to("/dev/zero")
    result = compile_file(write_mission(tmp_path, 'include "zero.coral"\n'))
    assert any("outside the mission's folder" in m for m in messages(result))


def test_reading_stops_at_the_cap(tmp_path: Path) -> None:
    path = tmp_path / "big.coral"
    path.write_bytes(b"#" * 1_001)
    with pytest.raises(UnreadableFile, match=r"too large \(more than 1,000 bytes\)"):
        read_text_file(path, 1_000)
    assert read_text_file(path, 1_001) == "#" * 1_001


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
def test_a_file_claiming_to_be_empty_is_still_capped() -> None:
    assert os.stat("/proc/self/status").st_size == 0  # it lies: there are KBs in it
    with pytest.raises(UnreadableFile, match="too large"):
        read_file_bytes("/proc/self/status", 10)


def test_a_mission_too_large_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "big.coral"
    with path.open("wb") as f:
        f.truncate(4 * 1024 * 1024 + 1)  # sparse: nothing is written, nothing read
    result = compile_file(path)
    assert any("too large" in m for m in messages(result)), messages(result)


def test_binary_and_non_utf8_files_are_refused(tmp_path: Path) -> None:
    (tmp_path / "bin.coral").write_bytes(b"mission m\0\n")
    (tmp_path / "latin.coral").write_bytes(b"mission caf\xe9\n")
    with pytest.raises(UnreadableFile, match="NUL characters"):
        read_text_file(tmp_path / "bin.coral", 100)
    with pytest.raises(UnreadableFile, match="not UTF-8 text"):
        read_text_file(tmp_path / "latin.coral", 100)


def test_an_include_with_a_nul_character_is_an_error() -> None:
    result = compile_source(HEADER + 'include "a\0b.coral"\n', "m.coral")
    [error] = result.errors
    assert error.code == "CORAL004" and "NUL character" in error.message
    assert "\0" not in rendered(result)


def test_an_include_symlink_loop_is_an_error(tmp_path: Path) -> None:
    (tmp_path / "loop.coral").symlink_to("loop.coral")
    (tmp_path / "ping.coral").symlink_to("pong.coral")
    (tmp_path / "pong.coral").symlink_to("ping.coral")
    result = compile_file(write_mission(tmp_path, 'include "loop.coral"\ninclude "ping.coral"\n'))
    assert [e.code for e in result.errors] == ["CORAL004", "CORAL004"]
    assert all("cannot include" in m or "symbolic links" in m for m in messages(result))


def test_an_include_outside_the_mission_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "outside.coral").write_text("place secret\n", encoding="utf-8")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "inner.coral").write_text("place inner\n", encoding="utf-8")
    mission = write_mission(
        tmp_path / "sub",
        f'include "../outside.coral"\ninclude "{tmp_path / "outside.coral"}"\n'
        'include "inner.coral"\ninclude "./../sub/inner.coral"\n',
    )
    result = compile_file(mission)
    refused = [e for e in result.errors if "outside the mission's folder" in e.message]
    assert [str(e.span) for e in refused] == [f"{mission}:3:1", f"{mission}:4:1"]
    assert not any("secret" in text for text in result.sources.values())
    assert any(file.endswith("inner.coral") for file in result.sources)
    # An explicit include root lets a mission reach further, as library code may ask.
    wider = compile_file(mission, include_root=tmp_path)
    assert not any("outside" in m for m in messages(wider)), messages(wider)
    assert any("secret" in text for text in wider.sources.values())


@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs /proc")
def test_proc_self_environ_is_never_read_or_quoted(tmp_path: Path) -> None:
    entries = [e for e in Path("/proc/self/environ").read_bytes().split(b"\0") if len(e) > 6]
    secrets = [e.decode("utf-8", "replace") for e in entries]
    mission = write_mission(tmp_path, 'include "/proc/self/environ"\n')
    results = [compile_file(mission), compile_file("/proc/self/environ")]
    for result in results:
        output = rendered(result)
        assert any(e.code == "CORAL004" for e in result.errors)
        assert not any(secret in output for secret in secrets)
        assert "/proc/self/environ" not in result.sources
    assert "outside the mission's folder" in messages(results[0])[0]
    assert "NUL characters" in messages(results[1])[0]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_pnml_and_profiles_refuse_special_files(tmp_path: Path) -> None:
    from coral_lang.diagnostics import PnmlError

    os.mkfifo(tmp_path / "net.pnml")
    os.mkfifo(tmp_path / "p.yaml")
    with pytest.raises(PnmlError, match=r"net\.pnml: cannot read: not a regular file"):
        run_with_timeout(lambda: read_pnml(tmp_path / "net.pnml"))
    with pytest.raises(ProfileError, match="cannot read profile: not a regular file"):
        run_with_timeout(lambda: load_profile(tmp_path / "p.yaml"))


# -- 5. a very long vehicle name ------------------------------------------------------------


@pytest.mark.parametrize("name", ["A" * 300, "../romeo", "a/b", ".."])
def test_odd_vehicle_names_find_no_bundled_profile(name: str) -> None:
    assert bundled_profile_path(name) is None
    with pytest.raises(ProfileError, match="no bundled profile"):
        load_bundled_profile(name)


def test_a_300_character_vehicle_name_is_a_compile_error() -> None:
    result = compile_source(f"mission m\nvehicle {'V' * 300}\nplace a = 1\n", "m.coral")
    [error] = result.errors
    assert error.code == "CORAL006" and str(error.span) == "m.coral:2:1"


# -- through the CLI: exit codes, no traceback ---------------------------------------------


def test_cli_refuses_a_yaml_bomb_profile_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    profile = tmp_path / "bomb.yaml"
    profile.write_text(BILLION_LAUGHS, encoding="utf-8")
    mission = write_mission(tmp_path, "place a = 1\nfinal { a }\n")
    assert main(["lint", "--profile", str(profile), str(mission)]) == 2
    err = capsys.readouterr().err
    assert f"{profile}:1:4" in err and "anchors" in err and "Traceback" not in err


def test_cli_refuses_a_python_tag_profile_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    profile = tmp_path / "evil.yaml"
    profile.write_text("vehicle: !!python/name:os.system X\ncommands: {}\n", encoding="utf-8")
    mission = write_mission(tmp_path, "place a = 1\nfinal { a }\n")
    assert main(["lint", "--profile", str(profile), str(mission)]) == 2
    err = capsys.readouterr().err
    assert "evil.yaml:1:10" in err and "!!python/name:os.system" in err
    assert "Traceback" not in err


def test_cli_reports_hostile_missions_as_errors_without_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    garbage = tmp_path / "garbage.coral"
    garbage.write_text(HEADER + "@" * 40_000 + "\nplace a = " + "9" * 5_000 + "\n")
    outside = write_mission(tmp_path, 'include "/proc/self/environ"\n', "outside.coral")
    # Errors in a mission are exit 1 by coral-check's contract (docs/verify.md).
    assert main(["lint", str(garbage), str(outside)]) == 1
    captured = capsys.readouterr()
    text = captured.out + captured.err
    assert "Traceback" not in text and len(text) < 5_000
    assert "garbage.coral:4:11: error: number too long" in text
    assert "outside the mission's folder" in text


# --------------------------------------------------------------------------- the CLI's own read


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_coral_check_refuses_a_special_file_as_input_without_reading_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str
) -> None:
    """A FIFO as the mission file hung, ``/dev/zero`` ran out of memory."""
    if kind == "fifo":
        path = tmp_path / "mission.coral"
        os.mkfifo(path)
    else:
        path = Path("/dev/zero")
    done: list[int] = []
    worker = threading.Thread(target=lambda: done.append(main([str(path)])), daemon=True)
    worker.start()
    worker.join(timeout=10)
    assert done == [2], "coral-check hung or did not refuse the file"
    assert "not a regular file" in capsys.readouterr().err


def test_a_pnml_count_beyond_64_bits_is_an_error_at_its_position(tmp_path: Path) -> None:
    path = tmp_path / "big.pnml"
    path.write_text(
        '<?xml version="1.0"?>\n<pnml xmlns="http://www.pnml.org/version-2009/grammar/pnml">'
        '<net id="n" type="http://www.pnml.org/version-2009/grammar/ptnet"><page id="g">'
        '<place id="p"><initialMarking><text>' + "9" * 5000 + "</text></initialMarking>"
        "</place></page></net></pnml>\n"
    )
    with pytest.raises(CoralError, match=r"big\.pnml:2:\d+: .*not an integer below 2\*\*63"):
        read_pnml(path)


def test_a_link_profile_must_be_a_regular_file(tmp_path: Path) -> None:
    from runtime.linkprofile import load_link_profile

    fifo = tmp_path / "link.yaml"
    os.mkfifo(fifo)
    with pytest.raises(LinkProfileError, match="not a regular file"):
        load_link_profile(fifo)
