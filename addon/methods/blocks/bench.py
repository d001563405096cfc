"""BLOCKS's budgets swept by the benchmarks, the report and AUTO."""

from __future__ import annotations
from ..contract import Bench


class BlocksBench(Bench):
    budget = ("blocks_tolerance", [0.3, 0.1, 0.01, 0.001])
