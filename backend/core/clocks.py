"""The two clocks of a recorded mission, and the order each puts its batches in.

*Ground time* is what the ground knew when: each batch at the time it was
journaled, in journal order. *Robot time* is what the robots later reported
happened when: a robot's report or answer at its own time (`at`, the robot's
clock), everything else (operators' operations, the link's notes) at its
journal time. Under a link delay a report reaches the ground minutes after
what it reports; robot time puts it back where it happened.

A batch's robot time (its *key*) is clamped so that replaying in key order
stays a mission the journal could have held:
- never later than its journal time (a robot's clock running ahead);
- never earlier than the robot's previous report (its messages apply in
  sequence order, whatever its clock did).

`Order` sorts the batches by key (ties in journal order) and answers, for a
position p (the first p batches applied), from which snapshot to start and
which batches to apply after it: the largest snapshot all of whose batches
are among the first p, then the rest of them in order.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass

GROUND = "ground"
ROBOT = "robot"
CLOCKS = (GROUND, ROBOT)

# operations whose own time is the robot's (the rest happen on the ground)
ROBOT_TIMED = frozenset({"report", "answer", "ask", "ask_ended"})


def robot_keys(
    ground: Sequence[float], robot: Sequence[float | None], actors: Sequence[str]
) -> list[float]:
    """Each batch's robot time: `robot[i]` the time its robot gave (None: a
    ground batch), `actors[i]` the robot for those (see the module's clamps)."""
    last: dict[str, float] = {}
    keys: list[float] = []
    for g, r, who in zip(ground, robot, actors, strict=True):
        if r is None:
            keys.append(g)
            continue
        k = min(g, max(r, last.get(who, r)))
        last[who] = k
        keys.append(k)
    return keys


@dataclass(frozen=True)
class Plan:
    """How to rebuild the state after the first p batches of an order:
    start from snapshot `snapshot` (a batch index: its mission holds batches
    0..snapshot; -1 for the base), then apply `apply` (batch indices) in order."""

    snapshot: int
    apply: list[int]


def _furthest_so_far(pos: list[int]) -> list[int]:
    """The furthest position among batches 0..i, for each i (a loop: the
    builtin max per item costs half as much again)."""
    out: list[int] = []
    top = -1
    for p in pos:
        top = p if p > top else top
        out.append(top)
    return out


def _nearest_from(pos: list[int]) -> list[int]:
    """The nearest position among batches i..n-1, for each i."""
    out = [0] * len(pos)
    low = len(pos)
    for i in range(len(pos) - 1, -1, -1):
        low = pos[i] if pos[i] < low else low
        out[i] = low
    return out


class Order:
    """Batch indices 0..n-1 sorted by `keys` (stable: ties keep journal order)."""

    def __init__(self, keys: Sequence[float]) -> None:
        n = len(keys)
        self.keys = keys
        self.order: Sequence[int]
        self.pos: Sequence[int]
        self.reach: Sequence[int]  # the furthest position among batches 0..i
        self.nearest: Sequence[int]  # the nearest position among batches i..n-1
        if all(a <= b for a, b in zip(keys, keys[1:], strict=False)):  # ground time
            self.order = self.pos = self.reach = self.nearest = range(n)
            self.sorted_keys = keys
            return
        order = sorted(range(n), key=keys.__getitem__)
        pos = [0] * n
        for p, i in enumerate(order):
            pos[i] = p
        self.order, self.pos = order, pos
        self.reach, self.nearest = _furthest_so_far(pos), _nearest_from(pos)
        self.sorted_keys = [keys[i] for i in order]

    def __len__(self) -> int:
        return len(self.order)

    def position_at(self, t: float) -> int:
        """How many batches happened at or before `t`."""
        return bisect.bisect_right(self.sorted_keys, t)

    def time_of(self, p: int) -> float | None:
        """The key of the p-th batch (1-based: the last one of the first p)."""
        return self.sorted_keys[p - 1] if 0 < p <= len(self.sorted_keys) else None

    def plan(self, p: int, snapshots: Sequence[int]) -> Plan:
        """How to rebuild the state after the first p batches, from the
        snapshots at batch indices `snapshots` (ascending; -1: the base)."""
        k = bisect.bisect_right(snapshots, p - 1) - 1
        while k >= 0 and snapshots[k] >= 0 and self.reach[snapshots[k]] >= p:
            k -= 1  # a batch it holds comes later in this order
        start = snapshots[k] if k >= 0 else -1
        rest: list[int] = []
        i = start + 1
        n = len(self.order)
        while i < n and self.nearest[i] < p:
            if self.pos[i] < p:
                rest.append(i)
            i += 1
        rest.sort(key=self.pos.__getitem__)
        return Plan(start, rest)
