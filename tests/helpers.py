"""Helpers shared by the tests (importable from every test folder: pyproject's
``pythonpath = ["tests"]``): random points and scenes, quad nets written as the
net files ``ase_maud.io`` reads with the energy Python relaxes them to, relaxed
trap clusters, BFGS's reference minimum, the command's one-line errors, and a
script of the checkout run as ``__main__``.

No test imports another test file; what two test files share lives here (data
tables and calculators that scripts share too live in ``ase_maud.bench``).
"""

import functools
import json
import runpy
import sys
from pathlib import Path

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian
from ase.optimize import BFGS

from ase_maud import Maud, MaudCalculator
from ase_maud.analysis.stationary import classify
from ase_maud.cli.command import main
from ase_maud.io.nets import edges_path
from ase_maud.physics.topology import A_PER_MEAN_SPRING
from ase_maud.scenes.catalogue import build

#: The checkout: examples/, benchmarks/ and dev/ beside tests/.
ROOT = Path(__file__).resolve().parent.parent


def random_points(n, dim=3, seed=0, spacing=1.0):
    """``n`` random points, shape (n, 3), about ``spacing`` apart.

    The points are a random subset of a grid twice as large, each moved by up
    to ``0.3 * spacing`` per axis, so no two are closer than ``0.4 * spacing``
    and finite differences stay well conditioned. ``dim=2`` puts every point
    on the plane ``z = 0``.
    """
    rng = np.random.default_rng(seed)
    side = int(np.ceil((2 * n) ** (1.0 / dim)))
    grid = np.stack(np.meshgrid(*[np.arange(side)] * dim), -1).reshape(-1, dim)
    points = np.zeros((n, 3))
    points[:, :dim] = rng.permutation(grid)[:n]
    points[:, :dim] += rng.uniform(-0.3, 0.3, size=(n, dim))
    return spacing * points


def quad_net(n=5, seed=0, flat=False):
    """A quad mesh of n x n points, spacing 1, the boundary fixed on the
    saddle z = (x^2 - y^2) / n (on z = 0 if ``flat``), the interior jittered
    by up to 0.3 per coordinate (in the plane if ``flat``).

    Returns positions (n*n, 3), the quads (lists of 4 indices), the springs
    (the quads' edges, sorted pairs) and the boundary's indices."""
    rng = np.random.default_rng(seed)
    c = np.arange(n) - (n - 1) / 2
    x, y = np.meshgrid(c, c, indexing='ij')
    positions = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])
    idx = np.arange(n * n).reshape(n, n)
    boundary = np.zeros((n, n), dtype=bool)
    boundary[[0, -1], :] = boundary[:, [0, -1]] = True
    boundary = boundary.ravel()
    if not flat:
        positions[boundary, 2] = (positions[boundary, 0]**2 - positions[boundary, 1]**2) / n
    axes = 2 if flat else 3
    positions[~boundary, :axes] += rng.uniform(-0.3, 0.3, ((~boundary).sum(), axes))
    quads = [[idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]]
             for i in range(n - 1) for j in range(n - 1)]
    springs = {tuple(sorted((int(q[k]), int(q[(k + 1) % 4])))) for q in quads for k in range(4)}
    return positions, quads, sorted(springs), np.flatnonzero(boundary)


def write_quad_net(folder, kind, n=5, seed=0, flat=False):
    """Write :func:`quad_net` as ``folder/net.<kind>`` (OBJ with quad faces, a
    COMPAS 2.x or 1.x mesh, a COMPAS 1.x network, or XYZ plus
    ``net.edges.txt``) and ``folder/fixed.txt``; return the net file, the
    positions, springs and fixed indices."""
    positions, quads, springs, fixed = quad_net(n, seed, flat)
    path = folder / f'net.{kind}'
    xyz = [dict(zip('xyz', map(float, p), strict=True)) for p in positions]
    if kind == 'obj':
        lines = ['# quad mesh', 'o net']
        lines += [f'v {x!r} {y!r} {z!r}' for x, y, z in positions.tolist()]
        lines += ['vn 0 0 1']
        lines += ['f ' + ' '.join(f'{i + 1}//1' for i in q) for q in quads]
        path.write_text('\n'.join(lines) + '\n')
    elif kind == 'mesh2.json':
        data = {'attributes': {'name': 'net'},
                'default_vertex_attributes': {'x': 0.0, 'y': 0.0, 'z': 0.0},
                'default_edge_attributes': {}, 'default_face_attributes': {},
                'vertex': {str(i): p for i, p in enumerate(xyz)},
                'face': {str(f): [int(i) for i in q] for f, q in enumerate(quads)},
                'facedata': {}, 'edgedata': {}, 'max_vertex': len(xyz) - 1,
                'max_face': len(quads) - 1}
        path.write_text(json.dumps({'dtype': 'compas.datastructures/Mesh', 'data': data,
                                    'guid': '00000000-0000-0000-0000-000000000000'}))
    elif kind == 'mesh1.json':
        data = {'attributes': {'name': 'net'}, 'dva': {'x': 0.0, 'y': 0.0, 'z': 0.0},
                'dea': {}, 'dfa': {}, 'vertex': {str(i): p for i, p in enumerate(xyz)},
                'face': {str(f): [int(i) for i in q] for f, q in enumerate(quads)},
                'facedata': {}, 'edgedata': {}, 'max_vertex': len(xyz) - 1,
                'max_face': len(quads) - 1}
        path.write_text(json.dumps({'dtype': 'compas.datastructures/Mesh', 'value': data}))
    elif kind == 'network1.json':
        edge = {str(i): {} for i in range(len(xyz))}
        for i, j in springs:
            edge[str(i)][str(j)] = {}
        data = {'attributes': {'name': 'net'}, 'dna': {'x': 0.0, 'y': 0.0, 'z': 0.0},
                'dea': {}, 'node': {str(i): p for i, p in enumerate(xyz)}, 'edge': edge,
                'adjacency': {}, 'max_node': len(xyz) - 1}
        path.write_text(json.dumps(data))
    else:
        path.write_text(f'{len(positions)}\nProperties=species:S:1:pos:R:3\n' + ''.join(
            f'X {x!r} {y!r} {z!r}\n' for x, y, z in positions.tolist()))
        edges_path(path).write_text('# i j\n' + ''.join(f'{i} {j}\n' for i, j in springs))
    (folder / 'fixed.txt').write_text('# the boundary\n' + '\n'.join(map(str, fixed)) + '\n')
    return path, positions, springs, fixed


def rule_a(positions, springs, supported=True):
    """The a that a net read from a file gets: 0 (the force-density
    equilibrium) if its supports hold every spring component, else the
    rule's fraction of the mean length of its springs."""
    return 0.0 if supported else A_PER_MEAN_SPRING * np.mean(
        [np.linalg.norm(positions[i] - positions[j]) for i, j in springs])


def relaxed_in_python(positions, springs, fixed, dim=3, fmax=1e-6):
    """The net relaxed with Maud from Python, with the a of :func:`rule_a`:
    its energy."""
    from ase import Atoms

    atoms = Atoms(positions=positions, pbc=False)
    atoms.calc = MaudCalculator(springs, dim=dim, a=rule_a(positions, springs))
    atoms.set_constraint(FixAtoms(indices=fixed))
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=fmax, steps=500)
    return atoms.get_potential_energy()


def random_scene(seed, dim=3, n=None, a=1.0, fixed=True, weighted=False):
    """Random points with a random connected spring graph (a random tree plus
    extra edges), some atoms held by FixAtoms and one by FixCartesian;
    ``weighted``: random force densities ``q`` in [0.2, 3] and random loads."""
    rng = np.random.default_rng(seed)
    n = n or int(rng.integers(6, 25))
    positions = np.zeros((n, 3))
    positions[:, :dim] = rng.uniform(0, 2 * n ** (1 / dim), (n, dim))
    tree = [(int(rng.integers(0, k)), k) for k in range(1, n)]
    extra = {tuple(sorted(rng.choice(n, 2, replace=False))) for _ in range(n // 2)}
    springs = sorted(set(tree) | extra)
    atoms = Atoms(positions=positions)
    atoms.calc = MaudCalculator(springs, a=a, Q=float(rng.uniform(0.5, 2)), dim=dim)
    if weighted:
        atoms.calc.set(q=rng.uniform(0.2, 3.0, len(springs)),
                       loads=rng.normal(0.0, 0.5, (n, dim)))
    if fixed:  # three points held: no rigid-body zero modes are left
        held = rng.choice(n, 4, replace=False)
        atoms.set_constraint([FixAtoms(indices=held[:3]),
                              FixCartesian(int(held[3]), mask=[True, False, False])])
    return atoms


def trap_cluster(size, seed=0):
    """A 2D trap cluster (``all_pairs2d``) relaxed to a verified minimum."""
    atoms = build('all_pairs2d', size, seed=seed)
    Maud(atoms, logfile=None).run(fmax=1e-8, steps=5000)
    assert classify(atoms).verdict == 'minimum'
    return atoms


@functools.cache
def bfgs_reference(seed):
    """BFGS's minimum of ``hanging_net(4)`` at a = Q = 1: energy, sorted pair
    distances."""
    atoms = build('hanging_net', 4, seed=seed)
    with BFGS(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-10, steps=5000)
    return atoms.get_potential_energy(), np.sort(atoms.get_all_distances(), axis=None)


def one_line_error(capsys, argv, status=2):
    """Run ``ase-maud argv``: ``status`` and one line on stderr, returned."""
    assert main([str(a) for a in argv]) == status
    error = capsys.readouterr().err
    assert error.count('\n') == 1, error
    return error


def run_example(name, argv, monkeypatch, tmp_path, folder='examples'):
    """Run ``folder/name`` (a script of the checkout) as ``__main__`` with ``argv``, in
    ``tmp_path``."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, 'argv', [name, *argv])
    runpy.run_path(str(ROOT / folder / name), run_name='__main__')
