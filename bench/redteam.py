"""Red-team campaign: hostile inputs of every class through the real entry points.

Run: ``.venv/bin/python bench/redteam.py [--seed S] [--per-class N] [--classes C ...]
[--workers W] [--out DIR]``.

Why: the trust issue's rule is that bad input gets a clear message naming the file and
exit 2, never a traceback, never exit 1 (which means "violated" or "mission failed"),
never a hang or unbounded memory. Unit tests pin the cases someone thought of; this
bench throws thousands of mutants of the real files at the real command lines and counts
what comes back, so the figure covers the cases nobody thought of.

Classes (seeds are the repository's own files, made fresh under ``--out``):

* ``mission``: CORAL text (``examples/``, ``tests/analysis/data``) through ``coral-check``.
* ``profile``: vehicle profiles (YAML) through ``coral-check lint --profile``.
* ``pnml``: PNML nets (``tests/data/mcc``) through ``coral-check verify``.
* ``query``: MCC query files (XML) through ``coral-check query``.
* ``certificate``: a certificate signed with a key from ``coral-check keygen``, through
  ``coral-run --certificate --trusted-keys``; also verdicts edited under the signature,
  and modified certificates re-signed with an untrusted key. Any modified certificate
  that a run accepts is a failure (a forgery).
* ``frames``: protocol frames fed to ``runtime.protocol.StreamCodec`` and
  ``DatagramReceiver``: garbage, flipped, cut, replayed and (signed with the key, as a
  buggy peer would) malformed frames. Must never raise, never accept an altered or
  replayed frame, never decode what the encoder would refuse.
* ``server``: hostile connections to a live ``coral-vehicle serve`` over TCP; after each,
  an honest controller must still complete the handshake, and the server must not log a
  traceback or die.
* ``log``: the controller log of a short ``coral-run`` of the pool mission (virtual time),
  with rows edited or deleted and pages overwritten, through ``coral-run --resume`` and
  ``coral-run timeline``.

File inputs run in a pool of long-lived worker processes (``--workers``) that call the
command lines' ``main([...])`` in-process with stdout and stderr captured, under an
address-space cap (``--mem-mib``) and a per-input time limit (``--timeout``); a worker is
replaced after a timeout or a crash, and every ``--recycle`` inputs. Outcomes:

* ``clean-error``: exit 2, no traceback, and the output names the input file (for
  ``mission``, also exit 1 with a ``FILE:LINE:COL: error`` diagnostic: coral-check's
  documented code for a mission with errors);
* ``accepted``: a legitimate verdict for an input that is still valid (0, 1 or 3 where
  the command documents them); never for a modified certificate;
* ``failure``: anything else. Each failure is listed with a reproducer under
  ``--out``/failures; the exit status is 1 when there is any.
"""

from __future__ import annotations

import argparse
import base64
import binascii
import contextlib
import gzip
import hashlib
import hmac
import io
import json
import os
import queue
import random
import re
import resource
import select
import shutil
import signal
import socket
import sqlite3
import statistics
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run as a script: make the project importable
    sys.path.insert(0, str(REPO))

CLASSES = ("mission", "profile", "pnml", "query", "certificate", "frames", "server", "log")
DEFAULT_PER_CLASS = 300
EXIT_USAGE = 2
DIAGNOSED_BY_EXIT_1 = ("mission", "pnml")
EXIT_1_DIAGNOSTIC = "exit 1 with a FILE:LINE:COL diagnostic"

# The small MCC nets: mutants of big ones cost seconds each and find nothing more.
PNML_SEEDS = (
    "Sudoku-PT-AN01",
    "SwimmingPool-PT-01",
    "Eratosthenes-PT-010",
    "TwoPhaseLocking-PT-nC00004vD",
    "PGCD-PT-D02N005",
    "Philosophers-PT-000005",
)
QUERY_EXAMS = ("ReachabilityCardinality", "CTLFireability", "LTLFireability", "UpperBounds")
SEARCH_BUDGET = ["--max-states", "20000", "--time-limit", "5"]


# ---------------------------------------------------------------------------- mutations

Mutator = Callable[[random.Random, bytes], bytes]

NON_ASCII_DIGITS = ("\u0663", "\uff13", "\u0967", "\u00b2", "\U0001d7d1")
ODD_TEXT = (
    "\u2028",
    "\u2029",
    "\x00",
    "\ufeff",
    "\u202e",
    "\ud800",
    "\U0010ffff",
    "e\u0301",
    "\x1b[31m",
    "\r",
    "\t",
    "\x85",
)
HUGE_NUMBERS = (
    "9" * 4400,
    "1" + "0" * 5000,
    str(2**63),
    str(-(2**63) - 1),
    str(2**64),
    "1e309",
    "-1e309",
    "1e-400",
    "nan",
    "inf",
    "0x7fffffffffffffff",
    "1_000_000",
    "00000000000000000001",
    "-0",
)
GRAMMAR_TOKENS = {
    "mission": (
        "transition t{n}\n",
        "wait { }",
        "signal { p{n} }",
        "action { ROMEO(DEPTH, z = 2.0 m) -> { ack: p{n} } }",
        "place q{n} = 1\n",
        "final { }\n",
        "assert never { }\n",
        "assert bound {p*99999999999999999999} <= 1\n",
        "const K = 1e400 m\n",
        'include "/dev/zero"\n',
        'include "/etc/passwd"\n',
        'include "pool_mission.coral"\n',
        'include "../../../../../../etc/hostname"\n',
        "priority -9223372036854775809\n",
        "capacity 0\n",
        "->",
        "{",
        "}",
        ",",
        "#",
        '"',
        "vehicle ROMEO\n",
        "mission m{n}\n",
        "require termination\n",
        "= 18446744073709551616",
    ),
    "profile": (
        "&a [*a]\n",
        "*undefined_alias",
        "!!python/object/apply:os.system ['true']\n",
        "!!binary AAAA",
        "!!float .nan",
        "? [a, b]\n  : c\n",
        "<<: *x\n",
        "---\n",
        "...\n",
        "%YAML 1.1\n",
        "- ",
        ": ",
        "{",
        "[",
        "'",
        '"',
        "\t",
        "duration_s: .inf\n",
        "min: 1e999\n",
        "kind: query\n",
        "replies: {}\n",
        "params: [{name: x, type: float, min: 5, max: 1}]\n",
    ),
    "xml": (
        '<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>',
        '<!DOCTYPE x [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">]>',
        "&e;",
        "&#0;",
        "&#xD800;",
        "<![CDATA[ ]]>",
        "<?xml-stylesheet href='x'?>",
        "<place id='p{n}'/>",
        "<transition id='t{n}'/>",
        "<arc id='a{n}' source='p{n}' target='t{n}'/>",
        "<initialMarking><text>-1</text></initialMarking>",
        "<inscription><text>99999999999999999999999</text></inscription>",
        "<property><id>x</id><formula><negation/></formula></property>",
        "<integer-constant>-5</integer-constant>",
        "<tokens-count><place>nope</place></tokens-count>",
        "<is-fireable><transition>nope</transition></is-fireable>",
        "</",
        "<",
        ">",
        "xmlns='urn:other'",
    ),
    "json": ("{", "}", "[", "]", ",", ":", '"', "null", "true", "NaN", "Infinity", "1e999"),
}
DEEP = {
    "mission": "{" * 60_000,
    "profile": "[" * 60_000,
    "xml": "<a>" * 30_000,
    "json": "[" * 60_000,
}
YAML_BOMB = (
    "a: &a [x, x, x, x, x, x, x, x, x]\n"
    "b: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
    "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]\n"
    "d: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
    "e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]\n"
    "f: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]\n"
    "g: &g [*f, *f, *f, *f, *f, *f, *f, *f, *f]\n"
    "h: &h [*g, *g, *g, *g, *g, *g, *g, *g, *g]\n"
)
XML_BOMB = (
    '<?xml version="1.0"?>\n<!DOCTYPE lolz [\n <!ENTITY lol "lol">\n'
    + "".join(
        f' <!ENTITY lol{i} "{("&lol" + (str(i - 1) if i > 1 else "") + ";") * 10}">\n'
        for i in range(1, 10)
    )
    + "]>\n<pnml>&lol9;</pnml>\n"
)


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


def flip_bytes(rng: random.Random, data: bytes) -> bytes:
    """Flip one bit in each of 1 to 6 random bytes."""
    if not data:
        return bytes([rng.randrange(256)])
    out = bytearray(data)
    for _ in range(rng.randint(1, 6)):
        i = rng.randrange(len(out))
        out[i] ^= 1 << rng.randrange(8)
    return bytes(out)


def truncate(rng: random.Random, data: bytes) -> bytes:
    """Cut the input at a random byte (a copy interrupted half-way)."""
    return data[: rng.randrange(len(data) + 1)]


def duplicate_line(rng: random.Random, data: bytes) -> bytes:
    lines = _lines(data)
    i = rng.randrange(len(lines))
    lines.insert(rng.randrange(len(lines) + 1), lines[i])
    return b"".join(lines)


def delete_lines(rng: random.Random, data: bytes) -> bytes:
    lines = _lines(data)
    i = rng.randrange(len(lines))
    del lines[i : i + rng.randint(1, 3)]
    return b"".join(lines)


def swap_lines(rng: random.Random, data: bytes) -> bytes:
    lines = _lines(data)
    i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
    lines[i], lines[j] = lines[j], lines[i]
    return b"".join(lines)


def _insert(rng: random.Random, data: bytes, text: bytes) -> bytes:
    at = rng.randrange(len(data) + 1)
    return data[:at] + text + data[at:]


def token_inserter(grammar: str) -> Mutator:
    """Insert a token of the input's own grammar somewhere: text that parses further."""

    def mutate(rng: random.Random, data: bytes) -> bytes:
        token = rng.choice(GRAMMAR_TOKENS[grammar]).replace("{n}", str(rng.randrange(100)))
        return _insert(rng, data, token.encode("utf-8"))

    mutate.__name__ = f"insert_{grammar}_token"
    return mutate


def huge_number(rng: random.Random, data: bytes) -> bytes:
    """Replace a number with one of 4,400 digits, 2**63, 1e309, nan..."""
    numbers = list(re.finditer(rb"\d+(\.\d+)?", data))
    value = rng.choice(HUGE_NUMBERS).encode()
    if not numbers:
        return _insert(rng, data, value)
    m = rng.choice(numbers)
    return data[: m.start()] + value + data[m.end() :]


def deep_nesting(grammar: str) -> Mutator:
    def mutate(rng: random.Random, data: bytes) -> bytes:
        return _insert(rng, data, DEEP[grammar].encode())

    mutate.__name__ = "deep_nesting"
    return mutate


def odd_unicode(rng: random.Random, data: bytes) -> bytes:
    """U+2028, NUL, a lone surrogate (as invalid UTF-8), non-ASCII digits, a BOM..."""
    choice = rng.randrange(3)
    if choice == 0:
        digits = list(re.finditer(rb"[0-9]", data))
        if digits:
            m = rng.choice(digits)
            digit = rng.choice(NON_ASCII_DIGITS).encode("utf-8")
            return data[: m.start()] + digit + data[m.end() :]
    if choice == 1:
        raw = rng.choice([b"\xff", b"\xc0\xaf", b"\xed\xa0\x80", b"\xe2\x82", b"\xf4\x90\x80\x80"])
        return _insert(rng, data, raw)
    text = rng.choice(ODD_TEXT).encode("utf-8", "surrogatepass")
    return _insert(rng, data, text)


def yaml_specials(rng: random.Random, data: bytes) -> bytes:
    """Alias bombs, python tags, merge keys and duplicate keys in a YAML file."""
    choice = rng.randrange(4)
    if choice == 0:
        return YAML_BOMB.encode() + data
    if choice == 1:
        lines = _lines(data)
        keyed = [i for i, line in enumerate(lines) if re.match(rb"^\s*[\w?]+:", line)]
        if keyed:  # a duplicate key
            i = rng.choice(keyed)
            lines.insert(i + 1, lines[i])
            return b"".join(lines)
    if choice == 2:
        return re.sub(rb": ", b": !!python/name:os.system ", data, count=1)
    return data.replace(b"vehicle:", b"vehicle: &v", 1) + b"\nextra: *v\n"


def xml_specials(rng: random.Random, data: bytes) -> bytes:
    """An entity bomb, an external entity, a DOCTYPE, an encoding lie."""
    choice = rng.randrange(4)
    body = re.sub(rb"^<\?xml[^>]*\?>\s*", b"", data)
    if choice == 0:
        return XML_BOMB.encode()
    if choice == 1:
        doctype = b'<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n'
        return b'<?xml version="1.0"?>\n' + doctype + body.replace(b"<text>", b"<text>&e;", 1)
    if choice == 2:
        return b'<?xml version="1.0" encoding="UTF-16"?>\n' + body
    return b'<?xml version="1.0" encoding="ebcdic-cp-us"?>\n' + body


HUGE_MARK = "__redteam_huge_number__"
"""Stands for a 4,400-digit number in a value `_dump` writes (Python's json refuses to
write an int past 4,300 digits)."""


def _dump(value: Any, *, indent: int | None = 2) -> bytes:
    text = json.dumps(value, indent=indent, default=str)
    return text.replace(f'"{HUGE_MARK}"', "9" * 4400).encode()


def _json_swap(rng: random.Random, value: Any) -> Any:
    """``value`` with one node (somewhere inside it) replaced by a value of another type."""
    replacements: list[Any] = [
        None,
        True,
        0,
        1.0,
        -1,
        2**63,
        HUGE_MARK,
        "",
        "1",
        "proven",
        [],
        {},
        [value] if not isinstance(value, list) else {"x": value},
        float("nan"),
    ]
    if isinstance(value, dict) and value and rng.random() < 0.75:
        key = rng.choice(sorted(value))
        out = dict(value)
        action = rng.randrange(6)
        if action == 0:
            del out[key]
        elif action == 1:
            out[key + "_extra"] = rng.choice(replacements)
        else:
            out[key] = _json_swap(rng, value[key])
        return out
    if isinstance(value, list) and value and rng.random() < 0.75:
        i = rng.randrange(len(value))
        out_list = list(value)
        if rng.random() < 0.2:
            del out_list[i]
        elif rng.random() < 0.2:
            out_list.append(out_list[i])
        else:
            out_list[i] = _json_swap(rng, value[i])
        return out_list
    return rng.choice(replacements)


def json_type_swap(rng: random.Random, data: bytes) -> bytes:
    try:
        value = json.loads(data)
    except (ValueError, RecursionError):
        return flip_bytes(rng, data)
    return _dump(_json_swap(rng, value))


def json_duplicate_key(rng: random.Random, data: bytes) -> bytes:
    """A key given twice, the second time with another value (a parser keeping the last
    one would read a different certificate from what was signed)."""
    m = list(re.finditer(rb'\n(\s*)"(\w+)": ("[^"\n]*"|[-\w.]+),?\n', data))
    if not m:
        return flip_bytes(rng, data)
    hit = rng.choice(m)
    extra = hit.group(1) + b'"' + hit.group(2) + b'": "proven",\n'
    return data[: hit.start() + 1] + extra + data[hit.start() + 1 :]


def text_mutators(grammar: str) -> list[Mutator]:
    common: list[Mutator] = [
        flip_bytes,
        truncate,
        duplicate_line,
        delete_lines,
        swap_lines,
        token_inserter(grammar),
        token_inserter(grammar),
        huge_number,
        deep_nesting(grammar),
        odd_unicode,
    ]
    if grammar == "profile":
        common += [yaml_specials, yaml_specials]
    if grammar == "xml":
        common += [xml_specials, xml_specials]
    if grammar == "json":
        common += [json_type_swap, json_type_swap, json_type_swap, json_duplicate_key]
    return common


def mutate(rng: random.Random, data: bytes, mutators: Sequence[Mutator]) -> tuple[bytes, str]:
    """Apply 1 to 3 mutators; returns the mutant and their names."""
    names = []
    for _ in range(rng.choice((1, 1, 1, 2, 3))):
        m = rng.choice(mutators)
        data = m(rng, data)
        names.append(getattr(m, "__name__", "mutate"))
    return data, "+".join(names)


# ---------------------------------------------------------------------------- jobs


@dataclass
class Job:
    """One input: how to run it and how to judge what comes back."""

    cls: str
    index: int
    kind: str  # "check", "run" (main of coral-check / coral-run) or "frames"
    argv: list[str]
    files: list[Path]  # the inputs: the output must name one of them
    how: str  # the mutators applied, for the report
    legit: frozenset[int] = frozenset({0, 1, 3})  # exit codes of a still-valid input
    modified_certificate: bool = False
    seed: int = 0
    folder: Path | None = None  # where its files live; copied as the reproducer


@dataclass
class Outcome:
    cls: str
    index: int
    verdict: str  # clean-error, accepted, failure
    seconds: float
    why: str = ""
    reproducer: str = ""


@dataclass
class Seeds:
    """The real files the mutants start from, made once under ``--out``/seeds."""

    root: Path
    mission_dirs: list[tuple[Path, str, list[str]]] = field(default_factory=list)
    profiles: list[tuple[Path, Path]] = field(default_factory=list)
    pnml: list[Path] = field(default_factory=list)
    queries: list[tuple[Path, Path]] = field(default_factory=list)
    mission: Path = Path()
    certificate: Path = Path()
    trusted: Path = Path()
    untrusted_key: Path = Path()
    psk: Path = Path()  # the run's key: with it the logs are authenticated (docs/eventlog.md)
    controller_logs: list[Path] = field(default_factory=list)
    vehicle_log: Path = Path()


def _quiet_main(kind: str, argv: list[str]) -> int:
    """Run a command line's ``main`` in this process (outputs already redirected)."""
    if kind == "check":
        from analysis.cli import main as check_main

        return check_main(argv)
    from runtime.cli import main as run_main

    return run_main(argv)


def make_seeds(root: Path) -> Seeds:
    """Copy and make the seed files: every input class starts from real files."""
    if root.exists():
        shutil.rmtree(root)
    root.mkdir(parents=True)
    seeds = Seeds(root)
    examples = REPO / "examples"
    pool = root / "pool"
    shutil.copytree(examples / "pool_mission", pool)
    temporal = root / "pool_temporal"
    shutil.copytree(REPO / "tests" / "analysis" / "data" / "pool_temporal", temporal)
    minnow = examples / "profiles" / "minnow.yaml"
    seeds.mission_dirs.append((pool, "pool_mission.coral", []))
    seeds.mission_dirs.append((temporal, "pool_mission.coral", []))
    missions = sorted((examples / "faulty").glob("*.coral"))
    for coral in [*missions, examples / "racy" / "racy_mission.coral"]:
        folder = root / "missions" / coral.stem
        folder.mkdir(parents=True)
        shutil.copy(coral, folder)
        seeds.mission_dirs.append((folder, coral.name, []))
    survey = root / "survey"
    survey.mkdir()
    shutil.copy(examples / "survey_auv" / "survey.coral", survey)
    seeds.mission_dirs.append((survey, "survey.coral", ["--profile", str(minnow)]))
    seeds.profiles.append((pool / "romeo.yaml", pool / "pool_mission.coral"))
    for yaml_file in sorted((examples / "profiles").glob("*.yaml")):
        seeds.profiles.append((yaml_file, survey / "survey.coral"))
    mcc = REPO / "tests" / "data" / "mcc"
    nets = root / "nets"
    nets.mkdir()
    for model in PNML_SEEDS:
        model_dir = nets / model
        model_dir.mkdir()
        target = model_dir / "model.pnml"
        target.write_bytes(gzip.decompress((mcc / "pnml" / f"{model}.pnml.gz").read_bytes()))
        seeds.pnml.append(target)
        for exam in QUERY_EXAMS:
            packed = mcc / "queries" / f"{model}.{exam}.xml.gz"
            if packed.exists():
                query = model_dir / f"{exam}.xml"
                query.write_bytes(gzip.decompress(packed.read_bytes()))
                seeds.queries.append((target, query))
    # A signed certificate and two keys: the trusted one signed it; the other is an
    # attacker's, valid but not trusted.
    run = root / "run"
    run.mkdir()
    seeds.mission = pool / "pool_mission.coral"
    seeds.certificate = run / "pool.certificate.json"
    key, other = run / "signing.key", run / "untrusted.key"
    steps: list[tuple[str, list[str]]] = [
        ("check", ["keygen", "--out", str(key), "--comment", "redteam"]),
        ("check", ["keygen", "--out", str(other), "--comment", "attacker"]),
        (
            "check",
            [
                "verify",
                str(seeds.mission),
                "--certificate",
                str(seeds.certificate),
                "--signing-key",
                str(key),
            ],
        ),
    ]
    seeds.trusted = run / "signing.key.pub"
    seeds.untrusted_key = other
    # A controller log (and the vehicle's): a run cut short by its time limit, so that
    # --resume has a mission to continue; virtual time, the in-process simulator, and a
    # key file, so that the logs are authenticated as a served run's are.
    seeds.psk = run / "psk.hex"
    fd = os.open(seeds.psk, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as handle:
        handle.write(random.Random(0).randbytes(32).hex())
    for name, extra in (("partial", ["--time-limit", "60"]),):
        steps.append(
            (
                "run",
                [
                    str(seeds.mission),
                    *_run_gate(seeds),
                    "--key-file",
                    str(seeds.psk),
                    "--out",
                    str(run / name),
                    "--no-plots",
                    "-q",
                    "--link",
                    "ideal",
                    *extra,
                ],
            )
        )
    for kind, argv in steps:
        with _captured() as (out, err):
            code = _quiet_main(kind, argv)
        if code not in (0, 1):
            raise SystemExit(
                f"redteam: making seeds failed: {argv}: {out.getvalue()}{err.getvalue()}"
            )
    seeds.controller_logs = [run / "partial" / "controller.sqlite"]
    seeds.vehicle_log = run / "partial" / "vehicle.sqlite"
    return seeds


def _run_gate(seeds: Seeds, certificate: Path | None = None) -> list[str]:
    return [
        "--certificate",
        str(certificate or seeds.certificate),
        "--trusted-keys",
        str(seeds.trusted),
    ]


@contextlib.contextmanager
def _captured() -> Iterator[tuple[io.StringIO, io.StringIO]]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        yield out, err


# -- per class: make one input ---------------------------------------------------------------


def _input_dir(out: Path, cls: str, index: int) -> Path:
    folder = out / "inputs" / cls / f"{index:05d}"
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    return folder


def make_job(cls: str, index: int, rng: random.Random, seeds: Seeds, out: Path) -> Job:
    """The ``index``-th hostile input of ``cls``, written under ``out``/inputs."""
    folder = _input_dir(out, cls, index)
    job = _make_job(cls, index, rng, seeds, folder)
    job.folder = folder
    return job


def _make_job(cls: str, index: int, rng: random.Random, seeds: Seeds, folder: Path) -> Job:
    if cls == "mission":
        source, top, extra = rng.choice(seeds.mission_dirs)
        for f in source.glob("*.coral"):
            shutil.copy(f, folder)
        victim = rng.choice(sorted(folder.glob("*.coral")))
        data, how = mutate(rng, victim.read_bytes(), text_mutators("mission"))
        victim.write_bytes(data)
        argv = [str(folder / top), *extra, *SEARCH_BUDGET, "--color", "never"]
        return Job(cls, index, "check", argv, [victim, folder / top], how)
    if cls == "profile":
        profile, mission = rng.choice(seeds.profiles)
        target = folder / profile.name
        data, how = mutate(rng, profile.read_bytes(), text_mutators("profile"))
        target.write_bytes(data)
        argv = ["lint", "--profile", str(target), str(mission), "--color", "never"]
        return Job(cls, index, "check", argv, [target], how, legit=frozenset({0, 1}))
    if cls == "pnml":
        net = rng.choice(seeds.pnml)
        target = folder / f"{net.parent.name}.pnml"
        data, how = mutate(rng, net.read_bytes(), text_mutators("xml"))
        target.write_bytes(data)
        argv = ["verify", str(target), *SEARCH_BUDGET, "--color", "never"]
        return Job(cls, index, "check", argv, [target], how)
    if cls == "query":
        net, query = rng.choice(seeds.queries)
        target = folder / f"{net.parent.name}.{query.name}"
        data, how = mutate(rng, query.read_bytes(), text_mutators("xml"))
        target.write_bytes(data)
        argv = ["query", str(net), str(target), *SEARCH_BUDGET]
        return Job(cls, index, "check", argv, [target], how, legit=frozenset({0, 3}))
    if cls == "certificate":
        return _certificate_job(index, rng, seeds, folder)
    if cls == "log":
        return _log_job(index, rng, seeds, folder)
    return Job(cls, index, cls, [], [], "", seed=rng.randrange(2**63))


def _canonical(data: bytes) -> str | None:
    """The certificate's content as the signer saw it, or None when it is not plain JSON
    (duplicate keys, NaN, not UTF-8...): then it is certainly a modified certificate."""

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        keys = [k for k, _ in items]
        if len(keys) != len(set(keys)):
            raise ValueError("duplicate key")
        return dict(items)

    def no_constants(name: str) -> Any:
        raise ValueError(name)

    try:
        value = json.loads(data, object_pairs_hook=pairs, parse_constant=no_constants)
        return json.dumps(value, sort_keys=True, separators=(",", ":"))
    except (ValueError, RecursionError):
        return None


def _certificate_job(index: int, rng: random.Random, seeds: Seeds, folder: Path) -> Job:
    original = seeds.certificate.read_bytes()
    target = folder / "pool.certificate.json"
    attack = rng.randrange(10)
    if attack <= 4:
        data, how = mutate(rng, original, text_mutators("json"))
    elif attack == 5:  # edit verdicts, keep the signature
        cert = json.loads(original)
        for prop in cert["properties"]:
            if rng.random() < 0.5:
                prop["verdict"] = rng.choice(("proven", "violated", "inconclusive"))
        cert["verdict"] = rng.choice(("proven", "violated"))
        if rng.random() < 0.5:
            cert["net_digest"] = "sha256:" + hashlib.sha256(rng.randbytes(8)).hexdigest()
        data, how = json.dumps(cert, indent=2).encode(), "edit-verdicts-keep-signature"
    elif attack == 6:  # drop one property, keep the signature
        cert = json.loads(original)
        del cert["properties"][rng.randrange(len(cert["properties"]))]
        data, how = json.dumps(cert, indent=2).encode(), "drop-property-keep-signature"
    else:  # a modified certificate re-signed with a key the run does not trust
        from analysis.signing import load_signing_key, sign_certificate

        cert = json.loads(original)
        if attack != 9:
            cert = _json_swap(rng, cert)
        if not isinstance(cert, dict):
            cert = {"certificate": cert}
        attacker = load_signing_key(seeds.untrusted_key)
        try:
            signed = sign_certificate(cert, attacker)
        except ValueError:  # NaN: the signer refuses it; sign the original content
            signed = sign_certificate(json.loads(original), attacker)
        how = "re-signed-untrusted"
        if attack == 8:  # and claim the trusted key's id
            trusted = json.loads(original)["signature"]["key_id"]
            sig = signed.get("signature")
            if isinstance(sig, dict):
                sig["key_id"] = trusted
            how = "re-signed-untrusted-trusted-id"
        data = _dump(signed)
    target.write_bytes(data)
    modified = _canonical(data) != _canonical(original)
    run_dir = folder / "run"
    argv = [
        str(seeds.mission),
        *_run_gate(seeds, target),
        "--out",
        str(run_dir),
        "--no-plots",
        "-q",
        "--link",
        "ideal",
        "--time-limit",
        "5",
    ]
    return Job(
        "certificate",
        index,
        "run",
        argv,
        [target],
        how,
        legit=frozenset({0, 1}),
        modified_certificate=modified,
    )


def _log_job(index: int, rng: random.Random, seeds: Seeds, folder: Path) -> Job:
    source = rng.choice(seeds.controller_logs)
    controller = folder / "controller.sqlite"
    shutil.copy(source, controller)
    timeline = rng.random() < 0.3
    vehicle = folder / "vehicle.sqlite"
    victim = controller
    if timeline:
        shutil.copy(seeds.vehicle_log, vehicle)
        victim = rng.choice((controller, vehicle))
    how = _mutate_sqlite(rng, victim)
    if timeline:
        argv = ["timeline", str(controller), str(vehicle), "--out", str(folder / "plots")]
        return Job("log", index, "run", argv, [victim], how, legit=frozenset({0}))
    argv = [
        "--resume",
        str(controller),
        *_run_gate(seeds),
        "--key-file",
        str(seeds.psk),
        "--no-plots",
        "-q",
        "--link",
        "ideal",
        "--time-limit",
        "400",
    ]
    return Job("log", index, "run", argv, [victim], how, legit=frozenset({0, 1}))


def _mutate_sqlite(rng: random.Random, path: Path) -> str:
    """Edit rows (SQL) or bytes (pages) of an event log; returns what was done."""
    if rng.random() < 0.35:
        data = bytearray(path.read_bytes())
        page = 4096
        action = rng.randrange(4)
        if action == 0:  # a garbage page
            n = rng.randrange(max(1, len(data) // page))
            data[n * page : (n + 1) * page] = rng.randbytes(page)
            path.write_bytes(bytes(data))
            return f"garbage-page-{n}"
        if action == 1:
            path.write_bytes(flip_bytes(rng, bytes(data)))
            return "flip-bytes"
        if action == 2:
            cut = rng.randrange(len(data))
            path.write_bytes(bytes(data[:cut]))
            return f"truncate-{cut}"
        path.write_bytes(bytes(data) + rng.randbytes(rng.randrange(1, 3 * page)))
        return "append-garbage"
    with contextlib.closing(sqlite3.connect(path)) as db:
        tables = [r[0] for r in db.execute("select name from sqlite_master where type='table'")]
        done = []
        for _ in range(rng.randint(1, 3)):
            done.append(_sql_edit(rng, db, tables))
        db.commit()
    return "sql:" + ";".join(done)


def _sql_edit(rng: random.Random, db: sqlite3.Connection, tables: list[str]) -> str:
    action = rng.randrange(12)
    try:
        seqs = [r[0] for r in db.execute("select seq from events")] or [1]
        seq = rng.choice(seqs)
        if action == 0:
            db.execute("delete from events where seq = ?", (seq,))
            return f"delete-event-{seq}"
        if action == 1:
            row = db.execute("select data from events where seq = ?", (seq,)).fetchone()
            data = row[0].encode() if row else b"{}"
            new, how = mutate(rng, data, text_mutators("json"))
            db.execute(
                "update events set data = ? where seq = ?",
                (new.decode("utf-8", "replace"), seq),
            )
            return f"event-data-{seq}-{how}"
        if action == 2:
            kind = rng.choice(("command-sent", "reply", "fire", "mission-end", "resume", "x", ""))
            db.execute("update events set kind = ? where seq = ?", (kind, seq))
            return f"event-kind-{seq}-{kind}"
        if action == 3:
            value: Any = rng.choice((float("nan"), -1e300, 1e308, None, "t", 2**63 - 1))
            db.execute("update events set time = ? where seq = ?", (value, seq))
            return f"event-time-{seq}"
        if action == 4:
            db.execute(
                "insert into events (time, kind, data) values (?, ?, ?)",
                (0.0, rng.choice(("command-sent", "reply", "checkpoint")), '{"command_id": -1}'),
            )
            return "insert-event"
        if action == 5:
            row = db.execute("select meta from header").fetchone()
            meta = row[0].encode() if row else b"{}"
            new, how = mutate(rng, meta, text_mutators("json"))
            db.execute("update header set meta = ?", (new.decode("utf-8", "replace"),))
            return f"header-meta-{how}"
        if action == 6:
            column, value = rng.choice(
                (
                    ("schema_version", 999),
                    ("schema_version", -1),
                    ("role", "vehicle"),
                    ("mission", ""),
                    ("net_json", "{"),
                    ("net_digest", "sha256:00"),
                    ("created", "\u2028"),
                )
            )
            with contextlib.suppress(sqlite3.Error):
                db.execute(f"update header set {column} = ?", (value,))
            return f"header-{column}"
        if action == 7:
            row = db.execute("select state from checkpoint").fetchone()
            state = row[0].encode() if row else b"{}"
            new, how = mutate(rng, state, text_mutators("json"))
            db.execute("update checkpoint set state = ?", (new.decode("utf-8", "replace"),))
            return f"checkpoint-state-{how}"
        if action == 8:
            db.execute(
                "update checkpoint set commits = ?, event_seq = ?",
                (rng.choice((-1, 0, 2**62)), rng.choice((-5, 0, 10**9))),
            )
            return "checkpoint-counters"
        if action == 9:
            table = rng.choice(tables)
            db.execute(f"drop table {table}")
            return f"drop-{table}"
        if action == 10:
            db.execute("delete from events where seq >= ?", (seq,))
            return f"delete-events-from-{seq}"
        db.execute(
            "update telemetry set x = ?, seq = ? where n = (select min(n) from telemetry)",
            (float("inf"), -1),
        )
        return "telemetry-row"
    except sqlite3.Error as exc:
        return f"sql-error-{exc}"


# -- frames: the decoder in-process ------------------------------------------------------------


def _forge(key: bytes, sender: int, ftype: int, counter: int, payload: bytes) -> bytes:
    """A frame laid out as ``docs/protocol.md`` says, tagged with ``key``: what a buggy
    (or compromised) peer holding the key could send."""
    from runtime.protocol import STREAM_MAGIC, TAG_SIZE

    head = STREAM_MAGIC + bytes([ftype]) + len(payload).to_bytes(2, "big")
    head += counter.to_bytes(4, "big")
    body = head + binascii.crc_hqx(head, 0xFFFF).to_bytes(2, "big") + payload
    return body + hmac.new(key, bytes([sender]) + body, hashlib.sha256).digest()[:TAG_SIZE]


def frames_case(seed: int) -> tuple[str, str, bytes]:
    """One hostile stream for a decoder; returns (verdict, why, the bytes fed).

    Both ends are set up with a real handshake, then one end receives legitimate frames
    from the other, mutated. Checked: ``feed`` never raises and never buffers more than a
    frame; a decoded message is either one that was sent intact, not yet decoded (no
    replay), or, from a frame signed with the key, one the encoder itself accepts.
    """
    from runtime import protocol as p

    rng = random.Random(seed)
    psk = rng.randbytes(32)
    nonce_c, nonce_v = rng.randbytes(p.NONCE_SIZE), rng.randbytes(p.NONCE_SIZE)
    ctrl = p.StreamCodec(psk, p.Role.CONTROLLER, nonce_c)
    veh = p.StreamCodec(psk, p.Role.VEHICLE, nonce_v)
    hello = p.Hello(nonce_c, 1.0, rng.randrange(2**64), False, 0, 5000)
    hello_frame = ctrl.encode(hello)
    fresh_vehicle = rng.random() < 0.15
    if not fresh_vehicle:
        veh.feed(hello_frame)
        ctrl.feed(veh.encode(p.HelloReply(nonce_c, nonce_v, 1.0, 1.1, False, 0, 30.0)))
    to_vehicle = fresh_vehicle or rng.random() < 0.6
    sender, receiver = (ctrl, veh) if to_vehicle else (veh, ctrl)
    sender_role = p.Role.CONTROLLER if to_vehicle else p.Role.VEHICLE
    msgs: list[Any] = []
    if fresh_vehicle:
        msgs.append(hello)
        frames = [hello_frame]
    else:
        for i in range(rng.randint(1, 6)):
            if to_vehicle:
                msg: Any = rng.choice(
                    (
                        p.Command(
                            i + 1,
                            rng.choice(("DEPTH?", "GOTO", "INIT")),
                            float(i),
                            {"z": 2.0, "time_out": 60, "tag": "x" * rng.randrange(10)},
                        ),
                        p.ReplyAck(i + 1),
                        p.Heartbeat(float(i)),
                    )
                )
            else:
                msg = rng.choice(
                    (
                        p.Reply(i + 1, i + 1, rng.choice(("done", "ack")), float(i), "d" * i),
                        p.Heartbeat(float(i)),
                    )
                )
            msgs.append(msg)
        frames = [sender.encode(m) for m in msgs]
    key = psk if fresh_vehicle else sender.session_key
    assert key is not None
    forged_ok = (
        _forge(
            key,
            sender_role,
            frames[0][2],
            int.from_bytes(frames[0][5:9], "big"),
            frames[0][p.HEADER_SIZE : -p.TAG_SIZE],
        )
        == frames[0]
    )
    signed: list[bytes] = []  # frames signed with the key whose payload was changed
    attack = rng.randrange(8)
    stream: bytes
    if attack == 0:
        stream = rng.randbytes(rng.randrange(1, 3000))
    elif attack == 1:
        stream = flip_bytes(rng, b"".join(frames))
    elif attack == 2:
        stream = truncate(rng, b"".join(frames))
    elif attack == 3:  # replays and reordering
        order = [rng.randrange(len(frames)) for _ in range(len(frames) + rng.randint(1, 4))]
        stream = b"".join(frames[i] for i in order)
    elif attack == 4:  # garbage between frames, magic bytes included
        parts = []
        for f in frames:
            parts.append(rng.choice((b"\xc5", b"\xc5\x01", rng.randbytes(5), b"\xc5\x01\x10")))
            parts.append(f)
        stream = b"".join(parts)
    else:  # signed with the key, payload malformed: a buggy peer
        counter = 10_000 + rng.randrange(100)
        for f in frames:
            payload = f[p.HEADER_SIZE : -p.TAG_SIZE]
            payload, _ = mutate(rng, payload, [flip_bytes, truncate, huge_payload, nan_payload])
            ftype = f[2] if rng.random() < 0.85 else rng.choice((0x00, 0x13, 0x14, 0x40, 0xFF))
            if len(payload) > p.MAX_PAYLOAD:
                payload = payload[: p.MAX_PAYLOAD]
            counter += rng.randint(1, 3)
            signed.append(_forge(key, sender_role, ftype, 0 if fresh_vehicle else counter, payload))
        stream = b"".join(signed)
    # Feed in random chunks: any chunking must give the same result.
    decoded: list[Any] = []
    rejected = 0
    pos = 0
    try:
        while pos < len(stream):
            step = rng.choice((1, 7, 64, 4096))
            for item in receiver.feed(stream[pos : pos + step]):
                if isinstance(item, p.Rejected):
                    rejected += 1
                else:
                    decoded.append(item)
            pos += step
            if receiver.buffered > p.MAX_FRAME:
                return "failure", f"decoder buffers {receiver.buffered} bytes", stream
    except Exception:  # the point of the bench: feed must never raise
        return "failure", "feed raised:\n" + traceback.format_exc(), stream
    if not forged_ok and signed:
        return "failure", "bench self-check: forged frame differs from the encoder's", stream
    remaining = list(msgs)
    for item in decoded:
        if item in remaining:
            remaining.remove(item)
            continue
        if not signed:
            return "failure", f"accepted an altered or replayed frame: {item!r}", stream
        try:
            p.frame_size(item)
        except p.ProtocolError as exc:
            return "failure", f"decoded what the encoder refuses: {item!r}: {exc}", stream
    # Datagrams: telemetry mutated; accept() must never raise nor take an altered one.
    if not fresh_vehicle and ctrl.session_key is not None:
        receiver_d = p.DatagramReceiver(ctrl.session_key)
        sent = [
            p.TelemetryRecord(float(i), 1.0, 2.0, 3.0, 4.0, None, 5.0, seq=i + 1) for i in range(3)
        ]
        grams = [p.encode_datagram(ctrl.session_key, t) for t in sent]
        for g in [*grams, flip_bytes(rng, rng.choice(grams)), truncate(rng, grams[0]), grams[0]]:
            try:
                got = receiver_d.accept(g)
            except Exception:
                return "failure", "datagram accept raised:\n" + traceback.format_exc(), g
            if isinstance(got, p.TelemetryRecord) and g not in grams:
                return "failure", f"accepted an altered datagram: {got!r}", g
            if isinstance(got, p.Rejected):
                rejected += 1
    if rejected:
        return "clean-error", "", stream
    return "accepted", "", stream


def huge_payload(rng: random.Random, data: bytes) -> bytes:
    """Length prefixes and counts at their maximum."""
    out = bytearray(data)
    for _ in range(rng.randint(1, 3)):
        if out:
            out[rng.randrange(len(out))] = 0xFF
    return bytes(out) + b"\xff" * rng.randrange(0, 40)


def nan_payload(rng: random.Random, data: bytes) -> bytes:
    """A NaN or an infinity where a float lies (8 bytes somewhere)."""
    if len(data) < 8:
        return data + b"\x7f\xf8" + b"\x00" * 6
    at = rng.randrange(len(data) - 7)
    value = rng.choice((b"\x7f\xf8" + b"\x00" * 6, b"\x7f\xf0" + b"\x00" * 6, b"\xff" * 8))
    return data[:at] + value + data[at + 8 :]


# ---------------------------------------------------------------------------- the worker


def worker_main(mem_mib: int) -> int:
    """Serve jobs read as JSON lines on stdin; answer on the original stdout.

    In-process calls are much faster than a process per input; the address-space cap
    turns unbounded memory into a MemoryError the parent records as a failure.
    """
    channel = os.fdopen(os.dup(1), "w", buffering=1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # stray writes to the file descriptors must not corrupt answers
    os.dup2(devnull, 2)
    limit = mem_mib * 1024 * 1024
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    import analysis.cli  # noqa: F401  (import once: every job then pays only its own work)
    import runtime.cli  # noqa: F401

    for line in sys.stdin:
        job = json.loads(line)
        start = time.perf_counter()
        result: dict[str, Any] = {}
        if job["kind"] == "frames":
            verdict, why, stream = frames_case(job["seed"])
            result = {"verdict": verdict, "why": why}
            if verdict == "failure":
                result["input"] = base64.b64encode(stream).decode()
        else:
            code: object = None
            crash = ""
            with _captured() as (out, err):
                try:
                    code = _quiet_main(job["kind"], job["argv"])
                except SystemExit as exc:
                    code = exc.code if isinstance(exc.code, int) else 2
                except BaseException:  # anything escaping main is what we hunt
                    crash = traceback.format_exc()
            result = {"code": code, "out": out.getvalue(), "err": err.getvalue(), "crash": crash}
        result["seconds"] = time.perf_counter() - start
        channel.write(json.dumps(result) + "\n")
    return 0


class Worker:
    """One long-lived worker process; replaced after a timeout, a crash or N jobs."""

    def __init__(self, mem_mib: int, recycle: int) -> None:
        self._mem = mem_mib
        self._recycle = recycle
        self._proc: subprocess.Popen[str] | None = None
        self._jobs = 0

    def _start(self) -> subprocess.Popen[str]:
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MPLBACKEND="Agg")
        env["PYTHONPATH"] = str(REPO)
        return subprocess.Popen(
            [sys.executable, __file__, "--worker", "--mem-mib", str(self._mem)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env=env,
            cwd=REPO,
            start_new_session=True,
        )

    def run(self, payload: dict[str, Any], timeout: float) -> dict[str, Any]:
        if self._proc is None or self._jobs >= self._recycle:
            self.stop()
            self._proc = self._start()
            self._jobs = 0
        proc = self._proc
        assert proc.stdin is not None and proc.stdout is not None
        self._jobs += 1
        try:
            proc.stdin.write(json.dumps(payload) + "\n")
            proc.stdin.flush()
        except BrokenPipeError:
            self.stop()
            return {"died": "worker gone before the job"}
        start = time.monotonic()
        # The first job of a worker also pays its imports.
        deadline = start + timeout + (15 if self._jobs == 1 else 0)
        while True:
            ready, _, _ = select.select(
                [proc.stdout], [], [], max(0.0, deadline - time.monotonic())
            )
            if ready:
                line = proc.stdout.readline()
                if not line:
                    code = proc.wait()
                    self._proc = None
                    return {"died": f"worker died (exit {code}, signal {-code if code < 0 else 0})"}
                answer: dict[str, Any] = json.loads(line)
                return answer
            if time.monotonic() >= deadline:
                self.stop()
                return {"timeout": time.monotonic() - start}

    def stop(self) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        for stream in (proc.stdin, proc.stdout):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()


def judge(job: Job, answer: dict[str, Any]) -> tuple[str, str]:
    """Classify a file input's outcome (see the module docstring)."""
    if "timeout" in answer:
        return "failure", f"timeout after {answer['timeout']:.1f} s"
    if "died" in answer:
        return "failure", answer["died"]
    if job.kind == "frames":
        return str(answer["verdict"]), str(answer.get("why", ""))
    text = answer["out"] + answer["err"]
    code = answer["code"]
    if answer["crash"]:
        return "failure", "exception escaped main:\n" + answer["crash"]
    if "Traceback" in text:
        return "failure", "traceback in the output:\n" + text[-3000:]
    named = any(str(f) in text or f.name in text for f in job.files)
    if code == EXIT_USAGE:
        return (
            ("clean-error", "")
            if named
            else ("failure", "exit 2 without naming the file:\n" + text[-1500:])
        )
    # coral-check's documented code for a mission (or a PNML file) with errors in it
    # (docs/verify.md): clean when a diagnostic names the file, line and column.
    if (
        code == 1
        and job.cls in DIAGNOSED_BY_EXIT_1
        and any(re.search(re.escape(f.name) + r":\d+:\d+: error", text) for f in job.files)
    ):
        return "clean-error", EXIT_1_DIAGNOSTIC
    if job.cls == "certificate" and job.modified_certificate and code in (0, 1):
        return "failure", f"a modified certificate was accepted (exit {code}):\n" + text[-1500:]
    if code in job.legit:
        return "accepted", ""
    return "failure", f"exit {code}:\n" + text[-1500:]


# ---------------------------------------------------------------------------- live server


class LiveServer:
    """A ``coral-vehicle serve`` subprocess fed hostile connections, checked after each."""

    def __init__(self, folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        self.psk = os.urandom(32)
        key = folder / "psk.hex"
        key.unlink(missing_ok=True)
        fd = os.open(key, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)  # never readable by others
        with os.fdopen(fd, "w") as handle:
            handle.write(self.psk.hex())
        self.stderr_path = folder / "server.stderr"
        self._err = self.stderr_path.open("w")
        settings = folder / "settings.yaml"
        settings.write_text("watchdog_s: 100000\n")
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "runtime.vehicle.cli",
                "serve",
                "--profile",
                str(REPO / "examples" / "profiles" / "minnow.yaml"),
                "--key-file",
                str(key),
                "--speed",
                "20",
                "--sim-config",
                str(settings),
            ],
            stdout=subprocess.PIPE,
            stderr=self._err,
            text=True,
            cwd=REPO,
            env=dict(os.environ, PYTHONPATH=str(REPO)),
            start_new_session=True,
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        match = re.match(r"listening on (\S+):(\d+)", line)
        if not match:
            self.stop()
            raise SystemExit(f"redteam: coral-vehicle serve did not start: {line!r}")
        self.address = (match.group(1), int(match.group(2)))

    def _connect(self) -> socket.socket:
        return socket.create_connection(self.address, timeout=5)

    def attack(self, seed: int) -> tuple[str, str, bytes]:
        """One hostile connection, then an honest controller's probe."""
        from runtime import protocol as p

        rng = random.Random(seed)
        kind = rng.randrange(6)
        sent = b""
        try:
            with self._connect() as sock:
                if kind == 0:  # garbage
                    sent = rng.randbytes(rng.randrange(1, 20000))
                elif kind == 1:  # a mutated Hello
                    codec = p.StreamCodec(self.psk, p.Role.CONTROLLER, rng.randbytes(16))
                    hello = codec.encode(p.Hello(codec.nonce, 0.0, rng.randrange(2**64)))
                    sent = flip_bytes(rng, hello) if rng.random() < 0.5 else truncate(rng, hello)
                elif kind == 2:  # a Hello with the wrong key, then junk
                    codec = p.StreamCodec(rng.randbytes(32), p.Role.CONTROLLER, rng.randbytes(16))
                    sent = codec.encode(p.Hello(codec.nonce, 0.0, 1)) + rng.randbytes(500)
                elif kind == 3:  # a flood of bytes after magic
                    sent = (b"\xc5\x01" + rng.randbytes(30)) * rng.randrange(10, 3000)
                else:  # a real session, then frames signed with the key but malformed
                    sent = self._authenticated_junk(sock, rng)
                if sent:
                    with contextlib.suppress(OSError):
                        sock.sendall(sent)
        except OSError as exc:
            if self.proc.poll() is not None:
                return "failure", f"server died: {exc}", sent
        return self._probe(sent)

    def _authenticated_junk(self, sock: socket.socket, rng: random.Random) -> bytes:
        from runtime import protocol as p

        codec = p.StreamCodec(self.psk, p.Role.CONTROLLER, rng.randbytes(16))
        sock.sendall(codec.encode(p.Hello(codec.nonce, 0.0, rng.randrange(2**64), False, 0, 0)))
        if not self._await_reply(sock, codec):
            return b""
        key = codec.session_key
        assert key is not None
        legit: list[Any] = [
            p.Command(1, "INIT", 0.0, {}),
            p.Command(2, rng.choice(("DEPTH?", "GOTO", "NOPE", "")), 0.0, {"z": 1.0}),
            p.ReplyAck(rng.randrange(2**32)),
            p.Heartbeat(0.0),
        ]
        frames = []
        counter = 0
        for msg in legit:
            with contextlib.suppress(p.ProtocolError):
                frame = codec.encode(msg)
                counter += 1
                payload = frame[p.HEADER_SIZE : -p.TAG_SIZE]
                if rng.random() < 0.7:
                    payload, _ = mutate(
                        rng, payload, [flip_bytes, truncate, huge_payload, nan_payload]
                    )
                    payload = payload[: p.MAX_PAYLOAD]
                    counter += 1
                    frame = _forge(key, p.Role.CONTROLLER, frame[2], counter + 100, payload)
                frames.append(frame)
        return b"".join(frames)

    @staticmethod
    def _await_reply(sock: socket.socket, codec: Any) -> bool:
        from runtime import protocol as p

        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            try:
                data = sock.recv(4096)
            except TimeoutError:
                return False
            if not data:
                return False
            if any(isinstance(m, p.HelloReply) for m in codec.feed(data)):
                return True
        return False

    def _probe(self, sent: bytes) -> tuple[str, str, bytes]:
        """An honest controller must still get its handshake answered, and nothing may
        have been logged as a traceback."""
        from runtime import protocol as p

        if self.proc.poll() is not None:
            return "failure", f"server exited with {self.proc.returncode}", sent
        try:
            with self._connect() as sock:
                codec = p.StreamCodec(self.psk, p.Role.CONTROLLER, os.urandom(16))
                sock.sendall(codec.encode(p.Hello(codec.nonce, 0.0, 7, False, 0, 0)))
                if not self._await_reply(sock, codec):
                    return "failure", "an honest controller got no HelloReply within 5 s", sent
                sock.sendall(codec.encode(p.Heartbeat(0.0)))
        except OSError as exc:
            return "failure", f"an honest controller could not connect: {exc}", sent
        self._err.flush()
        if "Traceback" in self.stderr_path.read_text(errors="replace"):
            return "failure", "traceback in the server's log", sent
        return "clean-error", "", sent

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        self._err.close()


# ---------------------------------------------------------------------------- the campaign


def save_reproducer(out: Path, job: Job, why: str, stream: bytes | None) -> str:
    """Copy the failing input where the report points, with how to replay it."""
    folder = out / "failures" / f"{job.cls}-{job.index:05d}"
    shutil.rmtree(folder, ignore_errors=True)
    if stream is not None:
        folder.mkdir(parents=True)
        (folder / "input.bin").write_bytes(stream)
        replay = f"seed {job.seed}: the {job.cls} case of bench/redteam.py with this seed"
    else:
        assert job.folder is not None
        shutil.copytree(job.folder, folder)
        main = "coral-check" if job.kind == "check" else "coral-run"
        argv = [a.replace(str(job.folder), str(folder)) for a in job.argv]
        replay = f"{main} " + " ".join(argv)
    (folder / "README.txt").write_text(
        f"{job.how}\n\n{replay}\n\n(paths under {out / 'seeds'} are remade by each "
        f"run of the bench with the same --out)\n\n{why}\n"
    )
    return str(folder)


def run_campaign(args: argparse.Namespace) -> int:
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(out / "failures", ignore_errors=True)
    shutil.rmtree(out / "inputs", ignore_errors=True)
    started = time.monotonic()
    seeds = make_seeds(out / "seeds")
    master = random.Random(args.seed)
    jobs: list[Job] = []
    for cls in args.classes:
        rng = random.Random(f"{args.seed}:{cls}")
        for i in range(args.per_class):
            jobs.append(make_job(cls, i, rng, seeds, out))
    master.shuffle(jobs)  # mix slow and fast classes across workers
    todo: queue.Queue[Job] = queue.Queue()
    for job in jobs:
        todo.put(job)
    outcomes: list[Outcome] = []
    lock = threading.Lock()
    server = LiveServer(out / "server") if "server" in args.classes else None

    def record(job: Job, verdict: str, why: str, seconds: float, stream: bytes | None) -> None:
        repro = save_reproducer(out, job, why, stream) if verdict == "failure" else ""
        if job.folder is not None and not args.keep_inputs:
            shutil.rmtree(job.folder, ignore_errors=True)
        with lock:
            outcomes.append(Outcome(job.cls, job.index, verdict, seconds, why, repro))

    def pool_thread() -> None:
        worker = Worker(args.mem_mib, args.recycle)
        try:
            while True:
                try:
                    job = todo.get_nowait()
                except queue.Empty:
                    return
                if job.cls == "server":
                    continue  # one at a time, on the server thread
                payload = {"kind": job.kind, "argv": job.argv, "seed": job.seed}
                answer = worker.run(payload, args.timeout)
                verdict, why = judge(job, answer)
                stream = None
                if job.kind == "frames" and "input" in answer:
                    stream = base64.b64decode(answer["input"])
                elif job.kind == "frames" and verdict == "failure":
                    stream = b""
                seconds = float(answer.get("seconds", answer.get("timeout", args.timeout)))
                record(job, verdict, why, seconds, stream)
        finally:
            worker.stop()

    def server_thread() -> None:
        assert server is not None
        for job in (j for j in jobs if j.cls == "server"):
            start = time.perf_counter()
            verdict, why, sent = server.attack(job.seed)
            record(job, verdict, why, time.perf_counter() - start, sent)

    threads = [threading.Thread(target=pool_thread) for _ in range(args.workers)]
    if server is not None:
        threads.append(threading.Thread(target=server_thread))
    for t in threads:
        t.start()
    try:
        for t in threads:
            t.join()
    finally:
        if server is not None:
            server.stop()
    print_table(args.classes, outcomes)
    failures = sorted(
        (o for o in outcomes if o.verdict == "failure"), key=lambda o: (o.cls, o.index)
    )
    for o in failures:
        first = o.why.strip().splitlines()[-1] if o.why.strip() else ""
        print(f"FAILURE {o.cls} #{o.index}: {first[:200]}\n  reproducer: {o.reproducer}")
    print(
        f"seed {args.seed}, {len(outcomes)} inputs, {time.monotonic() - started:.0f} s wall, "
        f"{args.workers} workers"
    )
    return 1 if failures else 0


VERDICTS = ("clean-error", "accepted", "failure")


def print_table(classes: Sequence[str], outcomes: list[Outcome]) -> None:
    """One row per class; ``(exit 1)`` counts the clean errors reported with exit 1 and a
    FILE:LINE:COL diagnostic (missions and PNML files with errors, as documented)."""
    print(
        f"{'class':<12} {'inputs':>7} {'clean-error':>12} {'(exit 1)':>9} {'accepted':>9} "
        f"{'failure':>8} {'median s':>9}"
    )
    total = dict.fromkeys(("inputs", "exit1", *VERDICTS), 0)
    for cls in classes:
        mine = [o for o in outcomes if o.cls == cls]
        counts = {v: sum(o.verdict == v for o in mine) for v in VERDICTS}
        exit1 = sum(o.why == EXIT_1_DIAGNOSTIC for o in mine)
        median = statistics.median(o.seconds for o in mine) if mine else 0.0
        print(
            f"{cls:<12} {len(mine):>7} {counts['clean-error']:>12} {exit1:>9} "
            f"{counts['accepted']:>9} {counts['failure']:>8} {median:>9.3f}"
        )
        total["inputs"] += len(mine)
        total["exit1"] += exit1
        for v, n in counts.items():
            total[v] += n
    print(
        f"{'total':<12} {total['inputs']:>7} {total['clean-error']:>12} {total['exit1']:>9} "
        f"{total['accepted']:>9} {total['failure']:>8}"
    )


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--per-class", type=int, default=DEFAULT_PER_CLASS, help="inputs per class")
    parser.add_argument("--classes", nargs="+", choices=CLASSES, default=list(CLASSES))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=REPO / "out" / "redteam")
    parser.add_argument("--timeout", type=float, default=20.0, help="seconds per input")
    parser.add_argument("--mem-mib", type=int, default=2048, help="address-space cap per worker")
    parser.add_argument(
        "--recycle", type=int, default=50, help="inputs per worker before a new one"
    )
    parser.add_argument(
        "--keep-inputs", action="store_true", help="keep every input (default: failures only)"
    )
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    if args.worker:
        return worker_main(args.mem_mib)
    args.out = args.out.resolve()
    return run_campaign(args)


if __name__ == "__main__":
    raise SystemExit(main())
