"""A search's window (ase_maud.saddles.search, issue 31, part 5): the rounds a
window asks for, the rounds in a row that find nothing, and the cost of the
whole map, on 2D trap clusters."""

import math

import numpy as np
import pytest

from ase_maud.analysis.stationary import classify
from ase_maud.counting import fresh_copy
from ase_maud.saddles.landscape import landscape
from ase_maud.saddles.search import search_saddles

from helpers import trap_cluster

WINDOW = 1.0


def test_a_window_goes_on_in_rounds_while_they_find_new_saddles_below_it():
    """Rounds of ``modes`` modes both ways: every round but the last finds a
    new saddle below the window, the last none (or the modes are used up);
    without a window, one round."""
    start = trap_cluster(15)
    energy = start.get_potential_energy()
    assert len(search_saddles(start, modes=2, local=0).attempts) == 4
    search = search_saddles(start, modes=2, local=0, window=WINDOW)
    rounds = math.ceil(len(search.attempts) / 4)
    assert rounds > 1
    new = [[a for a in search.attempts[4 * r:4 * r + 4]
            if a.outcome == 'saddle' and a.energy - energy < WINDOW] for r in range(rounds)]
    assert all(new[:-1])
    assert not new[-1] or 2 * len(classify(start).modes) == len(search.attempts)
    low = search_saddles(start, modes=2, local=0, window=1e-3)   # below every barrier
    assert len(low.attempts) == 4


@pytest.mark.parametrize('empty_rounds', [1, 3])
def test_the_rounds_stop_after_the_stated_rounds_in_a_row_find_nothing_new(empty_rounds):
    """Where no saddle counts (the test ``connected`` refuses every one),
    the search without its sweep makes exactly ``empty_rounds`` rounds of
    ``modes`` modes both ways and ``local`` points, says so and reports
    them."""
    start = trap_cluster(13)
    search = search_saddles(start, modes=1, local=1, window=WINDOW, empty_rounds=empty_rounds,
                            connected=lambda saddle: False, sweep=False)
    assert search.rounds == empty_rounds
    assert [(a.kind, a.where) for a in search.attempts] == [
        pair for r in range(empty_rounds)
        for pair in (('mode', r), ('mode', r), ('local', search.attempts[3 * r + 2].where))]
    assert len({a.where for a in search.attempts if a.kind == 'local'}) == empty_rounds
    assert f'attempts ({empty_rounds} round' in search.report().splitlines()[0]


def test_after_the_rounds_a_sweep_activates_every_free_point_not_yet_activated():
    """With a window and ``local`` above 0 the rounds end as they do
    without the sweep, then each free point that no round activated is
    activated once, in the order the search's seed draws (a fresh one);
    a saddle a sweep reaches is a saddle of the search."""
    seed = int(np.random.default_rng().integers(1000))
    start = trap_cluster(13)
    rounds = search_saddles(start, modes=1, local=1, window=WINDOW, empty_rounds=1, seed=seed,
                            connected=lambda saddle: False, sweep=False)
    swept = search_saddles(start, modes=1, local=1, window=WINDOW, empty_rounds=1, seed=seed,
                           connected=lambda saddle: False)
    made = len(rounds.attempts)
    assert [(a.kind, a.where, a.sign) for a in swept.attempts[:made]] == [
        (a.kind, a.where, a.sign) for a in rounds.attempts]
    assert swept.rounds == rounds.rounds == 1
    assert all(a.kind == 'local' for a in swept.attempts[made:])
    assert sorted(a.where for a in swept.attempts if a.kind == 'local') == list(range(13))
    assert len(swept.saddles) == len({a.saddle for a in swept.attempts if a.saddle is not None})
    assert len(swept.saddles) >= len(rounds.saddles)


def test_a_search_without_a_window_or_local_activations_makes_no_sweep():
    """The sweep follows a window's rounds only, and not where ``local=0``
    asks for no local activation."""
    start = trap_cluster(13)
    assert len(search_saddles(start, modes=1, local=1).attempts) == 3
    assert not any(a.kind == 'local' for a in search_saddles(
        start, modes=1, local=0, window=WINDOW, empty_rounds=1).attempts)


@pytest.mark.parametrize('sweep', [1, 'yes', None])
def test_the_sweep_is_checked(sweep):
    with pytest.raises(ValueError, match='sweep must be one of'):
        search_saddles(trap_cluster(13), modes=1, local=1, window=WINDOW, sweep=sweep)


def test_a_new_saddle_below_the_window_starts_the_count_of_empty_rounds_again():
    """With ``empty_rounds=2``, the last two rounds find no new saddle below
    the window, and the one before them found one (or it is the first); no
    two rounds in a row before them found nothing (the modes used up
    excepted)."""
    start = trap_cluster(15)
    energy = start.get_potential_energy()
    search = search_saddles(start, modes=1, local=0, window=WINDOW, empty_rounds=2)
    new = [any(a.outcome == 'saddle' and a.energy - energy < WINDOW
               for a in search.attempts[2 * r:2 * r + 2]) for r in range(search.rounds)]
    assert search.rounds == len(search.attempts) // 2 > 2
    assert new[-2:] == [False, False] or search.rounds == len(classify(start).modes)
    assert all(new[r] or new[r + 1] for r in range(search.rounds - 2))


@pytest.mark.parametrize('empty_rounds', [0, -1, 1.5, None])
def test_the_empty_rounds_are_checked(empty_rounds):
    with pytest.raises(ValueError, match='empty_rounds'):
        search_saddles(trap_cluster(13), modes=1, local=0, window=WINDOW, empty_rounds=empty_rounds)


@pytest.mark.parametrize('window', [0, -1.0, float('nan'), 'wide'])
def test_the_window_is_checked(window):
    with pytest.raises(ValueError, match='window'):
        search_saddles(trap_cluster(13), modes=1, local=0, window=window)


def test_a_saddle_into_a_minimum_with_a_flat_mode_is_kept_and_the_map_counted():
    """The 19-point trap cluster: one side of its lowest saddle relaxes into a
    minimum whose shells turn one against the other at almost no cost (a
    curvature below classify's zero tolerance, none negative). That is a
    minimum, and the saddle is kept (it was dropped as failed); the map's
    cost is the search's plus the descents'."""
    found = landscape(trap_cluster(19), modes=1)
    assert found.saddles and found.failed == 0
    for saddle in found.saddles:
        assert classify(fresh_copy(saddle), ftol=1e-6).index == 1
    assert all(classify(fresh_copy(m), ftol=1e-6).n_negative == 0 for m in found.minima)
    assert found.calls > 0
    assert found.cost == found.search.cost + found.calls + found.work.total
