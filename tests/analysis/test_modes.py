"""The phonopy bridge and ASE's VibrationsData against the analytic Hessian."""

import numpy as np
import pytest
from ase import Atoms, units
from ase.constraints import FixAtoms

from ase_maud.analysis.modes import (
    finite_difference_force_constants,
    force_constants,
    gamma_modes,
    vibrations,
)
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.scenes.catalogue import build


def scene(random_points, n, dim, seed):
    springs = [(i, (i + s) % n) for i in range(n) for s in (1, 3)]
    atoms = Atoms(f'X{n}', positions=1.5 * random_points(n, dim, seed))
    atoms.calc = MaudCalculator(springs=springs, a=1.1, Q=0.8, dim=dim)
    return atoms


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('seed', [0, 1, 2])
def test_phonopy_finite_differences_match_analytic(random_points, dim, seed):
    atoms = scene(random_points, 10, dim, seed)
    analytic = force_constants(atoms)
    numeric = finite_difference_force_constants(atoms)
    assert np.abs(numeric - analytic).max() < 1e-6 * np.abs(analytic).max()


def test_dim2_in_plane_block_is_the_2d_hessian(random_points):
    atoms = scene(random_points, 9, 2, 4)
    fc = force_constants(atoms)
    n = len(atoms)
    in_plane = fc[:, :, :2, :2].transpose(0, 2, 1, 3).reshape(2 * n, 2 * n)
    np.testing.assert_array_equal(in_plane, atoms.calc.get_hessian(atoms))
    assert not np.any(fc[:, :, :2, 2]) and not np.any(fc[:, :, 2, :2])


@pytest.mark.parametrize('seed', [0, 1])
def test_gamma_frequencies_square_to_hessian_eigenvalues(random_points, seed):
    atoms = scene(random_points, 8, 3, seed)
    hessian = atoms.calc.get_hessian(atoms)
    frequencies, modes, _ = gamma_modes(atoms)
    np.testing.assert_allclose(np.sign(frequencies) * frequencies**2,
                               np.linalg.eigvalsh(hessian),
                               atol=1e-12 * np.abs(hessian).max())
    flat = modes.reshape(len(modes), -1)
    np.testing.assert_allclose(flat @ flat.T, np.eye(len(flat)), atol=1e-12)
    np.testing.assert_allclose(flat @ hessian @ flat.T,
                               np.diag(np.sign(frequencies) * frequencies**2),
                               atol=1e-11 * np.abs(hessian).max())
    masses = np.random.default_rng(seed).uniform(1, 3, len(atoms))
    weights = np.repeat(masses, 3) ** -0.5
    weighted, _, _ = gamma_modes(atoms, masses=masses)
    np.testing.assert_allclose(
        np.sign(weighted) * weighted**2,
        np.linalg.eigvalsh(weights[:, None] * hessian * weights),
        atol=1e-12 * np.abs(hessian).max())


def test_vibrations_data_holds_the_same_modes(random_points):
    atoms = scene(random_points, 8, 3, 5)
    hessian = atoms.calc.get_hessian(atoms)
    data = vibrations(atoms)
    np.testing.assert_array_equal(data.get_hessian_2d(), hessian)
    # ASE's energies are hbar omega with omega^2 in eV / (Angstrom^2 amu)
    scale = units._hbar * 1e10 / np.sqrt(units._e * units._amu)
    squared = (data.get_energies() ** 2).real / scale**2
    np.testing.assert_allclose(np.sort(squared), np.linalg.eigvalsh(hessian),
                               atol=1e-9 * np.abs(hessian).max())


def test_vibrations_data_leaves_out_fixed_atoms(random_points):
    atoms = scene(random_points, 8, 2, 6)
    atoms.set_constraint(FixAtoms([0, 3]))
    data = vibrations(atoms)
    assert list(data.get_indices()) == [1, 2, 4, 5, 6, 7]
    assert data.get_hessian_2d().shape == (18, 18)


@pytest.mark.parametrize('seed', [0, 1])
def test_vibrations_of_a_planar_scene_keep_every_point(seed):
    """keep_on_plane's z mask (for ASE's drivers) does not empty the modes."""
    atoms = build('ring', 12, seed=seed)
    assert atoms.constraints                      # the plane's FixCartesian
    data = vibrations(atoms)
    assert list(data.get_indices()) == list(range(len(atoms)))
    assert len(data.get_energies()) == 3 * len(atoms)


@pytest.mark.parametrize('seed', [0, 1])
def test_gamma_modes_hold_fixed_points(seed):
    """A relaxed hanging net (a minimum, by classify) has no imaginary mode at
    Gamma: its supports are held, the modes those of the free points."""
    from ase_maud import Maud
    from ase_maud.analysis.stationary import classify
    atoms = build('hanging_net', 5, seed=seed)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-9, steps=2000)
    assert classify(atoms).verdict == 'minimum'
    free = np.setdiff1d(np.arange(len(atoms)), atoms.constraints[0].index)
    assert 0 < len(free) < len(atoms)
    frequencies, modes, phonon = gamma_modes(atoms)
    assert len(frequencies) == 3 * len(free) == 3 * len(phonon.unitcell)
    assert frequencies.min() > 0
    dofs = (3 * free[:, None] + np.arange(3)).ravel()
    block = atoms.calc.get_hessian(atoms)[np.ix_(dofs, dofs)]
    np.testing.assert_allclose(frequencies**2, np.linalg.eigvalsh(block),
                               atol=1e-10 * np.abs(block).max())
    assert not np.any(np.delete(modes, free, axis=1))   # the supports never move
