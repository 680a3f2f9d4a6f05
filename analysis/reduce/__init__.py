"""Structural reductions: smaller nets with the same answer, before any search.

Classic rule families (Berthelot 1986; Haddad & Pradat-Peyre 2006; as applied by
TAPAAL and ITS-Tools), each applied only when it preserves the `Goal` being checked:
dead parts (`dead`), redundant transitions (`redundant`: duplicates, dominated
self-loops, always-enabled ones), implicit places (`implicit`), transitions in series and
pre-/post-agglomeration (`agglomerate`), places in series (`fusion`). `reduce_net` drives
them; `decide_deadlock` answers the deadlock question on the reduced net (random walks,
the siphon-trap property, then a search) and maps the witness back. See
docs/analysis-methods.md, "Structural reductions".
"""

from analysis.reduce.deadlock import DeadlockAnswer, decide_deadlock
from analysis.reduce.driver import Reduction, reduce_net
from analysis.reduce.goal import Goal, Kind

__all__ = ["DeadlockAnswer", "Goal", "Kind", "Reduction", "decide_deadlock", "reduce_net"]
