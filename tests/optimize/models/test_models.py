"""Stiffness models and the step rule with them: against the analytic Hessian,
Newton's step, and BFGS from the same start."""

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.emt import EMT
from ase.constraints import FixAtoms, FixCartesian
from ase.optimize import BFGS

from ase_maud import Maud, MaudCalculator
from ase_maud.optimize.models.base import free_dofs
from ase_maud.optimize.models.exact import ExactModel
from ase_maud.optimize.models.global_model import GlobalModel
from ase_maud.optimize.models.nodal import NodalModel
from ase_maud.optimize.models.registry import choose_model
from ase_maud.optimize.models.secant import BFGSModel, SecantModel
from ase_maud.physics.dofs import allowed_basis, allowed_rigid_modes, project_off, rigid_body_modes
from ase_maud.scenes.catalogue import SCENES, build

from helpers import random_scene


def near_minimum(atoms, seed):
    """``atoms`` relaxed by BFGS, then nudged a little: a point where the free
    Hessian is positive definite (checked) and the forces are not zero."""
    with BFGS(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-8, steps=5000)
    nudge = np.random.default_rng(seed).normal(0, 1e-3, atoms.positions.shape)
    nudge[:, atoms.calc.dim:] = 0.0
    atoms.set_positions(atoms.positions + nudge)
    return atoms


def free_hessian(atoms):
    dim = atoms.calc.dim
    keep = free_dofs(atoms, dim).ravel()
    return atoms.calc.get_hessian(atoms)[np.ix_(keep, keep)], keep


@pytest.mark.parametrize('weighted', [False, True])
@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('dim', [2, 3])
def test_exact_step_is_newtons_step(seed, dim, weighted):
    atoms = near_minimum(random_scene(seed, dim, weighted=weighted), seed)
    hessian, keep = free_hessian(atoms)
    assert np.linalg.eigvalsh(hessian).min() > 0
    forces = atoms.get_forces()
    newton = np.linalg.solve(hessian, forces[:, :dim].ravel()[keep])
    move = ExactModel().at(atoms).solve(forces)
    # Newton's step on the Hessian shifted by its floor, 1e-8 of its largest
    # row sum: equal to 1e-8 over the condition number of the Hessian.
    condition = np.abs(hessian).sum(axis=1).max() / np.linalg.eigvalsh(hessian).min()
    gap = np.linalg.norm(move[:, :dim].ravel()[keep] - newton)
    assert gap <= 2e-8 * condition * np.linalg.norm(newton)
    assert not move[:, :dim].ravel()[~keep].any()
    if dim == 2:
        assert not move[:, 2].any()
    # One Maud step with the exact model (gamma 1, no memory) is that move.
    start = atoms.positions.copy()
    with Maud(atoms, model='exact', logfile=None) as opt:
        opt.run(fmax=1e-300, steps=1)  # exactly one step
    np.testing.assert_allclose(atoms.positions - start, move, rtol=1e-8,
                               atol=1e-12 * np.abs(move).max())


@pytest.mark.parametrize('seed', range(6))
@pytest.mark.parametrize('dim', [2, 3])
def test_global_model_is_symmetric_positive_definite(seed, dim):
    atoms = random_scene(seed, dim)
    matrix, free, diagonal = GlobalModel().assemble(atoms)
    assert matrix.shape == (free.sum(),) * 2
    assert free.sum() < len(atoms) * dim  # the fixed DOFs are gone
    dense = matrix.toarray()
    assert np.allclose(dense, dense.T, rtol=0, atol=1e-14 * np.abs(dense).max())
    assert np.linalg.eigvalsh(dense).min() > 0
    # Its solver inverts it.
    rng = np.random.default_rng(seed)
    forces = rng.normal(size=(len(atoms), 3))
    move = GlobalModel().at(atoms).solve(forces)
    rhs = forces[:, :dim][free]
    assert np.allclose(dense @ move[:, :dim][free], rhs, atol=1e-9 * np.abs(rhs).max())


@pytest.mark.parametrize('weighted', [False, True])
@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('dim', [2, 3])
def test_global_model_is_the_hessian_without_repulsion(seed, dim, weighted):
    # a -> 0: the repulsion a^3 Q / L vanishes and P is the exact Hessian.
    atoms = random_scene(seed, dim, a=1e-7, weighted=weighted)
    matrix, free, _ = GlobalModel().assemble(atoms)
    hessian, keep = free_hessian(atoms)
    assert np.allclose(matrix.toarray(), hessian, rtol=0,
                       atol=1e-12 * np.abs(hessian).max())


@pytest.mark.parametrize('weighted', [False, True])
@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('dim', [2, 3])
def test_global_model_spring_part_is_the_hessians(seed, dim, weighted):
    atoms = random_scene(seed, dim, fixed=False, weighted=weighted)
    calc = atoms.calc
    springless = MaudCalculator(a=calc.length_scale, Q=calc.parameters['Q'], dim=dim)
    spring_part = calc.get_hessian(atoms) - springless.get_hessian(atoms)
    assert np.allclose(calc.get_spring_hessian(atoms).toarray(), spring_part,
                       rtol=0, atol=1e-10 * np.abs(spring_part).max())


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('dim', [2, 3])
def test_global_model_product_is_its_matrix_and_solve_undoes_it(seed, dim):
    # The solver's P v (what the string's tangent is measured with) is the
    # assembled P on the free coordinates, zero where held, and solve undoes it.
    atoms = random_scene(seed, dim)
    solver = GlobalModel().at(atoms)
    matrix, free, _ = GlobalModel().assemble(atoms)
    move = np.random.default_rng(seed).normal(size=(len(atoms), 3))
    product = solver.dot(move)
    assert not product[:, dim:].any() and not product[:, :dim][~free].any()
    assert np.allclose(product[:, :dim][free], matrix @ move[:, :dim][free],
                       rtol=1e-12, atol=0)
    back = solver.solve(product)
    assert np.allclose(back[:, :dim][free], move[:, :dim][free], rtol=0, atol=1e-8)


def test_dense_spring_graph_is_solved_matrix_free():
    # Every pair sprung: L is dense; the CG path must solve P d = f.
    atoms = build('all_pairs', 120, seed=1)
    model = GlobalModel()
    solver = model.at(atoms)
    assert type(solver).__name__ == 'MatrixFreeSolver'
    forces = atoms.get_forces()
    move = solver.solve(forces)
    matrix, free, _ = model.assemble(atoms)
    assert np.allclose(matrix @ move.ravel(), forces.ravel(),
                       atol=1e-8 * np.abs(forces).max())


@pytest.mark.parametrize('seed', [3, 4])
def test_nodal_and_secant_models(seed):
    atoms = random_scene(seed)
    forces = atoms.get_forces(apply_constraint=False)
    free = free_dofs(atoms, 3)
    blocks = atoms.calc.get_stiffness(atoms)
    for method in ('tensor', 'scalar'):
        move = NodalModel(method=method).at(atoms).solve(forces)
        assert not move[~free].any()   # zero where FixAtoms, FixCartesian hold
    move = NodalModel().at(atoms).solve(forces)
    # Where a block is positive definite, the tensor step is its inverse.
    positive = (np.linalg.eigvalsh(blocks).min(axis=1) > 1e-2 * np.abs(
        np.linalg.eigvalsh(blocks)).max(axis=1)) & free.all(axis=1)
    expected = np.linalg.solve(blocks[positive], forces[positive][..., None])[..., 0]
    assert np.allclose(move[positive], expected)
    secant = SecantModel(kappa0=4.0)
    assert np.allclose(secant.at(atoms).solve(forces), np.where(free, forces / 4.0, 0))
    learnt = secant.observe(np.ones((2, 3)), 3 * np.ones((2, 3)), {})
    assert learnt == {'kappa': 3.0}
    assert np.allclose(secant.at(atoms, learnt).solve(forces), np.where(free, forces / 3, 0))
    assert secant.observe(np.ones((2, 3)), -np.ones((2, 3)), learnt) is learnt


@pytest.mark.parametrize('seed', [5, 6])
def test_bfgs_model_learns_the_mean_of_the_two_secant_curvatures(seed):
    """kappa is |y| / |s|, the geometric mean of s.y / s.s and y.y / s.y,
    between the two; a step with s.y <= 0 teaches nothing."""
    rng = np.random.default_rng(seed)
    s = rng.normal(size=(7, 3))
    y = 2.0 * s + 0.5 * rng.normal(size=(7, 3))   # s.y > 0
    model = BFGSModel(kappa0=70.0)
    assert model.at(None).solve(np.ones((1, 3)))[0, 0] == pytest.approx(1 / 70.0)
    learnt = model.observe(s, y, {})
    small, large = np.vdot(s, y) / np.vdot(s, s), np.vdot(y, y) / np.vdot(s, y)
    assert learnt['kappa'] == pytest.approx(np.sqrt(small * large), rel=1e-12)
    assert small < learnt['kappa'] < large
    assert model.observe(s, -y, learnt) is learnt


def test_auto_picks_by_size_and_calculator():
    assert choose_model(build('ring', 16)).name == 'exact'
    assert choose_model(build('hanging_net', 20)).name == 'springs'
    bulk = Atoms('Cu4', positions=np.eye(4, 3) * 2.5)
    bulk.calc = EMT()
    assert choose_model(bulk).name == 'bfgs'
    assert choose_model(bulk, target='stationary').name == 'secant'
    with pytest.raises(ValueError, match="property 'hessian'"):
        choose_model(bulk, 'exact')
    with pytest.raises(ValueError, match='model must be'):
        choose_model(build('dimer'), 'newton')


MULTI_BASIN = ('all_pairs', 'all_pairs2d')  # clusters with several minima


@pytest.mark.parametrize('name', sorted(set(SCENES) - set(MULTI_BASIN)))
def test_default_maud_reaches_bfgs_minimum(name):
    seed = int(np.random.default_rng(sum(map(ord, name))).integers(1000))
    size = {'molecule': 'C6H6', 'all_pairs': 10, 'hanging_net': 5, 'hub_net': 4, 'disc': 40,
            'neighbour_graph': 30}.get(name)
    atoms, reference = build(name, size, seed=seed), build(name, size, seed=seed)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-7, steps=5000)
    with BFGS(reference, logfile=None) as opt:
        assert opt.run(fmax=1e-7, steps=20000)
    energy, ref = atoms.get_potential_energy(), reference.get_potential_energy()
    assert energy <= ref * (1 + 1e-9), name


@pytest.mark.integration
@pytest.mark.parametrize('name', MULTI_BASIN)
def test_default_maud_in_multi_basin_clusters(name):
    # From a random start these clusters fall into one of a few minima, and
    # BFGS and FIRE disagree on some starts. Over seeded starts, every Maud
    # result must be a minimum that BFGS or FIRE also finds from some start,
    # and Maud must reach the lowest one at least as often as BFGS.
    from ase.optimize import FIRE

    from ase_maud.analysis.stationary import classify
    found = {'Maud': [], 'BFGS': [], 'FIRE': []}
    for seed in range(8):
        for label, opt in (('Maud', Maud), ('BFGS', BFGS), ('FIRE', FIRE)):
            atoms = build(name, 10, seed=seed)
            with opt(atoms, logfile=None) as dyn:
                assert dyn.run(fmax=1e-7, steps=20000)
            found[label].append(atoms.get_potential_energy())
            if label == 'Maud':
                assert classify(atoms).verdict == 'minimum'
    known = np.array(found['BFGS'] + found['FIRE'])
    for energy in found['Maud']:
        assert np.isclose(known, energy, rtol=1e-8).any(), (energy, known)
    lowest = known.min()
    hits = {k: int(np.isclose(v, lowest, rtol=1e-8).sum()) for k, v in found.items()}
    assert hits['Maud'] >= hits['BFGS'], hits


@pytest.mark.slow   # 17 s
def test_global_model_with_memory_relaxes_a_large_net_like_bfgs():
    atoms, reference = build('hanging_net', 12, seed=4), build('hanging_net', 12, seed=4)
    with Maud(atoms, model='global', logfile=None) as opt:
        assert opt.run(fmax=1e-6, steps=2000)
    with BFGS(reference, logfile=None) as opt:
        assert opt.run(fmax=1e-6, steps=5000)
    assert atoms.get_potential_energy() == pytest.approx(
        reference.get_potential_energy(), rel=1e-10)
    gap = (np.sort(atoms.get_all_distances(), axis=None)
           - np.sort(reference.get_all_distances(), axis=None))
    assert np.abs(gap).max() < 1e-4


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('scene, held, rigid', [
    ('all_pairs', [], 6), ('all_pairs', [0], 3), ('all_pairs', [0, 1, 2], 0),
    ('all_pairs2d', [], 3), ('all_pairs2d', [0], 1), ('ring', [], 3)])
def test_the_saddle_model_leaves_out_the_rigid_motions_the_constraints_allow(
        seed, scene, held, rigid):
    """``rigid`` orthonormal rigid motions inside the allowed moves; the saddle
    model's eigenpairs are the Hessian's on the allowed moves orthogonal to
    them (its projection off them, lifted out of the way, as the analysis's):
    classify's spectrum, and eigenvectors of the projected Hessian."""
    from ase_maud.analysis.stationary import classify
    atoms = build(scene, 7, seed=seed)
    if held:
        atoms.set_constraint(FixAtoms(held))
    dim = atoms.calc.parameters['dim']
    allowed = allowed_basis(atoms, dim) if held else np.eye(dim * len(atoms))
    motions = allowed_rigid_modes(atoms.positions, dim, allowed if held else None)
    assert motions.shape[1] == rigid
    np.testing.assert_allclose(motions.T @ motions, np.eye(rigid), atol=1e-12)
    np.testing.assert_allclose(allowed @ (allowed.T @ motions), motions, atol=1e-12)
    values, modes = ExactModel('saddle').at(atoms).eigenpairs(0, None)
    assert len(values) == allowed.shape[1] - rigid
    np.testing.assert_allclose(values, classify(atoms, ftol=np.inf).eigenvalues, rtol=1e-9,
                               atol=1e-9 * np.abs(values).max())
    flat = modes[:, :, :dim].reshape(len(values), -1).T
    np.testing.assert_allclose(flat.T @ flat, np.eye(len(values)), atol=1e-9)
    np.testing.assert_allclose(motions.T @ flat, 0.0, atol=1e-9)
    np.testing.assert_allclose(allowed @ (allowed.T @ flat), flat, atol=1e-9)
    hessian = atoms.calc.get_hessian(atoms)
    projected = allowed.T @ hessian @ allowed
    inside = allowed.T @ motions
    project_off(projected, inside)
    np.testing.assert_allclose(projected @ (allowed.T @ flat), allowed.T @ flat * values,
                               atol=1e-9 * np.abs(values).max())


def test_saddle_target_takes_the_exact_or_the_springs_model():
    atoms = build('all_pairs', 6)
    with pytest.raises(ValueError, match="target='saddle' needs model='exact' or 'springs'"):
        Maud(atoms, target='saddle', model='nodal', logfile=None)
    assert Maud(atoms, target='saddle', logfile=None).model.name == 'exact'
    big = build('all_pairs', 60)   # 180 free DOFs
    assert Maud(big, target='saddle', logfile=None).model.name == 'springs'
    assert Maud(big, target='saddle', model='exact', logfile=None).model.name == 'exact'


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('scene, size, held', [
    ('all_pairs', 20, []), ('all_pairs2d', 30, []), ('tree', 25, [0]), ('net2d', 6, None)])
def test_springs_saddle_model_gives_the_lowest_eigenpairs(seed, scene, size, held):
    """The lowest eigenpairs from Hessian-vector products (LOBPCG,
    preconditioned by the springs model) are the dense Hessian's lowest on
    the internal moves (:func:`ase_maud.analysis.stationary.classify`), rigid-body
    motions left out."""
    from ase_maud.analysis.stationary import classify
    atoms = build(scene, size, seed=seed)
    if held:
        atoms.set_constraint(FixAtoms(held))
    Maud(atoms, logfile=None).run(fmax=1e-3, steps=300)
    model = choose_model(atoms, 'springs', target='saddle')
    values, modes = model.at(atoms).eigenpairs(3, None)
    dense = classify(atoms, ftol=np.inf)
    # to MODES_RTOL's residual: eigenvalues to ~its square, modes to ~it over the gap;
    # the block's last pair converges last, so the two lowest are checked
    scale = np.abs(dense.eigenvalues).max()
    np.testing.assert_allclose(values[:2], dense.eigenvalues[:2], atol=1e-5 * scale)
    gaps = np.diff(dense.eigenvalues[:3])
    for k in range(2):
        if min(gaps[max(k - 1, 0):k + 1]) > 1e-2 * scale:
            assert abs(np.vdot(modes[k], dense.modes[k])) == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('scene, size, held', [
    ('all_pairs', 12, []), ('all_pairs2d', 15, []), ('tree', 14, [0]), ('net2d', 5, None)])
def test_springs_saddle_model_curvature_is_the_hessian_on_internal_moves(
        seed, scene, size, held):
    """``curvature`` (Hessian-vector products) is the dense analytic Hessian
    on the free coordinates, with the rigid-body motions projected out on
    both sides, times a random move; held coordinates get nothing."""
    atoms = build(scene, size, seed=seed)
    if held:
        atoms.set_constraint(FixAtoms(held))
    dim = atoms.calc.dim
    free = free_dofs(atoms, dim)
    rigid = rigid_body_modes(atoms.positions, free, dim)
    move = np.random.default_rng(seed).normal(size=(len(atoms), 3))
    got = choose_model(atoms, 'springs', target='saddle').at(atoms).curvature(move)
    projector = np.eye(int(free.sum())) - rigid @ rigid.T
    hessian = atoms.calc.get_hessian(atoms)[np.ix_(free.ravel(), free.ravel())]
    expected = projector @ hessian @ projector @ move[:, :dim][free]
    np.testing.assert_allclose(got[:, :dim][free], expected,
                               atol=1e-10 * np.abs(expected).max())
    assert not got[:, :dim][~free].any() and not got[:, dim:].any()


@pytest.mark.parametrize('seed', range(4))
def test_exact_model_selects_held_coordinates_and_projects_other_constraints(seed):
    """FixAtoms and FixCartesian hold whole coordinates: the exact model
    marks them held (its Hessian's free block is selected, not projected:
    the Newton move itself is test_exact_step_is_newtons_step's). With a
    FixedPlane too (a general basis) the move stays in the plane and is
    Newton's on the projected Hessian, to the floor's shift."""
    from ase.constraints import FixedPlane
    atoms = near_minimum(random_scene(seed), seed)
    model = ExactModel()
    model.at(atoms)
    free = free_dofs(atoms, 3)
    assert (model._held == ~free).all()
    normal = np.random.default_rng(seed).normal(size=3)
    planar = int(np.flatnonzero(free.all(axis=1))[0])
    atoms.set_constraint(atoms.constraints + [FixedPlane(planar, normal)])
    forces = atoms.get_forces()
    move = model.at(atoms).solve(forces)
    assert model._held is None
    basis = allowed_basis(atoms, 3)
    projected = basis.T @ atoms.calc.get_hessian(atoms) @ basis
    newton = basis @ np.linalg.solve(projected, basis.T @ forces.ravel())
    condition = np.abs(projected).sum(axis=1).max() / np.linalg.eigvalsh(projected).min()
    assert np.linalg.norm(move.ravel() - newton) <= 2e-8 * condition * np.linalg.norm(newton)
    assert abs(np.dot(move[planar], normal)) <= 1e-9 * np.abs(move).max()


@pytest.mark.parametrize('seed', range(3))
def test_cholesky_factor_is_that_of_the_matrix_plus_its_shift_times_identity(seed):
    """The exact model's shifted Cholesky factor has the digits of LAPACK's
    factor of ``matrix + shift I`` (zeros of either sign among the entries),
    and None where that matrix is not definite."""
    from scipy.linalg.lapack import dpotrf

    from ase_maud.optimize.models.exact import _cholesky
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((12, 30))
    matrix = a @ a.T + 30.0 * np.eye(12)   # definite with any two entries zeroed
    matrix[0, 5] = matrix[5, 0] = -0.0
    matrix[1, 7] = matrix[7, 1] = 0.0
    for shift in (0.0, 1e-8, 3.0):
        expected = dpotrf(matrix + shift * np.eye(12), lower=False, clean=False)[0]
        assert _cholesky(matrix, shift).tobytes() == expected.tobytes()
    assert _cholesky(matrix - 1e3 * np.eye(12), 1.0) is None


@pytest.mark.parametrize('seed', range(4))
def test_exact_model_of_results_is_its_model_at_the_atoms(seed):
    """The Hessian a loop hands over (:meth:`ExactModel.of_results`) gives
    the model :meth:`ExactModel.at` asks the calculator for, bit for bit
    (the Cholesky and the eigen paths, held coordinates or none), and results
    without a Hessian are asked of the calculator."""
    rng = np.random.default_rng(seed)
    atoms = random_scene(seed, fixed=bool(seed % 2))
    atoms.rattle(0.3, seed=seed)   # far from a minimum: the eigen path too
    forces = atoms.get_forces()
    for floor in (None, 1e-2):
        handed, asked = ExactModel(floor=floor), ExactModel(floor=floor)
        results = {'hessian': atoms.calc.get_hessian(atoms)}
        got, want = handed.of_results(atoms, results), asked.at(atoms)
        assert type(got) is type(want)
        probe = rng.normal(size=forces.shape)
        for f in (forces, probe):
            assert got.solve(f).tobytes() == want.solve(f).tobytes()
        assert handed.of_results(atoms, {}).solve(forces).tobytes() == \
            want.solve(forces).tobytes()


@pytest.mark.parametrize('seed', range(3))
def test_exact_model_follows_constraints_changed_between_calls(seed):
    """The exact model keeps its constraints' basis and free components, but
    a change of the constraints (a new set, or a FixAtoms changed in place)
    is followed: the held coordinates never move, and the moves are those of
    a fresh model."""
    atoms = near_minimum(random_scene(seed, fixed=False), seed)
    rng = np.random.default_rng(seed)
    model = ExactModel()
    forces = atoms.get_forces()
    model.at(atoms).solve(forces)   # no constraints: every component free
    fix = FixAtoms(indices=rng.choice(len(atoms), 3, replace=False))
    atoms.set_constraint(fix)
    for change in range(3):
        if change == 1:
            fix.index = np.sort(rng.choice(len(atoms), 2, replace=False))
        elif change == 2:
            atoms.set_constraint([fix, FixCartesian(int(np.flatnonzero(
                ~np.isin(np.arange(len(atoms)), fix.index))[0]), mask=[False, True, True])])
        move = model.of_results(atoms, {'hessian': atoms.calc.get_hessian(atoms)}).solve(forces)
        assert not move[~free_dofs(atoms, 3)].any()
        assert move[free_dofs(atoms, 3)].any()
        assert move.tobytes() == ExactModel().at(atoms).solve(forces).tobytes()
    atoms.set_constraint()
    assert model.at(atoms).solve(forces).tobytes() == \
        ExactModel().at(atoms).solve(forces).tobytes()


def test_exact_model_refuses_a_non_finite_hessian_asked_for_or_handed_over():
    """A non-finite Hessian is refused whether the model asks the calculator
    for it (``local``, what ``at`` builds on) or a loop hands it over
    (``of_results``: a MaudCalculator subclass may hold one)."""
    atoms = random_scene(5, fixed=False)
    hessian = atoms.calc.get_hessian(atoms)
    for bad in (np.nan, np.inf):
        broken = hessian.copy()
        broken[1, 2] = bad
        with pytest.raises(np.linalg.LinAlgError, match='not finite'):
            ExactModel().local(broken, atoms)
        with pytest.raises(np.linalg.LinAlgError, match='not finite'):
            ExactModel().of_results(atoms, {'hessian': broken})


@pytest.mark.parametrize('seed', range(6))
def test_global_models_staleness_bound_keeps_only_what_the_distances_keep(seed):
    # Random points, random moves from tiny to a neighbour distance: where the
    # bound keeps P, the exact test (nearest distances now) keeps it too, and
    # the bound keeps it for small moves.
    from scipy.spatial import cKDTree

    from ase_maud.optimize.models.global_model import _kept_by_bound

    rng = np.random.default_rng(seed)
    built = rng.uniform(0, 10, (rng.integers(20, 200), 3))
    distances = cKDTree(built).query(built, k=2)[0][:, 1]
    kept_by_bound = 0
    for scale in np.geomspace(1e-4, 1.0, 25) * distances.min():
        moves = rng.normal(size=built.shape) * rng.uniform(0, 1, (len(built), 1)) * scale
        moved = np.linalg.norm(moves, axis=1)
        now = cKDTree(built + moves).query(built + moves, k=2)[0][:, 1]
        if _kept_by_bound(moved, distances, 0.5):
            kept_by_bound += 1
            assert np.all(moved <= 0.5 * now)
    assert kept_by_bound >= 5   # the bound does keep P for small moves


@pytest.mark.parametrize('seed', range(3))
def test_global_model_rebuilds_where_the_exact_test_would(seed, monkeypatch):
    # A run with the bound and a run that searches the neighbours at every
    # check take the same steps, bit for bit; the bound spares searches.
    import ase_maud.optimize.models.global_model as global_model
    from ase_maud.physics.neighbours import NearestDistances

    class Counted(NearestDistances):
        searches = 0

        def __call__(self, x):
            self.searches += 1
            return super().__call__(x)

    runs = []
    for bound in (True, False):
        if not bound:
            monkeypatch.setattr(global_model, '_kept_by_bound', lambda *args: False)
        atoms = random_scene(seed, 3)
        nearest = Counted()
        with Maud(atoms, model=GlobalModel(nearest=nearest), logfile=None,
                  maxstep_nn=None) as opt:
            opt.run(fmax=1e-6, steps=60)
        runs.append((atoms.positions.copy(), opt.nsteps, nearest.searches))
    (with_bound, steps, few), (without, steps_without, many) = runs
    assert steps == steps_without
    np.testing.assert_array_equal(with_bound, without)
    assert few < many
