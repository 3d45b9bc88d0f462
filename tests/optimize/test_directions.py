"""The L-BFGS memory as rows kept from step to step
(ase_maud.optimize.directions.PairRows): the same direction, to the last bit,
as a memory stacked afresh, through a run's appends, drops and resets; the
pairs stored as views of their rows, one copy of each. The memory's reach
(within_reach): the newest pairs the points have not moved far from."""

import numpy as np
import pytest

from ase_maud.optimize.directions import PairRows, lbfgs, within_reach


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_kept_rows_give_the_direction_of_a_fresh_memory(seed):
    rng = np.random.default_rng(seed)
    n, memory = int(rng.integers(2, 40)), int(rng.integers(1, 8))
    scale = rng.uniform(0.5, 2.0, (n, 3))

    def solve(forces):
        return forces / scale

    rows, pairs = PairRows(), []
    for step in range(60):
        if rng.random() < 0.1:
            pairs = []   # a reset (the direction was uphill)
        s = rng.normal(size=(n, 3))
        pairs = [*pairs, (s, s * scale + 0.1 * rng.normal(size=(n, 3)))][-memory:]
        if rng.random() < 0.05 and len(pairs) > 1:
            pairs = pairs[:-2] + pairs[-1:]   # a pair dropped from the middle
        forces = rng.normal(size=(n, 3))
        kept = lbfgs(solve, forces, pairs, rows)
        fresh = lbfgs(solve, forces, pairs)
        assert np.array_equal(kept, fresh), step


def test_a_new_array_is_never_taken_for_a_dropped_pair():
    """A pair's row is known by the array itself, not by an address a freed
    array may leave to a new one."""
    rows, n = PairRows(), 5
    for step in range(200):
        s = np.full((n, 3), float(step))
        y = np.full((n, 3), 2.0 * step + 1.0)
        r = rows.rows([(s, y)])
        assert rows.s[r[0]][0] == step and rows.y[r[0]][0] == 2.0 * step + 1.0
        del s, y   # freed: the next step's arrays may take their addresses


@pytest.mark.parametrize('seed', [3, 4, 5])
def test_stored_pairs_are_their_rows_and_keep_their_values(seed):
    rng = np.random.default_rng(seed)
    n, memory = int(rng.integers(2, 40)), int(rng.integers(1, 8))
    rows, pairs, values = PairRows(), [], []
    for step in range(60):
        if rng.random() < 0.1:
            pairs, values = [], []   # a reset
        s, y = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
        values = [*values, (s.copy(), y.copy())][-memory:]
        pairs = rows.store([*pairs, (s, y)][-memory:], memory)
        before = [id(p) for p, _ in pairs]
        again = rows.store(pairs, memory)
        assert [id(p) for p, _ in again] == before   # a stored pair stays itself
        assert rows.s.shape == (memory, 3 * n)      # the only copy: rows for memory pairs
        for (ps, py), (vs, vy) in zip(pairs, values, strict=True):
            assert ps.base is rows.s and py.base is rows.y and ps.shape == (n, 3)
            assert np.array_equal(ps, vs) and np.array_equal(py, vy)   # none overwritten
        forces = rng.normal(size=(n, 3))
        assert np.array_equal(lbfgs(lambda f: f, forces, pairs, rows),
                              lbfgs(lambda f: f, forces, values)), step


@pytest.mark.parametrize('seed', [6, 7, 8])
def test_within_reach_keeps_the_pairs_taken_near_where_the_points_are(seed):
    """A pair stays while the longest point moves of the pairs after it sum
    to at most the reach: checked pair by pair against that sum, for reaches
    from none to all of the pairs' travel."""
    rng = np.random.default_rng(seed)
    n, count = int(rng.integers(2, 30)), int(rng.integers(1, 25))
    pairs = [(rng.normal(size=(n, 3)) * rng.uniform(0.01, 3.0), rng.normal(size=(n, 3)))
             for _ in range(count)]
    longest = np.array([np.linalg.norm(s, axis=1).max() for s, _ in pairs])
    after = np.concatenate([np.cumsum(longest[::-1])[::-1][1:], [0.0]])   # travel since each
    for reach in [0.0, *rng.uniform(0.0, longest.sum(), 5), longest.sum()]:
        kept = within_reach(pairs, reach)
        expected = [pair for pair, travel in zip(pairs, after, strict=True) if travel <= reach]
        assert [id(s) for s, _ in kept] == [id(s) for s, _ in expected]
        assert kept[-1][0] is pairs[-1][0]   # the newest always stays
    assert len(within_reach(pairs, np.inf)) == count
