"""The landscape around a minimum (ase_maud.saddles.landscape) against ASE's basin hopping."""

import functools

import numpy as np
import pytest
from ase.optimize.basin import BasinHopping

from ase_maud import Maud
from ase_maud.analysis.stationary import classify
from ase_maud.counting import fresh_copy
from ase_maud.optimize.models.exact import EXACT_MAX_DOFS
from ase_maud.saddles.landscape import landscape, same_point
from ase_maud.scenes.catalogue import build

FMAX = 1e-6


def _minimum(scene, size, seed):
    atoms = build(scene, size, seed=seed)
    Maud(atoms, logfile=None).run(fmax=FMAX, steps=3000)
    return atoms


@functools.cache
def _landscape(scene, size, seed):
    """The scene's minimum and its landscape (two modes), computed once for
    the tests that read them (none changes either)."""
    minimum = _minimum(scene, size, seed)
    return minimum, landscape(minimum, modes=2, fmax=FMAX)


@pytest.fixture(scope='module')
def client():
    """A client of two local dask workers (processes, one thread each),
    started once for the module's tests."""
    distributed = pytest.importorskip('distributed')
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        yield client


@pytest.mark.parametrize('scene, size, seed', [
    ('all_pairs2d', 9, 0), ('all_pairs2d', 9, 1), ('all_pairs', 6, 0), ('all_pairs', 7, 1)])
def test_landscape_is_minima_joined_by_index_one_saddles(scene, size, seed):
    """Each saddle is a verified index-1 point above both minima it joins,
    each minimum a verified minimum, and no two of either are the same."""
    _, found = _landscape(scene, size, seed)
    assert found.saddles and found.failed == 0
    for saddle in found.saddles:
        point = classify(fresh_copy(saddle), ftol=FMAX)
        assert point.verdict == 'saddle' and point.index == 1
    for minimum in found.minima:
        assert classify(fresh_copy(minimum), ftol=FMAX).verdict == 'minimum'
    assert all(min(pair) > 0 for pair in found.barriers())
    for points in (found.minima, found.saddles):
        assert not any(same_point(a, b) for i, a in enumerate(points) for b in points[:i])


@pytest.mark.parametrize('scene, size, seed', [
    ('all_pairs2d', 9, 0), ('all_pairs2d', 9, 1), ('all_pairs', 6, 1)])
def test_basin_hopping_finds_no_minimum_the_landscape_misses(scene, size, seed):
    """Every minimum a seeded basin-hopping run (30 hops, Maud as its local
    optimiser) visits, its relaxed start and each new lowest, is one of the
    landscape's, the lowest among them."""
    _, found = _landscape(scene, size, seed)
    atoms = build(scene, size, seed=seed)
    visited = []

    def keep():
        here = fresh_copy(atoms)
        if not any(same_point(here, known) for known in visited):
            visited.append(here)

    np.random.seed(seed)
    with BasinHopping(atoms, temperature=1.0, dr=0.5, optimizer=Maud, fmax=FMAX,
                      logfile=None, optimizer_logfile=None, trajectory=None,
                      local_minima_trajectory=None) as hopping:
        keep()   # the start, relaxed as the hopping began (before any observer was attached)
        hopping.attach(keep)
        hopping.run(30)
    assert visited
    for minimum in visited:
        assert any(same_point(minimum, known) for known in found.minima)
    lowest = min(m.get_potential_energy() for m in found.minima)
    assert min(m.get_potential_energy() for m in visited) == pytest.approx(lowest, rel=1e-9)


def test_landscape_needs_a_minimum():
    with pytest.raises(ValueError, match='needs a minimum to start from'):
        landscape(build('all_pairs2d', 7), modes=1)


def _same_graph(one, other) -> bool:
    """Whether two landscapes hold the same minima and saddles (energies to
    1e-10 relative: workers and the main process may round differently), the
    same joins and the same failures."""
    def energies(points):
        return [p.get_potential_energy() for p in points]
    return (energies(one.minima) == pytest.approx(energies(other.minima), rel=1e-10)
            and energies(one.saddles) == pytest.approx(energies(other.saddles), rel=1e-10)
            and (one.joins, one.failed) == (other.joins, other.failed))


@pytest.mark.parametrize('scene, size, seed', [('all_pairs2d', 9, 0), ('all_pairs', 6, 1)])
def test_a_landscape_on_two_workers_is_the_one_in_process(scene, size, seed, client):
    minimum, here = _landscape(scene, size, seed)
    spread = landscape(minimum, modes=2, fmax=FMAX, client=client)
    assert _same_graph(spread, here) and here.saddles


@functools.cache
def _large_landscape(seed):
    """A tree of 60 points (177 free coordinates, above EXACT_MAX_DOFS: the
    springs model's lowest modes climb) at its minimum, and its landscape
    (one mode), computed once for the tests that read them."""
    minimum = _minimum('tree', 60, seed)
    assert 3 * (len(minimum) - 1) > EXACT_MAX_DOFS   # the root is fixed
    return minimum, landscape(minimum, modes=1, fmax=FMAX, steps=500)


@pytest.mark.integration
@pytest.mark.parametrize('seed', range(2))
def test_a_large_landscape_finds_verified_saddles(seed):
    """Above the exact model's size the landscape finds saddles, each a
    verified index-1 saddle (seeds 0-3 measured to pass at 60 points; 100
    points took three times as long)."""
    _, here = _large_landscape(seed)
    assert here.saddles and here.failed == 0
    for saddle in here.saddles:
        point = classify(fresh_copy(saddle), ftol=FMAX)
        assert point.verdict == 'saddle' and point.index == 1


@pytest.mark.integration
def test_a_large_landscape_on_two_workers_is_the_one_in_process(client):
    minimum, here = _large_landscape(0)
    spread = landscape(minimum, modes=1, fmax=FMAX, steps=500, client=client)
    assert _same_graph(spread, here)
