"""Meshes through meshio (ase_maud.io.mesh): PLY, STL, OFF, VTK, VTU
read back as the net they were written from; --fix outer."""

import meshio
import numpy as np
import pytest
from scipy.spatial import cKDTree

from ase_maud.cli.command import main
from ase_maud.io.nets import read_net
from ase_maud.physics.topology import boundary_vertices, outer_rim

SUFFIXES = ('.ply', '.stl', '.off', '.vtk', '.vtu')


def grid_with_hole(n=7, hole=True, seed=0):
    """An n x n grid of points (spacing 1, random heights) triangulated,
    without the two triangles of the middle square if ``hole``: (points,
    triangles, the indices of the outer rim, of the hole's rim)."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(n), np.arange(n), indexing='ij')
    points = np.column_stack([x.ravel(), y.ravel(), rng.uniform(-0.2, 0.2, n * n)])
    index = np.arange(n * n).reshape(n, n)
    c = n // 2
    triangles = []
    for i in range(n - 1):
        for j in range(n - 1):
            if hole and i == j == c:
                continue
            a, b, c, d = index[i, j], index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]
            triangles += [[a, b, c], [a, c, d]]
    outer = np.flatnonzero((x.ravel() % (n - 1) == 0) | (y.ravel() % (n - 1) == 0))
    ring = np.isin(x, [c, c + 1]) & np.isin(y, [c, c + 1])
    return points, np.array(triangles), outer, np.flatnonzero(ring.ravel())


def edges_of(triangles):
    return {tuple(sorted(pair)) for t in triangles.tolist()
            for pair in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}


@pytest.mark.parametrize('suffix', SUFFIXES)
def test_meshes_read_back(tmp_path, suffix):
    seed = int(np.random.default_rng().integers(1000))
    points, triangles, *_ = grid_with_hole(seed=seed)
    path = tmp_path / f'net{suffix}'
    meshio.write_points_cells(path, points, [('triangle', triangles)],
                              **({'binary': False} if suffix in ('.ply', '.stl') else {}))
    atoms = read_net(path)
    # STL keeps no point list (and float32): its points come back merged,
    # in another order
    assert len(atoms) == len(points)
    distance, to_read = cKDTree(atoms.positions).query(points)
    assert distance.max() < 1e-6 and len(set(to_read.tolist())) == len(points)
    assert {tuple(sorted(s)) for s in atoms.calc.springs.tolist()} == \
        {tuple(sorted(to_read[list(e)].tolist())) for e in edges_of(triangles)}


def test_a_mesh_of_volume_cells_is_refused(tmp_path):
    path = tmp_path / 'tet.vtk'
    meshio.write_points_cells(path, np.eye(4, 3), [('tetra', [[0, 1, 2, 3]])])
    with pytest.raises(ValueError, match=r"tet\.vtk: cells of type 'tetra'"):
        read_net(path)


def test_an_unknown_file_names_the_formats_read(tmp_path):
    path = tmp_path / 'net.abc'
    path.write_text('nothing\n')
    with pytest.raises(ValueError, match=r'net\.abc: ASE cannot read it .*; a net is read '
                       r'from OBJ \(\.obj\).*\.ply, \.stl, \.off, \.vtk'):
        read_net(path)


def test_outer_rim_leaves_the_hole_free(tmp_path):
    points, triangles, outer, hole = grid_with_hole(seed=3)
    assert outer_rim(triangles, points).tolist() == outer.tolist()
    assert boundary_vertices(triangles).tolist() == sorted(outer.tolist() + hole.tolist())
    path = tmp_path / 'holed.off'
    meshio.write_points_cells(path, points, [('triangle', triangles)])
    atoms = read_net(path, fixed='outer')
    assert atoms.constraints[0].index.tolist() == outer.tolist()
    traj = tmp_path / 'r.traj'
    assert main(['relax', str(path), '--fix', 'outer', '--load', '0', '0', '-1',
                 '--quiet', '--traj', str(traj)]) == 0
    relaxed = read_net(traj)
    assert np.array_equal(relaxed.positions[outer], points[outer])
    assert (relaxed.positions[hole, 2] < points[hole, 2] - 0.5).all()   # the hole's rim hangs


def test_a_triangle_mesh_is_written_as_stl_with_its_faces(tmp_path, capsys):
    points, triangles, *_ = grid_with_hole(hole=False)
    path = tmp_path / 'net.ply'
    meshio.write_points_cells(path, points, [('triangle', triangles.astype(np.int32))])
    assert main(['relax', str(path), '--quiet', '--out', str(tmp_path / 'out.stl')]) == 0
    assert len(meshio.read(tmp_path / 'out.stl').cells_dict['triangle']) == len(triangles)
