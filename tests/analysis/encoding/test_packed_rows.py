"""`PackedRows`: keys stored in only the bytes their words use read back exactly (ranges,
gathers across growth), a `KeyStore` over them finds every key, and the explorer stores
no more bytes per key than its layout's fields reach."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis import statespace
from analysis.encoding import KeyArray, KeyStore, PackedRows
from analysis.statespace import explore
from coral_lang.net import Net
from tests.analysis.nets import make_net, replay
from tests.analysis.strategies import small_nets


def _keys(rng: np.random.Generator, n: int, word_bytes: tuple[int, ...]) -> KeyArray:
    """``n`` random keys whose word ``w`` uses at most ``word_bytes[w]`` bytes."""
    cols = [
        rng.integers(0, 1 << 62, size=n, dtype=np.int64).astype(np.uint64)
        >> np.uint64(64 - 8 * b if b < 8 else 0)
        for b in word_bytes
    ]
    keys: KeyArray = np.stack(cols, axis=1)
    return keys


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    st.lists(st.integers(1, 8), min_size=1, max_size=4),
    st.integers(0, 3000),
    st.integers(0, 2**32 - 1),
)
def test_rows_read_back_as_written(word_bytes: list[int], n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    rows = PackedRows(word_bytes, reserve=7)  # small: appends grow past the reservation
    keys = _keys(rng, n, tuple(word_bytes))
    for start in range(0, n, 700):
        rows.append(keys[start : start + 700])
    assert rows.size == n and rows.nbytes == n * sum(word_bytes)
    assert np.array_equal(rows.words(0, n), keys)
    assert np.array_equal(rows.words(n // 3, n // 2), keys[n // 3 : n // 2])
    ids = rng.integers(0, max(1, n), size=min(n, 500)) if n else np.zeros(0, np.int64)
    assert np.array_equal(rows.take(ids), keys[ids])
    if len(word_bytes) == 1:
        assert np.array_equal(rows.take_flat(ids), keys[ids, 0])


def test_a_key_wider_than_its_bytes_is_refused() -> None:
    rows = PackedRows([2], reserve=4)
    with pytest.raises(ValueError, match="more than 2 bytes"):
        rows.append(np.array([[1 << 16]], dtype=np.uint64))


def test_store_on_packed_rows_finds_every_key_and_repacks_to_other_bytes() -> None:
    rng = np.random.default_rng(5)
    keys = np.unique(_keys(rng, 40_000, (5, 3)), axis=0)
    keys = keys[rng.permutation(keys.shape[0])]
    store = KeyStore(2, capacity=16, word_bytes=(5, 3))
    added = store.add(np.concatenate([keys, keys[::7]]))
    assert added.first.size == keys.shape[0] and store.keys.nbytes == 8 * keys.shape[0]
    assert store.find(keys[::-1]).tolist() == list(range(keys.shape[0] - 1, -1, -1))
    # a new packing with more bytes: word 1 moves up a byte
    store.repack(lambda block: block << np.uint64(8) * np.array([0, 1], np.uint64), 2, (5, 4))
    moved: KeyArray = keys << np.array([0, 8], dtype=np.uint64)
    assert store.word_bytes == (5, 4)
    assert store.find(moved[::5]).tolist() == list(range(0, keys.shape[0], 5))
    assert np.array_equal(store.keys[:], moved)


@settings(max_examples=10, deadline=None, derandomize=True)
@given(small_nets(max_initial=3))
def test_explorer_stores_the_bytes_its_layout_reaches(net: Net) -> None:
    space = explore(net, max_states=500)
    n_words = space.layout.n_words
    expected = space.layout.word_bytes if n_words == 1 else (8,) * n_words
    assert space.store.word_bytes == expected
    words = space.keys[:]
    assert all(
        int(w).bit_length() <= 8 * b
        for row in words.tolist()
        for w, b in zip(row, space.layout.word_bytes, strict=True)
    )


@settings(max_examples=10, deadline=None, derandomize=True)
@given(small_nets(max_initial=3))
def test_wide_keys_packed_give_the_same_state_space(net: Net) -> None:
    packed = explore(net, max_states=500)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(statespace, "PACK_WIDE_KEYS", False)
        plain = explore(net, max_states=500)
    assert packed.store.word_bytes == packed.layout.word_bytes
    assert (packed.states, packed.edges) == (plain.states, plain.edges)
    assert packed.deadlocks.tolist() == plain.deadlocks.tolist()
    assert np.array_equal(packed.keys[:], plain.keys[:])
    last = packed.states - 1
    assert packed.trace_to(last) == plain.trace_to(last)


def test_wide_keys_packed_agree_on_a_net_of_several_words() -> None:
    big = 1 << 40  # four counts of 41 bits: a key of several words
    net = make_net(
        "wide",
        {"fuel": 50, "a": big, "b": big, "c": big, "d": big},
        {
            "ab": ({"fuel": 1, "a": 1}, {"b": 1}),
            "cd": ({"fuel": 1, "c": 1}, {"d": 1}),
        },
    )
    packed = explore(net)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(statespace, "PACK_WIDE_KEYS", False)
        plain = explore(net)
    assert packed.layout.n_words > 1 and sum(packed.store.word_bytes) < 8 * packed.layout.n_words
    assert plain.store.word_bytes == (8,) * plain.layout.n_words
    assert (packed.states, packed.edges) == (plain.states, plain.edges) == (51 * 52 // 2, 2550)
    assert np.array_equal(packed.keys[:], plain.keys[:])
    for index in (0, 700, packed.states - 1):
        trace = packed.trace_to(index)
        assert replay(net, trace) == packed.marking(index) == plain.marking(index)
        assert len(trace) == packed.depth_of(index)
