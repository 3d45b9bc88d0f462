"""Inverse form finding (ase_maud.form.inverse): the adjoint gradient against
finite differences, target heights reached on a 30 x 30 net within 1e-6 of
its diagonal in at most 50 forward solves (checked by compas_fd's forward
solve), and member forces brought within bounds."""

import numpy as np
import pytest
from ase import Atoms
from ase.constraints import FixAtoms

from ase_maud import MaudCalculator
from ase_maud.form.force_density import force_density_positions
from ase_maud.form.inverse import ForceDensityProblem, find_force_densities
from ase_maud.form.member_forces import form_result

fd_numpy = pytest.importorskip('compas_fd.solvers').fd_numpy


def grid_net(n, rng, load=-1.0):
    """An n x n grid, boundary fixed, a vertical load on every point, a
    slightly rough start."""
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing='ij')
    positions = np.c_[x.ravel(), y.ravel(), rng.normal(0, 0.01, n * n)]
    index = np.arange(n * n).reshape(n, n)
    springs = np.r_[np.c_[index[:-1].ravel(), index[1:].ravel()],
                    np.c_[index[:, :-1].ravel(), index[:, 1:].ravel()]]
    fixed = np.flatnonzero((x.ravel() % (n - 1) == 0) | (y.ravel() % (n - 1) == 0))
    loads = np.zeros((n * n, 3))
    loads[:, 2] = load
    atoms = Atoms(f'H{n * n}', positions=positions, constraint=FixAtoms(fixed))
    atoms.calc = MaudCalculator(springs=springs, a=0.0, loads=loads)
    return atoms, index, fixed


@pytest.mark.parametrize('sign', [1, -1], ids=['tension', 'compression'])
@pytest.mark.parametrize('seed', [0, 1])
def test_adjoint_gradient_equals_finite_differences(seed, sign):
    rng = np.random.default_rng(seed)
    atoms, index, _ = grid_net(6, rng)
    count = len(atoms.calc.springs)
    points = rng.choice(index[1:-1, 1:-1].ravel(), 4, replace=False)
    heights = {int(p): float(rng.normal(0, 1)) for p in points}
    forces = (sign * 0.6, sign * 1.4) if sign > 0 else (sign * 1.4, sign * 0.6)
    problem = ForceDensityProblem(atoms, heights=heights, forces=forces)
    q = sign * rng.uniform(0.5, 2.0, count)
    loss, grad, _ = problem.loss_and_gradient(q)
    assert loss > 0
    h = 1e-6
    for s in rng.choice(count, 12, replace=False):
        step = np.zeros(count)
        step[s] = h
        up, down = (problem.loss_and_gradient(q + d)[0] for d in (step, -step))
        assert grad[s] == pytest.approx((up - down) / (2 * h), rel=1e-5, abs=1e-9)


def test_forward_solve_equals_force_density_positions():
    rng = np.random.default_rng(3)
    atoms, _, _ = grid_net(7, rng)
    q = rng.uniform(0.3, 3.0, len(atoms.calc.springs))
    problem = ForceDensityProblem(atoms, heights={10: 0.0})
    atoms.calc.set(q=q)
    np.testing.assert_allclose(problem.positions(q), force_density_positions(atoms),
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_30x30_net_reaches_nine_target_heights_in_at_most_50_solves(seed):
    rng = np.random.default_rng(seed)
    atoms, index, fixed = grid_net(30, rng)
    start = atoms.positions.copy()
    reachable = rng.uniform(0.5, 3.0, len(atoms.calc.springs))   # targets a q can meet
    shape = ForceDensityProblem(atoms, heights={0: 0.0}).positions(reachable)
    points = index[[7, 15, 22]][:, [7, 15, 22]].ravel()
    heights = {int(p): float(shape[p, 2]) for p in points}
    result = find_force_densities(atoms, heights=heights, bounds=(0.1, 10.0))
    assert result.met and result.forward_solves <= 50, result
    assert (result.q >= 0.1).all() and (result.q <= 10.0).all()
    # the peer's forward solve with the q found meets the targets too
    peer = np.asarray(fd_numpy(vertices=start.tolist(), fixed=fixed.tolist(),
                               edges=atoms.calc.springs.tolist(),
                               forcedensities=result.q.tolist(),
                               loads=atoms.calc.potential.loads.tolist()).vertices)
    diagonal = np.linalg.norm(np.ptp(start, axis=0))
    assert np.abs(peer[points, 2] - [heights[int(p)] for p in points]).max() <= 1e-6 * diagonal
    np.testing.assert_allclose(atoms.positions, peer, rtol=0, atol=1e-9 * diagonal)
    np.testing.assert_array_equal(atoms.calc.potential.q, result.q)


def test_member_forces_are_brought_within_bounds():
    """Bounds that some q meets (the forces of a random one's form), from a
    start whose forces spread far wider."""
    rng = np.random.default_rng(4)
    atoms, _, _ = grid_net(10, rng)
    count = len(atoms.calc.springs)
    problem = ForceDensityProblem(atoms, forces=(None, None))
    feasible = rng.uniform(0.8, 1.2, count)
    x = problem.positions(feasible)
    forces = feasible * np.linalg.norm(x[atoms.calc.springs[:, 0]]
                                       - x[atoms.calc.springs[:, 1]], axis=1)
    low, high = forces.min(), forces.max()
    atoms.calc.set(q=rng.uniform(0.2, 5.0, count))
    atoms.positions = force_density_positions(atoms)
    before = form_result(atoms).forces
    assert before.min() < low - 0.1 * (high - low) and before.max() > high
    result = find_force_densities(atoms, forces=(low, high), bounds=(0.01, 100.0))
    assert result.met, result
    after = form_result(atoms).forces
    scale = max(abs(low), abs(high))
    assert after.min() >= low - 1e-6 * scale and after.max() <= high + 1e-6 * scale


def test_compressed_shell_reaches_heights_with_negative_bounds():
    rng = np.random.default_rng(5)
    atoms, index, _ = grid_net(12, rng)
    target = ForceDensityProblem(atoms, heights={0: 0.0}).positions(
        -rng.uniform(0.5, 2.0, len(atoms.calc.springs)))
    points = index[[3, 6, 8]][:, [3, 6, 8]].ravel()
    result = find_force_densities(atoms, heights={int(p): float(target[p, 2]) for p in points},
                                  bounds=(-10.0, -0.1))
    assert result.met and (result.q < 0).all()
    assert atoms.positions[points, 2].min() > 0   # loads down, the shell stands up


def test_bad_targets_and_bounds_are_refused_in_words():
    atoms, _, _ = grid_net(4, np.random.default_rng(6))
    with pytest.raises(ValueError, match='give a target'):
        find_force_densities(atoms)
    with pytest.raises(ValueError, match='one side of 0'):
        find_force_densities(atoms, heights={5: 1.0}, bounds=(-1.0, 1.0))
    with pytest.raises(ValueError, match='points 0 to 15'):
        find_force_densities(atoms, heights={99: 1.0})


def test_the_example_meets_its_targets(monkeypatch, tmp_path, capsys):
    import runpy
    import sys
    from pathlib import Path

    example = Path(__file__).parents[2] / 'examples' / 'inverse_form_finding.py'
    monkeypatch.setattr(sys, 'argv', [example.name, '--out', str(tmp_path / 'form.obj')])
    runpy.run_path(str(example), run_name='__main__')
    out = capsys.readouterr().out
    assert 'met True' in out
    assert (tmp_path / 'form.obj').read_text().count('\nf ') == 29 * 29
