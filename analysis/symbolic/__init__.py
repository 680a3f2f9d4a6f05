"""Symbolic state spaces: the reachable markings of a P/T net as a binary decision
diagram (CUDD through ``dd.cudd``), for nets whose state space no explicit search can
store. See docs/analysis-methods.md, "Symbolic state spaces"."""

from analysis.symbolic.choose import choose_method
from analysis.symbolic.explore import SymbolicLimits, SymbolicResult, explore_symbolic

__all__ = ["SymbolicLimits", "SymbolicResult", "choose_method", "explore_symbolic"]
