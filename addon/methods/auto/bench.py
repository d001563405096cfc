"""What the report and the panel read of AUTO: the method and budget it chose per object
for the newest frame."""

from __future__ import annotations

from ..contract import Bench
from .shading import LAST_CHOICES


class AutoBench(Bench):
    def last_choices(self):
        return list(LAST_CHOICES)
