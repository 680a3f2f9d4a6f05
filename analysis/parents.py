"""The parent of a stored state, found again from the stored markings alone
(`parent_step`), so that a search keeps no parent number and no arriving transition
per state (`analysis.statespace.StateSpace.trace_to` walks it back to the initial
marking).

Why this is enough: states are stored layer by layer in BFS order (``layer_starts``),
so a state of layer ``d > 0`` was found by firing some transition from a stored state of
layer ``d - 1``. Its candidate parents are the markings ``m - effect(t)`` of the
transitions ``t`` whose outputs ``m`` covers (exactly the markings that enable ``t`` and
lead to ``m`` by it); the store says which of them are stored, and where. Any one of
layer ``d - 1`` is a parent of a shortest trace. Each candidate found in the store is
checked against its decoded marking, so an encoding that cannot represent a candidate
(a count past its field, two tokens in a one-hot component) never yields a false
parent: it is either not found or found to differ.

What it costs: one step decodes one key and tests every output arc once, then packs
and looks up the candidates of a block of transitions at a time (`CANDIDATE_CELLS`
markings' worth of counts), stopping at the first block with a parent. Storing the
arriving transition instead cost one or two bytes per state during the whole search
(4 % of DoubleExponent-PT-003's resident memory) for traces that are asked of a few
states.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from analysis.encoding import CompactNet, KeyStore, Layout

CANDIDATE_CELLS = 1 << 20
"""Most (candidate parent, place) counts one lookup builds (8 MB of ``int64``)."""


def parent_step(
    cn: CompactNet,
    layout: Layout,
    store: KeyStore,
    layer_starts: npt.NDArray[np.int64],
    index: int,
) -> tuple[int, int]:
    """``(parent, transition)``: a stored state of the BFS layer before state
    ``index``'s and the transition that leads from it to ``index`` (of all such
    pairs, the one with the smallest transition, then the smallest parent).

    Raises:
        ValueError: ``index`` is the initial state (layer 0) or not stored, or no
            parent is stored (which a search never leaves: its stored states were
            each found from a stored state of the layer before).
    """
    if not 0 < index < store.size:
        raise ValueError(f"parent_step: state {index} has no parent (states: {store.size})")
    layer = int(np.searchsorted(layer_starts, index, side="right")) - 1
    if layer < 1:
        raise ValueError(f"parent_step: state {index} has no parent (it is of layer 0)")
    low, high = int(layer_starts[layer - 1]), int(layer_starts[layer])
    marking = layout.unpack(store.keys[index : index + 1])[0].astype(np.int64)
    for chunk in _candidate_chunks(cn, marking):
        found = _stored_parents(cn, layout, store, marking, chunk)
        hits = np.flatnonzero((found >= low) & (found < high))
        if hits.size:
            return int(found[hits[0]]), int(chunk[hits[0]])
    raise ValueError(f"parent_step: no stored parent of state {index} in layer {layer - 1}")


def _candidate_chunks(
    cn: CompactNet, marking: npt.NDArray[np.int64]
) -> list[npt.NDArray[np.int64]]:
    """The transitions that may lead to ``marking`` (it covers their outputs and they
    change something), ascending, in blocks of at most `CANDIDATE_CELLS` counts."""
    outputs = cn.outputs
    short = marking.take(outputs.places) < outputs.values
    lacking = np.bincount(outputs.rows.compress(short), minlength=cn.n_transitions)
    candidates = np.flatnonzero((lacking == 0) & ~cn.self_loops)
    step = max(1, CANDIDATE_CELLS // max(1, cn.n_places))
    return [candidates[i : i + step] for i in range(0, candidates.size, step)]


def _stored_parents(
    cn: CompactNet,
    layout: Layout,
    store: KeyStore,
    marking: npt.NDArray[np.int64],
    transitions: npt.NDArray[np.int64],
) -> npt.NDArray[np.int64]:
    """Per transition, the state number of ``marking`` un-fired by it, ``-1`` where
    that marking is not stored."""
    rows = np.tile(marking, (transitions.size, 1))
    owner, entry = cn.effects.expand(transitions)
    rows[owner, cn.effects.places.take(entry)] -= cn.effects.values.take(entry)
    ids = store.find(layout.pack(rows))
    hit = np.flatnonzero(ids >= 0)
    if hit.size:  # the keys found must decode to the markings looked up
        decoded = layout.unpack(store.keys.take(ids.take(hit)))
        wrong = (decoded != rows.take(hit, axis=0)).any(axis=1)
        ids[hit.compress(wrong)] = -1
    return ids
