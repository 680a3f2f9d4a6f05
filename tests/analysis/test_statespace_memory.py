"""What the explorer does to keep its resident memory close to what it stores: steps
sized in bytes (`BLOCK_TEMPORARY_BYTES`), sleep sets in a spool of their own, and the
C heap's free pages given back before the table grows. None of it may change what is
found."""

from __future__ import annotations

import pytest

import analysis.encoding.keystore as keystore
import analysis.statespace as statespace
from analysis.encoding import CompactNet
from analysis.statespace import explore
from coral_lang.pnml import read_pnml
from tests.analysis.explored import fingerprint
from tests.analysis.test_command_budget import _wide
from tests.conftest import CONFORMANCE


@pytest.fixture(scope="module")
def philosophers() -> CompactNet:
    # 59,049 states, 7.8 edges per marking, 1 word of sleep sets
    return CompactNet.from_net(read_pnml(CONFORMANCE / "pnml" / "Philosophers-PT-000010.pnml"))


def test_blocks_stay_within_their_byte_budget(
    monkeypatch: pytest.MonkeyPatch, philosophers: CompactNet
) -> None:
    budget = 1 << 20
    monkeypatch.setattr(statespace, "BLOCK_TEMPORARY_BYTES", budget)
    seen: list[tuple[int, int]] = []
    sized = statespace._Explorer.block_size

    def recorded(self: statespace._Explorer) -> int:
        size: int = sized(self)
        fired = self.bit_fired / max(1, self.bit_sources) if self.bits is not None else 0.0
        if self.bit_fired:
            seen.append((size, self.state_bytes + int(max(fired, 1.0) * self.edge_bytes)))
        return size

    monkeypatch.setattr(statespace._Explorer, "block_size", recorded)
    space = explore(philosophers, max_states=100_000)
    assert space.complete and seen
    assert all(size <= max(256, budget // per_state) for size, per_state in seen)
    assert max(size for size, _ in seen) < statespace.DEFAULT_CHUNK  # the budget bound


def test_small_blocks_find_the_same_space(
    monkeypatch: pytest.MonkeyPatch, philosophers: CompactNet
) -> None:
    whole = explore(philosophers, max_states=100_000)
    monkeypatch.setattr(statespace, "BLOCK_TEMPORARY_BYTES", 1)  # blocks of 256 markings
    small = explore(philosophers, max_states=100_000)
    assert fingerprint(small) == fingerprint(whole)
    assert small.trace_to(small.states - 1) == whole.trace_to(whole.states - 1)


def test_free_heap_is_given_back_before_the_table_grows(
    monkeypatch: pytest.MonkeyPatch, philosophers: CompactNet
) -> None:
    growths: list[int] = []
    resize = keystore.KeyStore._resize

    def recorded(self: keystore.KeyStore, slots: int) -> None:
        growths.append(self._table.growth_bytes(slots))
        resize(self, slots)

    calls: list[int] = []
    monkeypatch.setattr(keystore, "TRIM_GROWTH_BYTES", 1 << 16)
    monkeypatch.setattr(keystore, "release_free_heap", lambda: calls.append(1))
    monkeypatch.setattr(keystore.KeyStore, "_resize", recorded)
    explore(philosophers, max_states=100_000)
    assert len(calls) == sum(1 for grown in growths if grown >= 1 << 16) >= 1


def test_steps_of_a_wide_net_are_sized_by_edges_per_expanded_state(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # 300 two-place cycles with 20 parallel transitions each: about 6,000 edges per
    # marking. Sized by edges per *stored* state (a layer of 300 markings stores 45,000
    # successors), a block took 883 markings and 2.1 million edges here, and 7,513 and
    # 45 million later in the search (8-13 s for one step).
    cn = CompactNet.from_net(_wide(300, 20))
    steps: list[int] = []
    depth = [0]
    step = statespace._Explorer.step

    def recorded(self: statespace._Explorer, *args: object) -> object:
        depth[0] += 1
        before = self.edges
        try:
            return step(self, *args)  # type: ignore[arg-type]
        finally:
            depth[0] -= 1
            if not depth[0]:  # a block of the layer loop (halves of a split inside it)
                steps.append(self.edges - before)

    monkeypatch.setattr(statespace._Explorer, "step", recorded)
    space = explore(cn, max_states=100_000)
    assert space.states == 100_000 and len(steps) >= 2
    smallest_block = 256 * cn.n_transitions  # (blocks are never below 256 markings)
    assert max(steps) <= max(2 * statespace.EDGES_PER_STEP, smallest_block)
