"""The calibrated world reproduces the ROSMC pilot study (section V-B).

Each test plays one strategy (tests/sim/pilot.py) against the real mission server and
`missionctl sim` at sim speed, through the operator's interfaces only; the truth is
read after the 26.8 sim-minutes, to evaluate. Each strategy runs here on one seed (the
CI budget); bench/pilot_study.py runs all of them on 5 seeds, and docs/pilot-study.md
reports the scores beside the paper's.
"""

from __future__ import annotations

from .conftest import Stack, connect
from .pilot import BEST, DEADLINE, SIM_OPTIONS, Result, play

SPEED = 100.0  # 26.8 sim-minutes in about 16 wall seconds


async def run_strategy(stack: Stack, strategy: str, seed: int) -> Result:
    extra = SIM_OPTIONS.get(strategy, [])
    client, watch = await connect(stack, speed=SPEED, seed=seed, extra=extra)
    try:
        return await play(client, strategy, seed)
    finally:
        watch.close()
        await client.close()


def _why(r: Result) -> str:
    return "\n".join([f"score {r.score}", *r.notes, *r.skills, *r.refusals])


async def test_the_ideal_strategy_scores_the_best_participants_result_in_time(
    stack: Stack,
) -> None:
    """All three robots explore, LRU1's camera reveals the top scores out there, LRU2's
    Wi-Fi box brings coverage, LRU1 and LRU2 take the two most valuable stones."""
    r = await run_strategy(stack, "ideal", seed=1)
    assert r.score >= BEST, _why(r)
    assert r.reached_best_at is not None and r.reached_best_at <= DEADLINE, _why(r)
    # the two most valuable regions, far from the lander, bottom right
    assert {s.split("-s")[0] for s, _v, _t in r.deliveries} == {"RSS-E", "RSS-F"}, _why(r)
    assert r.truth is not None
    best = sorted(r.truth.regions, key=lambda g: -g.max_score)[:2]
    assert all(g.x > 50 and g.y < -30 and g.x**2 + g.y**2 > 90**2 for g in best)
    assert not r.failures, _why(r)


async def test_a_naive_plan_scores_about_one(stack: Stack) -> None:
    """The rovers explore near the lander and take what they find there together."""
    r = await run_strategy(stack, "naive", seed=2)
    assert 0.7 <= r.score <= 1.3, _why(r)


async def test_farming_the_nearest_region_scores_clearly_less_than_the_ideal(
    stack: Stack,
) -> None:
    r = await run_strategy(stack, "farming", seed=3)
    assert 0.0 < r.score <= BEST - 0.5, _why(r)
    assert {s.split("-s")[0] for s, _v, _t in r.deliveries} == {"RSS-A"}, _why(r)
    # the region holds few stones: farming it runs dry
    assert any("every stone of RSS-A is identified already" in why for *_, why in r.failures)


async def test_ignoring_the_batteries_fails(stack: Stack) -> None:
    """The ideal plan without recharging: a rover runs dry out there."""
    r = await run_strategy(stack, "ignoring_batteries", seed=4)
    assert r.score < BEST, _why(r)
    assert any("battery empty" in why for *_, why in r.failures), _why(r)


async def test_ignoring_the_coverage_fails(stack: Stack) -> None:
    """The ideal plan without a Wi-Fi box: LRU1 out there and LRU2 cannot talk, so their
    barrier never starts (LRU2, in range, shows LRU1 as unreachable): no top-score stone."""
    r = await run_strategy(stack, "ignoring_coverage", seed=5)
    assert r.score < BEST, _why(r)
    assert r.truth is not None
    assert not [s for s in r.truth.stones if s.score is not None and s.score > 0.1], _why(r)
    assert any("(unreachable)" in line for line in r.skills), _why(r)


async def test_lru1_broken_at_12_minutes_is_substituted_by_lru3(stack: Stack) -> None:
    """The ideal plan with LRU1 stopping at 12 sim-minutes and LRU3 (an lru_science)
    arriving at 15: the operator takes LRU2's queue back, adds LRU3, retires LRU1, gives
    it LRU1's plan, and LRU3 identifies the two best stones with LRU2 in LRU1's place.
    It plays on past the deadline (OVERTIME) so that the delivery's time is known."""
    r = await run_strategy(stack, "substituted", seed=1)
    notes = "\n".join(r.notes)
    assert "lru1 stopped responding" in notes and "lru2's queue taken back" in notes, _why(r)
    assert "lru3 (lru_science) added; lru1 retired" in notes, _why(r)
    assert any(
        line.startswith("lru3 identify_stone: success") and line.endswith("with lru2")
        for line in r.skills
    ), _why(r)
    # both top stones, by LRU3 and LRU2 together; the score counts what came in time
    assert {s.split("-s")[0] for s, _v, _t in r.deliveries} == {"RSS-E", "RSS-F"}, _why(r)
    assert sum(v for _s, v, _t in r.deliveries) >= BEST, _why(r)
    assert r.score == sum(v for _s, v, t in r.deliveries if t <= DEADLINE)
    assert not [f for f in r.failures if f[0] != "lru1"], _why(r)  # lru1's: outcome unknown
