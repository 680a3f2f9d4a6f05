"""Property tests: whatever arrives from the wire, the vehicle answers and never raises.

Random command sequences (names from the profile plus junk, parameters in and out of
range, of the wrong type, missing or extra), interleaved with random advances. The
invariants: no exception; every reply kind is one the profile declares for that command,
or ``error``; every query gets exactly one final reply, no earlier than it was sent and
no later than the first step after its time-out; later replies come in time order.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.profile import load_bundled_profile
from romeo_sim.vehicle import Reply, Vehicle

PROFILE = load_bundled_profile("ROMEO")
NAMES = [*PROFILE.command_names, "JUNK", "depth"]
VALUES = st.one_of(
    st.floats(min_value=-20.0, max_value=20.0),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-5, max_value=400),
    st.sampled_from(["2.0", "", "x"]),
    st.booleans(),
)


@st.composite
def commands(draw: st.DrawFn) -> tuple[str, dict[str, float | int | str]]:
    name = draw(st.sampled_from(NAMES))
    spec = PROFILE.command(name)
    params: dict[str, float | int | str] = {}
    if spec is not None:
        for p in spec.params:
            if draw(st.integers(0, 9)) == 0:
                continue  # missing
            if p.name == "time_out":
                params[p.name] = draw(st.floats(min_value=1.0, max_value=60.0))
            elif p.minimum is not None and p.maximum is not None and draw(st.booleans()):
                params[p.name] = draw(st.floats(min_value=max(p.minimum, -2.0), max_value=12.0))
            else:
                params[p.name] = draw(VALUES)
    if draw(st.integers(0, 9)) == 0:
        params["extra"] = 1.0
    return name, params


@pytest.mark.slow
@settings(max_examples=60)
@given(
    st.lists(
        st.tuples(commands(), st.floats(min_value=0.0, max_value=15.0), st.booleans()),
        max_size=12,
    ),
    st.integers(0, 3),
)
def test_vehicle_answers_every_sequence(
    script: list[tuple[tuple[str, dict[str, float | int | str]], float, bool]], seed: int
) -> None:
    vehicle = Vehicle(seed=seed)
    sent: dict[int, tuple[str, float, float]] = {}
    replies: list[Reply] = []
    for command_id, ((name, params), pause, resend) in enumerate(script, start=1):
        time_out = params.get("time_out")
        limit = float(time_out) if isinstance(time_out, float) else 0.0
        sent[command_id] = (name, vehicle.time, limit)
        replies += vehicle.command(command_id, name, params)
        if resend:
            assert vehicle.command(command_id, name, params) == list(
                vehicle.replies_for(command_id)
            )
        replies += vehicle.advance(pause)
    replies += vehicle.advance(61.0)
    late = [r.time for r in replies if r.kind not in ("ack", "error")]
    assert late == sorted(late)
    for reply in replies:
        name, at, limit = sent[reply.command_id]
        spec = PROFILE.command(name)
        allowed = {"error"} if spec is None else {*spec.replies, "error"}
        assert reply.kind in allowed, reply
        assert reply.time >= at - 0.05 - 1e-9
    for command_id, (name, at, limit) in sent.items():
        finals = [r for r in replies if r.command_id == command_id and r.kind != "ack"]
        if name.endswith("?") and PROFILE.command(name) is not None:
            if finals and finals[0].kind == "error":
                continue  # malformed: refused at once
            assert len(finals) == 1, (name, finals)
            assert finals[0].time <= at + limit + 0.05 + 1e-6  # checked once per step
    assert vehicle.status() is not None
