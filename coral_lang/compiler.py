"""Compile CORAL missions to a `Net`, checking every command against the vehicle profile.

Lowering (see ``docs/language.md``):

* ``place p = k`` becomes a place with k initial tokens; ``capacity c`` adds a
  complement place ``p.free`` holding the free room, so the net stays a plain P/T net
  and a transition that would overfill ``p`` is not enabled.
* ``transition t`` consumes its ``wait`` set and produces its ``signal`` set. With an
  ``action``, it also puts a token in the pending place ``t.pending``; each reply kind
  ``r`` of the command becomes a reply transition ``t.r`` that takes the pending token
  and marks the places the mission maps ``r`` to (nothing, for ``r: ignore``).
* ``input X`` declares the place ``X`` (no initial tokens) that only the operator
  marks: a place ``X.armed`` (one token) and an INPUT transition ``X.operator`` moving
  it to ``X``, so the operator gives each input at most once per run. No mission
  transition or reply may mark ``X``.

All errors of all files are collected before anything is reported.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from coral_lang import ast, units
from coral_lang.diagnostics import (
    CompileError,
    Diagnostic,
    ProfileError,
    Severity,
    Span,
    did_you_mean,
    sort_diagnostics,
)
from coral_lang.gcpause import cyclic_gc_paused
from coral_lang.net import (
    MAX_INPUTS,
    Assertion,
    AssertKind,
    Command,
    FinalMarking,
    Net,
    Place,
    PlaceKind,
    Transition,
    TransitionKind,
    Value,
)
from coral_lang.parser import parse
from coral_lang.printer import format_declaration, format_temporal
from coral_lang.profile import CommandSpec, ParamSpec, VehicleProfile, load_bundled_profile
from coral_lang.properties import Names, PropertyLowering, TransitionInfo
from coral_lang.safefile import MISSION_LIMIT, UnreadableFile, is_within, read_text_file

PENDING_SUFFIX = ".pending"
FREE_SUFFIX = ".free"
ARMED_SUFFIX = ".armed"
OPERATOR_SUFFIX = ".operator"
MAX_INCLUDED_BYTES = 16 * 1024 * 1024
"""All the files of one mission (the mission and everything it includes) together: each
file is bounded by ``MISSION_LIMIT``, and this bounds how many of them add up, so a
mission including hundreds of large files is refused at the include that crossed it."""
MAX_INCLUDED_FILES = 256
"""Distinct files one mission may read (itself included)."""
REQUIREMENTS = ("termination",)
"""What a ``require`` line may name: ``termination`` demands that every run of the
mission (under the runtime's fairness) ends in a declared final marking."""


@dataclass
class CompileResult:
    """What a compile produced: the net (None when there were errors) and every diagnostic."""

    net: Net | None
    diagnostics: list[Diagnostic]
    sources: dict[str, str]
    missions: list[ast.Mission] = field(default_factory=list)
    profile: VehicleProfile | None = None
    part_of: Path | None = None
    """Set when the file given was a *part* of a mission (it starts with ``# coral: part
    of FILE.coral``): the whole mission's file, which is what this result compiled."""
    part_path: Path | None = None
    """With `part_of`: the part's own path, the file that was given."""

    @property
    def errors(self) -> list[Diagnostic]:
        """The diagnostics of severity error."""
        return [d for d in self.diagnostics if d.severity is Severity.ERROR]

    @property
    def ok(self) -> bool:
        """True when the mission compiled without errors."""
        return self.net is not None and not self.errors

    def raise_for_errors(self) -> Net:
        """The net, or `CompileError` with every diagnostic."""
        if self.net is None or self.errors:
            raise CompileError(self.errors, self.sources)
        return self.net


def compile_file(
    path: str | Path,
    profiles: Sequence[VehicleProfile] = (),
    *,
    include_root: str | Path | None = None,
    include_path: Sequence[str | Path] = (),
) -> CompileResult:
    """Compile the mission in ``path`` (and the files it includes).

    Args:
        path: the mission file.
        profiles: vehicle profiles to use before the bundled ones (matched by vehicle name).
        include_root: the folder every included file must lie in (symlinks followed);
            default: the folder of ``path``. An include outside it (and outside every
            ``include_path`` folder) is an error.
        include_path: more folders to look for included files in (``coral-check
            --include-path``), in order, after the including file's own folder; files
            in them may be included too.
    """
    path = Path(path)
    with cyclic_gc_paused():
        compiler = _Compiler(
            profiles, Path(include_root) if include_root is not None else None, include_path
        )
        compiler.load_root(path)
        return compiler.finish()


def compile_source(
    text: str,
    file: str = "<mission>",
    profiles: Sequence[VehicleProfile] = (),
    base_dir: str | Path | None = None,
    *,
    include_root: str | Path | None = None,
    include_path: Sequence[str | Path] = (),
) -> CompileResult:
    """Compile mission ``text``; includes resolve against ``base_dir`` (default: cwd),
    then the ``include_path`` folders.

    Included files must lie in ``include_root`` (default: ``base_dir``) or an
    ``include_path`` folder.
    """
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    with cyclic_gc_paused():
        compiler = _Compiler(
            profiles, Path(include_root) if include_root is not None else base, include_path
        )
        compiler.load_text(text, file, base)
        return compiler.finish()


def compile_mission(path: str | Path, profiles: Sequence[VehicleProfile] = ()) -> Net:
    """Compile ``path`` to a `Net`; raises `CompileError` listing every error."""
    return compile_file(path, profiles).raise_for_errors()


PART_SUFFIX = ".coral"
_PART_HEADER = re.compile(r"^[ \t]*#[ \t]*coral:[ \t]*part\b[^\n]*", re.M)
_PART_OF = re.compile(r"#[ \t]*coral:[ \t]*part[ \t]+of[ \t]+(?P<file>\S(?:.*\S)?)[ \t\r]*$")
_FIRST_DECLARATION = re.compile(r"^[ \t\r\f\v]*[^#\s]", re.M)
_MAX_PART_ERRORS = 20
_MAX_PART_NAME = 1024
"""Longest mission file name a header may give: longer is refused as malformed, so a
hostile name never reaches the file system or a message at length."""


@dataclass(frozen=True)
class PartHeader:
    """A part's header ``# coral: part of FILE.coral``: the whole mission it belongs to.

    ``mission`` is the file name as written, relative to the part's folder; ``span``
    covers the comment, for diagnostics about it.
    """

    mission: str
    span: Span


def part_header(text: str, file: str) -> tuple[PartHeader | None, list[Diagnostic]]:
    """The part header of ``text``, if it has one, and the errors of its other ones.

    A header counts only as a comment line of its own before the file's first
    declaration (comments and blank lines may come before it). Why so strict: the
    header changes what checking the file means (its whole mission is checked
    instead), so it must be where a reader looks first. A header anywhere else, a
    second header, or one not of the form ``# coral: part of FILE.coral`` is an error
    (CORAL011), so a misplaced one is never silently ignored.
    """
    if "coral:" not in text:  # the common case, one scan of the text
        return None, []
    first = _FIRST_DECLARATION.search(text)
    top_end = first.start() if first is not None else len(text)
    header: PartHeader | None = None
    errors: list[Diagnostic] = []
    line, counted = 1, 0  # lines counted up to offset `counted`: linear in the text
    for match in _PART_HEADER.finditer(text):
        if len(errors) >= _MAX_PART_ERRORS:
            break  # a file of nothing but headers: the first ones say it all
        line += text.count("\n", counted, match.start())
        counted = match.start()
        comment = match.group().rstrip()
        col = len(comment) - len(comment.lstrip()) + 1
        span = Span(file, line, col, line, len(comment) + 1)
        parsed = _PART_OF.search(comment)
        named = parsed.group("file") if parsed is not None else ""
        if not (
            named.endswith(PART_SUFFIX) and named.isprintable() and len(named) <= _MAX_PART_NAME
        ):
            errors.append(
                Diagnostic(
                    Severity.ERROR,
                    "CORAL011",
                    "a part's header names its mission's file: "
                    f"'# coral: part of MISSION{PART_SUFFIX}'",
                    span,
                )
            )
        elif match.start() > top_end:
            errors.append(
                Diagnostic(
                    Severity.ERROR,
                    "CORAL011",
                    "'# coral: part of' must come before the file's first declaration",
                    span,
                    ("only comments and blank lines may come before a part's header",),
                )
            )
        elif header is not None:
            errors.append(
                Diagnostic(
                    Severity.ERROR,
                    "CORAL011",
                    "a file is a part of one mission only: "
                    f"line {header.span.line} already names {header.mission}",
                    span,
                )
            )
        else:
            header = PartHeader(named, span)
    return header, errors


@dataclass
class _PlaceInfo:
    name: str
    span: Span
    initial: int | None = None
    initial_span: Span | None = None
    capacity: int | None = None
    capacity_span: Span | None = None
    file: str = ""


@dataclass
class _InputInfo:
    """An operator input: its name and the span of its (first) declaration."""

    name: str
    span: Span


@dataclass
class _ConstInfo:
    decl: ast.Const
    file: str


class _Compiler:
    def __init__(
        self,
        profiles: Sequence[VehicleProfile],
        include_root: Path | None = None,
        include_path: Sequence[str | Path] = (),
    ) -> None:
        self.profiles = list(profiles)
        # Every included file must lie below this folder (resolved) or one of
        # include_dirs; None: the root mission's folder, set when it is loaded.
        self.include_root = include_root.resolve() if include_root is not None else None
        self.include_dirs = tuple(Path(d).resolve() for d in include_path)
        self.bytes_read = 0
        self.over_limit = False  # an include crossed a limit: the rest are not read
        self.diagnostics: list[Diagnostic] = []
        self.sources: dict[str, str] = {}
        self.missions: list[ast.Mission] = []
        self.loaded: set[Path] = set()
        self.declarations: list[tuple[ast.Declaration, str]] = []
        self.root_part: PartHeader | None = None  # the root file's part header, if any

    # -- loading and includes -------------------------------------------------------------

    def error(self, code: str, message: str, span: Span | None, *notes: str) -> None:
        self.diagnostics.append(Diagnostic(Severity.ERROR, code, message, span, tuple(notes)))

    def load_root(self, path: Path) -> None:
        text = self._read(path, None)
        if text is not None:
            self.bytes_read += len(text.encode("utf-8"))
            resolved = path.resolve()
            if self.include_root is None:
                self.include_root = resolved.parent
            self.load_text(text, str(path), resolved.parent, resolved=resolved)

    def _read(self, path: Path, span: Span | None) -> str | None:
        try:
            return read_text_file(path, MISSION_LIMIT)
        except UnreadableFile as exc:
            if exc.kind == "missing":
                self.error("CORAL004", f"file not found: {_clip(str(path))}", span)
            elif exc.kind == "directory":
                self.error(
                    "CORAL004", f"is a directory, not a mission file: {_clip(str(path))}", span
                )
            else:
                self.error("CORAL004", f"cannot read {_clip(exc.path)}: {exc.reason}", span)
        return None

    def load_text(
        self,
        text: str,
        file: str,
        base_dir: Path,
        resolved: Path | None = None,
        stack: tuple[Path, ...] = (),
    ) -> None:
        self.sources[file] = text
        if resolved is not None:
            self.loaded.add(resolved)
        header, misplaced = part_header(text, file)
        self.diagnostics.extend(misplaced)
        if not self.missions:
            self.root_part = header
        mission, diagnostics = parse(text, file)
        self.diagnostics.extend(diagnostics)
        self.missions.append(mission)
        for declaration in mission.declarations:
            if isinstance(declaration, ast.Include):
                self._include(declaration, base_dir, stack + ((resolved,) if resolved else ()))
            else:
                self.declarations.append((declaration, file))

    def _include(self, include: ast.Include, base_dir: Path, stack: tuple[Path, ...]) -> None:
        target = self._include_target(include, base_dir)
        if target is None:
            return
        if target in stack:
            chain = " -> ".join(p.name for p in (*stack, target))
            self.error("CORAL004", f"include cycle: {chain}", include.span)
            return
        if target in self.loaded:
            return  # included already (diamond): one copy of its declarations
        if self.over_limit:
            return  # reported once, at the include that crossed it
        if len(self.loaded) + 1 > MAX_INCLUDED_FILES:
            self._limit_crossed(include, f"more than {MAX_INCLUDED_FILES} files")
            return
        text = self._read(target, include.span)
        if text is None:
            return
        self.bytes_read += len(text.encode("utf-8"))
        if self.bytes_read > MAX_INCLUDED_BYTES:
            self._limit_crossed(
                include, f"{self.bytes_read:,} bytes, over the {MAX_INCLUDED_BYTES:,}-byte limit"
            )
            return
        self.load_text(text, _display_path(target), target.parent, resolved=target, stack=stack)

    def _limit_crossed(self, include: ast.Include, what: str) -> None:
        self.over_limit = True
        shown = _clip(include.path if include.path.isprintable() else repr(include.path))
        self.error(
            "CORAL004",
            f"include {shown} brings the mission's files to {what}",
            include.span,
            f"a mission and everything it includes may be at most {MAX_INCLUDED_FILES} files "
            f"and {MAX_INCLUDED_BYTES // (1024 * 1024)} MB together",
        )

    def _include_target(self, include: ast.Include, base_dir: Path) -> Path | None:
        """The resolved file ``include`` names, or None (reported) when it is refused.

        A relative path names a file beside the including file or, when there is none,
        in the first include-path folder that has it. Included files must lie in the
        include root (the root mission's folder unless given) or an include-path folder,
        after symlinks are followed: a mission must not read, and quote in its error
        messages, files elsewhere (``include "/proc/self/environ"``).
        """
        shown = _clip(include.path if include.path.isprintable() else repr(include.path))
        if "\0" in include.path:
            self.error("CORAL004", f"include path holds a NUL character: {shown}", include.span)
            return None
        try:
            target = (base_dir / include.path).resolve()
            if not target.exists() and not Path(include.path).is_absolute():
                found = (d / include.path for d in self.include_dirs)
                target = next((f.resolve() for f in found if f.exists()), target)
        except (OSError, RuntimeError, ValueError) as exc:  # RuntimeError: symlink loop
            self.error("CORAL004", f"cannot include {shown}: {exc}", include.span)
            return None
        root = self.include_root if self.include_root is not None else base_dir.resolve()
        if not any(is_within(target, folder) for folder in (root, *self.include_dirs)):
            where = f"the mission's folder {root}"
            if self.include_dirs:
                where += " and the include path " + ", ".join(map(str, self.include_dirs))
            self.error(
                "CORAL004",
                f"include {shown} is outside {where}",
                include.span,
                "included files must lie in the folder of the mission being checked (or "
                "below it), or in a folder given with --include-path",
            )
            return None
        return target

    # -- checking and lowering ------------------------------------------------------------

    def finish(self) -> CompileResult:
        if not self.missions:
            return CompileResult(None, self.diagnostics, self.sources)
        root = self.missions[0]
        profile = self._header(root)
        consts = self._consts()
        places = self._places(consts)
        inputs = self._inputs(places)
        finals = self._finals(places, consts)
        assertions = self._assertions(places, consts)
        transitions, pending = self._transitions(places, consts, profile, root.vehicle)
        self._check_input_writers(inputs)
        assertions.update(self._temporal(places, consts, profile, finals))
        requirements = self._requirements()
        net: Net | None = None
        if not any(d.severity is Severity.ERROR for d in self.diagnostics):
            in_order = [assertions[i] for i in sorted(assertions)]  # source order
            net = self._build(
                root, places, pending, transitions, finals, in_order, requirements, inputs
            )
        return CompileResult(
            net, sort_diagnostics(self.diagnostics), self.sources, self.missions, profile
        )

    def _header(self, root: ast.Mission) -> VehicleProfile | None:
        if root.name is None:
            self.error(
                "CORAL007",
                "a mission file starts with 'mission NAME'",
                Span(root.file, 1, 1, 1, 2),
                *self._part_note(),
            )
            if self.root_part is not None:
                return None  # a part: its mission says the vehicle
        if root.vehicle is None:
            self.error(
                "CORAL007",
                "the mission does not say its vehicle: add 'vehicle NAME' after the mission line",
                root.name_span if root.name else Span(root.file, 1, 1, 1, 2),
            )
            return None
        for included in self.missions[1:]:
            if included.vehicle is not None and included.vehicle != root.vehicle:
                self.error(
                    "CORAL004",
                    f"included file is written for vehicle '{included.vehicle}', "
                    f"the mission for '{root.vehicle}'",
                    included.vehicle_span,
                )
        for profile in self.profiles:
            if profile.name == root.vehicle:
                return profile
        try:
            return load_bundled_profile(root.vehicle)
        except ProfileError as exc:
            names = ", ".join(p.name for p in self.profiles)
            self.error(
                "CORAL006",
                f"no vehicle profile for '{root.vehicle}'",
                root.vehicle_span,
                exc.detail,
                *([f"profiles given: {names}"] if names else []),
                "pass the profile file with --profile FILE",
            )
            return None

    def _part_note(self) -> tuple[str, ...]:
        """For a part compiled on its own: where its whole mission is."""
        if self.root_part is None:
            return ()
        return (
            f"this file is a part of {self.root_part.mission} (line {self.root_part.span.line}): "
            "check that mission, or give this file to coral-check, which checks the "
            "mission it is a part of",
        )

    def _consts(self) -> dict[str, _ConstInfo]:
        consts: dict[str, _ConstInfo] = {}
        for declaration, file in self.declarations:
            if not isinstance(declaration, ast.Const):
                continue
            previous = consts.get(declaration.name)
            if previous is not None:
                if previous.file == file or previous.decl.value != declaration.value:
                    self.error(
                        "CORAL003",
                        f"constant '{declaration.name}' is declared twice",
                        declaration.span,
                        f"first declared at {previous.decl.span}",
                    )
                continue
            consts[declaration.name] = _ConstInfo(declaration, file)
        return consts

    def _resolve(
        self, value: ast.Value, consts: dict[str, _ConstInfo]
    ) -> ast.Number | ast.String | None:
        if isinstance(value, ast.Name):
            info = consts.get(value.name)
            if info is None:
                self.error(
                    "CORAL002",
                    f"unknown constant '{value.name}'{did_you_mean(value.name, consts)}",
                    value.span,
                )
                return None
            return info.decl.value
        return value

    def _count(
        self, value: ast.Number | ast.Name, consts: dict[str, _ConstInfo], what: str, minimum: int
    ) -> int | None:
        resolved = self._resolve(value, consts)
        if resolved is None:
            return None
        if (
            not isinstance(resolved, ast.Number)
            or not isinstance(resolved.value, int)
            or resolved.unit is not None
        ):
            shown = _show(resolved)
            self.error("CORAL005", f"{what} must be a whole number, got {shown}", value.span)
            return None
        if resolved.value < minimum:
            self.error(
                "CORAL005", f"{what} must be at least {minimum}, got {resolved.value}", value.span
            )
            return None
        return resolved.value

    def _places(self, consts: dict[str, _ConstInfo]) -> dict[str, _PlaceInfo]:
        places: dict[str, _PlaceInfo] = {}
        for declaration, file in self.declarations:
            if not isinstance(declaration, ast.Places):
                continue
            for decl in declaration.places:
                initial = (
                    self._count(decl.initial, consts, f"initial tokens of '{decl.name}'", 0)
                    if decl.initial is not None
                    else None
                )
                capacity = (
                    self._count(decl.capacity, consts, f"capacity of '{decl.name}'", 1)
                    if decl.capacity is not None
                    else None
                )
                info = places.get(decl.name)
                if info is None:
                    places[decl.name] = _PlaceInfo(
                        decl.name,
                        decl.span,
                        initial,
                        decl.initial.span if decl.initial else None,
                        capacity,
                        decl.capacity.span if decl.capacity else None,
                        file,
                    )
                    continue
                if info.file == file:
                    self.error(
                        "CORAL003",
                        f"place '{decl.name}' is declared twice",
                        decl.span,
                        f"first declared at {info.span}",
                    )
                    continue
                # The same place declared in another file (a shared interface place).
                if initial is not None:
                    if info.initial is not None and info.initial != initial:
                        self.error(
                            "CORAL003",
                            f"place '{decl.name}' is given {initial} initial tokens here and "
                            f"{info.initial} at {info.initial_span}",
                            decl.span,
                        )
                    info.initial, info.initial_span = initial, decl.span
                if capacity is not None:
                    if info.capacity is not None and info.capacity != capacity:
                        self.error(
                            "CORAL003",
                            f"place '{decl.name}' is given capacity {capacity} here and "
                            f"{info.capacity} at {info.capacity_span}",
                            decl.span,
                        )
                    info.capacity, info.capacity_span = capacity, decl.span
        for info in places.values():
            if info.capacity is not None and (info.initial or 0) > info.capacity:
                self.error(
                    "CORAL005",
                    f"place '{info.name}' starts with {info.initial} tokens, "
                    f"more than its capacity {info.capacity}",
                    info.initial_span or info.span,
                )
        return places

    def _inputs(self, places: dict[str, _PlaceInfo]) -> dict[str, _InputInfo]:
        """The ``input`` statements, checked, in first-declaration order; each input
        name is added to ``places`` (a `place` of the same name is the same place).

        An input declared twice (say in two included files) is one input. The place
        must start empty and have no capacity: the operator's token arrives only when
        the operator acts, and a capacity would block the operator's transition.
        """
        inputs: dict[str, _InputInfo] = {}
        for declaration, file in self.declarations:
            if not isinstance(declaration, ast.Inputs):
                continue
            for decl in declaration.names:
                if decl.name in inputs:
                    continue
                if len(inputs) == MAX_INPUTS:
                    self.error(
                        "CORAL010",
                        f"too many operator inputs: '{decl.name}' would be number "
                        f"{MAX_INPUTS + 1}, at most {MAX_INPUTS} are supported",
                        decl.span,
                        "inputs declared: " + ", ".join(inputs),
                    )
                    continue
                info = places.get(decl.name)
                if info is None:
                    places[decl.name] = _PlaceInfo(decl.name, decl.span, file=file)
                else:
                    if info.initial:
                        self.error(
                            "CORAL010",
                            f"operator input '{decl.name}' must start empty, but the place "
                            f"is given {info.initial} initial tokens at {info.initial_span}",
                            decl.span,
                            "only the operator marks an input place",
                        )
                    if info.capacity is not None:
                        self.error(
                            "CORAL010",
                            f"operator input '{decl.name}' cannot have a capacity "
                            f"(given at {info.capacity_span})",
                            decl.span,
                            "a full input place would block the operator",
                        )
                inputs[decl.name] = _InputInfo(decl.name, decl.span)
        return inputs

    def _check_input_writers(self, inputs: dict[str, _InputInfo]) -> None:
        """Refuse a ``signal`` or reply mapping that marks an operator input."""
        if not inputs:
            return
        for declaration, _ in self.declarations:
            if not isinstance(declaration, ast.TransitionDecl):
                continue
            for ref in declaration.signal:
                if ref.place in inputs:
                    self.error(
                        "CORAL010",
                        f"transition '{declaration.name}' signals operator input "
                        f"'{ref.place}': only the operator marks it",
                        ref.span,
                        f"'{ref.place}' is declared an input at {inputs[ref.place].span}; "
                        "a transition may wait on it, not signal it",
                    )
            if declaration.action is None:
                continue
            for reply in declaration.action.replies:
                for ref in reply.targets or ():
                    if ref.place in inputs:
                        self.error(
                            "CORAL010",
                            f"reply '{reply.reply}' of transition '{declaration.name}' marks "
                            f"operator input '{ref.place}': only the operator marks it",
                            ref.span,
                            f"'{ref.place}' is declared an input at {inputs[ref.place].span}",
                        )

    def _tokens(
        self,
        refs: Sequence[ast.TokenRef],
        places: dict[str, _PlaceInfo],
        consts: dict[str, _ConstInfo],
        what: str,
    ) -> tuple[tuple[str, int], ...] | None:
        result: dict[str, int] = {}
        ok = True
        for ref in refs:
            if ref.place not in places:
                self.error(
                    "CORAL002",
                    f"unknown place '{ref.place}'{did_you_mean(ref.place, places)}",
                    ref.span,
                )
                ok = False
                continue
            weight = 1
            if ref.weight is not None:
                counted = self._count(ref.weight, consts, f"weight of '{ref.place}'", 1)
                if counted is None:
                    ok = False
                    continue
                weight = counted
            if ref.place in result:
                self.error(
                    "CORAL003",
                    f"place '{ref.place}' appears twice in {what}; "
                    f"write '{ref.place}*N' for N tokens",
                    ref.span,
                )
                ok = False
                continue
            result[ref.place] = weight
        return tuple(result.items()) if ok else None

    def _finals(
        self, places: dict[str, _PlaceInfo], consts: dict[str, _ConstInfo]
    ) -> list[FinalMarking]:
        finals: list[FinalMarking] = []
        seen: set[tuple[tuple[str, int], ...]] = set()
        for declaration, _ in self.declarations:
            if isinstance(declaration, ast.Final):
                tokens = self._tokens(declaration.tokens, places, consts, "a final marking")
                if tokens is not None and tuple(sorted(tokens)) not in seen:
                    seen.add(tuple(sorted(tokens)))
                    finals.append(FinalMarking(tokens, declaration.span))
        return finals

    def _assertions(
        self, places: dict[str, _PlaceInfo], consts: dict[str, _ConstInfo]
    ) -> dict[int, Assertion]:
        """``never``, ``reachable``, ``bound`` and ``within``, by position among the
        declarations."""
        assertions: dict[int, Assertion] = {}
        for position, (declaration, _) in enumerate(self.declarations):
            if not isinstance(declaration, ast.AssertDecl):
                continue
            if declaration.kind is ast.AssertKind.WITHIN:
                within = self._within(declaration, places, consts)
                if within is not None:
                    assertions[position] = within
                continue
            tokens = self._tokens(declaration.tokens, places, consts, "an assertion")
            bound = None
            if declaration.bound is not None:
                bound = self._count(declaration.bound, consts, "a bound", 0)
                if bound is None:
                    continue
            if tokens is not None:
                assertions[position] = Assertion(
                    AssertKind(declaration.kind.value), tokens, bound, declaration.span
                )
        return assertions

    def _within(
        self,
        declaration: ast.AssertDecl,
        places: dict[str, _PlaceInfo],
        consts: dict[str, _ConstInfo],
    ) -> Assertion | None:
        """``assert within T { ... }``: the places (at least one) and the deadline in
        seconds. Only timed analysis decides it; the net carries it for that."""
        tokens = self._tokens(declaration.tokens, places, consts, "an assertion")
        if not declaration.tokens:
            self.error(
                "CORAL005",
                "'assert within' names no place, so it would hold at the start",
                declaration.span,
                "name the places the mission must mark in time, e.g. "
                "'assert within 600 s { done }'",
            )
        assert declaration.deadline is not None  # the parser always sets it for 'within'
        deadline = self._deadline(declaration.deadline, consts)
        if tokens is None or deadline is None or not declaration.tokens:
            return None
        return Assertion(
            AssertKind.WITHIN,
            tokens,
            span=declaration.span,
            text=format_declaration(declaration)[0],
            deadline_s=deadline,
        )

    def _deadline(
        self, value: ast.Number | ast.Name, consts: dict[str, _ConstInfo]
    ) -> float | None:
        """The deadline of ``assert within`` in seconds: a time with its unit (a bare
        number would leave the reader to guess seconds or minutes), above 0 and finite
        once converted (``1e308 h`` is not)."""
        resolved = self._resolve(value, consts)
        if resolved is None:
            return None
        via: tuple[str, ...] = ()
        if isinstance(value, ast.Name):
            via = (f"'{value.name}' is defined at {consts[value.name].decl.span}",)
        what = "the deadline of 'assert within'"
        time_units = ", ".join(u for u in units.UNITS if units.dimension(u) == "time")
        if not isinstance(resolved, ast.Number):
            self.error(
                "CORAL005", f"{what} must be a time, got {_show(resolved)}", value.span, *via
            )
            return None
        if resolved.unit is None:
            self.error(
                "CORAL005",
                f"{what} needs a time unit: write '{_show(resolved)} s' ({time_units})",
                value.span,
                *via,
            )
            return None
        dimension = units.dimension(resolved.unit)
        if dimension != "time":
            self.error(
                "CORAL005",
                f"{what} must be a time ({time_units}), got '{_show(resolved)}' ({dimension})",
                value.span,
                *via,
            )
            return None
        seconds = units.convert(float(resolved.value), resolved.unit, "s")
        if not math.isfinite(seconds):
            self.error(
                "CORAL005", f"{what} is out of range, got {_show(resolved)}", value.span, *via
            )
            return None
        if seconds <= 0:
            self.error(
                "CORAL005",
                f"{what} must be more than 0 s, got {_show(resolved)}",
                value.span,
                *via,
            )
            return None
        return seconds

    def _temporal(
        self,
        places: dict[str, _PlaceInfo],
        consts: dict[str, _ConstInfo],
        profile: VehicleProfile | None,
        finals: list[FinalMarking],
    ) -> dict[int, Assertion]:
        """``assert always/eventually/leadsto/ltl/ctl``, lowered by `PropertyLowering`,
        by position among the declarations."""
        declared = [
            (position, d)
            for position, (d, _) in enumerate(self.declarations)
            if isinstance(d, ast.TemporalAssert)
        ]
        if not declared:
            return {}
        transitions: dict[str, TransitionInfo] = {}
        pending: list[str] = []
        for declaration, _ in self.declarations:
            if not isinstance(declaration, ast.TransitionDecl):
                continue
            if declaration.name in transitions:
                continue
            action = declaration.action
            if action is None:
                transitions[declaration.name] = TransitionInfo(None, ())
                continue
            spec = profile.command(action.command) if profile is not None else None
            replies = spec.replies if spec is not None else tuple(r.reply for r in action.replies)
            pending_name = declaration.name + PENDING_SUFFIX
            pending.append(pending_name)
            transitions[declaration.name] = TransitionInfo(pending_name, tuple(replies))
        names = Names(
            places=tuple(places),
            constants=frozenset(consts),
            transitions=transitions,
            finals=[f.tokens for f in finals],
            state_places=(*places, *pending),
        )
        lowering = PropertyLowering(
            names,
            lambda value, what, minimum: self._count(value, consts, what, minimum),
            self.error,
        )
        assertions: dict[int, Assertion] = {}
        for position, declaration in declared:
            lowered = lowering.lower(declaration)
            if lowered is not None:
                kind, formula = lowered
                assertions[position] = Assertion(
                    kind,
                    (),
                    span=declaration.span,
                    formula=formula,
                    text=format_temporal(declaration),
                )
        return assertions

    def _requirements(self) -> tuple[str, ...]:
        """The names of the ``require`` lines, checked; each once, in source order."""
        found: dict[str, None] = {}
        for declaration, _ in self.declarations:
            if not isinstance(declaration, ast.Require):
                continue
            if declaration.name not in REQUIREMENTS:
                self.error(
                    "CORAL009",
                    f"unknown requirement '{declaration.name}'"
                    f"{did_you_mean(declaration.name, REQUIREMENTS)}",
                    declaration.name_span,
                    f"known requirements: {', '.join(REQUIREMENTS)}",
                )
                continue
            found[declaration.name] = None
        return tuple(found)

    def _transitions(
        self,
        places: dict[str, _PlaceInfo],
        consts: dict[str, _ConstInfo],
        profile: VehicleProfile | None,
        vehicle: str | None,
    ) -> tuple[list[Transition], list[Place]]:
        transitions: list[Transition] = []
        pending: list[Place] = []
        seen: dict[str, Span] = {}
        for declaration, _ in self.declarations:
            if not isinstance(declaration, ast.TransitionDecl):
                continue
            name = declaration.name
            if name in seen:
                self.error(
                    "CORAL003",
                    f"transition '{name}' is declared twice",
                    declaration.span,
                    f"first declared at {seen[name]}",
                )
                continue
            seen[name] = declaration.span
            if name in places:
                self.error(
                    "CORAL003",
                    f"'{name}' names both a place and a transition",
                    declaration.span,
                    f"the place is declared at {places[name].span}",
                )
            priority = 0
            if declaration.priority is not None:
                value = self._resolve(declaration.priority, consts)
                if (
                    isinstance(value, ast.Number)
                    and isinstance(value.value, int)
                    and value.unit is None
                ):
                    priority = value.value
                elif value is not None:
                    self.error(
                        "CORAL005",
                        f"priority must be a whole number, got {_show(value)}",
                        declaration.priority.span,
                    )
            inputs = self._tokens(declaration.wait, places, consts, "'wait'")
            outputs = self._tokens(declaration.signal, places, consts, "'signal'")
            if declaration.action is None:
                if inputs is not None and outputs is not None:
                    transitions.append(
                        Transition(
                            name,
                            inputs,
                            outputs,
                            TransitionKind.PLAIN,
                            priority,
                            name,
                            declaration.span,
                        )
                    )
                continue
            lowered = self._action(
                declaration, declaration.action, places, consts, profile, vehicle
            )
            if lowered is None or inputs is None or outputs is None:
                continue
            command, replies = lowered
            pending_name = name + PENDING_SUFFIX
            pending.append(
                Place(
                    pending_name,
                    0,
                    PlaceKind.PENDING,
                    label=f"{command.name} pending",
                    span=declaration.action.span,
                    resources=command.resources,
                    pending_of=name,
                )
            )
            transitions.append(
                Transition(
                    name,
                    inputs,
                    (*outputs, (pending_name, 1)),
                    TransitionKind.COMMAND,
                    priority,
                    command.header(),
                    declaration.span,
                    command=command,
                    pending=pending_name,
                )
            )
            for reply, targets, span in replies:
                transitions.append(
                    Transition(
                        f"{name}.{reply}",
                        ((pending_name, 1),),
                        targets,
                        TransitionKind.REPLY,
                        0,
                        command.name,
                        span,
                        reply_to=name,
                        reply=reply,
                    )
                )
        return transitions, pending

    def _action(
        self,
        transition: ast.TransitionDecl,
        action: ast.Action,
        places: dict[str, _PlaceInfo],
        consts: dict[str, _ConstInfo],
        profile: VehicleProfile | None,
        vehicle: str | None,
    ) -> tuple[Command, list[tuple[str, tuple[tuple[str, int], ...], Span]]] | None:
        if vehicle is not None and action.system != vehicle:
            self.error(
                "CORAL006",
                f"this mission commands vehicle '{vehicle}', not '{action.system}'",
                action.span,
                f"write {vehicle}({action.command}, ...)",
            )
            return None
        if profile is None:
            return None
        spec = profile.command(action.command)
        if spec is None:
            self.error(
                "CORAL101",
                f"unknown command '{action.command}' for {profile.name}"
                f"{did_you_mean(action.command, profile.command_names)}",
                action.command_span,
                f"{profile.name} accepts: {', '.join(profile.command_names)}",
            )
            return None
        params = self._params(action, spec, consts)
        replies = self._replies(transition, action, spec, places, consts)
        if params is None or replies is None:
            return None
        command = Command(profile.name, spec.name, params, spec.resources, spec.replies)
        return command, replies

    def _params(
        self, action: ast.Action, spec: CommandSpec, consts: dict[str, _ConstInfo]
    ) -> tuple[tuple[str, Value], ...] | None:
        given: dict[str, ast.Arg] = {}
        ok = True
        seen_named = False
        signature = _Signature(spec)
        for index, arg in enumerate(action.args):
            if arg.name is None:
                if seen_named:
                    self.error(
                        "CORAL102",
                        "positional argument after a named one",
                        arg.span,
                        f"signature: {signature}",
                    )
                    ok = False
                    continue
                if index >= len(spec.params):
                    self.error(
                        "CORAL102",
                        f"{spec.name} takes {len(spec.params)} parameter"
                        f"{'' if len(spec.params) == 1 else 's'}, got {len(action.args)}",
                        arg.span,
                        f"signature: {signature}",
                    )
                    ok = False
                    continue
                pname = spec.params[index].name
            else:
                seen_named = True
                pname = arg.name
                if spec.param(pname) is None:
                    names = [p.name for p in spec.params]
                    self.error(
                        "CORAL102",
                        f"{spec.name} has no parameter '{pname}'{did_you_mean(pname, names)}",
                        arg.span,
                        f"signature: {signature}",
                    )
                    ok = False
                    continue
            if pname in given:
                self.error("CORAL102", f"parameter '{pname}' given twice", arg.span)
                ok = False
                continue
            given[pname] = arg
        missing = [p.name for p in spec.params if p.name not in given]
        if missing and ok:
            plural = "s" if len(missing) > 1 else ""
            self.error(
                "CORAL102",
                f"{spec.name} is missing parameter{plural} {', '.join(repr(m) for m in missing)}",
                action.command_span,
                f"signature: {signature}",
            )
            ok = False
        values: list[tuple[str, Value]] = []
        for param in spec.params:
            if param.name not in given:
                continue
            value = self._param_value(spec, param, given[param.name], consts)
            if value is None:
                ok = False
            else:
                values.append((param.name, value))
        return tuple(values) if ok else None

    def _param_value(
        self, spec: CommandSpec, param: ParamSpec, arg: ast.Arg, consts: dict[str, _ConstInfo]
    ) -> Value | None:
        resolved = self._resolve(arg.value, consts)
        if resolved is None:
            return None
        where = arg.value.span
        via: tuple[str, ...] = ()
        if isinstance(arg.value, ast.Name):
            via = (f"'{arg.value.name}' is defined at {consts[arg.value.name].decl.span}",)
        label = f"parameter '{param.name}' of {spec.name}"
        if param.type == "string":
            if not isinstance(resolved, ast.String):
                self.error("CORAL103", f"{label} is text, got {_show(resolved)}", where, *via)
                return None
            return resolved.value
        if not isinstance(resolved, ast.Number):
            self.error(
                "CORAL103",
                f"{label} is a number ({param.type}), got {_show(resolved)}",
                where,
                *via,
            )
            return None
        number: float | int = resolved.value
        if param.type == "int" and not isinstance(number, int):
            self.error(
                "CORAL103", f"{label} must be a whole number, got {_show(resolved)}", where, *via
            )
            return None
        if resolved.unit is not None:
            if param.unit is None:
                self.error("CORAL104", f"{label} takes no unit, got '{resolved.unit}'", where, *via)
                return None
            try:
                number = units.convert(float(number), resolved.unit, param.unit)
            except ValueError:
                self.error(
                    "CORAL104",
                    f"{label} is in {param.unit} ({units.dimension(param.unit)}), got "
                    f"'{resolved.unit}' ({units.dimension(resolved.unit)})",
                    where,
                    *via,
                )
                return None
            if not math.isfinite(number):  # 1e308 km: finite as written, not in metres
                self.error(
                    "CORAL105", f"{label} is out of range, got {_show(resolved)}", where, *via
                )
                return None
            if param.type == "int":
                if not float(number).is_integer():
                    self.error(
                        "CORAL103",
                        f"{label} must be a whole number of {param.unit}, got {number:g}",
                        where,
                        *via,
                    )
                    return None
                number = int(number)
        if param.type == "float":
            number = float(number)
        unit = f" {param.unit}" if param.unit else ""
        if (param.minimum is not None and number < param.minimum) or (
            param.maximum is not None and number > param.maximum
        ):
            low = "-inf" if param.minimum is None else f"{param.minimum:g}"
            high = "inf" if param.maximum is None else f"{param.maximum:g}"
            self.error(
                "CORAL105",
                f"{label} must be in [{low}, {high}]{unit}, got {number:g}{unit}",
                where,
                *via,
            )
            return None
        return number

    def _replies(
        self,
        transition: ast.TransitionDecl,
        action: ast.Action,
        spec: CommandSpec,
        places: dict[str, _PlaceInfo],
        consts: dict[str, _ConstInfo],
    ) -> list[tuple[str, tuple[tuple[str, int], ...], Span]] | None:
        mapped: dict[str, tuple[tuple[tuple[str, int], ...], Span]] = {}
        misspelt: set[str] = set()  # kinds a misspelling already points at: no second error
        ok = True
        for reply in action.replies:
            if reply.reply not in spec.replies:
                misspelt.update(
                    difflib.get_close_matches(reply.reply, spec.replies, n=1, cutoff=0.6)
                )
                self.error(
                    "CORAL107",
                    f"{spec.name} never replies '{reply.reply}'"
                    f"{did_you_mean(reply.reply, spec.replies)}",
                    reply.span,
                    f"{spec.name} replies: {', '.join(spec.replies)}",
                )
                ok = False
                continue
            if reply.reply in mapped:
                self.error(
                    "CORAL108",
                    f"reply '{reply.reply}' is mapped twice",
                    reply.span,
                    f"first mapped at {mapped[reply.reply][1]}",
                )
                ok = False
                continue
            targets: tuple[tuple[str, int], ...] | None = ()
            if reply.targets is not None:
                targets = self._tokens(reply.targets, places, consts, f"reply '{reply.reply}'")
            if targets is None:
                ok = False
                continue
            mapped[reply.reply] = (targets, reply.span)
        missing = [r for r in spec.replies if r not in mapped]
        if missing and not set(missing) <= misspelt:
            plural = "s" if len(missing) > 1 else ""
            example = ", ".join(f"{r}: PLACE" for r in missing)
            self.error(
                "CORAL106",
                f"{spec.name} can reply {', '.join(repr(r) for r in missing)}, but "
                f"transition '{transition.name}' does not say where that reply goes",
                action.command_span,
                f"map the reply kind{plural} to a place ({example}), "
                f"or write '{missing[0]}: ignore' to drop it on purpose",
            )
            ok = False
        if not ok:
            return None
        return [(r, mapped[r][0], mapped[r][1]) for r in spec.replies]

    def _build(
        self,
        root: ast.Mission,
        places: dict[str, _PlaceInfo],
        pending: list[Place],
        transitions: list[Transition],
        finals: list[FinalMarking],
        assertions: list[Assertion],
        requirements: tuple[str, ...] = (),
        inputs: dict[str, _InputInfo] | None = None,
    ) -> Net:
        mission_places = [
            Place(
                info.name, info.initial or 0, PlaceKind.MISSION, info.capacity, info.name, info.span
            )
            for info in places.values()
        ]
        complements = [
            Place(
                info.name + FREE_SUFFIX,
                info.capacity - (info.initial or 0),
                PlaceKind.COMPLEMENT,
                label=f"free room of {info.name}",
                span=info.capacity_span,
                complement_of=info.name,
            )
            for info in places.values()
            if info.capacity is not None
        ]
        bounded = {
            info.name: info.name + FREE_SUFFIX
            for info in places.values()
            if info.capacity is not None
        }
        if bounded:
            transitions = [_with_complements(t, bounded) for t in transitions]
        armed, operator = _operator_inputs(list((inputs or {}).values()))
        return Net(
            name=root.name or "mission",
            places=(*mission_places, *pending, *complements, *armed),
            transitions=(*transitions, *operator),
            finals=tuple(finals),
            assertions=tuple(assertions),
            vehicle=root.vehicle,
            sources=tuple(self.sources),
            requirements=requirements,
        )


def _operator_inputs(inputs: list[_InputInfo]) -> tuple[list[Place], list[Transition]]:
    """For each input ``X``: the place ``X.armed`` (1 token: the operator may still give
    it) and the INPUT transition ``X.operator`` moving that token to ``X``."""
    places: list[Place] = []
    transitions: list[Transition] = []
    for info in inputs:
        armed = info.name + ARMED_SUFFIX
        places.append(
            Place(
                armed,
                1,
                PlaceKind.ARMED,
                label=f"operator may give {info.name}",
                span=info.span,
                armed_of=info.name,
            )
        )
        transitions.append(
            Transition(
                info.name + OPERATOR_SUFFIX,
                ((armed, 1),),
                ((info.name, 1),),
                TransitionKind.INPUT,
                0,
                f"operator: {info.name}",
                info.span,
                operator_input=info.name,
            )
        )
    return places, transitions


def _with_complements(transition: Transition, bounded: dict[str, str]) -> Transition:
    """Add arcs to complement places so firing never overfills a bounded place."""
    pre = dict(transition.inputs)
    post = dict(transition.outputs)
    changed = False
    for place, free in bounded.items():
        delta = post.get(place, 0) - pre.get(place, 0)
        if delta > 0:
            pre[free] = delta
            changed = True
        elif delta < 0:
            post[free] = -delta
            changed = True
    if not changed:
        return transition
    return replace(transition, inputs=tuple(pre.items()), outputs=tuple(post.items()))


def _show(value: ast.Number | ast.String) -> str:
    if isinstance(value, ast.String):
        return f'text "{value.value}"'
    unit = f" {value.unit}" if value.unit else ""
    return f"{value.value!r}{unit}"


def _clip(text: str, width: int = 200) -> str:
    """``text`` (a path) cut to ``width`` characters: a message stays a line or two."""
    return text if len(text) <= width else text[: width - 3] + "..."


def _display_path(path: Path) -> str:
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


class _Signature:
    """A command's signature for notes, built only if an error note needs it."""

    def __init__(self, spec: CommandSpec) -> None:
        self.spec = spec

    def __str__(self) -> str:
        return f"{self.spec.name}({', '.join(p.describe() for p in self.spec.params)})"
