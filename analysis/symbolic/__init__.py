"""Symbolic state spaces: the reachable markings of a P/T net as a decision diagram
(a multi-valued one built by node saturation; binary ones through CUDD, ``dd.cudd``),
for nets whose state space no explicit search can store. See docs/analysis-methods.md,
"Symbolic state spaces".

The exploration is imported on first use: loading CUDD costs about 0.15 s, which a
run that never builds a diagram should not pay."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from analysis.symbolic.explore import SymbolicLimits, SymbolicResult, explore_symbolic

__all__ = ["SymbolicLimits", "SymbolicResult", "explore_symbolic"]


def __getattr__(name: str) -> Any:
    if name in ("SymbolicLimits", "SymbolicResult", "explore_symbolic"):
        from analysis.symbolic import explore

        return getattr(explore, name)
    raise AttributeError(f"module 'analysis.symbolic' has no attribute {name!r}")
