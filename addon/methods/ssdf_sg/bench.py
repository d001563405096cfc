"""SSDF_SG's budgets swept by the benchmarks, the report and AUTO."""

from __future__ import annotations
from ....core.methods.ssdf_sg import scene as scene
from ..contract import Bench


class SSDFSGBench(Bench):
    budget = ("ssdf_error_budget", [0.2, 0.1, 0.05, 0.025])
