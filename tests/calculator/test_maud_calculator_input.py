"""Every bad input is a ValueError that names the offender."""

import itertools
import re

import numpy as np
import pytest
from ase import Atoms

from ase_maud import Maud, MaudCalculator, backends
from ase_maud.physics.spring_list import check_springs
from ase_maud.scenes.catalogue import build

#: The exact backends (the fmm one is tested in test_fmm.py).
BACKENDS = [name for name in backends.names() if backends.get(name).exact]


def points(n=5, seed=0):
    return Atoms(f'H{n}', np.random.default_rng(seed).uniform(0, 3, (n, 3)))


@pytest.mark.parametrize('springs, match', [
    ([[0, 1], [-1, 2]], r'spring 1 \(-1, 2\).*negative'),
    ([[0, 1], [1, 2], [2, 2]], r'spring 2 \(2, 2\) ties an atom to itself'),
    ([[0, 1, 2]], r'shape \(K, 2\), got \(1, 3\)'),
    ([0, 1], r'shape \(K, 2\), got \(2,\)'),
    ([[0, 1], [1, 2.5]], r'spring 1 \[1.0, 2.5\] is not .*integer'),
    ([[0, 1], [np.inf, 2]], r'spring 1 \[inf, 2.0\] is not .*integer'),
    ([['0', '1']], r'integer atom indices'),
    ([[0, 1], [2, 3], [1, 0]], r'springs \[0, 2\] all tie atoms 0 and 1'),
    ([[3, 4], [3, 4]], r'springs \[0, 1\] all tie atoms 3 and 4'),
    ([[0, 1], [1, 2j]], r'integer atom indices, got dtype complex'),
    ([[0, 1], [1, 1e20]], r'spring 1 \[1.0, 1e\+20\] is not .*integer'),
    (np.array([[0, 1], [1, 2**64 - 1]], dtype=np.uint64), r'spring 1 .* is not .*integer'),
])
def test_bad_springs(springs, match):
    with pytest.raises(ValueError, match=match):
        MaudCalculator(springs=springs)
    calc = MaudCalculator()
    with pytest.raises(ValueError, match=match):
        calc.set(springs=springs)


@pytest.mark.parametrize('seed', range(6))
def test_the_lowest_pair_listed_twice_is_named_with_all_its_springs(seed):
    """Of several pairs listed twice (in either order), the error names the
    lowest (by its lower atom, then its higher) and each spring of it."""
    rng = np.random.default_rng(seed)
    pairs = np.array(list(itertools.combinations(range(12), 2)))
    pairs = pairs[rng.choice(len(pairs), 20, replace=False)]
    twice = pairs[rng.choice(20, 3, replace=False)]
    springs = np.concatenate([pairs, twice[:, ::-1]])[rng.permutation(23)]
    low = min(tuple(sorted(pair)) for pair in twice.tolist())
    named = [k for k, pair in enumerate(springs.tolist()) if tuple(sorted(pair)) == low]
    with pytest.raises(ValueError, match=re.escape(
            f'springs {named} all tie atoms {low[0]} and {low[1]}: list each pair once')):
        check_springs(springs)


def test_spring_beyond_last_atom():
    atoms = points(5)
    atoms.calc = MaudCalculator(springs=[[0, 1], [4, 5]])
    with pytest.raises(ValueError, match=r'spring 1 \(4, 5\).*index 4'):
        atoms.get_potential_energy()


@pytest.mark.parametrize('value', [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize('backend', BACKENDS)
def test_non_finite_position_names_atom(value, backend):
    atoms = points(5)
    atoms.positions[3, 1] = value
    atoms.calc = MaudCalculator(backend=backend)
    with pytest.raises(ValueError, match='atom 3 has a non-finite position'):
        atoms.get_forces()


@pytest.mark.filterwarnings('ignore:divide by zero:RuntimeWarning')
@pytest.mark.filterwarnings('error:invalid value:RuntimeWarning')
@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('backend', BACKENDS)
def test_coincident_points_name_both(dim, backend):
    atoms = points(6)
    atoms.positions[:, 2] = 0.0
    atoms.positions[4] = atoms.positions[1]
    atoms.calc = MaudCalculator(dim=dim, backend=backend)
    with pytest.raises(ValueError, match='atoms 1 and 4 are at the same'):
        atoms.get_potential_energy()


@pytest.mark.parametrize('backend', BACKENDS)
def test_very_close_points_are_finite(backend):
    a = 0.7
    atoms = points(4)
    atoms.positions[2] = atoms.positions[0] + [1e-8 * a, 0, 0]
    atoms.calc = MaudCalculator(springs=[[0, 2]], a=a, backend=backend)
    assert np.isfinite(atoms.get_potential_energy())
    forces = atoms.get_forces()
    assert np.all(np.isfinite(forces))
    assert np.all(np.isfinite(atoms.calc.get_stiffness(atoms)))
    assert forces[2, 0] == pytest.approx(a**3 / (1e-8 * a) ** 2, rel=1e-6)


@pytest.mark.parametrize('name', ['a', 'Q'])
@pytest.mark.parametrize('value', [0.0, -1.0, np.nan, np.inf, '1', None])
def test_bad_a_and_Q(name, value):
    if name == 'a' and value == 0.0:
        return   # a = 0 is the force-density method (tests/form/test_member_forces.py)
    rule = {'a': 'a finite number >= 0', 'Q': 'a positive finite'}[name]
    with pytest.raises(ValueError, match=f'{name} must be {rule}'):
        MaudCalculator(**{name: value})
    with pytest.raises(ValueError, match=f'{name} must be {rule}'):
        MaudCalculator().set(**{name: value})


@pytest.mark.parametrize('dim', [1, 4, 0, 2.0, '3', None])
def test_bad_dim(dim):
    with pytest.raises(ValueError, match=f'dim must be 2 or 3, got {dim!r}'):
        MaudCalculator(dim=dim)


def test_unknown_backend():
    with pytest.raises(ValueError, match="backend must be one of .*'cuda'"):
        MaudCalculator(backend='cuda')


@pytest.mark.parametrize('pbc', [True, [False, True, False],
                                 [False, False, True]])
def test_periodic_boundaries_refused(pbc):
    atoms = points(4)
    atoms.pbc = pbc
    atoms.cell = [10, 10, 10]
    atoms.calc = MaudCalculator()
    with pytest.raises(ValueError, match=r'periodic boundaries.*pbc='):
        atoms.get_potential_energy()


def test_point_off_the_plane_in_2d():
    atoms = points(6)
    atoms.positions[:, 2] = 1.5
    atoms.positions[4, 2] += 1e-6
    atoms.calc = MaudCalculator(dim=2)
    with pytest.raises(ValueError, match='atom 4 has z = 1.500001'):
        atoms.get_potential_energy()
    with pytest.raises(ValueError, match='atom 4'):
        atoms.calc.get_hessian(atoms)


def test_hessian_size_limit():
    atoms = points(5)
    atoms.calc = MaudCalculator()
    assert atoms.calc.get_hessian(atoms).shape == (15, 15)
    atoms.calc.max_hessian_atoms = 4
    with pytest.raises(ValueError, match='5 atoms exceed max_hessian_atoms'):
        atoms.calc.get_hessian(atoms)


@pytest.mark.parametrize('backend', BACKENDS)
def test_no_atoms_is_named(backend):
    atoms = Atoms()
    atoms.calc = MaudCalculator(backend=backend)
    with pytest.raises(ValueError, match='no atoms'):
        atoms.get_potential_energy()
    from ase_maud.analysis.stationary import classify
    with pytest.raises(ValueError, match='no atoms'):
        Maud(atoms, logfile=None).run(fmax=1e-3)
    with pytest.raises(ValueError, match='no atoms'):
        classify(atoms)


def test_off_plane_error_says_what_to_add():
    atoms = build('ring', 8, seed=1)
    del atoms.constraints
    atoms.positions[2, 2] += 0.1
    with pytest.raises(ValueError, match=r'atom 2 has z = 0.1.*keep_on_plane\(atoms\)'):
        atoms.get_potential_energy()


@pytest.mark.parametrize('springs, bad', [([[0, 1], [1, 2, 3]], '[1, 2, 3]'),
                                          ([[0, 1], [1, 2], [2]], '[2]'),
                                          ([[0, 1], [2, [3]]], '[2, [3]]')])
def test_ragged_springs_name_the_spring(springs, bad):
    row = next(s for s, pair in enumerate(springs) if str(pair) == bad)
    with pytest.raises(ValueError, match=re.escape(f'spring {row} is {bad}')):
        MaudCalculator(springs=springs)
