"""What the watch page needs once, before any snapshot: the net's drawing and its keys.

A snapshot says which places hold tokens and which transitions fire; to show that on the
net the page needs the picture itself and the names behind its ``p<i>``/``t<i>`` nodes,
which do not change during a run. `page_info` computes them from what a controller log
holds (``header.net_json``, the net's canonical form, and ``header.meta``), so the live
server embedded in ``coral-run`` and ``coral-run watch LOG`` serve the same ``/info``.

The net is rebuilt from its canonical form (`net_from_canonical`) rather than recompiled
from the mission's source: the source may have changed or gone since the run, the log's
net is the one that ran. The canonical form keeps every place, arc, kind and command but
not the labels and source positions, so the drawing labels transitions by name.

Everything here is best-effort decoration around the snapshots: a net that cannot be
rebuilt gives an empty drawing, a profile that cannot be read no workspace; never an error.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections import deque
from collections.abc import Mapping
from typing import Final

from analysis.netdraw import draw_net
from coral_lang.net import (
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
from coral_lang.profile import VehicleProfile
from runtime.timeline_context import find_profile, param_metres

__all__ = ["CanonicalNetError", "net_from_canonical", "page_info", "waypoints_of"]

_SAME_POINT_M: Final = 1e-6


class CanonicalNetError(ValueError):
    """A ``net_json`` that is not a net's canonical form; the message names the field."""


def net_from_canonical(net_json: str) -> Net:
    """The `Net` whose `Net.canonical` is ``net_json`` (as a log's header stores it).

    Places and transitions come out in name order (the canonical order), so ``p<i>`` of
    a drawing of this net is the i-th place by name. Exact for every net without temporal
    assertions (`Net.digest` is the same); a temporal assertion keeps its text only (the
    formula as `Net.canonical` writes it, ``formula`` None: the tree is not rebuilt), which
    changes the digest but not how the net runs or is drawn. Raises `CanonicalNetError`
    naming the field that is malformed.
    """
    try:
        data = json.loads(net_json)
    except ValueError as error:
        raise CanonicalNetError(f"net_json: not JSON ({error})") from None
    root = _dict(data, "net_json")
    try:
        places = tuple(_place(entry, i) for i, entry in enumerate(_list(root, "places")))
        transitions = tuple(
            _transition(entry, i) for i, entry in enumerate(_list(root, "transitions"))
        )
        finals = tuple(
            FinalMarking(_tokens(entry, f"finals[{i}]"))
            for i, entry in enumerate(_list(root, "finals", optional=True))
        )
        assertions = tuple(
            _assertion(entry, i) for i, entry in enumerate(_list(root, "assertions", optional=True))
        )
        requirements = tuple(
            _str(item, "requirements") for item in _list(root, "requirements", optional=True)
        )
        vehicle = root.get("vehicle")
        return Net(
            _str(root.get("name"), "name"),
            places,
            _labelled(transitions),
            finals,
            assertions,
            vehicle=None if vehicle is None else _str(vehicle, "vehicle"),
            requirements=requirements,
        )
    except CanonicalNetError:
        raise
    except ValueError as error:  # NetError, a bad enum value
        raise CanonicalNetError(f"net_json: {error}") from None


def _labelled(transitions: tuple[Transition, ...]) -> tuple[Transition, ...]:
    """Labels as the compiler gives them (not part of the canonical form, so not logged):
    a command its text, a reply its command's name, so the drawing reads
    ``check_depth: DEPTH? replied timeout`` as the report's does."""
    commands = {t.name: t.command for t in transitions if t.command is not None}
    out: list[Transition] = []
    for transition in transitions:
        label = transition.name
        if transition.command is not None:
            label = transition.command.header()
        elif transition.reply_to in commands:
            label = commands[transition.reply_to].name
        out.append(dataclasses.replace(transition, label=label))
    return tuple(out)


def _dict(value: object, where: str) -> dict[str, object]:
    if not isinstance(value, dict):
        raise CanonicalNetError(f"{where}: expected an object")
    return value


def _list(root: Mapping[str, object], key: str, *, optional: bool = False) -> list[object]:
    value = root.get(key)
    if value is None and optional:
        return []
    if not isinstance(value, list):
        raise CanonicalNetError(f"net_json: {key}: expected a list")
    return value


def _str(value: object, where: str) -> str:
    if not isinstance(value, str):
        raise CanonicalNetError(f"net_json: {where}: expected a string")
    return value


def _opt_str(value: object, where: str) -> str | None:
    return None if value is None else _str(value, where)


def _int(value: object, where: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise CanonicalNetError(f"net_json: {where}: expected an integer")
    return value


def _tokens(value: object, where: str) -> tuple[tuple[str, int], ...]:
    if not isinstance(value, list):
        raise CanonicalNetError(f"net_json: {where}: expected a list of [place, weight]")
    pairs: list[tuple[str, int]] = []
    for item in value:
        if not isinstance(item, list) or len(item) != 2:
            raise CanonicalNetError(f"net_json: {where}: expected [place, weight] pairs")
        pairs.append((_str(item[0], where), _int(item[1], where)))
    return tuple(pairs)


def _place(entry: object, i: int) -> Place:
    where = f"places[{i}]"
    if not isinstance(entry, list) or len(entry) not in (7, 8):
        raise CanonicalNetError(f"net_json: {where}: expected a list of 7 or 8 fields")
    resources = entry[4]
    if not isinstance(resources, list):
        raise CanonicalNetError(f"net_json: {where}: resources: expected a list")
    return Place(
        _str(entry[0], where),
        _int(entry[1], where),
        PlaceKind(_str(entry[2], where)),
        capacity=None if entry[3] is None else _int(entry[3], where),
        resources=tuple(_str(r, where) for r in resources),
        pending_of=_opt_str(entry[5], where),
        complement_of=_opt_str(entry[6], where),
        armed_of=_opt_str(entry[7], where) if len(entry) == 8 else None,
    )


def _value(value: object, where: str) -> Value:
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise CanonicalNetError(f"net_json: {where}: expected a number or a string")
    return value


def _command(value: object, where: str) -> Command | None:
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != 5:
        raise CanonicalNetError(f"net_json: {where}: expected [system, name, params, ...]")
    system, name, params, resources, replies = value
    if not (isinstance(params, list) and isinstance(resources, list)):
        raise CanonicalNetError(f"net_json: {where}: params and resources: expected lists")
    if not isinstance(replies, list):
        raise CanonicalNetError(f"net_json: {where}: replies: expected a list")
    pairs: list[tuple[str, Value]] = []
    for item in params:
        if not isinstance(item, list) or len(item) != 2:
            raise CanonicalNetError(f"net_json: {where}: params: expected [name, value]")
        pairs.append((_str(item[0], where), _value(item[1], where)))
    return Command(
        _str(system, where),
        _str(name, where),
        tuple(pairs),
        tuple(_str(r, where) for r in resources),
        tuple(_str(r, where) for r in replies),
    )


def _transition(entry: object, i: int) -> Transition:
    where = f"transitions[{i}]"
    data = _dict(entry, f"net_json: {where}")
    return Transition(
        _str(data.get("name"), f"{where}.name"),
        _tokens(data.get("inputs"), f"{where}.inputs"),
        _tokens(data.get("outputs"), f"{where}.outputs"),
        kind=TransitionKind(_str(data.get("kind"), f"{where}.kind")),
        priority=_int(data.get("priority", 0), f"{where}.priority"),
        command=_command(data.get("command"), f"{where}.command"),
        pending=_opt_str(data.get("pending"), f"{where}.pending"),
        reply_to=_opt_str(data.get("reply_to"), f"{where}.reply_to"),
        reply=_opt_str(data.get("reply"), f"{where}.reply"),
        operator_input=_opt_str(data.get("operator_input"), f"{where}.operator_input"),
    )


def _assertion(entry: object, i: int) -> Assertion:
    where = f"assertions[{i}]"
    if not isinstance(entry, list) or len(entry) not in (3, 4):
        raise CanonicalNetError(
            f"net_json: {where}: expected [kind, places, bound(, formula or deadline)]"
        )
    kind = AssertKind(_str(entry[0], where))
    bound = entry[2]
    deadline: float | None = None
    text = ""
    if kind is AssertKind.WITHIN:
        value = entry[3] if len(entry) == 4 else None
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CanonicalNetError(
                f"net_json: {where}: a 'within' assertion needs its deadline in seconds"
            )
        deadline = float(value)
    elif len(entry) == 4:
        text = _str(entry[3], where)
    return Assertion(
        kind,
        _tokens(entry[1], where),
        None if bound is None else _int(bound, where),
        text=text,
        deadline_s=deadline,
    )


def waypoints_of(net: Net, profile: VehicleProfile | None) -> list[dict[str, object]]:
    """The targets (``x``, ``y`` in metres) of the net's commands that have both, each
    point once, in mission order: transitions by breadth-first distance from the initial
    marking (then by name), which puts a way-point sequence in the order it is flown."""
    points: list[dict[str, object]] = []
    seen: list[tuple[float, float]] = []
    for transition in _mission_order(net):
        command = transition.command
        if command is None:
            continue
        params = dict(command.params)
        x = param_metres(command.name, params, "x", profile)
        y = param_metres(command.name, params, "y", profile)
        if x is None or y is None:
            continue
        if any(math.dist(point, (x, y)) < _SAME_POINT_M for point in seen):
            continue
        seen.append((x, y))
        points.append({"x": x, "y": y, "command": command.name, "transition": transition.name})
    return points


def _mission_order(net: Net) -> list[Transition]:
    """Transitions by breadth-first distance from the initially marked places."""
    consumers: dict[str, list[int]] = {}
    for index, transition in enumerate(net.transitions):
        for place, _ in transition.inputs:
            consumers.setdefault(place, []).append(index)
    distance: dict[int, int] = {}
    queue: deque[tuple[str, int]] = deque((p.name, 0) for p in net.places if p.initial > 0)
    seen = {name for name, _ in queue}
    while queue:
        place, depth = queue.popleft()
        for index in consumers.get(place, ()):
            if index in distance:
                continue
            distance[index] = depth
            for target, _ in net.transitions[index].outputs:
                if target not in seen:
                    seen.add(target)
                    queue.append((target, depth + 1))
    unreached = len(net.transitions)
    order = sorted(
        range(len(net.transitions)),
        key=lambda i: (distance.get(i, unreached), net.transitions[i].name),
    )
    return [net.transitions[i] for i in order]


def page_info(net_json: str | None, meta: Mapping[str, object]) -> dict[str, object]:
    """The static data of ``/info`` (JSON-ready), from a controller log's header.

    Keys: ``mission``; ``vehicle``; ``net_svg`` (the drawing, `analysis.netdraw`, "" when
    the net cannot be rebuilt or is too large to draw), ``net_layout`` and ``net_note``
    (which layout, and why not another); ``places`` and ``transitions`` (node id, as the
    drawing's ``data-node``, to name); ``place_kinds``, ``transition_kinds`` (name to
    kind); ``commands`` (command transition to its text, e.g. ``ROMEO(GOTO, x = 4.0)``);
    ``replies`` (command transition to the reply kinds it may get); ``inputs`` (the
    operator inputs the mission declares) and ``input_transitions`` (input to its
    transition); ``workspace`` (``{x_min, x_max, y_min, y_max}`` in metres, x north, from
    the vehicle's profile, or None); ``waypoints`` (`waypoints_of`).
    """
    info: dict[str, object] = {
        "mission": str(meta.get("mission", "")),
        "vehicle": None,
        "net_svg": "",
        "net_layout": "none",
        "net_note": "",
        "places": {},
        "transitions": {},
        "place_kinds": {},
        "transition_kinds": {},
        "commands": {},
        "replies": {},
        "inputs": [],
        "input_transitions": {},
        "workspace": None,
        "waypoints": [],
    }
    if net_json is None:
        info["net_note"] = "the log holds no net"
        return info
    try:
        net = net_from_canonical(net_json)
    except CanonicalNetError as error:
        info["net_note"] = f"the log's net cannot be read: {error}"
        return info
    drawing = draw_net(net)
    profile = find_profile(net.vehicle, meta)
    space = None if profile is None else profile.workspace
    info.update(
        {
            "mission": info["mission"] or net.name,
            "vehicle": net.vehicle,
            "net_svg": drawing.svg,
            "net_layout": drawing.layout,
            "net_note": drawing.note,
            "places": {f"p{i}": p.name for i, p in enumerate(net.places)},
            "transitions": {f"t{i}": t.name for i, t in enumerate(net.transitions)},
            "place_kinds": {p.name: p.kind.value for p in net.places},
            "transition_kinds": {t.name: t.kind.value for t in net.transitions},
            "commands": {t.name: t.command.header() for t in net.transitions if t.command},
            "replies": {t.name: list(t.command.replies) for t in net.transitions if t.command},
            "inputs": list(net.inputs),
            "input_transitions": {name: net.input_transition(name).name for name in net.inputs},
            "workspace": None
            if space is None
            else {
                "x_min": space.x_min,
                "x_max": space.x_max,
                "y_min": space.y_min,
                "y_max": space.y_max,
            },
            "waypoints": waypoints_of(net, profile),
        }
    )
    return info
