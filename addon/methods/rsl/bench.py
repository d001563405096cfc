"""RSL's budgets swept by the benchmarks, the report and AUTO."""

from __future__ import annotations
from ..contract import Bench


class RSLBench(Bench):
    budget = ("rsl_lights", [10, 30, 60, 100])

    def budget_between(self, lower, upper):
        """Light count halfway (the per-frame cost is about linear in it)."""
        mid = (int(lower) + int(upper)) // 2
        return mid if lower < mid < upper else None
