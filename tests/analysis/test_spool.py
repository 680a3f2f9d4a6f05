"""`analysis.spool.RowSpool`: rows come out as they went in, in order, whatever the
pieces they were appended and taken in, and read segments are let go."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis import spool
from analysis.spool import RowSpool


@st.composite
def appends_and_takes(draw: st.DrawFn) -> tuple[int, list[np.ndarray], list[int]]:
    width = draw(st.integers(1, 10))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    words = np.array([0, 1, 2**63, 2**64 - 1, 12345], dtype=np.uint64)
    zeros = draw(st.floats(0.0, 1.0))  # share of zero words: sleep sets are mostly zero
    pieces = []
    for n in draw(st.lists(st.integers(0, 40), max_size=8)):
        piece = rng.choice(words, size=(n, width))
        piece[rng.random((n, width)) < zeros] = 0
        pieces.append(piece)
    total = sum(p.shape[0] for p in pieces)
    cuts = sorted(draw(st.lists(st.integers(0, total), max_size=6)))
    takes = np.diff([0, *cuts, total]).tolist()
    return width, pieces, takes


@settings(max_examples=150, deadline=None)
@given(appends_and_takes())
def test_rows_come_out_in_order(case: tuple[int, list[np.ndarray], list[int]]) -> None:
    width, pieces, takes = case
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(spool, "SEGMENT_BYTES", 64)  # many segments, values split across them
        queue = RowSpool(width)
        for piece in pieces:
            queue.append(piece)
        got = [queue.take(k) for k in takes]
    expected = np.concatenate([np.zeros((0, width), np.uint64), *pieces])
    out = np.concatenate([np.zeros((0, width), np.uint64), *got])
    assert out.dtype == np.uint64 and out.shape == expected.shape
    assert np.array_equal(out, expected)
    assert queue.size == 0


def test_takes_interleaved_with_appends() -> None:
    rng = np.random.default_rng(7)
    queue = RowSpool(4)
    pending: list[np.ndarray] = []
    for _ in range(50):
        rows = rng.integers(0, 3, size=(int(rng.integers(0, 500)), 4)).astype(np.uint64)
        queue.append(rows)
        pending.extend(rows)
        k = int(rng.integers(0, queue.size + 1))
        got = queue.take(k)
        assert np.array_equal(got, np.array(pending[:k], dtype=np.uint64).reshape(k, 4))
        del pending[:k]
    assert queue.size == len(pending)


def test_read_segments_are_released(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(spool, "SEGMENT_BYTES", 4096)
    queue = RowSpool(1)
    queue.append(np.arange(10 * 512, dtype=np.uint64)[:, None])  # ten segments
    full = queue.mapped_bytes
    assert full >= 10 * 4096
    queue.take(5 * 512)
    assert queue.mapped_bytes <= full // 2 + 4096
    queue.take(5 * 512)
    assert queue.mapped_bytes == 0


def test_sparse_rows_keep_only_nonzero_words() -> None:
    queue = RowSpool(8)
    rows = np.zeros((4096, 8), dtype=np.uint64)
    rows[:, 3] = 5  # one nonzero word in eight
    queue.append(rows)
    assert queue.sparse
    assert queue.nbytes < rows.nbytes // 2
    assert np.array_equal(queue.take(4096), rows)


def test_dense_rows_are_kept_whole() -> None:
    queue = RowSpool(4)
    rows = np.full((1000, 4), 7, dtype=np.uint64)
    rows[::10, 0] = 0  # 97.5 % nonzero: the marks would cost more than they save
    queue.append(rows)
    assert queue.sparse is False
    queue.append(np.zeros((10, 4), dtype=np.uint64))  # later rows follow the first ones
    assert queue.sparse is False and queue.nbytes == rows.nbytes + 10 * 32
    assert np.array_equal(queue.take(1000), rows)


def test_bad_shapes_and_counts_are_refused() -> None:
    queue = RowSpool(2)
    with pytest.raises(ValueError, match="width 2"):
        queue.append(np.zeros((3, 3), dtype=np.uint64))
    queue.append(np.ones((3, 2), dtype=np.uint64))
    with pytest.raises(ValueError, match="cannot take 4 rows of 3"):
        queue.take(4)
    with pytest.raises(ValueError, match="at least one word"):
        RowSpool(0)
