"""The registry of backends, and every backend against ase_maud.physics."""

import sys

import numpy as np
import pytest
from ase import Atoms

from ase_maud import backends
from ase_maud.backends import Backend, direct, reference, voigt_to_blocks
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.physics import pair_law as physics

RTOL = 1e-12
#: ``fmm_eps`` for the element-wise comparison: below a few hundred points
#: FMM3D sums directly, so this leaves only rounding.
TIGHT = {'fmm_eps': 1e-12}


def assert_close(actual, expected, rtol=RTOL):
    """Equal to ``rtol`` relative to the largest entry of ``expected``."""
    scale = np.abs(expected).max(initial=0.0)
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rtol * scale)


def physics_sums(points):
    """Energy, forces and (N, 3, 3) nodal blocks of the unit repulsion, as
    plain sums of :mod:`ase_maud.physics` over every ordered pair."""
    n = len(points)
    d = points[:, None, :] - points[None, :, :]
    off = ~np.eye(n, dtype=bool)
    energy = 0.5 * physics.repulsion_energy(d[off]).sum()
    forces = np.zeros((n, 3))
    blocks = np.zeros((n, 3, 3))
    np.add.at(forces, np.nonzero(off)[0], physics.repulsion_force(d[off]))
    np.add.at(blocks, np.nonzero(off)[0], physics.repulsion_block(d[off]))
    return energy, forces, blocks


def installed(name):
    if not backends.get(name).installed:
        pytest.skip(f'{name} is not installed')
    return backends.get(name)


@pytest.mark.parametrize('name', backends.names())
@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('n', [1, 2, 3, 4, 5, 16, 17, 64, 127, 300])
@pytest.mark.parametrize('seed', [0, 1])
def test_backend_matches_physics(random_points, name, n, dim, seed):
    backend = installed(name)
    options = {k: v for k, v in TIGHT.items() if k in backend.parameters}
    points = random_points(n, dim, seed, spacing=10.0 ** (seed - 0.5))
    energy, forces, block6 = backend.evaluate(points, True, **options)
    ref_energy, ref_forces, ref_blocks = physics_sums(points)
    assert energy == pytest.approx(ref_energy, rel=RTOL, abs=0)
    assert forces.shape == (n, 3) and block6.shape == (n, 6)
    assert_close(forces, ref_forces)
    assert_close(voigt_to_blocks(block6, 3), ref_blocks)
    # Without blocks: the same energy and forces, and no blocks returned.
    e2, f2, b2 = backend.evaluate(points, False, **options)
    assert b2 is None
    assert e2 == pytest.approx(energy, rel=RTOL, abs=0)
    assert_close(f2, forces)


@pytest.mark.parametrize('chunk_pairs', [1, 7, 1000])
def test_reference_chunks_sum_the_same(random_points, chunk_pairs):
    points = random_points(40, 3, seed=4)
    energy, forces, block6 = reference.evaluate(points, True, chunk_pairs)
    ref_energy, ref_forces, ref_block6 = reference.evaluate(points, True)
    assert energy == pytest.approx(ref_energy, rel=RTOL)
    assert_close(forces, ref_forces)
    assert_close(block6, ref_block6)


@pytest.mark.parametrize('n, nchunks', [
    # measured 12 s and 17 s in full runs on a loaded machine (0.5 s alone)
    pytest.param(n, nchunks, marks=pytest.mark.slow)
    if (n, nchunks) in ((2 * direct.TILE + 3, 2), (2 * direct.TILE + 3, 3)) else (n, nchunks)
    for n in [3, 50, direct.TILE, direct.TILE + 1, 2 * direct.TILE + 3, 4 * direct.TILE - 5]
    for nchunks in [1, 2, 3, 7]])
def test_chunks_share_rows(random_points, n, nchunks):
    """Tile rows k and T-1-k go to chunk k % nchunks; every split sums the same.

    Sizes of one tile, a tile and one point, and several tiles with a part
    tile at the end. Calls the compiled kernels with more chunks than threads,
    so the split is tested whatever ``NUMBA_NUM_THREADS`` is.
    """
    points = random_points(n, 3, seed=n)
    ref_energy, ref_forces, ref_blocks = physics_sums(points)
    xyz = [points[:, k].copy() for k in range(3)]
    for want_blocks in (False, True):
        energy, forces, block6 = direct.direct_sum(*xyz, nchunks, want_blocks)
        assert energy == pytest.approx(ref_energy, rel=RTOL, abs=0)
        assert_close(forces, ref_forces)
    assert_close(voigt_to_blocks(block6, 3), ref_blocks)


@pytest.mark.parametrize('name', backends.names())
def test_blocks_in_voigt_order(name):
    """Entries are xx, yy, zz, xy, xz, yz of ``3 d d^T / L**5 - I / L**3``."""
    backend = installed(name)
    d = np.array([1.0, 2.0, 2.0])  # L = 3
    points = np.array([d, np.zeros(3)])
    expected = physics.repulsion_block(d)
    energy, forces, block6 = backend.evaluate(points, True)
    assert energy == pytest.approx(1 / 3)
    np.testing.assert_allclose(forces, [d / 27, -d / 27], rtol=1e-14)
    blocks = voigt_to_blocks(block6, 3)
    np.testing.assert_allclose(blocks, [expected, expected], rtol=1e-14)
    np.testing.assert_array_equal(voigt_to_blocks(block6, 2),
                                  blocks[:, :2, :2])


# -- the registry -------------------------------------------------------------

def test_registered_backends_describe_themselves():
    assert backends.names() == ['numba', 'numpy', 'fmm', 'auto']
    for name in backends.names():
        backend = backends.get(name)
        assert backend.name == name and backend.summary
        assert backend.computes == {'energy', 'forces', 'blocks'}
    numba, fmm = backends.get('numba'), backends.get('fmm')
    assert (numba.cost, numba.exact, numba.accuracy) == ('N^2', True, 'exact')
    assert numba.options({'backend': 'numba', 'fmm_eps': 0.1}) == {}
    assert (fmm.cost, fmm.exact) == ('N', False)
    assert fmm.accuracy == 'approximate (fmm_eps)'
    assert fmm.options({'fmm_eps': 0.1, 'a': 2.0}) == {'fmm_eps': 0.1}
    # every parameter a backend takes is a calculator parameter
    for name in backends.names():
        assert set(backends.get(name).parameters) <= set(
            MaudCalculator.default_parameters)


def test_installed_follows_the_imports(monkeypatch):
    assert set(backends.installed()) <= set(backends.names())
    assert {'numba', 'numpy'} <= set(backends.installed())
    monkeypatch.setitem(sys.modules, 'fmm3dpy', None)  # import fails
    assert not backends.get('fmm').installed
    assert 'fmm' not in backends.installed()


@pytest.mark.parametrize('name', ['cuda', None, ['numba']])
def test_unknown_name(name):
    with pytest.raises(ValueError, match=r"backend must be one of \['auto', "
                       r"'fmm', 'numba', 'numpy'\], got "):
        backends.get(name)


def test_check_parameters():
    backends.check_parameters({'backend': 'numba', 'fmm_eps': 1e-3})
    with pytest.raises(ValueError, match='fmm_eps must be a number in'):
        backends.check_parameters({'backend': 'numba', 'fmm_eps': 2.0})
    with pytest.raises(ValueError, match='backend must be one of'):
        backends.check_parameters({'backend': 'gpu'})


def test_a_new_backend_is_one_registration(monkeypatch, random_points):
    """A backend registered at run time is at once a calculator backend."""
    monkeypatch.setattr(backends, '_REGISTRY', dict(backends._REGISTRY))
    calls = []

    def evaluate(positions, want_blocks=False):
        calls.append(want_blocks)
        return reference.evaluate(positions, want_blocks)

    backends.register(Backend(name='mine', evaluate=evaluate, cost='N^2',
                              summary='the reference, counted'))
    assert backends.names()[-1] == 'mine' and 'mine' in backends.installed()
    with pytest.raises(ValueError, match="'mine' is already registered"):
        backends.register(Backend(name='mine', evaluate=evaluate, cost='N',
                                  summary=''))
    atoms = Atoms('H6', random_points(6, 3, seed=2))
    expected = MaudCalculator(springs=[[0, 1]]).get_forces(atoms)
    atoms.calc = MaudCalculator(springs=[[0, 1]], backend='mine')
    np.testing.assert_allclose(atoms.get_forces(), expected, rtol=1e-13)
    atoms.calc.get_stiffness(atoms)
    assert calls == [False, True]


def test_an_approximate_backend_says_both_errors(monkeypatch):
    """An approximate backend that does not delegate is registered only with
    the force and the energy error it promises."""
    monkeypatch.setattr(backends, '_REGISTRY', dict(backends._REGISTRY))
    loose = dict(evaluate=reference.evaluate, cost='N', summary='', tolerance='tol',
                 parameters={'tol': 1e-3})
    with pytest.raises(ValueError, match="'loose' must say the errors it promises"):
        backends.register(Backend(name='loose', force_tolerance=lambda tol: tol, **loose))
    backends.register(Backend(name='loose', force_tolerance=lambda tol: tol,
                              energy_tolerance=lambda tol: tol / 100, **loose))
    choice, = backends.get('loose').choices(10, 3, False, {'tol': 1e-3})
    assert (choice.tolerance, choice.energy_tolerance) == (1e-3, 1e-5)


def test_kernel_variants_have_their_own_cache_entries():
    """numba keys a cached closure by its code and closure values only, so
    the four kernels (with or without blocks, parallel or not) must differ in
    their closure values, or a run would load another variant's machine code."""
    keys = {tuple(cell.cell_contents for cell in kernel.py_func.__closure__)
            for kernel in direct._KERNELS.values()}
    assert len(keys) == len(direct._KERNELS) == 4


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('seed', range(6))
def test_compiled_hessian_block_is_the_reference_to_round_off(dim, seed):
    """The compiled block (what a MaudCalculator's ``get_hessian_block``
    sums) against :func:`physics.repulsion_hessian_block` on a fresh random
    scene and subset: the same law, only ``pow``'s rounding differs."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 40))
    points = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-1, 1)
    if dim == 2:
        points[:, 2] = 0.0
    index = rng.permutation(n)[:int(rng.integers(1, n + 1))]
    block = direct.repulsion_hessian_block(points, index, dim)
    assert_close(block, physics.repulsion_hessian_block(points, index, dim), rtol=1e-14)
    assert np.array_equal(block, block.T)
