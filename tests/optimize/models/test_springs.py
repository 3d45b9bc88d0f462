"""The springs model (the large-scene default): the springs' exact Hessian per
coordinate, factorised once; the Hessian-vector product it could be checked
against; and the L-BFGS memory's guard against nearly degenerate pairs."""

import numpy as np
import pytest
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian

import ase_maud.optimize.models.sparse as sparse
from ase_maud import Maud, MaudCalculator
from ase_maud.analysis.stationary import classify
from ase_maud.calculator.potential import MaudPotential
from ase_maud.optimize.directions import MIN_PAIR_COSINE
from ase_maud.optimize.models.registry import choose_model
from ase_maud.optimize.models.springs import SpringsModel
from ase_maud.optimize.strategy import Minimise
from ase_maud.physics.dofs import free_dofs
from ase_maud.scenes.catalogue import build


def net(seed, side=7, a=1.0, dim=3, partial=False, weighted=False):
    """A side x side net of spacing 1 with its boundary fixed on a random
    saddle and a random interior, repelling with ``a``; ``partial``: some
    interior points held in x only; ``weighted``: random force densities in
    [0.2, 3] and random loads."""
    rng = np.random.default_rng(seed)
    atoms = build('hanging_net', side, seed=seed)
    atoms.positions += rng.uniform(-0.2, 0.2, atoms.positions.shape)
    if dim == 2:
        atoms.positions[:, 2] = 0.0
    springs = atoms.calc.springs
    atoms.calc = MaudCalculator(springs, a=a, dim=dim)
    if weighted:
        atoms.calc.set(q=rng.uniform(0.2, 3.0, len(springs)),
                       loads=rng.normal(0.0, 0.5, (len(atoms), dim)))
    if partial:
        held = [c for c in atoms.constraints if isinstance(c, FixAtoms)]
        interior = np.setdiff1d(np.arange(len(atoms)), held[0].index)
        some = rng.choice(interior, 4, replace=False)
        atoms.set_constraint([*held, FixCartesian(some, mask=[True, False, False])])
    return atoms


@pytest.mark.parametrize('weighted', [False, True])
@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('dim, partial', [(3, False), (2, False), (3, True)])
def test_a_springs_only_scene_takes_one_step(seed, dim, partial, weighted):
    # a = 1e-4 on a net of spacing 1: the repulsion a^3 Q / L is 1e-12 of the
    # springs, whose Hessian the model holds exactly: one Newton step (loads
    # are constant forces: still one)
    atoms = net(seed, a=1e-4, dim=dim, partial=partial, weighted=weighted)
    start = np.abs(atoms.get_forces()).max()
    with Maud(atoms, model='springs', logfile=None) as opt:
        assert opt.run(fmax=1e-9 * start, steps=5)
    assert opt.nsteps == 1
    held = ~free_dofs(atoms, dim)
    start = net(seed, a=1e-4, dim=dim, partial=partial, weighted=weighted).positions[:, :dim]
    np.testing.assert_array_equal(atoms.positions[:, :dim][held], start[held])


@pytest.mark.parametrize('weighted', [False, True])
@pytest.mark.parametrize('seed', [0, 1])
def test_the_solver_is_the_springs_hessian_per_coordinate(seed, weighted):
    atoms = net(seed, partial=True, weighted=weighted)
    solver = SpringsModel().at(atoms)
    free = free_dofs(atoms, 3)
    forces = np.random.default_rng(seed).standard_normal((len(atoms), 3))
    move = solver.solve(forces)
    assert not move[~free].any()
    laplacian = np.zeros((len(atoms), len(atoms)))   # weighted by q, written out
    q = atoms.calc.parameters['q']
    for (i, j), qs in zip(atoms.calc.springs, np.ones(len(atoms.calc.springs))
                          if q is None else q, strict=True):
        laplacian[[i, j, i, j], [i, j, j, i]] += [qs, qs, -qs, -qs]
    for c in range(3):
        keep = free[:, c]
        np.testing.assert_allclose(laplacian[np.ix_(keep, keep)] @ move[keep, c],
                                   forces[keep, c], rtol=1e-9, atol=1e-12)
    assert SpringsModel().at(atoms) is not solver   # a new model, a new factor
    model = SpringsModel()
    assert model.at(atoms) is model.at(atoms)        # one factorisation per run


def test_multigrid_and_factorisation_agree(monkeypatch):
    atoms = build('hanging_net', 30, seed=4)
    forces = atoms.get_forces()
    direct = SpringsModel().at(atoms).solve(forces)
    monkeypatch.setattr(sparse, 'AMG_MIN_DOFS', 10)
    multigrid = SpringsModel().at(atoms).solve(forces)
    np.testing.assert_allclose(multigrid, direct, rtol=0,
                               atol=1e-5 * np.abs(direct).max())


def test_auto_takes_the_springs_model_for_large_scenes():
    assert choose_model(build('hanging_net', 20)).name == 'springs'
    assert choose_model(build('ring', 16)).name == 'exact'


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('dim', [2, 3])
def test_hessian_vector_product_is_the_derivative_of_the_forces(random_points, seed, dim):
    n = 40
    rng = np.random.default_rng(seed)
    positions = random_points(n, dim, seed)
    springs = np.array([(i, (i + 1 + int(rng.integers(4))) % n) for i in range(n)])
    springs = np.unique(np.sort(springs, axis=1), axis=0)
    potential = MaudPotential(springs, a=1.3, Q=0.7, dim=dim)
    atoms = Atoms(positions=positions)
    atoms.calc = MaudCalculator(springs, a=1.3, Q=0.7, dim=dim, tol=0)
    v = np.zeros((n, 3))
    v[:, :dim] = rng.standard_normal((n, dim))
    h = 1e-5

    def forces(x):
        atoms.positions = x
        return atoms.get_forces()

    fd = (forces(positions - h * v) - forces(positions + h * v)) / (2 * h)
    hv = potential.hvp(positions, v[:, :dim])
    np.testing.assert_allclose(hv, fd[:, :dim], rtol=0, atol=1e-7 * np.abs(fd).max())


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_nearly_degenerate_pair_in_the_memory_does_no_harm(seed, monkeypatch):
    # A secant pair with s.y / (|s| |y|) = 9e-7, as one once made every
    # clipped move uphill until gamma underflowed: the rule no longer keeps
    # such a pair, and a run that has one in its memory all the same still
    # converges on a minimum (the Hessian says so).
    assert 9e-7 < MIN_PAIR_COSINE
    atoms = net(seed, side=9)
    step = Minimise.step
    injected = []

    def poisoned_step(self, state, x, merit, forces, noise, solver_at):
        if len(state.pairs) == 3 and not injected:
            s = np.random.default_rng(seed).standard_normal(x.shape)
            y = np.cross(s, np.random.default_rng(seed + 1).standard_normal(x.shape))
            y += 9e-7 * np.linalg.norm(y) / np.linalg.norm(s) * s
            state.pairs = [*state.pairs, (s, y)]
            injected.append(np.vdot(s, y) / np.linalg.norm(s) / np.linalg.norm(y))
        return step(self, state, x, merit, forces, noise, solver_at)

    monkeypatch.setattr(Minimise, 'step', poisoned_step)
    with Maud(atoms, model='springs', logfile=None) as opt:
        assert opt.run(fmax=1e-7, steps=2000)
    assert injected and 0 < injected[0] < 1e-6
    assert classify(atoms).verdict == 'minimum'
