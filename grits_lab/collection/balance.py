"""Balanced acceptance for the spillage dataset: fill (shape, label) buckets from candidate trials in index order.

Candidates of a shape are numbered 0, 1, 2, ...; their outcomes arrive in any order (parallel
workers), but decisions are made strictly in index order: candidate k is accepted iff its label's
bucket for that shape is not yet full once candidates 0..k-1 are decided. So the accepted set
depends only on the seeds, never on timing, worker count or interruptions, and a resumed job
reproduces an uninterrupted one. Outcomes that arrive early wait (bounded by the number in flight).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class Decision:
    shape: str
    index: int
    label: int | None  # None: the candidate failed (no label)
    accepted: bool
    payload: Any = None


@dataclass
class _ShapeState:
    next_submit: int = 0
    next_decide: int = 0
    counts: dict[int, int] = field(default_factory=lambda: {0: 0, 1: 0})
    waiting: dict[int, tuple[int | None, Any]] = field(default_factory=dict)


class BalancedAcceptor:
    """targets[shape] = (no-spill count, spill count). `max_candidates` caps tries per shape."""

    def __init__(self, targets: dict[str, tuple[int, int]], max_candidates: int):
        self.targets = targets
        self.max_candidates = max_candidates
        self.state = {shape: _ShapeState() for shape in targets}

    def full(self, shape: str) -> bool:
        s, (n0, n1) = self.state[shape], self.targets[shape]
        return s.counts[0] >= n0 and s.counts[1] >= n1

    def exhausted(self, shape: str) -> bool:
        return self.state[shape].next_submit >= self.max_candidates

    def done(self) -> bool:
        """Every bucket full, or every unfinished shape out of candidates and fully decided."""
        return all(
            self.full(sh) or (self.exhausted(sh) and self.state[sh].next_decide >= self.state[sh].next_submit)
            for sh in self.targets
        )

    def next_candidate(self, in_flight: dict[str, int]) -> tuple[str, int] | None:
        """The next (shape, index) to run, or None if no shape needs more right now.

        A shape is offered more only while its undecided candidates (in flight or waiting) are
        fewer than its still-missing trials, so a nearly full bucket does not draw a crowd of
        candidates that will be thrown away. Shapes are served least-advanced first.
        """
        best = None
        for shape in self.targets:
            s = self.state[shape]
            if self.full(shape) or self.exhausted(shape):
                continue
            n0, n1 = self.targets[shape]
            missing = max(0, n0 - s.counts[0]) + max(0, n1 - s.counts[1])
            undecided = s.next_submit - s.next_decide
            if undecided >= max(missing, 1) and in_flight.get(shape, 0) > 0:
                continue
            if best is None or s.next_submit < self.state[best].next_submit:
                best = shape
        if best is None:
            return None
        s = self.state[best]
        s.next_submit += 1
        return best, s.next_submit - 1

    def skip_to(self, shape: str, index: int) -> None:
        """Mark candidates below `index` as submitted (used when replaying a log on resume)."""
        s = self.state[shape]
        s.next_submit = max(s.next_submit, index)

    def add(self, shape: str, index: int, label: int | None, payload: Any = None) -> list[Decision]:
        """Record an outcome; return the decisions that became possible, in index order."""
        s = self.state[shape]
        s.waiting[index] = (label, payload)
        out = []
        while s.next_decide in s.waiting:
            label_k, payload_k = s.waiting.pop(s.next_decide)
            accepted = False
            if label_k is not None:
                bucket = self.targets[shape][label_k]
                if s.counts[label_k] < bucket:
                    s.counts[label_k] += 1
                    accepted = True
            out.append(Decision(shape, s.next_decide, label_k, accepted, payload_k if accepted else None))
            s.next_decide += 1
        return out

    def counts(self) -> dict[str, dict[int, int]]:
        return {shape: dict(s.counts) for shape, s in self.state.items()}
