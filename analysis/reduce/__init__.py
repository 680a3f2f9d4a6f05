"""Structural reductions: smaller nets with the same answer, before any search.

Classic rule families (Berthelot 1986; Haddad & Pradat-Peyre 2006; as applied by
TAPAAL and ITS-Tools), each applied only when it preserves the `Goal` being checked:
dead parts (`dead`), implicit places (`implicit`), transitions in series
(`agglomerate`), places in series (`fusion`). `reduce_net` drives them;
`decide_deadlock` answers the deadlock question on the reduced net and maps the
witness back. See docs/analysis-methods.md, "Structural reductions".
"""

from analysis.reduce.deadlock import DeadlockAnswer, decide_deadlock
from analysis.reduce.driver import Reduction, reduce_net
from analysis.reduce.goal import Goal, Kind

__all__ = ["DeadlockAnswer", "Goal", "Kind", "Reduction", "decide_deadlock", "reduce_net"]
