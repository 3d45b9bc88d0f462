"""Meshes in, meshes out: every meshio format written back with its faces
and lines, OBJ faces kept from any input, and the fast readers equal to the
statement-by-statement ones."""

import meshio
import numpy as np
import pytest
from scipy.spatial import cKDTree

from ase_maud.cli.command import main
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_net
from ase_maud.io.obj import _any_obj_file, _plain_obj_file
from ase_maud.physics.topology import boundary_edges, boundary_vertices, unique_pairs

fd_numpy = pytest.importorskip('compas_fd.solvers').fd_numpy


def grid_cells(n, rng, triangles_only=False, quads_only=False):
    """An n x n grid on a random hump: quads, a random half of them split
    into triangles (all of them: ``triangles_only``; none: ``quads_only``)."""
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing='ij')
    points = np.c_[x.ravel(), y.ravel(), rng.normal(0, 0.2, n * n)]
    index = np.arange(n * n).reshape(n, n)
    quads = np.c_[index[:-1, :-1].ravel(), index[1:, :-1].ravel(),
                  index[1:, 1:].ravel(), index[:-1, 1:].ravel()]
    split = (np.ones(len(quads), bool) if triangles_only else np.zeros(len(quads), bool)
             if quads_only else rng.random(len(quads)) < 0.5)
    triangles = np.r_[quads[split][:, [0, 1, 2]], quads[split][:, [0, 2, 3]]]
    return points, triangles, quads[~split]


def springs_set(springs):
    return {tuple(sorted(pair)) for pair in np.asarray(springs).tolist()}


def faces_set(faces):
    return {tuple(sorted(face)) for face in (np.asarray(f).tolist() for f in faces)}


@pytest.mark.parametrize('suffix', ['ply', 'vtk', 'vtu', 'obj'])
@pytest.mark.parametrize('seed', [0, 1])
def test_a_mesh_is_written_back_with_its_faces_and_lines(tmp_path, suffix, seed):
    rng = np.random.default_rng(seed)
    points, triangles, quads = grid_cells(6, rng)
    extra = np.c_[rng.choice(36, 3, replace=False), 36 + np.arange(3)]   # lines to new points
    points = np.r_[points, rng.normal(0, 3, (3, 3))]
    source = tmp_path / 'in.vtu'
    meshio.write(source, meshio.Mesh(points, [('triangle', triangles), ('quad', quads),
                                              ('line', extra)]))
    atoms = read_net(source, fixed='boundary', a=0.0)
    atoms.positions[:, 2] += rng.normal(0, 0.1, len(atoms))   # it moved
    out = tmp_path / f'out.{suffix}'
    write_net(out, atoms)
    back = read_net(out)
    assert np.array_equal(back.positions, atoms.positions)
    assert springs_set(back.calc.springs) == springs_set(atoms.calc.springs)
    assert faces_set(back.info['faces']) == faces_set(atoms.info['faces'])


@pytest.mark.parametrize('suffix', ['stl', 'off'])
def test_triangle_formats_take_triangles_and_refuse_quads_in_words(tmp_path, suffix):
    rng = np.random.default_rng(5)
    points, triangles, _ = grid_cells(5, rng, triangles_only=True)
    meshio.write(tmp_path / 'tri.ply', meshio.Mesh(points, [('triangle', triangles)]))
    atoms = read_net(tmp_path / 'tri.ply')
    write_net(tmp_path / f'out.{suffix}', atoms)
    back = read_net(tmp_path / f'out.{suffix}')
    # STL stores each triangle's corners anew (float32): points come back merged, in
    # the order of the triangles' corners
    distance, ours = cKDTree(atoms.positions).query(back.positions)
    assert distance.max() < 1e-6 and len(set(ours.tolist())) == len(atoms)
    assert faces_set(ours[np.asarray(back.info['faces'])]) == faces_set(atoms.info['faces'])
    points, triangles, quads = grid_cells(5, rng)
    meshio.write(tmp_path / 'mixed.ply', meshio.Mesh(points, [('triangle', triangles),
                                                              ('quad', quads)]))
    with pytest.raises(ValueError, match='triangles only.*quad'):
        write_net(tmp_path / f'bad.{suffix}', read_net(tmp_path / 'mixed.ply'))


def test_ply_in_ply_out_in_one_command_equals_compas_fd(tmp_path, capsys):
    """A compression gridshell: a PLY grid, boundary fixed, self-weight,
    q = -1, a = 0; written as PLY with its quads."""
    rng = np.random.default_rng(11)
    points, _, quads = grid_cells(9, rng, quads_only=True)
    points[:, 2] = 0.0
    source, out = tmp_path / 'grid.ply', tmp_path / 'shell.ply'
    meshio.write(source, meshio.Mesh(points, [('quad', quads.astype(np.int32))]))
    start = read_net(source, fixed='boundary')
    assert main(['relax', str(source), '--fix', 'boundary', '--load', '0', '0', '-0.1',
                 '--q', '-1', '--a', '0', '--quiet', '--traj', str(tmp_path / 'r.traj'),
                 '--out', str(out)]) == 0
    assert '(compression)' in capsys.readouterr().out
    mesh = meshio.read(out)
    assert len(mesh.cells_dict['quad']) == len(quads)
    fixed = boundary_vertices(quads)
    springs = start.calc.springs
    loads = np.zeros((len(points), 3))
    loads[np.setdiff1d(np.arange(len(points)), fixed), 2] = -0.1
    peer = np.asarray(fd_numpy(vertices=start.positions.tolist(), fixed=fixed.tolist(),
                               edges=springs.tolist(), forcedensities=[-1.0] * len(springs),
                               loads=loads.tolist()).vertices)
    diagonal = np.linalg.norm(np.ptp(peer, axis=0))
    assert np.abs(read_net(out).positions - peer).max() <= 1e-9 * diagonal
    assert peer[:, 2].max() > 0.1   # the shell stands up


def random_obj_text(rng):
    """An OBJ file with comments, vt, groups, faces of 3 to 5 corners given
    as v, v/vt or v//vn, positive and negative indices, and polylines."""
    lines, count = ['# a random net', 'o net'], 0
    for _ in range(rng.integers(20, 40)):
        if count < 6 or rng.random() < 0.5:
            lines.append(f'v {" ".join(f"{x:.6f}" for x in rng.normal(size=3))}'
                         + ('  # a point' if rng.random() < 0.1 else ''))
            count += 1
            if rng.random() < 0.2:
                lines.append('vt 0.5 0.5')
            continue
        size = rng.integers(2, 6)
        corners = rng.choice(count, size, replace=False) + 1
        tokens = [str(c) if rng.random() < 0.5 else str(c - count - 1) for c in corners]
        tokens = [t + rng.choice(['', '/1', '//1']) for t in tokens]
        lines.append(('l ' if size == 2 or rng.random() < 0.2 else 'f ') + ' '.join(tokens))
        if rng.random() < 0.1:
            lines.append('g part')
    return '\n'.join(lines) + '\n'


@pytest.mark.parametrize('seed', range(8))
def test_the_fast_obj_reader_equals_the_statement_by_statement_one(tmp_path, seed):
    path = tmp_path / 'net.obj'
    path.write_text(random_obj_text(np.random.default_rng(seed)))
    fast, slow = _plain_obj_file(path), _any_obj_file(path)
    assert fast is not None
    assert np.array_equal(fast[0].positions, slow[0].positions)
    assert np.array_equal(fast[0].springs, slow[0].springs)   # the same order too
    assert [list(f) for f in fast[0].faces] == [list(f) for f in slow[0].faces]
    assert np.array_equal(fast[1], slow[1]) and fast[2] == slow[2]


@pytest.mark.parametrize('text', ['v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n',
                                  'v 0 0 0\nv 1 0 0\nf 1 2 3\n',
                                  'v 0 0 0\nv 1 0 0\nv 0 1 0\ncstype bspline\nf 1 2 3\n'])
def test_the_fast_obj_reader_leaves_anything_odd_to_the_careful_one(tmp_path, text):
    path = tmp_path / 'odd.obj'
    path.write_text(text)
    assert _plain_obj_file(path) is None


@pytest.mark.parametrize('seed', range(4))
def test_boundary_and_unique_pairs_equal_the_plain_definitions(seed):
    rng = np.random.default_rng(seed)
    points, triangles, quads = grid_cells(int(rng.integers(3, 9)), rng)
    faces = triangles.tolist() + quads.tolist()
    count = {}
    for face in faces:
        for i, j in zip(face, face[1:] + face[:1], strict=True):
            count[min(i, j), max(i, j)] = count.get((min(i, j), max(i, j)), 0) + 1
    once = sorted(edge for edge, k in count.items() if k == 1)
    assert boundary_edges(faces).tolist() == [list(e) for e in once]
    assert boundary_vertices(faces).tolist() == sorted({i for e in once for i in e})
    pairs = rng.integers(0, 7, (50, 2))
    inverse, first, k = unique_pairs(pairs)
    rows, first_np, inverse_np, k_np = np.unique(np.sort(pairs, axis=1), axis=0,
                                                 return_index=True, return_inverse=True,
                                                 return_counts=True)
    assert np.array_equal(first, first_np) and np.array_equal(k, k_np)
    assert np.array_equal(inverse, inverse_np.ravel())
