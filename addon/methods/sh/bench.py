"""SH's budgets swept by the benchmarks, the report and AUTO."""

from __future__ import annotations
from ..contract import Bench


class SHBench(Bench):
    budget = ("sh_order", [2, 3, 4, 5])
