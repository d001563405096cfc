"""WAVELET's budgets swept by the benchmarks, the report and AUTO."""

from __future__ import annotations
import numpy as np
from ..contract import Bench


class WaveletBench(Bench):
    budget = ("wavelet_terms", [32, 128, 512, 2048])

    def budget_between(self, lower, upper):
        """Term count at the geometric mean (the values are spaced by factors)."""
        mid = int(round(float(np.sqrt(float(lower) * float(upper)))))
        return mid if lower < mid < upper else None
