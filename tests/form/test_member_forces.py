"""Member forces, reactions and out-of-balance (ase_maud.form.member_forces), the
force-density solve (ase_maud.form.force_density) and ``a = 0``."""

import csv
import re

import numpy as np
import pytest
from ase import Atoms
from ase.constraints import FixAtoms

from ase_maud import Maud, MaudCalculator
from ase_maud.cli.command import main
from ase_maud.form.force_density import solve_force_density
from ase_maud.form.member_forces import form_result, write_forces_csv
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_net

from helpers import ROOT

compas = pytest.importorskip('compas')
fd_numpy = pytest.importorskip('compas_fd.solvers').fd_numpy


def hanging_truss(seed, a=0.0):
    """Two supports 2 w apart, two free points, three members: a cable
    hanging under the loads P at its free points, with random q, Q, P, w."""
    rng = np.random.default_rng(seed)
    w, Q, P = rng.uniform(0.5, 2.0, 3)
    q = rng.uniform(0.5, 2.0, 3)
    start = np.array([[-w, 0, 0], [w, 0, 0], [-w / 3, 0.1, 0.2], [w / 3, -0.1, 0.1]])
    atoms = Atoms(positions=start)
    atoms.set_constraint(FixAtoms([0, 1]))
    loads = np.zeros((4, 3))
    loads[2:, 2] = -P
    atoms.calc = MaudCalculator(springs=[[0, 2], [2, 3], [3, 1]], a=a, Q=Q, q=q,
                                loads=loads)
    return atoms, w, Q, q, P


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_truss_forces_and_reactions_by_hand(seed):
    atoms, w, Q, q, P = hanging_truss(seed)
    solve_force_density(atoms)
    x = atoms.positions
    # by hand: each member pulls Q q_s (r_j - r_i); the horizontal pull H is
    # the same in each member, so Q q_0 (x2 + w) = Q q_1 (x3 - x2) = Q q_2 (w - x3);
    # vertically point 2 carries P by members 0 and 1, point 3 by 1 and 2
    d = 1 / q
    x2 = -w + 2 * w * d[0] / d.sum()
    x3 = w - 2 * w * d[2] / d.sum()
    H = Q * q[0] * (x2 + w)
    # z: Q q0 (0 - z2) + Q q1 (z3 - z2) = P and Q q2 (0 - z3) + Q q1 (z2 - z3) = P
    matrix = Q * np.array([[q[0] + q[1], -q[1]], [-q[1], q[1] + q[2]]])
    z2, z3 = np.linalg.solve(matrix, [-P, -P])
    assert np.allclose(x[2:], [[x2, 0, z2], [x3, 0, z3]], atol=1e-12)
    result = form_result(atoms)
    lengths = np.array([np.hypot(x2 + w, z2), np.hypot(x3 - x2, z3 - z2),
                        np.hypot(w - x3, z3)])
    assert np.allclose(result.lengths, lengths, rtol=1e-12)
    assert np.allclose(result.forces, Q * q * lengths, rtol=1e-12)
    assert np.allclose(result.force_densities, Q * q, rtol=1e-15)
    # the supports pull the cable outwards by H and hold it up by their share of 2 P
    assert result.supports.tolist() == [0, 1]
    assert np.allclose(result.reactions, [[-H, 0, Q * q[0] * -z2], [H, 0, Q * q[2] * -z3]],
                       atol=1e-12)
    assert np.allclose(result.reaction_sum, [0, 0, 2 * P], rtol=0, atol=1e-9 * 2 * P)
    assert result.max_residual < 1e-12 and result.max_out_of_balance < 1e-12


@pytest.mark.parametrize('seed', [0, 1])
def test_maud_at_a_zero_reaches_the_force_density_solution(seed):
    atoms, *_ = hanging_truss(seed)
    expected = atoms.copy()
    expected.calc = atoms.calc
    solve_force_density(expected)
    solution = expected.positions.copy()
    atoms, *_ = hanging_truss(seed)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-10, steps=20)
    assert opt.nsteps <= 5
    assert np.abs(atoms.positions - solution).max() < 1e-9
    assert atoms.calc.last_backend == 'none'


def test_a_zero_has_no_repulsion():
    atoms, *_ = hanging_truss(3, a=0.0)
    forces = atoms.get_forces(apply_constraint=False)
    springs = atoms.calc.get_spring_hessian(atoms)
    linear = -(springs @ atoms.positions.ravel()).reshape(-1, 3) + atoms.calc.potential.loads
    assert np.allclose(forces, linear, rtol=1e-12, atol=1e-12)
    hessian = atoms.calc.get_hessian(atoms)
    assert np.allclose(hessian, atoms.calc.get_spring_hessian(atoms).toarray())
    stiffness = atoms.calc.get_stiffness(atoms)
    assert np.allclose(stiffness, [hessian[3 * m:3 * m + 3, 3 * m:3 * m + 3]
                                   for m in range(4)])


@pytest.mark.parametrize('seed', [0, 1])
def test_reactions_balance_loads_with_repulsion(seed):
    atoms, w, Q, q, P = hanging_truss(seed, a=0.05)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-11, steps=300)
    result = form_result(atoms)
    # loads, springs and repulsion: the reactions balance the loads all the same
    assert np.allclose(result.reaction_sum, [0, 0, 2 * P], rtol=0, atol=1e-9 * 2 * P)
    # and the repulsion carries what the members and loads leave out of balance
    assert result.max_out_of_balance > 1e3 * result.max_residual


def test_forces_against_compas_fd_on_a_sample_net():
    atoms = read_net(compas.get('faces.obj'), fixed='boundary', dim=3)
    rng = np.random.default_rng(4)
    springs, start = atoms.calc.springs, atoms.positions.copy()
    edge = np.linalg.norm(start[springs[:, 0]] - start[springs[:, 1]], axis=1).mean()
    q = rng.uniform(0.5, 2.0, len(springs))
    fixed = np.flatnonzero([i in atoms.constraints[0].index for i in range(len(atoms))])
    loads = np.zeros_like(start)
    free = np.setdiff1d(np.arange(len(atoms)), fixed)
    loads[free] = rng.normal(0.0, 0.3 * edge, (len(free), 3))
    atoms.calc.set(a=1e-4 * edge, q=q, loads=loads)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-11 * edge, steps=200)
    peer = fd_numpy(vertices=start.tolist(), fixed=fixed.tolist(), edges=springs.tolist(),
                    forcedensities=q.tolist(), loads=loads.tolist())
    result = form_result(atoms)
    scale = np.abs(peer.forces).max()
    assert np.allclose(result.forces, np.ravel(peer.forces), rtol=0, atol=1e-8 * scale)
    assert np.allclose(result.lengths, np.ravel(peer.lengths), rtol=1e-8)
    # compas_fd's residual at a fixed point is the force on it: minus the reaction
    assert np.allclose(result.reactions, -np.asarray(peer.residuals)[fixed], rtol=0,
                       atol=1e-8 * scale)
    assert np.allclose(result.reaction_sum, -loads.sum(axis=0), rtol=0,
                       atol=1e-9 * np.abs(loads).sum())
    assert result.repulsion_share < 1e-6
    # the solve gives the same net at a = 0
    atoms.calc.set(a=0.0)
    atoms.positions = start
    solve_force_density(atoms)
    assert np.abs(atoms.positions - np.asarray(peer.vertices)).max() < 1e-10 * edge


def test_force_density_solve_refuses_an_unsupported_component():
    atoms = Atoms(positions=np.arange(12.0).reshape(4, 3))
    atoms.set_constraint(FixAtoms([0]))
    atoms.calc = MaudCalculator(springs=[[0, 1], [2, 3]], a=0)
    with pytest.raises(ValueError, match='point 2 is on a spring component with no support'):
        solve_force_density(atoms)


def test_forces_csv(tmp_path):
    atoms, *_ = hanging_truss(5)
    solve_force_density(atoms)
    result = form_result(atoms)
    path = write_forces_csv(tmp_path / 'forces.csv', result)
    with open(path, newline='') as f:
        rows = list(csv.DictReader(f))
    members = [r for r in rows if r['kind'] == 'member']
    reactions = [r for r in rows if r['kind'] == 'reaction']
    assert [[int(r['i']), int(r['j'])] for r in members] == result.edges.tolist()
    assert [float(r['force']) for r in members] == result.forces.tolist()
    assert [float(r['force_density']) for r in members] == result.force_densities.tolist()
    assert [int(r['i']) for r in reactions] == [0, 1]
    assert np.array_equal([[float(r[k]) for k in ('rx', 'ry', 'rz')] for r in reactions],
                          result.reactions)


def test_form_result_needs_a_maud_calculator():
    atoms = Atoms('H2', positions=[[0, 0, 0], [1, 0, 0]])
    with pytest.raises(ValueError, match='MaudCalculator'):
        form_result(atoms)


def test_relax_writes_forces_and_compas_reads_them_back(tmp_path, capsys):
    """relax --forces --out net.json on a compas sample with a load: the CSV
    and the JSON (read by compas's own Graph) hold the forces and reactions
    of form_result, the supports as is_anchor; the summary gives them."""
    from compas.datastructures import Graph

    source = compas.get('faces.obj')
    csv_path, out = tmp_path / 'forces.csv', tmp_path / 'net.json'
    assert main(['relax', source, '--fix', 'boundary', '--load', '0', '0', '-0.25',
                 '--quiet', '--traj', str(tmp_path / 'r.traj'), '--forces', str(csv_path),
                 '--out', str(out)]) == 0
    summary = capsys.readouterr().out
    relaxed = read_net(tmp_path / 'r.traj')
    result = form_result(relaxed)
    assert relaxed.calc.parameters['a'] == 0.0 and 'a 0 (the force-density' in summary
    assert f'largest member force {result.max_force:.4g}' in summary
    free = len(relaxed) - len(result.supports)
    assert np.allclose(result.reaction_sum, [0, 0, 0.25 * free], rtol=0, atol=1e-9 * free)
    graph = Graph.from_json(out)
    assert sorted(graph.nodes_where(is_anchor=True)) == result.supports.tolist()
    for (i, j), force, length in zip(result.edges.tolist(), result.forces, result.lengths,
                                     strict=True):
        edge = (i, j) if graph.has_edge((i, j)) else (j, i)
        assert graph.edge_attribute(edge, 'force') == pytest.approx(force, rel=1e-12)
        assert graph.edge_attribute(edge, 'length') == pytest.approx(length, rel=1e-12)
        assert graph.edge_attribute(edge, 'q') == 1.0
    for n, reaction in zip(result.supports.tolist(), result.reactions, strict=True):
        assert np.allclose(graph.node_attributes(n, ['rx', 'ry', 'rz']), reaction,
                           rtol=1e-12, atol=1e-12)
    with open(csv_path, newline='') as f:
        rows = list(csv.DictReader(f))
    assert sum(r['kind'] == 'member' for r in rows) == len(result.edges)
    # read back: the supports survive, and the next relaxation has nothing to do
    again = read_net(out)
    assert np.flatnonzero([i in again.constraints[0].index for i in range(len(again))]
                          ).tolist() == result.supports.tolist()
    assert np.abs(again.positions - relaxed.positions).max() == 0


def test_relax_refuses_forces_over_an_input_or_output(tmp_path, capsys):
    source = tmp_path / 'net.obj'
    atoms, *_ = hanging_truss(0)
    write_net(source, atoms)
    text = source.read_text()
    for argv, message in (
            (['--forces', str(source)], "--forces '" + str(source) + "' is the file NET_FILE"),
            (['--forces', str(tmp_path / 'o.json'), '--out', str(tmp_path / 'o.json')],
             'are one file')):
        assert main(['relax', str(source), '--quiet', '--traj', str(tmp_path / 'r.traj'),
                     *argv]) == 2
        assert message in capsys.readouterr().err
    assert source.read_text() == text


def test_relax_warns_of_a_net_without_supports(tmp_path, capsys):
    """A quad net with no supports shrinks under its springs: said, naming
    --fix; with its boundary fixed, nothing is said."""
    from helpers import write_quad_net

    source, *_ = write_quad_net(tmp_path, 'obj', n=5, seed=int(np.random.default_rng().
                                                                 integers(100)))
    traj = str(tmp_path / 'r.traj')
    assert main(['relax', str(source), '--quiet', '--traj', traj]) == 0
    err = capsys.readouterr().err
    assert 'warning: the net has no supports' in err and '--fix' in err
    assert main(['relax', str(source), '--quiet', '--traj', traj, '--fix', 'boundary']) == 0
    assert 'warning' not in capsys.readouterr().err


def test_relax_takes_loads_and_force_densities_from_csv(tmp_path, capsys):
    """--loads and --q give the net the force-density solution of those
    loads and q (compas_fd's); bad rows are named by file and line."""
    source = compas.get('faces.obj')
    atoms = read_net(source, fixed='boundary', dim=3)
    springs, start = atoms.calc.springs, atoms.positions.copy()
    fixed = atoms.constraints[0].index
    rng = np.random.default_rng()
    q = np.ones(len(springs))
    chosen = rng.choice(len(springs), 10, replace=False)
    q[chosen] = rng.uniform(0.5, 3.0, 10)
    loads = np.zeros_like(start)
    loaded = rng.choice(np.setdiff1d(np.arange(len(atoms)), fixed), 5, replace=False)
    loads[loaded] = rng.normal(size=(5, 3))
    q_csv, loads_csv = tmp_path / 'q.csv', tmp_path / 'loads.csv'
    q_csv.write_text('i,j,q\n' + ''.join(f'{springs[s][1]},{springs[s][0]},{float(q[s])!r}\n'
                                         for s in chosen.tolist()))
    loads_csv.write_text('i,px,py,pz\n' + ''.join(
        f'{n},{x!r},{y!r},{z!r}\n'
        for n, (x, y, z) in zip(loaded.tolist(), loads[loaded].tolist(), strict=True)))
    traj = tmp_path / 'r.traj'
    assert main(['relax', source, '--fix', 'boundary', '--dim', '3', '--loads', str(loads_csv),
                 '--q', str(q_csv), '--quiet', '--traj', str(traj)]) == 0
    peer = fd_numpy(vertices=start.tolist(), fixed=list(fixed), edges=springs.tolist(),
                    forcedensities=q.tolist(), loads=loads.tolist())
    assert np.abs(read_net(traj).positions - np.asarray(peer.vertices)).max() < 1e-10
    for name, text, message in (
            ('q.csv', 'i,j,q\n0,35,1\n', r'q\.csv line 2: points 0 and 35 are tied by no spring'),
            ('q.csv', 'i,j,q\n0,1,0\n', r'q\.csv line 2: q must be a finite nonzero'),
            ('q.csv', 'i,j,q\n0,1,x\n', r"q\.csv line 2: q must be a number, got 'x'"),
            ('loads.csv', 'i,px,py\n', r'loads\.csv line 1: expected the header i,px,py,pz'),
            ('loads.csv', 'i,px,py,pz\n36,0,0,1\n', r'loads\.csv line 2: point index .36. is '
             r'not a whole number in 0\.\.35'),
            ('loads.csv', 'i,px,py,pz\n3,0,0,1\n3,0,0,1\n', r'point 3 is loaded on line 2')):
        (tmp_path / name).write_text(text)
        option = '--q' if name == 'q.csv' else '--loads'
        assert main(['relax', source, '--quiet', '--traj', str(traj), option,
                     str(tmp_path / name)]) == 2
        assert re.search(message, capsys.readouterr().err)


def test_a_net_hanging_below_its_supports_is_no_reason_to_warn(tmp_path, capsys):
    """The canopy hangs far below its rim under a load: at a small a nothing
    is said (the loads hang it there); at a = 1 the repulsion moves it and
    that is said."""

    from ase_maud.physics.topology import support_excursion

    canopy = ROOT / 'examples' / 'nets' / 'canopy.obj'
    traj = str(tmp_path / 'r.traj')
    weight = np.random.default_rng().uniform(0.4, 0.6)
    for a, warned in (('0.05', False), ('1', True)):
        assert main(['relax', str(canopy), '--fix', 'outer', '--load', '0', '0',
                     str(-weight), '--a', a, '--quiet', '--traj', traj]) == 0
        err = capsys.readouterr().err
        beyond, diagonal = support_excursion(read_net(traj))
        assert beyond > diagonal / 10
        assert ('warning: the repulsion of a = ' in err) == warned


@pytest.mark.parametrize('name, rule', [('hypar.obj', 'boundary'),
                                        ('tubemesh.json', 'boundary'),
                                        ('lines_big.obj', 'leaves')])
def test_the_default_form_of_a_sample_net_is_compas_fd_s(tmp_path, name, rule):
    """relax NET --fix RULE --load ..., no --a: compas_fd's solution of the
    same net within 1e-9 of its diagonal, in one force call; the reactions
    balance the loads within 1e-9 of their sum."""
    path = compas.get(name)
    start = read_net(path, fixed=rule)
    load = np.random.default_rng().uniform(-0.3, -0.05)
    traj = tmp_path / 'r.traj'
    assert main(['relax', path, '--fix', rule, '--load', '0', '0', str(load), '--quiet',
                 '--traj', str(traj)]) == 0
    relaxed = read_net(traj)
    fixed = start.constraints[0].index.tolist()
    loads = np.where(np.isin(np.arange(len(start)), fixed)[:, None], 0.0, [0.0, 0.0, load])
    peer = fd_numpy(vertices=start.positions.tolist(), fixed=fixed,
                    edges=start.calc.springs.tolist(),
                    forcedensities=[1.0] * len(start.calc.springs), loads=loads.tolist())
    diagonal = np.linalg.norm(np.ptp(np.asarray(peer.vertices), axis=0))
    assert np.abs(relaxed.positions - np.asarray(peer.vertices)).max() < 1e-9 * diagonal
    result = form_result(relaxed)
    assert np.allclose(result.reaction_sum, -loads.sum(axis=0), rtol=0,
                       atol=1e-9 * np.abs(loads).sum())
