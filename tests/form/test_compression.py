"""Negative force densities (compression): the a = 0 solve against compas_fd
and an analytic arch, and what Maud finds with the repulsion on (a
stationary point, never a silent minimum)."""

import numpy as np
import pytest
from ase import Atoms
from ase.constraints import FixAtoms

from ase_maud import Maud, MaudCalculator
from ase_maud.form.force_density import force_density_positions
from ase_maud.form.member_forces import describe_result, form_result

fd_numpy = pytest.importorskip('compas_fd.solvers').fd_numpy


def grid(n, rng, q_low, q_high, sag=0.0):
    """An n x n grid net with its boundary fixed, force densities drawn from
    [q_low, q_high], random loads mostly down, and a random start."""
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing='ij')
    positions = np.c_[x.ravel(), y.ravel(), sag * rng.normal(size=n * n)]
    index = np.arange(n * n).reshape(n, n)
    springs = np.r_[np.c_[index[:-1].ravel(), index[1:].ravel()],
                    np.c_[index[:, :-1].ravel(), index[:, 1:].ravel()]]
    fixed = np.flatnonzero((x.ravel() % (n - 1) == 0) | (y.ravel() % (n - 1) == 0))
    q = rng.uniform(q_low, q_high, len(springs))
    loads = np.c_[rng.normal(0, 0.05, (n * n, 2)), rng.uniform(-1.0, -0.2, n * n)]
    atoms = Atoms(f'H{n * n}', positions=positions)
    atoms.set_constraint(FixAtoms(fixed))
    atoms.calc = MaudCalculator(springs=springs, a=0.0, q=q, loads=loads)
    return atoms, fixed


def peer(atoms, fixed):
    calc = atoms.calc
    return np.asarray(fd_numpy(vertices=atoms.positions.tolist(), fixed=fixed.tolist(),
                               edges=calc.springs.tolist(),
                               forcedensities=calc.potential.q.tolist(),
                               loads=calc.potential.loads.tolist()).vertices)


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('q_range', [(-2.0, -0.5), (-1.0, 3.0)], ids=['gridshell', 'mixed'])
def test_force_density_solve_equals_compas_fd_with_compression(seed, q_range):
    rng = np.random.default_rng(seed)
    atoms, fixed = grid(9 + seed, rng, *q_range, sag=0.3)
    q = atoms.calc.potential.q
    if q_range[0] * q_range[1] < 0:   # keep the mixed net away from singular
        atoms.calc.set(q=np.where(np.abs(q) < 0.3, 0.3 * np.sign(q), q))
    ours = force_density_positions(atoms)
    theirs = peer(atoms, fixed)
    diagonal = np.linalg.norm(np.ptp(theirs, axis=0))
    assert np.abs(ours - theirs).max() <= 1e-9 * diagonal
    assert np.abs(ours - atoms.positions).max() > 1e-3 * diagonal   # it moved


def test_compressed_gridshell_stands_up_and_its_members_push():
    atoms, _ = grid(8, np.random.default_rng(3), -2.0, -0.5)
    atoms.positions = force_density_positions(atoms)
    assert atoms.positions[:, 2].max() > 0.5          # loads down, the shell rises
    result = form_result(atoms)
    assert (result.forces < 0).all() and result.max_force == result.max_compression < 0
    assert result.max_residual < 1e-10
    np.testing.assert_allclose(result.reaction_sum, -result.loads.sum(axis=0), atol=1e-9)
    assert '(compression)' in describe_result(result, repulsion=False)


@pytest.mark.parametrize('n', [5, 12])
def test_arch_under_even_loads_is_the_analytic_parabola(n):
    """A chain x = 0..n-1, ends held, q = -c, load -w at each free point:
    ``c (z_{i+1} - 2 z_i + z_{i-1}) = w`` gives ``z_i = w i (n-1-i) / (2 c)``."""
    rng = np.random.default_rng(n)
    c, w = rng.uniform(0.5, 2.0), rng.uniform(0.1, 1.0)
    positions = np.c_[np.arange(n, dtype=float), np.zeros(n), rng.normal(0, 0.1, n)]
    positions[[0, -1], 2] = 0.0
    atoms = Atoms(f'H{n}', positions=positions, constraint=FixAtoms([0, n - 1]))
    loads = np.zeros((n, 3))
    loads[:, 2] = -w
    atoms.calc = MaudCalculator(springs=np.c_[np.arange(n - 1), np.arange(1, n)], a=0.0,
                                q=np.full(n - 1, -c), loads=loads)
    found = force_density_positions(atoms)
    i = np.arange(n)
    np.testing.assert_allclose(found[:, 2], w * i * (n - 1 - i) / (2 * c), rtol=0, atol=1e-12)
    np.testing.assert_allclose(found[:, 0], i, atol=1e-12)


def test_forces_with_compression_are_minus_the_energy_gradient():
    """Finite differences of the energy against the forces, with q of both signs."""
    rng = np.random.default_rng(7)
    atoms, _ = grid(5, rng, -1.5, 1.5, sag=0.5)
    atoms.calc.set(a=0.3)
    forces = atoms.get_forces(apply_constraint=False)
    h = 1e-6
    for k in rng.choice(len(atoms), 6, replace=False):
        for d in range(3):
            shifted = []
            for sign in (1, -1):
                moved = atoms.copy()
                moved.calc = atoms.calc
                moved.positions[k, d] += sign * h
                shifted.append(moved.get_potential_energy())
            assert -(shifted[0] - shifted[1]) / (2 * h) == pytest.approx(forces[k, d],
                                                                          abs=1e-6)


def test_singular_force_densities_are_refused_in_words():
    atoms = Atoms('H3', positions=[[0, 0, 0], [1, 0, 0], [2, 0, 0]],
                  constraint=FixAtoms([0, 2]))
    atoms.calc = MaudCalculator(springs=[[0, 1], [1, 2]], a=0.0, q=[1.0, -1.0])
    with pytest.raises(ValueError, match='singular'):
        force_density_positions(atoms)


def test_maud_with_repulsion_finds_a_stationary_point_and_says_so(tmp_path):
    atoms, _ = grid(7, np.random.default_rng(4), -2.0, -0.5)
    reference = force_density_positions(atoms)
    atoms.calc.set(a=0.05)
    with pytest.raises(ValueError, match="no minimum.*target='stationary'"):
        Maud(atoms, target='minimum', logfile=None)
    log = tmp_path / 'maud.log'
    with Maud(atoms, logfile=str(log)) as opt:
        assert opt.target == 'stationary'
        assert opt.run(fmax=1e-8, steps=300)
    assert "target='stationary'" in log.read_text() and 'not a minimum' in log.read_text()
    diagonal = np.linalg.norm(np.ptp(reference, axis=0))
    # the repulsion a**3 Q / L moves the form by about (a / edge)**3 of it
    assert np.abs(atoms.positions - reference).max() < 1e-3 * diagonal
    assert np.abs(atoms.get_forces()).max() < 1e-8


def test_q_refuses_zero_and_takes_negative():
    with pytest.raises(ValueError, match='nonzero'):
        _ = MaudCalculator(springs=[[0, 1]], q=[0.0]).potential
    calc = MaudCalculator(springs=[[0, 1], [1, 2]], q=[-1.0, 2.0])
    assert calc.potential.compressed.tolist() == [0]
