"""The demo's simulated crowd draws: crowd 0 is the demo's own, others draw other workers."""

import numpy as np

from backend.crowd.simulate import draw_assisted
from backend.demo import MAX_ROUNDS, MAX_SOLVE_PASSES, round_seed


def test_crowd_zero_is_the_demos_own_draw() -> None:
    assert [round_seed(0, r) for r in (1, 2, 3)] == [8, 9, 10]


def test_no_two_rounds_share_a_seed() -> None:
    # Nor two passes: the crowd that comes back for views a solve published is a new draw.
    seeds = [round_seed(c, r, p) for c in range(40) for p in range(1, MAX_SOLVE_PASSES + 1)
             for r in range(1, MAX_ROUNDS + 1)]
    assert len(set(seeds)) == len(seeds)


def test_other_crowds_put_blind_acceptors_on_other_units() -> None:
    # In one round the workers take the open HITs in order (hand views first): with one
    # crowd the blind acceptors always sit on the same positions, so other crowd seeds must
    # move them.
    placements = {tuple(draw_assisted(16, "mixed", np.random.default_rng(round_seed(c, 1))))
                  for c in range(8)}
    assert len(placements) >= 6
    firsts = [draw_assisted(16, "mixed", np.random.default_rng(round_seed(c, 1)))[:8]
              for c in range(8)]
    assert any("blind" in f for f in firsts)
