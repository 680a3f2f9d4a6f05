"""`SlotTable`: three-byte slots that read back every value a key store writes, a claim
that the least position wins whatever order numpy writes repeated slots in, and the
switch to whole words past `THREE_BYTE_SLOTS` without losing a state."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.encoding import KeyStore, SlotTable
from analysis.encoding import slots as slots_module


def test_three_byte_slots_read_back_the_extremes_of_their_range() -> None:
    table = SlotTable(1 << 12)
    table.use(1 << 12)
    assert table.slot_bytes == 3 and table.nbytes == 3 << 12
    limit = slots_module.THREE_BYTE_SLOTS
    values = np.array([1, -1, limit - 1, -limit, 65535, 65536, -65536, -65537, 0], np.int64)
    at = np.arange(values.size, dtype=np.int64) * 7
    table.put(at, values)
    assert table.take(at).tolist() == values.tolist()
    assert table.take(at.reshape(3, 3)).tolist() == values.reshape(3, 3).tolist()
    table.clear()
    assert not table.take(np.arange(1 << 12)).any()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 40), min_size=1, max_size=200), st.booleans())
def test_a_claim_gives_each_slot_its_least_claimant(targets: list[int], wide: bool) -> None:
    table = SlotTable(64)
    if wide:  # the same contract in whole words
        table = SlotTable(64, wide=True)
        table._allocate(slots_module.THREE_BYTE_SLOTS + 1)
    table.use(64)
    at = np.array(targets, dtype=np.int64)
    positions = np.arange(at.size, dtype=np.int64) * 3 + 5
    won = table.claim(at, positions)
    least = {int(s): int(positions[at == s].min()) for s in set(targets)}
    assert won.tolist() == [least[int(s)] for s in at]
    assert table.take(at).tolist() == [-1 - least[int(s)] for s in at]


def test_a_claim_that_numpy_wrote_in_another_order_is_redone() -> None:
    """Force what numpy does not promise against: the last write of a repeated slot
    losing, in one plane only (the two planes then disagree)."""
    table = SlotTable(16)
    table.use(16)
    real_put = table.put

    def scrambled(at: np.ndarray, values: np.ndarray) -> None:
        real_put(at, values)
        assert table._hi is not None
        table._hi[at[0]] = np.int8(values[0] >> 16)  # the first write wins the high plane

    table.put = scrambled  # type: ignore[method-assign]
    at = np.array([3, 3], dtype=np.int64)
    positions = np.array([1, 1 << 17], dtype=np.int64)
    won = table.claim(at, positions)
    assert won.tolist() == [1, 1]


def test_growth_bytes_counts_three_bytes_a_slot_then_whole_words() -> None:
    table = SlotTable(1000)
    table.use(100)
    assert table.growth_bytes(100) == 0
    assert table.growth_bytes(400) == 300 * 3
    past = slots_module.THREE_BYTE_SLOTS + 1
    assert table.growth_bytes(past) == past * 4


def test_a_store_past_the_three_byte_limit_keeps_every_state(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(slots_module, "THREE_BYTE_SLOTS", 1 << 12)
    rng = np.random.default_rng(5)
    keys = rng.integers(0, 1 << 62, size=(6000, 1), dtype=np.int64).astype(np.uint64)
    keys = np.unique(keys, axis=0)
    store = KeyStore(1, capacity=16)
    sizes = set()
    for start in range(0, keys.shape[0], 700):
        store.add(keys[start : start + 700])
        sizes.add(store._table.slot_bytes)
    assert sizes == {3, 4}  # it started in three bytes and went on in four
    assert store.find(keys).tolist() == list(range(keys.shape[0]))
    assert store.add(keys[::5]).first.size == 0  # all known
