"""`KeyStore`'s table of state numbers: what it costs per state, that it grows by
`GROWTH` without losing a key, and that traces rebuilt from it (no parent numbers are
stored) are shortest firing sequences to every state."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings

from analysis.encoding import BATCH_LOAD, MAX_LOAD, KeyStore
from analysis.encoding.keystore import GROWTH
from analysis.statespace import explore
from coral_lang.net import Net
from tests.analysis.nets import replay
from tests.analysis.strategies import small_nets


def test_table_costs_at_most_three_bytes_per_slot_at_the_lowest_load() -> None:
    rng = np.random.default_rng(11)
    store = KeyStore(1, capacity=16)
    slots: set[int] = set()
    for _ in range(120):  # many growth steps, each rebuilding the table from the keys
        batch = rng.integers(0, 1 << 62, size=(500, 1), dtype=np.int64).astype(np.uint64)
        store.add(batch)
        table = store.nbytes - store.keys.nbytes
        if store.size > 2000:  # past the first batches, which grow it several times
            slots.add(table // 3)
        assert table <= 3 * GROWTH / MAX_LOAD * store.size + 64
        assert store.size <= MAX_LOAD * (table // 3)
    assert len(slots) > 5  # it did grow, by less than doubling each time
    assert max(b / a for a, b in zip(sorted(slots), sorted(slots)[1:], strict=False)) < 1.6
    ids = store.find(store.keys[::-1])
    assert ids.tolist() == list(range(store.size - 1, -1, -1))


def test_growth_put_off_until_settle_keeps_the_batch_load_and_every_number() -> None:
    rng = np.random.default_rng(12)
    eager, lazy = KeyStore(2, capacity=16), KeyStore(2, capacity=16)
    past = 0
    for _ in range(60):
        batch = rng.integers(0, 1 << 40, size=(700, 2), dtype=np.int64).astype(np.uint64)
        batch[::7] = batch[1::7][: batch[::7].shape[0]]  # repeats within the batch
        one = eager.add(batch)
        other = lazy.add(batch, grow=False)
        assert one.first.tolist() == other.first.tolist() and one.start == other.start
        slots = (lazy.nbytes - lazy.keys.nbytes) // 3
        assert lazy.size <= BATCH_LOAD * slots  # never past the batch load
        past += lazy.size > MAX_LOAD * slots
        lazy.settle()
        assert lazy.size <= MAX_LOAD * ((lazy.nbytes - lazy.keys.nbytes) // 3)
    assert past  # some batch did leave the growth to settle
    assert lazy.find(eager.keys[:]).tolist() == list(range(eager.size))


def test_rekey_to_wider_keys_keeps_every_number() -> None:
    store = KeyStore(1)
    keys = np.arange(1, 30_001, dtype=np.uint64)[:, None] * np.uint64(7919)
    store.add(keys)
    wider = np.concatenate([keys, keys ^ np.uint64(0xFF)], axis=1)
    store.rekey(wider)
    assert store.n_words == 2
    assert store.find(wider[::3]).tolist() == list(range(0, 30_000, 3))
    assert store.find(np.array([[1, 2]], dtype=np.uint64)).tolist() == [-1]


@settings(max_examples=4, deadline=None, derandomize=True)
@given(small_nets(max_initial=3))
def test_every_state_has_a_shortest_trace_without_parent_numbers(net: Net) -> None:
    space = explore(net, max_states=300)
    for index in range(space.states):
        trace = space.trace_to(index)
        assert replay(net, trace) == space.marking(index)
        assert len(trace) == space.depth_of(index)
