"""`KeyStore` over keys kept in byte planes (`PackedRows`), compared a plane at a time:
it numbers and finds keys exactly as a store of whole words does, for every shape of
planes, keys that differ in one plane only, repeats within a batch, small batches
(probed a window at a time) and large ones, and a state limit; a key using bytes its
words do not keep is never found and never stored."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.encoding import KeyArray, KeyStore, PackedRows, keystore

_SHAPES = [
    (8, 1),
    (8, 2),
    (8, 3),
    (8, 4),
    (8, 5),
    (8, 6),
    (8, 7),
    (3, 8, 2),
    (5, 8, 7),
    (1, 8, 8),
    (7, 7),
    (5,),
    (8,),
    (8, 8),
    (2, 4, 6, 1),
]


def _mask(b: int) -> np.uint64:
    return np.uint64((1 << (8 * b)) - 1)


def _pool(rng: np.random.Generator, n: int, word_bytes: tuple[int, ...]) -> KeyArray:
    """``n`` distinct keys fitting ``word_bytes``: random ones, then copies of them
    that differ in a single byte (so in a single plane), often the last word's top
    byte (the last plane)."""
    base_n = max(1, n // 2)
    cols = [rng.integers(0, 1 << 64, size=base_n, dtype=np.uint64) & _mask(b) for b in word_bytes]
    base: KeyArray = np.stack(cols, axis=1)
    twins = base[rng.integers(0, base_n, size=n - base_n)].copy()
    last = len(word_bytes) - 1
    for row in twins:
        if rng.random() < 0.5:
            w, byte = last, word_bytes[last] - 1
        else:
            w = int(rng.integers(0, len(word_bytes)))
            byte = int(rng.integers(0, word_bytes[w]))
        flip = np.uint64(int(rng.integers(1, 256)) << (8 * byte))
        row[w] ^= flip
    keys: KeyArray = np.unique(np.concatenate([base, twins]), axis=0)
    return keys[rng.permutation(keys.shape[0])]


def _batches(rng: np.random.Generator, pool: KeyArray, sizes: list[int]) -> list[KeyArray]:
    """Batches drawn from ``pool`` with repeats (within and across batches)."""
    return [pool[rng.integers(0, pool.shape[0], size=m)] for m in sizes]


def _agree(word_bytes: tuple[int, ...], seed: int, sizes: list[int]) -> None:
    rng = np.random.default_rng(seed)
    n_words = len(word_bytes)
    pool = _pool(rng, 3 * sum(sizes) // 4 + 2, word_bytes)
    packed = KeyStore(n_words, capacity=16, word_bytes=word_bytes)
    plain = KeyStore(n_words, capacity=16)
    numbers: dict[tuple[int, ...], int] = {}
    for batch in _batches(rng, pool, sizes):
        got = packed.add(batch, want_ids=True)
        want = plain.add(batch, want_ids=True)
        assert got.first.tolist() == want.first.tolist()
        assert got.start == want.start and not got.cut
        assert got.ids is not None and want.ids is not None
        assert got.ids.tolist() == want.ids.tolist()
        for key, number in zip(map(tuple, batch.tolist()), got.ids.tolist(), strict=True):
            assert numbers.setdefault(key, number) == number
    assert packed.size == plain.size == len(numbers)
    ids = packed.find(pool)
    assert ids.tolist() == plain.find(pool).tolist()
    assert ids.tolist() == [numbers.get(key, -1) for key in map(tuple, pool.tolist())]
    assert np.array_equal(packed.keys[:], plain.keys[:])


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    st.sampled_from(_SHAPES),
    st.integers(0, 2**32 - 1),
    st.lists(st.integers(0, 900), min_size=1, max_size=6),
)
def test_planes_agree_with_whole_words(
    word_bytes: tuple[int, ...], seed: int, sizes: list[int]
) -> None:
    _agree(word_bytes, seed, sizes)


@pytest.mark.parametrize("word_bytes", [(8, 6), (8, 7), (3, 8, 2), (8, 8), (6,)])
def test_large_batches_and_windows_agree(
    word_bytes: tuple[int, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Batches above `PROBE_WINDOW_BELOW` probe a slot at a time, smaller ones a window."""
    monkeypatch.setattr(keystore, "PROBE_WINDOW_BELOW", 64)
    _agree(word_bytes, 17, [5, 40, 300, 3000, 20_000, 70])


@pytest.mark.parametrize("n_words", [2, 3, 9])
def test_whole_words_compared_a_word_at_a_time_or_as_rows(
    n_words: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Whole words below `WIDE_KEYS` are compared a word at a time, wider keys as rows;
    both number keys as a dict does."""
    for wide in (keystore.WIDE_KEYS, 3):
        monkeypatch.setattr(keystore, "WIDE_KEYS", wide)
        rng = np.random.default_rng(n_words)
        pool = _pool(rng, 4000, (8,) * n_words)
        store = KeyStore(n_words, capacity=16)
        numbers: dict[tuple[int, ...], int] = {}
        for batch in _batches(rng, pool, [10, 1000, 5000, 300]):
            added = store.add(batch, want_ids=True)
            assert added.ids is not None
            for key in map(tuple, batch.tolist()):
                numbers.setdefault(key, len(numbers))
            assert added.ids.tolist() == [numbers[key] for key in map(tuple, batch.tolist())]
        assert store.find(pool).tolist() == [numbers.get(k, -1) for k in map(tuple, pool.tolist())]


@pytest.mark.parametrize("word_bytes", [(8, 6), (4, 8, 1), (5,)])
def test_a_state_limit_turns_away_the_same_keys(word_bytes: tuple[int, ...]) -> None:
    rng = np.random.default_rng(3)
    pool = _pool(rng, 3000, word_bytes)
    packed = KeyStore(len(word_bytes), capacity=16, word_bytes=word_bytes)
    plain = KeyStore(len(word_bytes), capacity=16)
    for batch in _batches(rng, pool, [500, 2000, 2000]):
        got = packed.add(batch, limit=700, want_ids=True)
        want = plain.add(batch, limit=700, want_ids=True)
        assert (got.first.tolist(), got.cut) == (want.first.tolist(), want.cut)
        assert got.ids is not None and want.ids is not None
        assert got.ids.tolist() == want.ids.tolist()
    assert packed.find(pool).tolist() == plain.find(pool).tolist()


@pytest.mark.parametrize("word_bytes", [(8, 6), (2, 8), (5,)])
def test_a_key_beyond_the_kept_bytes_is_never_found_nor_stored(word_bytes: tuple[int, ...]) -> None:
    keys = np.array([[1] * len(word_bytes), [2] * len(word_bytes)], dtype=np.uint64)
    store = KeyStore(len(word_bytes), word_bytes=word_bytes)
    store.add(keys)
    # the same planes as key 0, plus a byte its word does not keep
    w = word_bytes.index(min(word_bytes))
    beyond = keys[:1].copy()
    beyond[0, w] |= np.uint64(1) << np.uint64(8 * word_bytes[w])
    assert store.find(np.concatenate([keys, beyond])).tolist() == [0, 1, -1]
    with pytest.raises(ValueError, match="more bytes"):
        store.add(np.concatenate([keys[1:], beyond]))
    assert store.size == 2 and store.find(keys).tolist() == [0, 1]


@settings(max_examples=20, deadline=None, derandomize=True)
@given(st.sampled_from(_SHAPES), st.integers(0, 2**32 - 1), st.integers(0, 500))
def test_rows_split_and_compare_plane_by_plane(
    word_bytes: tuple[int, ...], seed: int, n: int
) -> None:
    rng = np.random.default_rng(seed)
    pool = _pool(rng, n + 2, word_bytes)
    rows = PackedRows(word_bytes, reserve=4)
    rows.append(pool)
    m = pool.shape[0]
    ids = rng.integers(0, m, size=200)
    at = rng.integers(0, m, size=200)
    parts, fits = rows.split(pool)
    assert fits is None
    want = (pool[ids] == pool[at]).all(axis=1)
    assert rows.same(ids, parts, at).tolist() == want.tolist()
    assert keystore.same_parts(parts, ids, at).tolist() == want.tolist()
    assert np.array_equal(rows.take(ids), pool[ids])
