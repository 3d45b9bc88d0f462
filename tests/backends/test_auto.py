"""backend='auto': the cheapest backend that meets tol, in O(N) memory."""

import os
import sys
import tracemalloc

import numba
import numpy as np
import pytest
from ase import Atoms

from ase_maud.backends import auto, fmm
from ase_maud.calculator.maud_calculator import MaudCalculator

pytest.importorskip('fmm3dpy')

#: Points for the FMM path, which ``crossover=CROSSOVER`` makes ``auto`` take.
N = 1200
CROSSOVER = 1000


def scene(random_points, kind, dim, seed):
    """``N`` points about 1 apart, a ring of springs, and one of: nothing
    more ('plain'), a pair at 1e-13 of the scene's size ('near'), or two
    halves 1e4 apart ('far')."""
    points = random_points(N, dim, seed)
    if kind == 'near':
        size = np.ptp(points, axis=0).max()
        points[1] = points[0] + 1e-13 * size * np.array([0.6, 0.8, 0.0])
    elif kind == 'far':
        points[N // 2:, 0] += 1e4
    ring = np.random.default_rng(seed).permutation(N)
    springs = np.c_[ring, np.roll(ring, 1)]
    return Atoms(f'H{N}', points), springs


def evaluate(atoms, **parameters):
    """Energy, forces and blocks of one E+F+K call, and the calculator."""
    atoms = atoms.copy()
    atoms.calc = MaudCalculator(**parameters)
    calc = atoms.calc
    calc.calculate(atoms, ['energy', 'forces', 'stiffness'])
    return calc.results['energy'], calc.results['forces'], \
        calc.results['stiffness'], calc


@pytest.mark.parametrize('dim, kind, seed, tol', [
    (2, 'plain', 0, 1e-4), (3, 'plain', 1, 1e-6), (2, 'near', 2, 1e-6),
    (3, 'near', 3, 1e-4), (2, 'far', 4, 1e-4), (3, 'far', 5, 1e-8)])
def test_auto_meets_tol(random_points, dim, kind, seed, tol):
    atoms, springs = scene(random_points, kind, dim, seed)
    common = {'springs': springs, 'a': 1.3, 'Q': 0.7, 'dim': dim}
    e, f, k, calc = evaluate(atoms, tol=tol, crossover=CROSSOVER, **common)
    e0, f0, k0, exact = evaluate(atoms, backend='numba', **common)
    assert (calc.last_backend, exact.last_backend) == ('fmm', 'numba')
    assert calc.last_tolerance == pytest.approx(tol)
    assert exact.last_tolerance == 0.0
    assert calc.last_force_scale == pytest.approx(exact.last_force_scale,
                                                  rel=tol)
    error = np.linalg.norm(f - f0, axis=1).max()
    assert error <= tol * exact.last_force_scale
    assert abs(e - e0) <= calc.last_energy_error
    assert exact.last_energy_error == 0.0
    # the energy's promise, relative to the repulsion's energy alone
    e_rep = exact.results['energy'] - MaudCalculator(**{**common, 'a': 0.0}).get_potential_energy(
        atoms)
    assert calc.last_energy_error == pytest.approx(
        fmm.energy_tolerance(fmm.eps_for(tol)) * abs(e_rep), rel=1e-6)
    assert np.abs(k - k0).max() <= 10 * tol * np.abs(k0).max()
    if dim == 2:
        assert not f[:, 2].any()


def test_default_is_auto_and_small_scenes_are_exact(random_points):
    calc = MaudCalculator()
    assert calc.parameters['backend'] == 'auto'
    assert calc.parameters['tol'] == auto.DEFAULT_TOL
    assert calc.last_backend is calc.last_tolerance is None
    atoms = Atoms('H50', random_points(50, 3, 0), calculator=calc)
    atoms.get_forces()
    assert (calc.last_backend, calc.last_tolerance) == ('numba', 0.0)


def test_choices_follow_n_tol_and_threads(monkeypatch):
    monkeypatch.setattr(auto, 'CROSSOVER', {
        (3, False): {1e-3: 100, 1e-9: 1000}, (3, True): {1e-3: 50}})
    monkeypatch.setattr(numba, 'get_num_threads', lambda: 2)
    monkeypatch.setenv(fmm.WORKERS_VARIABLE, '1')   # the wheel in one process

    def picked(n, dim=3, blocks=False, **options):
        return [(c.backend.name, c.options) for c in
                auto.choose(n, dim, blocks, **options)]

    exact = ('numba', {})
    assert picked(199, tol=1e-3) == [exact]          # 100 points x 2 threads
    assert picked(200, tol=1e-3) == [('fmm', {'fmm_eps': 1e-3}), exact]
    assert picked(200, tol=1e-8) == [exact]          # eps 1e-8: 681 x 2
    assert auto.crossover_points(1e-6, 3, False) == 2 * 316   # log-log
    assert picked(2000, tol=1e-9)[0] == ('fmm', {'fmm_eps': 1e-9})
    assert picked(10**9, tol=1e-10) == [exact]       # below the table
    assert picked(100, blocks=True, tol=1e-3)[0][0] == 'fmm'
    assert picked(10**9, tol=0.0) == [exact]         # 0: exact
    assert picked(3, tol=1e-12, crossover=3)[0][0] == 'fmm'
    assert picked(10**6, tol=1e-300, crossover=3) == [exact]   # beyond FMM3D
    monkeypatch.setenv(fmm.THREADS_VARIABLE, '4')       # an OpenMP build
    assert auto.crossover_points(1e-3, 3, False) == 100 * 2 / 4
    assert picked(49, tol=1e-3) == [exact]
    assert picked(50, tol=1e-3)[0][0] == 'fmm'          # 100 x 2 / 4
    assert picked(24, blocks=True, tol=1e-3) == [exact]
    assert picked(25, blocks=True, tol=1e-3)[0][0] == 'fmm'   # 50 x 2 / 4
    monkeypatch.setitem(sys.modules, 'fmm3dpy', None)   # not installed
    assert picked(10**9, tol=1e-4) == [exact]


@pytest.mark.parametrize('numba_threads, fmm_threads, processes, start', [
    (1, '1', '1', 35793), (2, '1', '1', 71586), (2, '1', '2', 35793),
    (2, '2', None, 35793), (1, '2', None, 17896.5)])
def test_choice_at_tol_1e4_follows_the_measured_table(
        monkeypatch, numba_threads, fmm_threads, processes, start):
    """docs/calculator.md: in 3D at tol 1e-4 (E+F) the FMM wins from 35793
    points with one thread each (log-log between the 1e-5 and 1e-3 rows),
    twice that with the direct sum on 2 threads and the wheel in one process
    (a 6x10^4-point net keeps the direct sum), 35793 again with the wheel in
    two (the default on 2 cores) or an OpenMP build on 2 threads (which
    keeps one process)."""
    monkeypatch.setattr(numba, 'get_num_threads', lambda: numba_threads)
    monkeypatch.setenv(fmm.THREADS_VARIABLE, fmm_threads)
    monkeypatch.setattr(fmm, '_can_fork', lambda: True)
    if processes is None:
        monkeypatch.delenv(fmm.WORKERS_VARIABLE, raising=False)
    else:
        monkeypatch.setenv(fmm.WORKERS_VARIABLE, processes)
    assert auto.crossover_points(1e-4, 3, False) == pytest.approx(start)
    below = auto.choose(int(start) - 1, 3, False, tol=1e-4)
    above = auto.choose(int(start) + 1, 3, False, tol=1e-4)
    assert [c.backend.name for c in below] == ['numba']
    assert [c.backend.name for c in above] == ['fmm', 'numba']
    assert above[0].options == {'fmm_eps': 1e-4}
    net = auto.choose(60025, 3, False, tol=1e-4)[0].backend.name
    assert net == ('fmm' if start < 60025 else 'numba')


@pytest.mark.parametrize('value, threads', [(None, 1), ('1', 1), ('3', 3)])
def test_fmm_threads_as_declared(monkeypatch, value, threads):
    monkeypatch.setenv(fmm.WORKERS_VARIABLE, '1')
    if value is None:
        monkeypatch.delenv(fmm.THREADS_VARIABLE, raising=False)
    else:
        monkeypatch.setenv(fmm.THREADS_VARIABLE, value)
    assert fmm.threads() == threads


def test_fmm_workers_default_to_the_cores_at_most_two(monkeypatch):
    monkeypatch.delenv(fmm.WORKERS_VARIABLE, raising=False)
    monkeypatch.delenv(fmm.THREADS_VARIABLE, raising=False)
    monkeypatch.setattr(fmm, '_can_fork', lambda: True)
    cores = len(os.sched_getaffinity(0))
    assert fmm.workers() == min(2, cores) == fmm.threads()
    monkeypatch.setenv(fmm.THREADS_VARIABLE, '3')       # an OpenMP build
    assert (fmm.workers(), fmm.threads()) == (1, 3)
    monkeypatch.setenv(fmm.WORKERS_VARIABLE, '3')       # as set
    assert (fmm.workers(), fmm.threads()) == (3, 9)
    monkeypatch.delenv(fmm.WORKERS_VARIABLE)
    monkeypatch.delenv(fmm.THREADS_VARIABLE)
    monkeypatch.setattr(fmm, '_can_fork', lambda: False)   # not Linux
    assert fmm.workers() == 1


@pytest.mark.parametrize('variable', ['THREADS_VARIABLE', 'WORKERS_VARIABLE'])
@pytest.mark.parametrize('bad', ['0', '-2', '1.5', 'two', ''])
def test_bad_fmm_threads_name_the_variable(monkeypatch, bad, variable):
    variable = getattr(fmm, variable)
    monkeypatch.setenv(variable, bad)
    with pytest.raises(ValueError, match=f'{variable} must be '
                       f'a positive integer .* got {bad!r}'):
        auto.choose(10**6, 3, False, tol=1e-4)


def test_set_tol_keeps_results_that_meet_it(random_points):
    atoms = Atoms(f'H{N}', random_points(N, 3, 2))
    atoms.calc = calc = MaudCalculator(tol=1e-6, crossover=CROSSOVER)
    forces = atoms.get_forces()
    assert calc.last_backend == 'fmm'
    calc.set(tol=1e-4)                                  # looser: kept
    assert calc.results['forces'] is not None
    np.testing.assert_array_equal(atoms.get_forces(), forces)
    assert calc.last_tolerance == pytest.approx(1e-6)
    calc.set(tol=1e-9)                                  # tighter: discarded
    assert calc.results == {} and calc.last_tolerance is None
    tight = atoms.get_forces()
    assert calc.last_tolerance == pytest.approx(1e-9)
    assert np.abs(tight - forces).max() <= 1e-6 * calc.last_force_scale
    exact = MaudCalculator(backend='numba')
    atoms.calc = exact
    atoms.get_forces()
    exact.set(tol=1e-12)                                # exact: kept
    assert 'forces' in exact.results
    exact.set(a=2.0)                                    # the potential: not
    assert exact.results == {}


def test_explicit_backends_still_work(random_points):
    atoms = Atoms('H40', random_points(40, 3, 3))
    results = []
    for backend in ('numba', 'numpy', 'fmm', 'auto'):
        atoms.calc = MaudCalculator(springs=[[0, 1]], backend=backend,
                                    fmm_eps=1e-12)
        results.append(atoms.get_forces())
        assert atoms.calc.last_backend == (
            'numba' if backend == 'auto' else backend)
    for forces in results[1:]:
        np.testing.assert_allclose(forces, results[0], rtol=0,
                                   atol=1e-11 * np.abs(results[0]).max())
    assert atoms.calc.last_tolerance == 0.0
    atoms.calc = MaudCalculator(backend='fmm', fmm_eps=1e-5)
    atoms.get_forces()
    assert atoms.calc.last_tolerance == pytest.approx(1e-5)   # FORCE_ERROR_PER_EPS fmm_eps


@pytest.mark.parametrize('bad', [-1e-3, 1.0, np.nan, '1e-6', None])
def test_bad_tol(bad):
    with pytest.raises(ValueError, match='tol must be a number in'):
        MaudCalculator(tol=bad)


@pytest.mark.parametrize('bad', [-1, 1.5, '100', True])
def test_bad_crossover(bad):
    with pytest.raises(ValueError, match='crossover must be None'):
        MaudCalculator(crossover=bad)


@pytest.mark.parametrize('dim', [2, 3])
def test_fmm_sums_a_near_pair_exactly(random_points, dim):
    atoms, _ = scene(random_points, 'near', dim, seed=5)
    e, f, k, _ = evaluate(atoms, backend='fmm', fmm_eps=1e-3, dim=dim)
    e0, f0, k0, _ = evaluate(atoms, backend='numba', dim=dim)
    assert e == pytest.approx(e0, rel=1e-12)
    scale = np.linalg.norm(f0, axis=1).max()
    assert np.linalg.norm(f - f0, axis=1)[:2].max() <= 1e-12 * scale
    # the pair's own blocks, exact; every other entry within fmm_eps
    assert np.abs(k[:2] - k0[:2]).max() <= 1e-12 * np.abs(k0[:2]).max()
    assert np.linalg.norm(f - f0, axis=1).max() <= 1e-4 * scale


def test_too_many_near_points_name_the_direct_backend(random_points,
                                                      monkeypatch):
    monkeypatch.setattr(fmm, 'MAX_NEAR_POINTS', 3)
    points = random_points(N, 3, 6)
    for k in (0, 2, 4):
        points[k + 1] = points[k] + [1e-12, 0, 0]
    atoms = Atoms(f'H{N}', points)
    atoms.calc = MaudCalculator(backend='fmm')
    with pytest.raises(ValueError, match=r"atoms \d and \d .* use "
                       r"backend='numba'"):
        atoms.get_forces()
    atoms.calc = MaudCalculator(crossover=CROSSOVER)   # auto: the direct sum
    atoms.get_forces()
    assert atoms.calc.last_backend == 'numba'


def test_no_dense_array_above_the_crossover(random_points):
    n = 3000
    atoms = Atoms(f'H{n}', random_points(n, 3, 7))
    ring = np.arange(n)
    atoms.calc = MaudCalculator(springs=np.c_[ring, np.roll(ring, 1)],
                                crossover=CROSSOVER, tol=1e-6)
    atoms.calc.calculate(atoms, ['stiffness'])      # warm-up
    tracemalloc.start()
    try:
        atoms.calc.calculate(atoms, ['energy', 'forces', 'stiffness'])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert atoms.calc.last_backend == 'fmm'
    assert peak < n * n * 8 / 20      # 3.6 MB; an N x N array is 72 MB


def test_last_tolerance_is_the_held_results(random_points):
    """An FMM call, then an exact one at new positions: the results held
    are exact, and last_tolerance and last_energy_error say so."""
    atoms = Atoms(f'H{N}', random_points(N, 3, 4))
    atoms.calc = calc = MaudCalculator(tol=1e-4, crossover=CROSSOVER)
    atoms.get_forces()
    assert calc.last_backend == 'fmm' and calc.last_tolerance > 0
    assert calc.last_energy_error > 0
    calc.set(crossover=10 * N)            # the direct sum from now on
    atoms.positions[0] += 0.1
    atoms.get_forces()
    assert calc.last_backend == 'numba' and calc.last_tolerance == 0.0
    assert calc.last_energy_error == 0.0
