"""``make demo``: compile the paper's pool mission and print what it became."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from coral_lang.compiler import compile_file
from coral_lang.diagnostics import render_all
from coral_lang.net import PlaceKind, TransitionKind, format_tokens


def main(argv: Sequence[str] | None = None) -> int:
    """Compile the mission named in ``argv`` and print a summary; returns an exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    path = args[0] if args else "examples/pool_mission/pool_mission.coral"
    result = compile_file(path)
    if result.diagnostics:
        print(render_all(result.diagnostics, result.sources))
    if result.net is None:
        return 1
    net = result.net
    print(f"compiled {path} ({len(result.sources)} files)")
    print(f"  {net.summary()}")
    print(f"  vehicle {net.vehicle}; digest {net.digest()}")
    kinds = {kind: sum(1 for p in net.places if p.kind is kind) for kind in PlaceKind}
    print(
        f"  places: {kinds[PlaceKind.MISSION]} mission, {kinds[PlaceKind.PENDING]} pending "
        f"commands, {kinds[PlaceKind.COMPLEMENT]} capacity complements"
    )
    commands = [t for t in net.transitions if t.kind is TransitionKind.COMMAND]
    replies = [t for t in net.transitions if t.kind is TransitionKind.REPLY]
    print(
        f"  transitions: {len(commands)} send a command, {len(replies)} are vehicle replies, "
        f"{len(net.transitions) - len(commands) - len(replies)} plain"
    )
    print("  commands in source order:")
    for transition in commands:
        assert transition.command is not None and transition.span is not None
        print(
            f"    {transition.span.file}:{transition.span.line}  {transition.name}: "
            f"{transition.command.header()}"
        )
    print("  final markings: " + "; ".join(format_tokens(f.tokens) for f in net.finals))
    return 0


if __name__ == "__main__":
    sys.exit(main())
