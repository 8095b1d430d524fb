"""What a finder gives (its tests, or why it has none) and the plan they go in; the
helpers every finder shares."""

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from credibility import indices
from credibility.plan import NotScorable

#: The paper's weights (section 4.2.4): frequency counts most for a dynamic system.
PAPER_WEIGHTS = {"performance": 0.3, "time": 0.3, "frequency": 0.4}


@dataclass(frozen=True)
class PlannedTest:
    """One test of the plan: its keys as the plan file writes them, and what was found."""

    name: str
    kind: indices.Kind
    #: The comment above the test: what the finder found, in numbers, and by what criterion.
    found: str
    keys: dict[str, Any]


@dataclass(frozen=True)
class Draft:
    """A plan found in a log, before it is written."""

    name: str
    description: str
    tests: tuple[PlannedTest, ...]
    not_scorable: tuple[NotScorable, ...]

    @property
    def weights(self) -> dict[str, float]:
        """The paper's weights over the kinds the plan holds, scaled to sum 1."""
        kinds = {test.kind for test in self.tests}
        present = {kind: alpha for kind, alpha in PAPER_WEIGHTS.items() if kind in kinds}
        total = sum(present.values())
        return {kind: round(alpha / total, 6) for kind, alpha in present.items()}


#: A finder gives its tests, or the entries it could not plan.
Found = tuple[list[PlannedTest], list[NotScorable]]


def runs(
    time_s: NDArray[np.float64], values: NDArray[Any], end_s: float
) -> list[tuple[float, float, float]]:
    """(start, end, value) of each run of equal values of a logged state; the last run ends
    at ``end_s``."""
    changes = np.flatnonzero(np.diff(values)) + 1
    starts = np.concatenate(([0], changes))
    ends = np.append(time_s[changes], max(end_s, float(time_s[-1])))
    return [
        (float(time_s[i]), float(e), float(values[i])) for i, e in zip(starts, ends, strict=True)
    ]


def span(start: float, end: float) -> tuple[float, float]:
    """[start, end] to the hundredth, inside the times given (a plan file is read by
    people; a segment rounded past the log's end would not be scored)."""
    return math.ceil(start * 100) / 100, math.floor(end * 100) / 100


def without_path(error: Exception) -> str:
    """A LogError's message without the log's path, which the plan names once."""
    text = str(error)
    head, sep, rest = text.partition(": ")
    return rest if sep and head.endswith((".ulg", ".ULG")) else text
