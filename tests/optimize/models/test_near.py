"""The near-field model (``model='near'``, :mod:`ase_maud.optimize.models.near`): its
``P`` against the dense Hessian's entries on small scenes, its products and
its truncated CG against the dense ``P``, the pairs it keeps, and runs to
L-BFGS-B's minimum, verified by the Hessian."""

import itertools

import numpy as np
import pytest

from ase_maud import Maud
from ase_maud.analysis.stationary import classify, same_point
from ase_maud.bench.optimizers import OPTIMIZERS
from ase_maud.counting import fresh_copy
from ase_maud.optimize.models import near as nearfield
from ase_maud.optimize.models.near import NearModel, near_pairs, sparse_springs
from ase_maud.optimize.models.registry import MODELS, choose_model
from ase_maud.physics import pair_law as physics
from ase_maud.physics.dofs import free_dofs
from ase_maud.scenes.catalogue import build


def jiggled(name, size, seed, by=0.1):
    """Scene ``name`` of ``size`` (seeded), its free coordinates moved by a
    seeded uniform jiggle of up to ``by``."""
    atoms = build(name, size, seed=seed)
    free = np.zeros((len(atoms), 3), bool)
    free[:, :atoms.calc.potential.dim] = free_dofs(atoms, atoms.calc.potential.dim)
    atoms.positions += np.where(free, np.random.default_rng(seed).uniform(
        -by, by, atoms.positions.shape), 0.0)
    return atoms


def dense(solver, atoms):
    """The solver's ``P`` on the free degrees of freedom, column by column
    from its products, and their indices into the (N, dim) coordinates."""
    dim = atoms.calc.potential.dim
    free = free_dofs(atoms, dim)
    keep = np.flatnonzero(free.ravel())
    columns = []
    for k in keep:
        v = np.zeros((len(atoms), 3))
        e = np.zeros(len(atoms) * dim)
        e[k] = 1.0
        v[:, :dim] = e.reshape(-1, dim)
        columns.append(solver.dot(v)[:, :dim].ravel()[keep])
    return np.array(columns).T, keep


def hessian_less(atoms, pairs):
    """The calculator's dense Hessian on the free degrees of freedom less the
    repulsion blocks of every pair not in ``pairs`` (a set of ``(i, j)``,
    ``i < j``): what ``P`` is on a scene whose springs leave nothing singular."""
    potential = atoms.calc.potential
    dim = potential.dim
    x = potential.reduced(atoms.positions)[:, :dim]
    far = np.zeros((dim * len(x),) * 2)
    for i, j in itertools.combinations(range(len(x)), 2):
        if (i, j) in pairs:
            continue
        block = potential.Q * physics.repulsion_block(x[i] - x[j])
        for p, q, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            far[dim * p:dim * p + dim, dim * q:dim * q + dim] += sign * block
    keep = np.flatnonzero(free_dofs(atoms, dim).ravel())
    hessian = potential.hessian(atoms.positions)
    return (hessian - far)[np.ix_(keep, keep)], far[np.ix_(keep, keep)]


@pytest.mark.parametrize('scene, seed', [('hanging_net', 3), ('hanging_net', 14),
                                         ('net2d', 4), ('net2d', 21)])
def test_without_a_cutoff_p_is_the_dense_hessian(scene, seed):
    atoms = jiggled(scene, 5, seed)   # every point sprung and anchored: no shift
    solver = NearModel(cutoff=1e9, per_point=None).at(atoms)
    matrix, _ = dense(solver, atoms)
    hessian, _ = hessian_less(atoms, set(itertools.combinations(range(len(atoms)), 2)))
    np.testing.assert_allclose(matrix, hessian, rtol=1e-10, atol=1e-12 * np.abs(hessian).max())


@pytest.mark.parametrize('seed', [5, 8, 17])
def test_p_is_the_hessian_on_the_near_and_sprung_pairs(seed):
    atoms = jiggled('hanging_net', 5, seed)
    x = atoms.positions
    solver = NearModel().at(atoms)
    matrix, _ = dense(solver, atoms)
    spacing = np.median(np.sort(np.linalg.norm(x[:, None] - x[None], axis=2), axis=1)[:, 1])
    near = {(i, j) for i, j in itertools.combinations(range(len(x)), 2)
            if np.linalg.norm(x[i] - x[j]) < nearfield.NEAR_CUTOFF * spacing}
    pairs = near | {tuple(sorted(s)) for s in atoms.calc.springs.tolist()}
    hessian, far = hessian_less(atoms, pairs)
    assert np.abs(far).max() > 1e-3 * np.abs(hessian).max()   # the cutoff drops something
    np.testing.assert_allclose(matrix, hessian, rtol=1e-10, atol=1e-12 * np.abs(hessian).max())
    # P v of a random move against the dense P
    v = np.zeros_like(x)
    v[free_dofs(atoms, 3)] = np.random.default_rng(seed).standard_normal(
        free_dofs(atoms, 3).sum())
    pv = solver.dot(v)
    assert not pv[~free_dofs(atoms, 3)].any()
    np.testing.assert_allclose(pv[free_dofs(atoms, 3)], hessian @ v[free_dofs(atoms, 3)],
                               rtol=1e-10, atol=1e-12 * np.abs(pv).max())


@pytest.mark.parametrize('seed', [0, 6, 13])
def test_the_pairs_are_the_near_ones_and_the_sparse_ends_springs(seed):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 4, (40, 3))
    dense_ends = rng.choice(40, 5, replace=False)   # sprung to every point
    springs = np.array([p for p in itertools.combinations(range(40), 2)
                        if np.isin(p, dense_ends).any() or rng.random() < 0.1])
    count = int(rng.integers(6, 12))
    degree = np.bincount(springs.ravel(), minlength=40)
    assert degree.max() > count   # the cap binds somewhere
    expected = {tuple(s) for s in springs if min(degree[s]) <= count}
    kept = sparse_springs(springs, 40, count)
    assert {tuple(s) for s in kept} == expected and len(kept) == len(expected)
    assert len(kept) <= count * 40
    assert any(tuple(s) not in expected for s in springs)   # a dense-dense spring goes
    spacing = np.median(np.sort(np.linalg.norm(x[:, None] - x[None], axis=2), axis=1)[:, 1])
    near = {(i, j) for i, j in itertools.combinations(range(40), 2)
            if np.linalg.norm(x[i] - x[j]) < 1.5 * spacing}
    i, j = near_pairs(x, kept, 1.5)
    assert len(i) == len(near | expected)   # each pair once
    assert set(zip(i.tolist(), j.tolist(), strict=True)) == near | expected
    assert len(sparse_springs(springs, 40, None)) == len(springs)


@pytest.mark.parametrize('scene, seed', [('hanging_net', 12), ('net2d', 13), ('hub_net', 2)])
def test_the_cg_solves_p_at_a_minimum(scene, seed, monkeypatch):
    # P z = r + R z inside the CG: to a tight residual it is P^-1 f
    atoms = jiggled(scene, 5 if scene != 'hub_net' else 4, seed)
    assert Maud(atoms, model='exact', logfile=None).run(fmax=1e-7, steps=500)
    dim = atoms.calc.potential.dim
    solver = NearModel().at(atoms)
    matrix, keep = dense(solver, atoms)
    assert np.linalg.eigvalsh(matrix).min() > 0   # anchored, near a minimum: definite
    monkeypatch.setattr(nearfield, 'NEAR_RTOL', 1e-12)
    monkeypatch.setattr(nearfield, 'NEAR_MAXITER', 1000)
    forces = np.zeros((len(atoms), 3))
    forces[:, :dim] = np.random.default_rng(seed).standard_normal((len(atoms), dim))
    move = solver.solve(forces)
    assert not move[:, :dim][~free_dofs(atoms, dim)].any() and not move[:, dim:].any()
    np.testing.assert_allclose(move[:, :dim].ravel()[keep],
                               np.linalg.solve(matrix, forces[:, :dim].ravel()[keep]),
                               rtol=1e-7, atol=1e-9 * np.abs(move).max())


@pytest.mark.parametrize('seed', [1, 4])
def test_a_move_is_downhill_and_free_of_rigid_motion(seed):
    atoms = build('neighbour_graph', 30, seed=seed)   # free: no point held
    model = NearModel()
    forces = atoms.get_forces()
    move = model.at(atoms).solve(forces)
    assert np.vdot(move, forces) > 0
    assert model.work.near_products > 0 and model.work.total == 0
    x = atoms.positions - atoms.positions.mean(axis=0)
    rigid = [np.tile(e, (30, 1)) for e in np.eye(3)] + [np.cross(e, x) for e in np.eye(3)]
    basis = np.linalg.qr(np.array([r.ravel() for r in rigid]).T)[0]
    assert np.abs(basis.T @ move.ravel()).max() < 1e-10 * np.abs(move).max()


@pytest.mark.integration   # a relaxation compared with another optimiser's
@pytest.mark.parametrize('scene, size, seed', [('hub_net', 6, 2), ('hub_net', 6, 5),
                                               ('all_pairs', 24, 3), ('all_pairs', 24, 8),
                                               ('hanging_net', 8, 1)])
def test_a_run_reaches_the_verified_minimum_of_lbfgsb(scene, size, seed):
    start = jiggled(scene, size, seed, by=0.2)
    atoms, peer = fresh_copy(start), fresh_copy(start)
    opt = Maud(atoms, model='near', logfile=None)
    assert opt.run(fmax=1e-6, steps=1000)
    assert opt.model.name == 'near' and opt.work.near_products > 0
    assert OPTIMIZERS['L-BFGS-B'](peer).run(fmax=1e-6, steps=5000)
    assert np.abs(atoms.get_forces()).max() < 1e-6
    assert atoms.get_potential_energy() == pytest.approx(peer.get_potential_energy(),
                                                         rel=1e-9)
    assert same_point(atoms, peer, distance_atol=1e-4)
    assert classify(atoms, ftol=1e-6).verdict == 'minimum'


def test_the_cap_keeps_a_clusters_products_linear():
    atoms = build('all_pairs', 60, seed=0)   # every pair sprung: 1770 springs
    capped, _ = NearModel().pairs(atoms)
    every, _ = NearModel(per_point=None).pairs(atoms)
    assert len(every) == 1770
    assert len(capped) <= 10 * len(atoms) < len(every) / 2   # the near pairs alone
    solver = NearModel().at(atoms)
    assert solver.incidence.shape == (len(capped), len(atoms))


def test_the_model_is_named_and_seeks_a_minimum_only():
    atoms = build('hub_net', 4, seed=0)
    assert 'near' in MODELS
    model = choose_model(atoms, 'near')
    assert isinstance(model, NearModel) and model.todict()['model'] == 'near'
    with pytest.raises(ValueError, match="model='near' seeks a minimum only"):
        choose_model(atoms, 'near', target='stationary')
    with pytest.raises(ValueError, match='per_point'):
        NearModel(per_point=-1)


@pytest.mark.parametrize('scene, size, seed', [('neighbour_graph', 40, 3), ('hub_net', 5, 7)])
def test_a_run_stopped_and_resumed_repeats_the_uninterrupted_one(tmp_path, scene, size, seed):
    straight = build(scene, size, seed=seed)
    with Maud(straight, logfile=None, model='near') as opt:
        opt.run(fmax=1e-300, steps=30)
    assert opt.work.near_products > 0
    interrupted = build(scene, size, seed=seed)
    restart = tmp_path / 'maud.json'
    for steps in (11, 6, 13):
        with Maud(interrupted, logfile=None, restart=restart, model='near') as opt:
            opt.run(fmax=1e-300, steps=steps)
    np.testing.assert_array_equal(interrupted.positions, straight.positions)
