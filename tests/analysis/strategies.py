"""Hypothesis strategies for random small place/transition nets."""

from __future__ import annotations

from hypothesis import strategies as st

from coral_lang.net import Net, Place, Transition


@st.composite
def small_nets(
    draw: st.DrawFn,
    max_places: int = 5,
    max_transitions: int = 6,
    max_weight: int = 2,
    max_initial: int = 2,
) -> Net:
    """A random net; may be unbounded, dead, or trivially small, on purpose."""
    n_places = draw(st.integers(1, max_places))
    n_transitions = draw(st.integers(1, max_transitions))
    places = tuple(
        Place(name=f"p{i}", initial=draw(st.integers(0, max_initial))) for i in range(n_places)
    )
    arcs = st.dictionaries(
        st.integers(0, n_places - 1), st.integers(1, max_weight), max_size=min(3, n_places)
    )
    transitions = []
    for j in range(n_transitions):
        inputs = draw(arcs)
        outputs = draw(arcs)
        transitions.append(
            Transition(
                name=f"t{j}",
                inputs=tuple((f"p{i}", w) for i, w in sorted(inputs.items())),
                outputs=tuple((f"p{i}", w) for i, w in sorted(outputs.items())),
            )
        )
    return Net(name="random", places=places, transitions=tuple(transitions))
