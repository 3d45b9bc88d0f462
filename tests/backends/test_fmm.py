"""The fast multipole backend against the direct sums, and in the calculator."""

import multiprocessing
import sys

import numpy as np
import pytest
from ase import Atoms

from ase_maud import Maud, counting
from ase_maud.backends import auto, direct, fmm
from ase_maud.bench.backends import measure_backends
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.scenes.catalogue import build

import helpers

pytest.importorskip('fmm3dpy')


def rel_err(actual, expected):
    """Largest deviation relative to the largest entry of ``expected``."""
    return np.abs(actual - expected).max() / np.abs(expected).max()


@pytest.mark.parametrize('eps', [1e-3, 1e-6, 1e-9])
@pytest.mark.parametrize('dim, n', [(2, 1200), (3, 2500)])
@pytest.mark.parametrize('seed', [0, 1])
def test_error_is_bounded_by_eps(random_points, eps, dim, n, seed):
    # Enough points that FMM3D uses multipole expansions (at eps = 1e-3 the
    # error is far above rounding), on a plane z = 0 for dim = 2.
    points = random_points(n, dim, seed) + [0.5, -2.0, 3.0 * (dim == 3)]
    energy, forces, block6 = fmm.evaluate(points, True, fmm_eps=eps)
    e_ref, f_ref, b_ref = direct.evaluate(points, True)
    norm = np.linalg.norm
    force_err = (norm(forces - f_ref, axis=1).max()
                 / norm(f_ref, axis=1).max())
    assert abs(energy / e_ref - 1) <= fmm.energy_tolerance(eps)
    assert force_err < 10 * eps
    assert rel_err(block6, b_ref) < 10 * eps
    if eps == 1e-3:
        assert force_err > 1e-12
    e2, f2, none = fmm.evaluate(points, False, fmm_eps=eps)
    assert none is None
    assert e2 == pytest.approx(energy, rel=10 * eps)
    assert rel_err(f2, f_ref) < 10 * eps


@pytest.mark.parametrize('n', [0, 1])
def test_fewer_than_two_points(n):
    energy, forces, block6 = fmm.evaluate(np.ones((n, 3)), True)
    assert energy == 0.0
    assert forces.shape == (n, 3) and block6.shape == (n, 6)
    assert not forces.any() and not block6.any()


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('seed', [0, 4])
def test_calculator_matches_numba(random_points, dim, seed):
    n = 1500
    ring = np.random.default_rng(seed).permutation(n)
    springs = np.c_[ring, np.roll(ring, 1)]  # one random closed loop
    points = random_points(n, dim, seed)
    points[:, 2] += 0.7  # any plane z = const
    results = {}
    for backend in ('numba', 'fmm'):
        atoms = Atoms(f'H{n}', points)
        atoms.calc = MaudCalculator(springs, a=1.3, Q=0.7, dim=dim,
                                    backend=backend, fmm_eps=1e-8)
        results[backend] = (atoms.get_potential_energy(), atoms.get_forces(),
                            atoms.calc.get_stiffness(atoms))
    (e_fmm, f_fmm, k_fmm), (e_ref, f_ref, k_ref) = (results['fmm'],
                                                    results['numba'])
    assert e_fmm == pytest.approx(e_ref, rel=1e-7)
    assert rel_err(f_fmm, f_ref) < 1e-7
    assert rel_err(k_fmm, k_ref) < 1e-7
    assert k_fmm.shape == (n, dim, dim)
    if dim == 2:
        assert not f_fmm[:, 2].any()


@pytest.mark.parametrize('scene, size', [('net2d', 6), ('hanging_net', 6),
                                         ('random_graph', 24)])
def test_relaxation_finds_the_same_minimum(scene, size):
    # fmax 1e-8 needs a tight eps: forces are only good to about eps times
    # the repulsive forces, so a looser eps stalls above such an fmax.
    final = {}
    for backend in ('numba', 'fmm'):
        atoms = build(scene, size, seed=2)
        atoms.calc.set(backend=backend, fmm_eps=1e-10)
        with Maud(atoms, logfile=None) as opt:
            assert opt.run(fmax=1e-8, steps=2000)
        # The shape (sorted pair distances): a scene with nothing fixed may
        # end rotated, its rigid modes driven by the FMM's small torque.
        final[backend] = (atoms.get_potential_energy(),
                          np.sort(atoms.get_all_distances(), axis=None))
    assert final['fmm'][0] == pytest.approx(final['numba'][0], rel=1e-12)
    np.testing.assert_allclose(final['fmm'][1], final['numba'][1], rtol=0,
                               atol=1e-8)


@pytest.mark.parametrize('eps', [0, 0.0, -1e-6, 1.0, 2.0, np.nan, np.inf,
                                 '1e-6', None])
def test_bad_eps(eps):
    match = 'fmm_eps must be a number in \\(0, 1\\)'
    with pytest.raises(ValueError, match=match):
        MaudCalculator(backend='fmm', fmm_eps=eps)
    calc = MaudCalculator(backend='fmm')
    with pytest.raises(ValueError, match=match):
        calc.set(fmm_eps=eps)
    assert calc.parameters['fmm_eps'] == 1e-6


@pytest.mark.parametrize('dim', [2, 3])
def test_coincident_points_name_both(random_points, dim):
    # FMM3D silently drops a pair at distance zero; the backend must not.
    atoms = Atoms('H900', random_points(900, dim, seed=1))
    atoms.positions[700] = atoms.positions[123]
    atoms.calc = MaudCalculator(dim=dim, backend='fmm')
    with pytest.raises(ValueError, match='atoms 123 and 700 are at the same'):
        atoms.get_forces()


def test_missing_fmm3dpy_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, 'fmm3dpy', None)  # import fails
    atoms = Atoms('H3', np.eye(3))
    atoms.calc = MaudCalculator(backend='fmm')
    with pytest.raises(ImportError, match='pip install fmm3dpy'):
        atoms.get_potential_energy()


def test_measure_backends_reports_each_eps():
    rows = measure_backends(natoms=[1000], backends=['numba', 'fmm'],
                            repeats=1, tolerances=(1e-3, 1e-9))
    names = {r['backend'] for r in rows}
    assert names == {'numpy', 'numba', 'fmm eps=0.001', 'fmm eps=1e-09'}
    for row in rows:
        if row['backend'].startswith('fmm'):
            assert row['rel_error'] < 10 * float(row['backend'][8:])


def test_library_eps_is_the_tighter_row():
    rows = sorted(fmm.LIBRARY_EPS.items())   # tightest promise first
    for promise, eps in rows:
        assert fmm.library_eps(promise) == eps
        assert fmm.library_eps(promise * 1.5) == eps   # between rows: this one
    # a tighter promise never gets a looser eps
    assert all(a[1] <= b[1] for a, b in zip(rows, rows[1:], strict=False))
    tightest = rows[0][0]
    assert fmm.library_eps(tightest / 10) == tightest / 10
    assert fmm.library_eps(0.5) == rows[-1][1]


def promise_scene(kind, n, seed):
    """``n`` points of a fresh seeded scene: random points about 1 apart in
    3D or on a plane (helpers.random_points: no close pair, so the largest
    force is modest), on a curved sheet, or the start of a hanging net (a
    grid: the FMM's worst relative error)."""
    if kind == 'net':
        return build('hanging_net', round(np.sqrt(n)), seed=seed).positions
    points = helpers.random_points(n, 3 if kind == 'cube' else 2, seed)
    if kind == 'sheet':
        centre = points[:, :2].mean(axis=0)
        side = np.ptp(points[:, 0])
        points[:, 2] = 0.1 * side * (1 - ((points[:, :2] - centre) ** 2).sum(1)
                                     / (side / 2) ** 2 / 2)
    return points


def assert_promise(points, tol, crossover):
    """``auto`` at ``tol`` (taking the FMM) against the exact sum: the
    force error within ``tol`` of the largest force, the energy's within
    its own promise (far below ``tol``), the blocks' within ``10 tol`` of the
    largest entry."""
    dim = 2 if np.ptp(points[:, 2]) == 0 else 3
    choice = auto.choose(len(points), dim, True, tol, crossover)[0]
    assert choice.backend.name == 'fmm'
    energy, forces, blocks = auto.evaluate(points, True, tol, crossover)
    e0, f0, b0 = direct.evaluate(points, True)
    norm = np.linalg.norm
    force_error = norm(forces - f0, axis=1).max() / norm(f0, axis=1).max()
    assert force_error <= choice.tolerance
    assert choice.tolerance == fmm.force_tolerance(min(tol, auto.MAX_EPS))
    assert choice.energy_tolerance == fmm.energy_tolerance(min(tol, auto.MAX_EPS))
    assert abs(energy / e0 - 1) <= choice.energy_tolerance < tol
    assert rel_err(blocks, b0) <= 10 * tol
    return force_error


@pytest.mark.parametrize('tol', [1e-3, 1e-4, 1e-6, 1e-8])
@pytest.mark.parametrize('kind', ['cube', 'plane', 'sheet', 'net'])
@pytest.mark.parametrize('seed', [11, 12])
def test_auto_keeps_its_promise(kind, tol, seed):
    # 2500 points: FMM3D's multipoles at work, the direct sum instant
    assert_promise(promise_scene(kind, 2500, seed), tol, crossover=1000)


@pytest.mark.slow
@pytest.mark.parametrize('tol', [1e-4, 1e-8])
@pytest.mark.parametrize('kind', ['cube', 'net'])
def test_auto_keeps_its_promise_at_scale(kind, tol):
    # the net's error grows with N: 2x10^4 points, with room to spare
    points = promise_scene(kind, 20000, 21)
    assert assert_promise(points, tol, crossover=1000) <= tol / 3


@pytest.mark.parametrize('count', [2, 3])
@pytest.mark.parametrize('kind, seed', [('cube', 31), ('net', 32)])
def test_split_across_processes_is_one_call_to_round_off(monkeypatch, kind, seed,
                                                         count):
    points = promise_scene(kind, 3000, seed)
    monkeypatch.setattr(fmm, 'POOL_MIN_POINTS', 1000)
    monkeypatch.setattr(fmm, '_can_fork', lambda: True)
    results = {}
    for workers in (1, count):
        monkeypatch.setenv(fmm.WORKERS_VARIABLE, str(workers))
        before = counting.worker_cpu_seconds()
        results[workers] = fmm.evaluate(points, True, fmm_eps=1e-6)
        workers_cpu = counting.worker_cpu_seconds() - before
        # the workers' CPU is counted (time.process_time leaves it out); none without them
        assert (workers_cpu > 0) == (workers > 1)
    (e1, f1, b1), (e2, f2, b2) = results[1], results[count]
    assert fmm._POOL['count'] == count
    assert e2 == pytest.approx(e1, rel=1e-13)
    assert rel_err(f2, f1) < 1e-13 and rel_err(b2, b1) < 1e-13
    fmm.shutdown()
    assert not fmm._POOL
    assert fmm.evaluate(points, False, fmm_eps=1e-6)[0] == pytest.approx(e1, rel=1e-13)
    fmm.shutdown()


def test_calls_are_split_between_the_pool_bounds(monkeypatch):
    monkeypatch.delenv(fmm.WORKERS_VARIABLE, raising=False)
    monkeypatch.delenv(fmm.THREADS_VARIABLE, raising=False)
    monkeypatch.setattr(fmm, '_can_fork', lambda: True)
    monkeypatch.setattr(fmm.os, 'sched_getaffinity', lambda pid: {0, 1})
    low, high = fmm.POOL_MIN_POINTS, fmm.POOL_MAX_POINTS
    counts = [fmm.call_workers(n) for n in (low - 1, low, high, high + 1)]
    assert counts == [1, 2, 2, 1]
    monkeypatch.setenv(fmm.WORKERS_VARIABLE, '2')   # set: larger calls too
    assert fmm.call_workers(high + 1) == 2 and fmm.call_workers(low - 1) == 1
    monkeypatch.setenv(fmm.WORKERS_VARIABLE, '1')
    assert fmm.call_workers(high) == 1


@pytest.mark.parametrize('seed', [33, 34])
def test_a_call_above_the_pool_stays_in_this_process(monkeypatch, seed):
    points = promise_scene('net', 3000, seed)
    monkeypatch.delenv(fmm.WORKERS_VARIABLE, raising=False)
    monkeypatch.delenv(fmm.THREADS_VARIABLE, raising=False)
    monkeypatch.setattr(fmm, '_can_fork', lambda: True)
    monkeypatch.setattr(fmm.os, 'sched_getaffinity', lambda pid: {0, 1})
    monkeypatch.setattr(fmm, 'POOL_MIN_POINTS', 1000)
    fmm.shutdown()
    monkeypatch.setattr(fmm, 'POOL_MAX_POINTS', 2000)
    before = counting.worker_cpu_seconds()
    alone = fmm.evaluate(points, False, fmm_eps=1e-6)
    assert not fmm._POOL and counting.worker_cpu_seconds() == before
    monkeypatch.setattr(fmm, 'POOL_MAX_POINTS', 4000)
    split = fmm.evaluate(points, False, fmm_eps=1e-6)
    assert fmm._POOL['count'] == 2 and counting.worker_cpu_seconds() > before
    assert split[0] == pytest.approx(alone[0], rel=1e-13)
    assert rel_err(split[1], alone[1]) < 1e-13
    fmm.shutdown()


def _daemon_evaluate(points):
    """In a daemonic process (a multiprocessing.Pool worker): the workers
    it would use, and the energy."""
    return fmm.workers(), fmm.evaluate(points, False, fmm_eps=1e-6)[0]


def test_a_daemonic_process_sums_in_itself(monkeypatch):
    # a Pool worker may have no children: the call stays in it
    monkeypatch.setattr(fmm, 'POOL_MIN_POINTS', 1000)
    monkeypatch.delenv(fmm.WORKERS_VARIABLE, raising=False)
    monkeypatch.delenv(fmm.THREADS_VARIABLE, raising=False)
    points = promise_scene('cube', 1500, 41)
    with multiprocessing.get_context('fork').Pool(1) as pool:
        count, energy = pool.apply(_daemon_evaluate, (points,))
    assert count == 1
    assert energy == pytest.approx(fmm.evaluate(points, False, fmm_eps=1e-6)[0], rel=1e-13)
    fmm.shutdown()
