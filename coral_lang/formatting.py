"""The canonical layout of a mission file, comments kept: what ``coral-check fmt`` writes.

The printer (`coral_lang.printer`) lays out a syntax tree, and the tree has no comments.
A formatter that lost them would destroy a user's file, and one kind of comment is load
bearing: lint reads ``# coral: allow CODE -- why`` from the line it ends (or, alone on
its line, the next one). So the layout is the printer's, and the comments are put back
by where they were:

* Each top-level statement is printed on its own (``mission``, ``vehicle`` and every
  declaration, in the order written), and the tokens of the printed text are matched to
  the tokens of the source (they are nearly the same sequence: the printer only
  normalises numbers, braces and parentheses), which says on which printed line every
  source token ended up.
* A comment after code on its line (trailing) goes at the end of the printed line that
  holds the first token of that source line: a statement written on one line and printed
  on several keeps its comment by its first line, where a finding about it points. A
  comment alone on its line goes on its own line just above the printed line of the
  token that follows it, at that line's indentation.
* When several comments end up on one printed line, all but the last trailing one go
  above it, in their order: no comment is ever merged into another (that would change
  what lint reads) and their order never changes.
* Blank lines between top-level statements and the comments before them are kept, at
  most one at a time; blank lines inside a statement are dropped.
* Trailing comments on consecutive lines are aligned, two spaces after the longest line;
  so are the ``=`` of consecutive constants and the clauses of consecutive one-line
  transitions.

Where the source's own lines carry meaning the layout follows them: a ``place`` or
``input`` list written over several lines keeps its breaks (its items' comments stay by
them), and a transition without an action written on one line stays on one line.

Lint's findings must not change, and rather than trust the rules above to get every
case right, `format_source` checks: for every place a finding can point at (`_anchors`)
it compares which suppression comments cover its line before and after, and lays the
statements where they differ out as written (`_clusters`: statements sharing a source
line go together), until they agree. A comment reading ``# coral: part of ...`` is load
bearing too (alone on its line before the first declaration it makes the file a part of
a mission; alone anywhere else it is an error; after code it is a plain comment), so the
same check holds what the compiler makes of each such comment (`_part_comments`): one
the layout would move between trailing and own-line, or above the first declaration,
keeps its statements as written. Formatting twice gives what formatting once gave,
and the formatted text parses to the same tree (`tests/coral_lang/test_formatting.py`
holds it to all of that, on every example and on generated missions).
"""

from __future__ import annotations

import bisect
import difflib
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import accumulate

from coral_lang import ast
from coral_lang.compiler import part_header
from coral_lang.diagnostics import CompileError, Severity
from coral_lang.gcpause import cyclic_gc_paused
from coral_lang.lexer import Kind, Token, tokenize
from coral_lang.parser import parse_tokens
from coral_lang.printer import MAX_WIDTH, format_declaration, list_items, transition_fields

_TRAILING_GAP = 2
"""Spaces between the longest code line of a run and its aligned trailing comments."""

_SUPPRESSION = re.compile(r"#\s*coral:\s*allow\b")
"""A comment lint may read as a suppression (lint's own pattern is stricter, so every
comment it reads is one of these)."""


def format_source(text: str, file: str) -> str:
    """The canonical text of mission ``text`` (read from ``file``), comments preserved.

    Raises `CompileError` with the parse diagnostics when ``text`` does not parse: only
    a whole tree can be laid out, and half a file rewritten would lose the rest.
    """
    with cyclic_gc_paused():
        comments: list[Token] = []
        tokens, diagnostics = tokenize(text, file, comments)
        mission, diagnostics = parse_tokens(tokens, file, diagnostics)
        if any(d.severity is Severity.ERROR for d in diagnostics):
            raise CompileError(diagnostics, {file: text})
        items = _items(mission, tokens)
        clusters = _clusters(items, tokens)
        wanted = _coverage(text, comments, _anchors(mission))
        parts = _part_comments(text, file, comments)
        item_at = [(tokens[item.start].line, tokens[item.start].col) for item in items]
        kept: set[int] = set()  # clusters laid out as written
        while True:
            placed = _place_comments(comments, tokens, items, clusters, kept)
            out = _render(items, placed, text, clusters, kept)
            changed = _changed(out, file, wanted)
            moved = _parts_changed(out, file, parts)
            if not changed and not moved:
                return out
            owners = {clusters[max(bisect.bisect_right(item_at, at) - 1, 0)] for at in changed}
            for at in moved if items else ():  # between two statements: keep both
                after = bisect.bisect_right(item_at, at)
                owners.update(clusters[k] for k in (max(after - 1, 0), min(after, len(items) - 1)))
            owners -= kept
            if not owners:  # not expected (clusters as written read as the source
                # does), but what the file means is never risked: the text as written
                return _as_written(text, file, parts)
            kept |= owners


@dataclass(slots=True)
class _Item:
    """One top-level statement: where its tokens start, and its printed lines."""

    start: int  # index of its first token
    lines: list[str]
    line_of: list[int | None] = field(default_factory=list)  # per source token: printed line
    first_line: int = 0  # the source line its first token is on
    last_line: int = 0  # the last source line its tokens are on
    fields: list[str] | None = None  # a one-line transition: its columns


@dataclass(slots=True)
class _Placed:
    """The comments that go with one printed line."""

    above: list[Token] = field(default_factory=list)
    trailing: Token | None = None


def _anchors(mission: ast.Mission) -> list[tuple[int, int]]:
    """Where a lint finding can point, in source order: the mission's name, the start of
    every statement, every place and input of a list (the first included: after
    ``place`` alone on its line, the first name starts another line)."""
    found: list[tuple[int, int]] = []
    if mission.name is not None:
        found.append((mission.name_span.line, mission.name_span.col))
    for declaration in mission.declarations:
        found.append((declaration.span.line, declaration.span.col))
        if isinstance(declaration, ast.Places):
            found.extend((p.span.line, p.span.col) for p in declaration.places)
        elif isinstance(declaration, ast.Inputs):
            found.extend((n.span.line, n.span.col) for n in declaration.names)
    return sorted(set(found))


def _coverage(
    text: str, comments: list[Token], anchors: list[tuple[int, int]]
) -> dict[tuple[int, int], frozenset[int]]:
    """Per anchor, the suppression-like comments (by their number in the file) that
    cover its line as lint reads them: a comment after code covers its own line, one
    alone on its line the next line."""
    lines = text.split("\n")
    covering: dict[int, set[int]] = {}
    for number, comment in enumerate(comments):
        if _SUPPRESSION.search(comment.text) is None:
            continue
        alone = not lines[comment.line - 1][: comment.col - 1].strip()
        covering.setdefault(comment.line + alone, set()).add(number)
    return {at: frozenset(covering.get(at[0], ())) for at in anchors}


def _changed(
    out: str, file: str, wanted: dict[tuple[int, int], frozenset[int]]
) -> list[tuple[int, int]]:
    """The source anchors whose suppressions in ``out`` differ from ``wanted``."""
    if not any(wanted.values()) and _SUPPRESSION.search(out) is None:
        return []  # no suppression anywhere: nothing lint reads can have moved
    comments: list[Token] = []
    tokens, diagnostics = tokenize(out, file, comments)
    mission, _ = parse_tokens(tokens, file, diagnostics)
    got = list(_coverage(out, comments, _anchors(mission)).values())
    source = list(wanted)
    if len(got) != len(source):
        return source
    return [at for at, cover in zip(source, got, strict=True) if wanted[at] != cover]


_PART_LIKE = re.compile(r"#[ \t]*coral:[ \t]*part\b")
"""A comment the compiler may read as a part's header (`coral_lang.compiler.part_header`):
only alone on its line, before the first declaration, and well formed is it one; written
anywhere else it is an error (CORAL011), and after code it is a plain comment."""

_LINE_NUMBER = re.compile(r"\bline \d+")


def _part_comments(
    text: str, file: str, comments: list[Token]
) -> list[tuple[tuple[int, int], str]]:
    """Per comment that reads like a part header, in order: where it is, and what the
    compiler makes of it ("" nothing, "header", or its error without line numbers,
    which formatting moves). Equal lists before and after formatting: the same part
    header and the same errors about headers, so the same compile."""
    like = [c for c in comments if _PART_LIKE.search(c.text) is not None]
    if not like:
        return []
    header, errors = part_header(text, file)
    said = {e.span.line: _LINE_NUMBER.sub("line", e.message) for e in errors if e.span}
    if header is not None:
        said[header.span.line] = "header"
    return [((c.line, c.col), said.get(c.line, "")) for c in like]


def _parts_changed(
    out: str, file: str, parts: list[tuple[tuple[int, int], str]]
) -> list[tuple[int, int]]:
    """The source positions of the part-header-like comments ``out`` reads differently
    from the source (a trailing one moved onto its own line, an own-line one made
    trailing or moved above the first declaration)."""
    if not parts:
        return []
    comments: list[Token] = []
    tokenize(out, file, comments)
    got = _part_comments(out, file, comments)
    if len(got) != len(parts):
        return [at for at, _ in parts]
    return [at for (at, want), (_, have) in zip(parts, got, strict=True) if want != have]


def _as_written(text: str, file: str, parts: list[tuple[tuple[int, int], str]]) -> str:
    """``text`` with trailing white space dropped, or as it is if even that would change
    how a part header reads (a header ending in a form feed is malformed)."""
    lines = text.split("\n")  # the lexer's lines: not str.splitlines's (form feed...)
    if lines[-1] == "":
        lines.pop()
    out = "".join(line.rstrip() + "\n" for line in lines)
    return text if _parts_changed(out, file, parts) else out


def _clusters(items: list[_Item], tokens: list[Token]) -> list[int]:
    """Per item, its cluster: statements sharing a source line are laid out as written
    together or not at all."""
    out: list[int] = []
    for number, item in enumerate(items):
        joined = number > 0 and tokens[item.start].line == items[number - 1].last_line
        out.append(out[-1] if joined else (out[-1] + 1 if out else 0))
    return out


def _list_lines(declaration: ast.Places | ast.Inputs) -> list[str]:
    """A ``place`` or ``input`` list broken where its source broke before an item, the
    continuation lines under the first item: a list written over several lines stays
    so, and the comments about its items stay by them (and by the same places, which
    is what lint's suppressions read)."""
    keyword = "place " if isinstance(declaration, ast.Places) else "input "
    groups: list[tuple[int, list[str]]] = []
    for line, text in list_items(declaration):
        if groups and groups[-1][0] == line:
            groups[-1][1].append(text)
        else:
            groups.append((line, [text]))
    last = len(groups) - 1
    return [
        (keyword if k == 0 else " " * len(keyword)) + ", ".join(texts) + ("," * (k < last))
        for k, (_, texts) in enumerate(groups)
    ]


def _items(mission: ast.Mission, tokens: list[Token]) -> list[_Item]:
    """The statements of ``mission`` in source order, their tokens matched to the printed ones."""
    starts: list[tuple[tuple[int, int], list[str], ast.Declaration | None]] = []
    if mission.name is not None:
        at = (mission.name_span.line, mission.name_span.col)
        starts.append((at, [f"mission {mission.name}"], None))
    if mission.vehicle is not None:
        span = mission.vehicle_span
        starts.append(((span.line, span.col), [f"vehicle {mission.vehicle}"], None))
    for declaration in mission.declarations:
        span = declaration.span
        lines = format_declaration(declaration)
        if isinstance(declaration, ast.Places | ast.Inputs) and span.end_line > span.line:
            lines = _list_lines(declaration)
        starts.append(((span.line, span.col), lines, declaration))
    starts.sort(key=lambda triple: triple[0])
    positions = [(t.line, t.col) for t in tokens]
    items = [_Item(bisect.bisect_left(positions, at), lines) for at, lines, _ in starts]
    ends = [item.start for item in items[1:]] + [len(tokens) - 1] * bool(items)  # no EOF
    for item, end, (_, _, statement) in zip(items, ends, starts, strict=True):
        source = tokens[item.start : end]
        item.first_line = tokens[item.start].line
        item.last_line = source[-1].line if source else item.first_line
        if isinstance(statement, ast.TransitionDecl) and item.first_line == item.last_line:
            fields = transition_fields(statement)
            if fields is not None and len(line := " ".join(f for f in fields if f)) <= MAX_WIDTH:
                item.lines, item.fields = [line], fields
        item.line_of = _match(source, item.lines)
    return items


def _match(source: Sequence[Token], lines: list[str]) -> list[int | None]:
    """For each source token, the printed line (0-based) its equal ended up on, if any."""
    printed, _ = tokenize("\n".join(lines), "<printed>")
    printed.pop()  # EOF
    left = [(t.kind, t.text) for t in source]
    right = [(t.kind, t.text) for t in printed]
    if left == right:  # the common case: the printer changed no token
        return [t.line - 1 for t in printed]
    line_of: list[int | None] = [None] * len(source)
    matcher = difflib.SequenceMatcher(None, left, right, autojunk=False)
    for block in matcher.get_matching_blocks():
        for offset in range(block.size):
            line_of[block.a + offset] = printed[block.b + offset].line - 1
    return line_of


def _place_comments(
    comments: list[Token],
    tokens: list[Token],
    items: list[_Item],
    clusters: list[int],
    kept: set[int],
) -> dict[tuple[int, int], _Placed]:
    """Which printed line (item, line) each comment goes with; the end of file is
    ``(len(items), 0)``. Comments on the lines of a cluster laid out as written stay in
    its text."""
    positions = [(t.line, t.col) for t in tokens]
    item_starts = [item.start for item in items]
    as_written = [
        (tokens[item.start].line, item.last_line)
        for item, cluster in zip(items, clusters, strict=True)
        if cluster in kept
    ]
    placed: dict[tuple[int, int], _Placed] = {}
    previous = (0, 0, 0)
    for comment in comments:
        if any(first <= comment.line <= last for first, last in as_written):
            continue
        after = bisect.bisect_left(positions, (comment.line, comment.col))
        if after > 0 and tokens[after - 1].line == comment.line:
            first = after - 1  # trailing: anchored at the first token of its line
            while first > 0 and tokens[first - 1].line == comment.line:
                first -= 1
            key = (*_printed_line(items, item_starts, first, after), 1)
        elif tokens[after].kind is Kind.EOF or not items:
            key = (len(items), 0, 0)
        else:
            key = (*_printed_line(items, item_starts, after, None), 0)
        key = max(key, previous)  # never reorder comments, whatever the matching said
        previous = key
        spot = placed.setdefault(key[:2], _Placed())
        if key[2] == 0:
            spot.above.append(comment)
        else:
            if spot.trailing is not None:
                spot.above.append(spot.trailing)
            spot.trailing = comment
    return placed


def _printed_line(
    items: list[_Item], item_starts: list[int], index: int, stop: int | None
) -> tuple[int, int]:
    """The (item, printed line) of source token ``index``. A token the printer did not
    keep as it was (``2.50`` printed ``2.5``, a dropped ``wait { }``) takes the line of
    the next matched token up to ``stop`` (exclusive; None: to the item's end), then
    that of the nearest one before it."""
    which = max(bisect.bisect_right(item_starts, index) - 1, 0)
    item = items[which]
    local = index - item.start
    end = len(item.line_of) if stop is None else min(stop - item.start, len(item.line_of))
    for line in item.line_of[local:end]:
        if line is not None:
            return which, line
    for line in reversed(item.line_of[:local]):
        if line is not None:
            return which, line
    for line in item.line_of[end:]:
        if line is not None:
            return which, line
    return which, 0


def _render(
    items: list[_Item],
    placed: dict[tuple[int, int], _Placed],
    text: str,
    clusters: list[int],
    kept: set[int],
) -> str:
    """The output text: statements, comments and blank lines, trailing comments aligned;
    the clusters in ``kept`` as written (trailing white space and repeated blank lines
    aside)."""
    source_lines = text.split("\n")
    blanks = [0, *accumulate(1 if not line.strip() else 0 for line in source_lines)]

    def blank_between(a: int | None, b: int) -> bool:
        """Whether source lines ``a`` and ``b`` (1-based) have a blank line between."""
        return a is not None and b > a + 1 and blanks[b - 1] - blanks[a] > 0

    rows: list[tuple[str, Token | None]] = []  # (code or comment line, trailing comment)
    constants: set[int] = set()  # the rows holding a constant
    table: dict[int, list[str]] = {}  # the rows holding a one-line transition: its fields
    last: int | None = None  # the source line the previous top-level row came from

    def gap(line: int) -> None:
        if blank_between(last, line) and rows and rows[-1][0]:
            rows.append(("", None))

    for number, item in enumerate(items):
        first_line = item.first_line
        cluster = clusters[number]
        if cluster in kept:
            for comment in placed.get((number, 0), _Placed()).above:
                gap(comment.line)
                rows.append((comment.text, None))
                last = comment.line if last is None else max(last, comment.line)
            if number > 0 and clusters[number - 1] == cluster:
                continue  # its lines went out with the cluster's first statement
            gap(first_line)
            end = max(i.last_line for i, c in zip(items, clusters, strict=True) if c == cluster)
            for k, line in enumerate(source_lines[first_line - 1 : end]):
                code = line.strip() if k == 0 else line.rstrip()
                if code or rows[-1][0]:  # one blank line at most
                    rows.append((code, None))
            last = end if last is None else max(last, end)
            continue
        for j, code in enumerate(item.lines):
            spot = placed.get((number, j), _Placed())
            indent = code[: len(code) - len(code.lstrip())]
            for comment in spot.above:
                if j == 0:
                    gap(comment.line)
                rows.append((indent + comment.text, None))
                last = comment.line if last is None else max(last, comment.line)
            if j == 0:
                gap(first_line)
            if code.startswith("const "):
                constants.add(len(rows))
            if item.fields is not None:
                table[len(rows)] = item.fields
            rows.append((code, spot.trailing))
        last = item.last_line if last is None else max(last, item.last_line)
    for comment in placed.get((len(items), 0), _Placed()).above:
        gap(comment.line)
        rows.append((comment.text, None))
        last = comment.line
    aligned = _align_table(_align_constants(rows, constants), table)
    return "".join(line + "\n" for line in _align(aligned))


def _align_table(
    rows: list[tuple[str, Token | None]], table: dict[int, list[str]]
) -> list[tuple[str, Token | None]]:
    """Consecutive one-line transitions as a table: each field (name, priority, wait,
    signal) starts in the same column on every row of the run."""
    out = list(rows)
    run: list[int] = []
    for number in [*sorted(table), -2]:
        if run and number != run[-1] + 1:
            widths = [max(len(table[r][k]) for r in run) for k in range(4)]
            for r in run:
                cells = [
                    cell.ljust(width) for cell, width in zip(table[r], widths, strict=True) if width
                ]
                out[r] = (" ".join(cells).rstrip(), out[r][1])
            run = []
        run.append(number)
    return out


def _align_constants(
    rows: list[tuple[str, Token | None]], constants: set[int]
) -> list[tuple[str, Token | None]]:
    """Consecutive ``const`` lines with their ``=`` in one column, as a table of
    constants is usually written (and as the paper's pool mission is)."""
    out = list(rows)
    run: list[int] = []
    for number in [*sorted(constants), -2]:
        if run and number != run[-1] + 1:
            names = [out[r][0][len("const ") :].split(" = ", 1) for r in run]
            width = max(len(name) for name, _ in names)
            for r, (name, value) in zip(run, names, strict=True):
                out[r] = (f"const {name.ljust(width)} = {value}", out[r][1])
            run = []
        run.append(number)
    return out


def _align(rows: list[tuple[str, Token | None]]) -> list[str]:
    """Rows as text: each run of consecutive rows with trailing comments aligned."""
    out: list[str] = []
    run: list[tuple[str, Token]] = []

    def flush() -> None:
        if run:
            column = max(len(code) for code, _ in run) + _TRAILING_GAP
            out.extend(code.ljust(column) + comment.text for code, comment in run)
            run.clear()

    for code, trailing in rows:
        if trailing is None:
            flush()
            out.append(code)
        else:
            run.append((code, trailing))
    flush()
    return out
