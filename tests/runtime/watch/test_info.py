"""The page's static info: the net rebuilt from a log's canonical form, its drawing, its
node names, inputs, workspace and way-points."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from coral_lang.mission import load_mission
from coral_lang.net import Command, Net, Place, PlaceKind, Transition, TransitionKind
from coral_lang.profile import load_profile
from runtime.eventlog import EventLog
from runtime.watch.info import CanonicalNetError, net_from_canonical, page_info, waypoints_of
from tests.conftest import EXAMPLES
from tests.runtime.watch.conftest import POOL_MISSION

OPERATED = """\
mission operated
vehicle ROMEO
place start = 1
place going, there, stopped
input abort_requested
final { there }
final { stopped }
transition go
    wait   { start }
    action { ROMEO(GOTO, x = 3.0, y = 2.0, psi = 0.0) -> { ack: going, error: stopped } }
transition arrive
    wait   { going }
    action { ROMEO(XY?, x = 3.0, y = 2.0, time_out = 30.0) -> { done: there, timeout: stopped } }
transition stop
    wait   { going, abort_requested }
    signal { stopped }
"""


@pytest.fixture(scope="module")
def pool_net() -> Net:
    return load_mission(POOL_MISSION, []).net


@pytest.fixture(scope="module")
def operated_net(tmp_path_factory: pytest.TempPathFactory) -> Net:
    path = tmp_path_factory.mktemp("operated") / "operated.coral"
    path.write_text(OPERATED, encoding="utf-8")
    return load_mission(path, []).net


def _json(net: Net) -> str:
    return json.dumps(net.canonical(), sort_keys=True)


def test_the_canonical_form_gives_back_the_same_net(pool_net: Net, operated_net: Net) -> None:
    minnow = load_profile(EXAMPLES / "profiles" / "minnow.yaml")
    survey = load_mission(EXAMPLES / "survey_auv" / "survey.coral", [minnow]).net
    for net in (pool_net, operated_net, survey):
        rebuilt = net_from_canonical(_json(net))
        if net is survey:  # temporal assertions keep their text, not their formula tree
            assert {a.text for a in rebuilt.assertions if a.temporal} == {
                str(a.formula) for a in net.assertions if a.temporal
            }
            assert rebuilt.requirements == net.requirements == ("termination",)
        else:
            assert rebuilt.digest() == net.digest(), net.name
        assert rebuilt.canonical()["transitions"] == net.canonical()["transitions"]
        assert rebuilt.canonical()["places"] == net.canonical()["places"]
        assert rebuilt.canonical()["finals"] == net.canonical()["finals"]
        assert sorted(rebuilt.place_names) == sorted(net.place_names)
        assert rebuilt.inputs == net.inputs
        for transition in net.transitions:
            again = rebuilt.transition(transition.name)
            assert (again.kind, again.command, again.priority) == (
                transition.kind,
                transition.command,
                transition.priority,
            )
            assert again.describe() == transition.describe()  # drawn as the report draws it


@pytest.mark.parametrize(
    ("mutate", "field"),
    [
        (lambda d: d.pop("places"), "places"),
        (lambda d: d["places"][0].__setitem__(1, "one"), "places[0]"),
        (lambda d: d["places"][0].__setitem__(2, "weird"), "weird"),
        (lambda d: d["transitions"][0].__setitem__("inputs", [["x"]]), "transitions[0].inputs"),
        (lambda d: d["transitions"][0].__setitem__("inputs", [["nowhere", 1]]), "nowhere"),
        (lambda d: d.__setitem__("name", 3), "name"),
    ],
)
def test_a_malformed_canonical_form_is_refused_naming_the_field(
    operated_net: Net, mutate: object, field: str
) -> None:
    data = json.loads(_json(operated_net))
    assert callable(mutate)
    mutate(data)
    with pytest.raises(CanonicalNetError, match=re.escape(field)):
        net_from_canonical(json.dumps(data))
    info = page_info(json.dumps(data), {})
    assert info["net_svg"] == "" and field in str(info["net_note"])


def test_pool_mission_info(pool_log: Path, pool_net: Net) -> None:
    with EventLog.open(pool_log) as log:
        net_json, meta = log.net_json, dict(log.meta)
    info = page_info(net_json, meta)
    assert json.loads(json.dumps(info)) == info  # JSON-ready as it is
    assert info["mission"] == "pool_mission" and info["vehicle"] == "ROMEO"
    svg = str(info["net_svg"])
    assert svg.startswith("<svg") and 'class="net"' in svg
    places = info["places"]
    assert isinstance(places, dict)
    assert sorted(places.values()) == sorted(pool_net.place_names)
    for node in places:
        assert f'data-node="{node}"' in svg
    transitions = info["transitions"]
    assert isinstance(transitions, dict)
    assert sorted(transitions.values()) == sorted(t.name for t in pool_net.transitions)
    kinds = info["transition_kinds"]
    assert isinstance(kinds, dict)
    assert kinds["initialise"] == "command" and kinds["initialise.done"] == "reply"
    # The ROMEO profile the run used: the pool of the paper, 12 x 8 m.
    assert info["workspace"] == {"x_min": 0.0, "x_max": 12.0, "y_min": 0.0, "y_max": 8.0}
    targets = {
        (float(dict(t.command.params)["x"]), float(dict(t.command.params)["y"]))
        for t in pool_net.transitions
        if t.command is not None and t.command.name in ("GOTO", "LRM")
    }
    waypoints = info["waypoints"]
    assert isinstance(waypoints, list)
    assert {(w["x"], w["y"]) for w in waypoints} == targets
    assert len(waypoints) == len(targets)  # each point once
    assert waypoints[0]["command"] == "GOTO"  # the operating site comes first, then the legs
    assert [w["transition"] for w in waypoints[1:]] == ["go_wp1", "go_wp2", "go_wp3", "go_wp4"]
    assert info["inputs"] == []


def test_inputs_and_a_net_without_profile_or_drawing(operated_net: Net) -> None:
    info = page_info(_json(operated_net), {"profiles": ["/nonexistent/romeo.yaml"]})
    assert info["inputs"] == ["abort_requested"]
    assert info["input_transitions"] == {"abort_requested": "abort_requested.operator"}
    assert info["replies"] == {"go": ["ack", "error"], "arrive": ["done", "timeout"]}
    assert info["waypoints"] == [{"x": 3.0, "y": 2.0, "command": "GOTO", "transition": "go"}]
    # The profile named is gone: the bundled ROMEO profile gives the workspace.
    assert info["workspace"] == {"x_min": 0.0, "x_max": 12.0, "y_min": 0.0, "y_max": 8.0}
    nothing = page_info(None, {"mission": "m"})
    assert nothing["net_svg"] == "" and nothing["mission"] == "m" and nothing["places"] == {}


def test_way_points_are_converted_to_metres_with_the_profile_units() -> None:
    usv = load_profile(EXAMPLES / "profiles" / "usv.yaml")
    goto = Command("USV", "GOTO_WAYPOINT", (("x", 1.5), ("y", -0.5), ("speed", 3.0)))
    net = Net(
        "usv",
        (Place("start", 1), Place("going"), Place("go.pending", kind=PlaceKind.PENDING)),
        (
            Transition(
                "go",
                (("start", 1),),
                (("go.pending", 1),),
                kind=TransitionKind.COMMAND,
                command=goto,
                pending="go.pending",
            ),
        ),
        vehicle="USV",
    )
    assert waypoints_of(net, usv) == [
        {"x": 1500.0, "y": -500.0, "command": "GOTO_WAYPOINT", "transition": "go"}
    ]
    assert waypoints_of(net, None)[0]["x"] == 1.5  # no profile: taken as metres
