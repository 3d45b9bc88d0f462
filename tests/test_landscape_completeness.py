"""How complete the landscape is (issue 31, part 5): the rounds a window asks
for, the cost of the whole map, and the share of a larger search's connected
saddles below the window that the landscape finds, on 2D trap clusters."""

import math
import runpy
from pathlib import Path

import pytest

from ase_maud import Maud
from ase_maud.analysis.stationary import classify
from ase_maud.counting import fresh_copy
from ase_maud.saddles.landscape import landscape, same_point
from ase_maud.saddles.search import search_saddles
from ase_maud.scenes.catalogue import build

#: The benchmark's count of the saddles that join the start below a window.
COUNTED = runpy.run_path(str(Path(__file__).parent.parent / 'benchmarks'
                             / 'landscape_completeness.py'))['counted']
WINDOW = 1.0


def cluster(size, seed=0):
    """A 2D trap cluster (``all_pairs2d``) relaxed to a verified minimum."""
    atoms = build('all_pairs2d', size, seed=seed)
    Maud(atoms, logfile=None).run(fmax=1e-8, steps=5000)
    assert classify(atoms).verdict == 'minimum'
    return atoms


def test_a_window_goes_on_in_rounds_while_they_find_new_saddles_below_it():
    """Rounds of ``modes`` modes both ways: every round but the last finds a
    new saddle below the window, the last none (or the modes are used up);
    without a window, one round."""
    start = cluster(15)
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
    the search makes exactly ``empty_rounds`` rounds of ``modes`` modes both
    ways and ``local`` points, says so and reports them."""
    start = cluster(13)
    search = search_saddles(start, modes=1, local=1, window=WINDOW, empty_rounds=empty_rounds,
                            connected=lambda saddle: False)
    assert search.rounds == empty_rounds
    assert [(a.kind, a.where) for a in search.attempts] == [
        pair for r in range(empty_rounds)
        for pair in (('mode', r), ('mode', r), ('local', search.attempts[3 * r + 2].where))]
    assert len({a.where for a in search.attempts if a.kind == 'local'}) == empty_rounds
    assert f'attempts ({empty_rounds} round' in search.report().splitlines()[0]


def test_a_new_saddle_below_the_window_starts_the_count_of_empty_rounds_again():
    """With ``empty_rounds=2``, the last two rounds find no new saddle below
    the window, and the one before them found one (or it is the first); no
    two rounds in a row before them found nothing (the modes used up
    excepted)."""
    start = cluster(15)
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
        search_saddles(cluster(13), modes=1, local=0, window=WINDOW, empty_rounds=empty_rounds)


@pytest.mark.parametrize('window', [0, -1.0, float('nan'), 'wide'])
def test_the_window_is_checked(window):
    with pytest.raises(ValueError, match='window'):
        search_saddles(cluster(13), modes=1, local=0, window=window)


def test_a_saddle_into_a_minimum_with_a_flat_mode_is_kept_and_the_map_counted():
    """The 19-point trap cluster: one side of its lowest saddle relaxes into a
    minimum whose shells turn one against the other at almost no cost (a
    curvature below classify's zero tolerance, none negative). That is a
    minimum, and the saddle is kept (it was dropped as failed); the map's
    cost is the search's plus the descents'."""
    found = landscape(cluster(19), modes=1)
    assert found.saddles and found.failed == 0
    for saddle in found.saddles:
        assert classify(fresh_copy(saddle), ftol=1e-6).index == 1
    assert all(classify(fresh_copy(m), ftol=1e-6).n_negative == 0 for m in found.minima)
    assert found.calls > 0
    assert found.cost == found.search.cost + found.calls + found.work.total


@pytest.mark.integration
def test_the_landscape_finds_most_of_a_larger_search_s_connected_saddles():
    """On trap clusters of 15-17 points, the landscape told the window (its
    default rounds: 2 modes and 1 point each, until 6 in a row find nothing
    new) finds at least 0.9 of the connected saddles below it that climbs
    along every mode find (measured 14 of 14 on seed 0: 7 of 7, 4 of 4, 3 of 3;
    12 of 14 with rounds that stopped at the first that found nothing), each
    verified index 1, joining the start."""
    hits = total = 0
    for size in (15, 16, 17):
        start = cluster(size)
        mine = COUNTED(landscape(start, window=WINDOW), WINDOW)
        theirs = COUNTED(landscape(start, modes=len(classify(start).modes)), WINDOW)
        for saddle, barrier, _ in mine:
            assert 0 < barrier < WINDOW
            assert classify(fresh_copy(saddle), ftol=1e-6).index == 1
        hits += sum(any(same_point(s, m) for m, _, _ in mine) for s, _, _ in theirs)
        total += len(theirs)
    assert total >= 10 and hits >= 0.9 * total
