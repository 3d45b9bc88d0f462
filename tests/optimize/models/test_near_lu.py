"""The factorised near-field model (ase_maud.optimize.models.near_lu: the springs'
Hessian plus the repulsion's near pair blocks, signed, factorised) against
the dense Hessian and finite differences of the forces on small scenes, and
runs of it to L-BFGS-B's minimum; the package's matrix-free model
(``model='near'``) is tested in tests/optimize/models/test_near.py."""

import itertools

import numpy as np
import pytest

from ase_maud import Maud
from ase_maud.analysis.stationary import same_point
from ase_maud.bench.optimizers import OPTIMIZERS
from ase_maud.counting import fresh_copy
from ase_maud.optimize.models.near_lu import NearLUModel
from ase_maud.optimize.models.springs import SpringsModel
from ase_maud.physics import pair_law as physics
from ase_maud.physics.dofs import free_dofs, rigid_body_modes
from ase_maud.scenes.catalogue import build


def relaxed(name, size, seed, fmax=1e-7):
    """Scene ``name`` of ``size`` (seeded), its start moved by a seeded
    jiggle, relaxed by the exact model: a minimum, where ``P`` is definite."""
    atoms = build(name, size, seed=seed)
    dim = atoms.calc.potential.dim
    free = np.zeros((len(atoms), 3), bool)
    free[:, :dim] = free_dofs(atoms, dim)
    atoms.positions += np.where(free, np.random.default_rng(seed).uniform(
        -0.1, 0.1, atoms.positions.shape), 0.0)
    assert Maud(atoms, model='exact', logfile=None).run(fmax=fmax, steps=500)
    return atoms


def dense_hessian(atoms):
    """The calculator's dense Hessian on the free degrees of freedom, and
    their indices into the (N, dim) coordinates."""
    keep = np.flatnonzero(free_dofs(atoms, atoms.calc.potential.dim).ravel())
    return atoms.calc.potential.hessian(atoms.positions)[np.ix_(keep, keep)], keep


@pytest.mark.parametrize('scene, seed', [('hanging_net', 3), ('hanging_net', 11),
                                         ('net2d', 4)])
def test_without_a_cutoff_p_is_the_dense_hessian_and_solves_newton(scene, seed):
    atoms = relaxed(scene, 5, seed)
    dim = atoms.calc.potential.dim
    hessian, keep = dense_hessian(atoms)
    model = NearLUModel(cutoff=1e9)
    np.testing.assert_allclose(model.matrix(atoms).toarray(), hessian,
                               rtol=1e-10, atol=1e-12 * np.abs(hessian).max())
    solver = model.factor(atoms)
    assert solver is not None   # a minimum: definite
    forces = np.zeros((len(atoms), 3))
    forces[:, :dim] = np.random.default_rng(seed).standard_normal((len(atoms), dim))
    move = solver.solve(forces)
    assert not move[:, :dim][~free_dofs(atoms, dim)].any() and not move[:, dim:].any()
    np.testing.assert_allclose(move[:, :dim].ravel()[keep],
                               np.linalg.solve(hessian, forces[:, :dim].ravel()[keep]),
                               rtol=1e-8, atol=1e-10 * np.abs(move).max())
    # the quadratic model's energy change along the move against the energy's
    t = 1e-3
    predicted = -t * np.vdot(atoms.get_forces(), move) + 0.5 * t * t * np.vdot(
        move, forces)   # P move = forces
    energy = atoms.get_potential_energy()
    atoms.positions += t * move
    assert atoms.get_potential_energy() - energy == pytest.approx(
        predicted, rel=1e-3, abs=1e-9 * abs(energy))


@pytest.mark.parametrize('seed', [5, 8])
def test_p_is_the_hessian_less_the_far_pairs_and_matches_finite_differences(seed):
    atoms = relaxed('hanging_net', 5, seed)
    hessian, keep = dense_hessian(atoms)
    model = NearLUModel(cutoff=1.5)
    matrix = model.matrix(atoms).toarray()
    x = atoms.positions
    spacing = np.median(np.sort(np.linalg.norm(x[:, None] - x[None], axis=2), axis=1)[:, 1])
    sprung = {tuple(sorted(s)) for s in atoms.calc.springs.tolist()}
    far = np.zeros((3 * len(x),) * 2)
    for i, j in itertools.combinations(range(len(x)), 2):
        if (i, j) in sprung or np.linalg.norm(x[i] - x[j]) <= 1.5 * spacing:
            continue
        block = physics.repulsion_block(x[i] - x[j])   # a = Q = 1
        for p, q, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            far[3 * p:3 * p + 3, 3 * q:3 * q + 3] += sign * block
    assert np.abs(far).max() > 1e-3 * np.abs(hessian).max()   # the cut-off drops something
    np.testing.assert_allclose(matrix, hessian - far[np.ix_(keep, keep)],
                               rtol=1e-10, atol=1e-12 * np.abs(hessian).max())
    # P v against central differences of the forces, less the far pairs
    v = np.zeros_like(x)
    v[free_dofs(atoms, 3)] = np.random.default_rng(seed).standard_normal(len(keep))
    h = 1e-5
    forces = []
    for sign in (1, -1):
        moved = atoms.copy()
        moved.calc = atoms.calc
        moved.positions = x + sign * h * v
        forces.append(moved.get_forces().ravel()[keep])
    hv = (forces[1] - forces[0]) / (2 * h)
    np.testing.assert_allclose(matrix @ v.ravel()[keep] + far[np.ix_(keep, keep)] @ (
        v.ravel()[keep]), hv, rtol=1e-5, atol=1e-6 * np.abs(hv).max())


@pytest.mark.parametrize('seed', [2, 9])
def test_a_free_scene_moves_without_rigid_motion(seed):
    atoms = relaxed('neighbour_graph', 30, seed, fmax=1e-6)
    solver = NearLUModel().factor(atoms)
    assert solver is not None
    forces = atoms.get_forces() + np.random.default_rng(seed).normal(0, 1e-3, (30, 3))
    move = solver.solve(forces)
    rigid = rigid_body_modes(atoms.positions, np.ones((30, 3), bool), 3)
    assert np.abs(rigid.T @ move.ravel()).max() < 1e-10 * np.abs(move).max()
    assert np.vdot(move, forces) > 0   # downhill


@pytest.mark.parametrize('seed', [4, 6])
def test_where_p_is_indefinite_the_springs_model_steps(seed):
    atoms = build('neighbour_graph', 40, seed=seed)   # a packed ball: repulsion pushes out
    model = NearLUModel()
    hessian, _ = dense_hessian(atoms)
    assert np.linalg.eigvalsh(model.matrix(atoms).toarray()).min() < 0
    assert np.linalg.eigvalsh(hessian).min() < 0
    assert model.factor(atoms) is None
    forces = atoms.get_forces()
    np.testing.assert_allclose(model.at(atoms).solve(forces),
                               SpringsModel().at(atoms).solve(forces), rtol=1e-12)


@pytest.mark.parametrize('seed', [1, 7])
def test_a_run_reaches_lbfgsb_minimum(seed):
    start = build('hanging_net', 8, seed=seed)
    start.positions[:, 2] += np.where(free_dofs(start, 3)[:, 2], np.random.default_rng(
        seed).uniform(-0.5, 0.5, len(start)), 0.0)
    atoms, peer = fresh_copy(start), fresh_copy(start)
    model = NearLUModel()
    assert Maud(atoms, model=model, logfile=None).run(fmax=1e-6, steps=500)
    assert model.definite > 0   # P, not the springs model alone, stepped
    assert OPTIMIZERS['L-BFGS-B'](peer).run(fmax=1e-6, steps=5000)
    assert atoms.get_potential_energy() == pytest.approx(peer.get_potential_energy(),
                                                         rel=1e-10)
    assert same_point(atoms, peer, distance_atol=1e-4)   # or its mirror image
