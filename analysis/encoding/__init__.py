"""Compact, array-based views of a `Net` for fast exploration.

One module per piece; this package re-exports their public names, so
``from analysis.encoding import X`` works whichever module ``X`` lives in:

* `analysis.encoding.compact` — `CompactNet`: the net as numpy arrays, built once from
  its arcs. Presets and effects are sparse (one entry per arc), grouped by preset size
  so that enabling over a whole frontier is a handful of vectorised gathers. Dense
  ``pre``/``post``/``delta`` matrices (transitions x places) are built only when asked
  for: a mission with 10,000 transitions and places would need gigabytes for them.
* `analysis.encoding.components` — `one_hot_components`: sets of places proven (on the
  arcs, exactly) never to hold more than one token between them, e.g. the control
  states of a process or a branch of a mission.
* `analysis.encoding.layout` — `Layout`: how a marking is packed into a few ``uint64``
  words. Each *field* is either one place's token count (wide enough for the tokens
  seen so far) or a component, stored as which of its ``k`` places is marked:
  ``log2 k`` bits instead of ``k``. Packing is linear and injective on reachable
  markings, so two markings are equal exactly when their keys are, and the key of
  ``m + delta(t)`` is ``key(m) + key_delta(t)`` (mod ``2**64`` per word) as long as no
  count field overflows, which the explorer checks before it trusts a successor key.
  `FieldNet`: the net seen through the fields, so that the frontier holds field values
  (11 per Peterson marking instead of 244 place counts).
* `analysis.encoding.keystore` — `KeyStore`: the packed keys in discovery order plus an
  open-addressing hash table of them, with batch insertion vectorised over whole
  frontiers; `analysis.encoding.slots` — `SlotTable`, that table's slots (3 bytes
  each while it is small enough); `analysis.encoding.reserved` — zeroed memory
  reserved up front for arrays that grow.
"""

from analysis.encoding.bounds import UNBOUNDED, invariant_place_bounds
from analysis.encoding.compact import (
    FIELD_LOOP,
    MAX_FIELD_BITS,
    NEVER,
    Arcs,
    BoolArray,
    CompactNet,
    IntArray,
    KeyArray,
    PresetGroup,
)
from analysis.encoding.components import (
    DENSE_SEARCH_CELLS,
    GROW_CLASSES,
    SEARCH_PLACES,
    SEARCH_ROWS,
    SEARCH_SECONDS,
    Component,
    one_hot_components,
)
from analysis.encoding.keystore import (
    BATCH_LOAD,
    EMPTY,
    FILL_CHUNK,
    MAX_LOAD,
    PROBE_WINDOW_BELOW,
    RESERVE_LIMIT,
    WIDE_KEYS,
    Added,
    Growable,
    KeyStore,
    KeyView,
    PackedRows,
    first_occurrences,
    word_multipliers,
)
from analysis.encoding.layout import FieldGroup, FieldNet, Layout, row_dtype
from analysis.encoding.reserved import RESERVE_BYTES
from analysis.encoding.slots import THREE_BYTE_SLOTS, SlotTable

__all__ = [
    "BATCH_LOAD",
    "DENSE_SEARCH_CELLS",
    "EMPTY",
    "FIELD_LOOP",
    "FILL_CHUNK",
    "GROW_CLASSES",
    "MAX_FIELD_BITS",
    "MAX_LOAD",
    "NEVER",
    "PROBE_WINDOW_BELOW",
    "RESERVE_BYTES",
    "RESERVE_LIMIT",
    "SEARCH_PLACES",
    "SEARCH_ROWS",
    "SEARCH_SECONDS",
    "THREE_BYTE_SLOTS",
    "UNBOUNDED",
    "WIDE_KEYS",
    "Added",
    "Arcs",
    "BoolArray",
    "CompactNet",
    "Component",
    "FieldGroup",
    "FieldNet",
    "Growable",
    "IntArray",
    "KeyArray",
    "KeyStore",
    "KeyView",
    "Layout",
    "PackedRows",
    "PresetGroup",
    "SlotTable",
    "first_occurrences",
    "invariant_place_bounds",
    "one_hot_components",
    "row_dtype",
    "word_multipliers",
]
