"""ase_maud.io: nets from OBJ, COMPAS JSON, trajectories and XYZ plus edge
lists, and back; malformed files are ValueErrors naming the line."""

import json
import os
import stat

import numpy as np
import pytest
from ase.constraints import FixAtoms

from ase_maud import Maud, MaudCalculator
from ase_maud.bench.hard_inputs import BROKEN
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import (
    MERGE_TOLERANCE,
    edges_path,
    merge_coincident,
    read_compas,
    read_edges,
    read_frames,
    read_net,
    read_obj,
)

from helpers import quad_net, rule_a, write_quad_net

FORMATS = ('obj', 'mesh2.json', 'mesh1.json', 'network1.json', 'xyz')


def pairs(springs):
    return sorted(tuple(sorted(map(int, p))) for p in springs)


@pytest.mark.parametrize('kind', FORMATS)
def test_read_gives_the_net_built_in_python(tmp_path, kind):
    path, positions, springs, fixed = write_quad_net(tmp_path, kind, seed=3)
    atoms = read_net(path, fixed=tmp_path / 'fixed.txt')
    np.testing.assert_array_equal(atoms.positions, positions)
    assert pairs(atoms.calc.springs) == springs
    assert atoms.calc.dim == 3 and not atoms.pbc.any()
    assert atoms.constraints[0].index.tolist() == fixed.tolist()
    assert atoms.calc.parameters['a'] == pytest.approx(rule_a(positions, springs), rel=1e-14)
    assert atoms.calc.parameters['Q'] == 1.0


def test_flat_net_is_2d_unless_told(tmp_path):
    path, *_ = write_quad_net(tmp_path, 'obj', flat=True)
    assert read_net(path).calc.dim == 2
    assert read_net(path, dim=3, a=0.5, Q=2.0).calc.parameters['a'] == 0.5
    assert read_net(path, dim=3).calc.dim == 3


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_flat_net_stays_on_its_plane_under_ase_optimizers(tmp_path, seed):
    # ASE's BFGS moves z by itself; read_net holds it for a 2D net
    from ase.optimize import BFGS
    path, _, _, fixed = write_quad_net(tmp_path, 'obj', flat=True, seed=seed)
    atoms, reference = read_net(path, fixed=fixed), read_net(path, fixed=fixed)
    z = atoms.positions[0, 2]
    with BFGS(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-7, steps=3000)
    assert (atoms.positions[:, 2] == z).all()
    with Maud(reference, logfile=None) as opt:
        assert opt.run(fmax=1e-7)
    assert atoms.get_potential_energy() == pytest.approx(
        reference.get_potential_energy(), rel=1e-9)


def test_obj_faces_and_polylines(tmp_path):
    """Each face edge once (shared edges too), polyline segments, v/vt/vn and
    negative indices, and coordinates beyond x y z ignored."""
    path = tmp_path / 'mixed.obj'
    path.write_text('v 0 0 0\nv 1 0 0 1.0\nv 1 1 0\nv 0 1 0\nvt 0 0\n'
                    'f 1/1 2/1 3/1\nf 1 3 -1\n'     # shares the edge 1-3
                    'v 2 0 0\nv 3 0 0\nl 2 -2 -1\n')  # 2-5, 5-6
    positions, springs, faces, anchors = read_obj(path)
    assert positions.shape == (6, 3) and positions[1].tolist() == [1, 0, 0]
    assert springs.tolist() == [[0, 1], [1, 2], [2, 0], [2, 3], [3, 0], [1, 4], [4, 5]]
    assert faces == [[0, 1, 2], [0, 2, 3]] and anchors == []


@pytest.mark.parametrize('kind', FORMATS)
def test_read_write_read_is_identical(tmp_path, kind):
    path, *_ = write_quad_net(tmp_path, kind, seed=1)
    atoms = read_net(path)
    rng = np.random.default_rng(2)
    atoms.positions += rng.normal(size=atoms.positions.shape)   # "relaxed"
    out = tmp_path / f'out.{kind}'
    written = write_net(out, atoms, like=path if kind != 'xyz' else None)
    again = read_net(out)
    np.testing.assert_array_equal(again.positions, atoms.positions)
    np.testing.assert_array_equal(again.calc.springs, atoms.calc.springs)
    if kind == 'obj':   # everything but the coordinates kept
        def rest(p):
            return [line for line in p.read_text().splitlines() if not line.startswith('v ')]
        assert rest(out) == rest(path)
    if kind == 'xyz':   # the fixed points too, as extended XYZ's move_mask
        assert written == [out, edges_path(out)]
        atoms.set_constraint(FixAtoms(indices=[0, 3]))
        write_net(out, atoms)
        assert read_net(out).constraints[0].index.tolist() == [0, 3]


@pytest.mark.parametrize('kind', ('obj', 'json'))
def test_fresh_files_keep_points_and_springs(tmp_path, kind):
    """Written without an original: OBJ with ``l`` springs, a COMPAS 2.x
    graph with the fixed points as anchors."""
    path, positions, springs, fixed = write_quad_net(tmp_path, 'obj', seed=4)
    atoms = read_net(path, fixed=fixed)
    out = tmp_path / f'fresh.{kind}'
    write_net(out, atoms)
    again = read_net(out)
    np.testing.assert_array_equal(again.positions, positions)
    assert pairs(again.calc.springs) == springs
    if kind == 'json':
        document = json.loads(out.read_text())
        assert document['dtype'] == 'compas.datastructures/Graph'
        assert again.constraints[0].index.tolist() == fixed.tolist()
        assert read_compas(out).anchors == fixed.tolist()


def test_trajectory_keeps_springs_a_q_dim_and_fixed(tmp_path):
    path, *_ = write_quad_net(tmp_path, 'obj', flat=True, seed=5)
    atoms = read_net(path, fixed=tmp_path / 'fixed.txt', a=0.7, Q=2.5)
    assert atoms.calc.dim == 2
    with Maud(atoms, logfile=None, trajectory=str(tmp_path / 'run.traj')) as opt:
        opt.run(fmax=1e-3, steps=3)
    frames = read_frames(tmp_path / 'run.traj')
    assert len(frames) == 4
    for frame in frames:
        p = frame.calc.parameters
        assert isinstance(frame.calc, MaudCalculator)
        np.testing.assert_array_equal(frame.calc.springs, atoms.calc.springs)
        assert (p['a'], p['Q'], p['dim']) == (0.7, 2.5, 2)
        assert frame.constraints[0].index.tolist() == atoms.constraints[0].index.tolist()
    np.testing.assert_array_equal(frames[-1].positions, atoms.positions)
    assert frames[-1].get_potential_energy() == pytest.approx(
        atoms.get_potential_energy(), rel=1e-14)
    first = read_net(tmp_path / 'run.traj', index=0, Q=1.0)   # an override
    assert first.calc.parameters['Q'] == 1.0 and first.calc.parameters['a'] == 0.7
    write_net(tmp_path / 'one.traj', atoms)
    assert read_net(tmp_path / 'one.traj').calc.parameters['Q'] == 2.5


@pytest.mark.parametrize('name, text, message', BROKEN)
def test_malformed_net_files_name_the_line(tmp_path, name, text, message):
    (tmp_path / name).write_text(text)
    with pytest.raises(ValueError, match=message):
        read_net(tmp_path / name)


def test_a_directory_is_not_a_net(tmp_path):
    (tmp_path / 'net.obj').mkdir()
    for path in (tmp_path / 'net.obj', tmp_path):
        with pytest.raises(ValueError, match=f'{path} is a directory, not a net file'):
            read_net(path)


@pytest.mark.parametrize('seed', [0, 1])
def test_a_byte_order_mark_is_skipped(tmp_path, seed):
    for kind in ('obj', 'mesh2.json'):
        net = write_quad_net(tmp_path, kind, seed=seed)[0]
        marked = tmp_path / f'bom.{kind}'
        marked.write_bytes(b'\xef\xbb\xbf' + net.read_bytes())
        plain, marked = read_net(net), read_net(marked)
        np.testing.assert_array_equal(marked.positions, plain.positions)
        np.testing.assert_array_equal(marked.calc.springs, plain.calc.springs)


@pytest.mark.parametrize('name', ['net.obj', 'net.json'])
def test_bytes_that_are_not_text_are_named(tmp_path, name):
    (tmp_path / name).write_bytes(b'v 0 0 0\nv 1 0 0\nv \xff\xfe 0 0\n')
    with pytest.raises(ValueError, match=r'net\.(obj|json).*not UTF-8 text'):
        read_net(tmp_path / name)


BROKEN_LISTS = [
    ('0 1\n1 2 3\n', r'edges\.txt line 2: expected two integer indices, got 3'),
    ('# pairs\n0 1\n1 x\n', r"edges\.txt line 3: expected two integer indices, got '1 x'"),
    ('0 1\n\n1 9\n', r'edges\.txt line 3: index 9 out of range \(3 points'),
    ('0 1\n1 1\n', r'edges\.txt line 2: spring ties point 1 to itself'),
    ('0 1\n1 2\n1 0  # again\n', r'edges\.txt line 3: spring \(0, 1\) repeats line 1'),
]


@pytest.mark.parametrize('text, message', BROKEN_LISTS)
def test_malformed_edge_lists_name_the_line(tmp_path, text, message):
    (tmp_path / 'p.xyz').write_text('3\n\nX 0 0 0\nX 1 0 0\nX 0 1 0\n')
    (tmp_path / 'edges.txt').write_text(text)
    with pytest.raises(ValueError, match=message):
        read_net(tmp_path / 'p.xyz', edges=tmp_path / 'edges.txt')
    with pytest.raises(ValueError, match=message):
        read_edges(tmp_path / 'edges.txt', 3)


def test_missing_springs_and_bad_fixed_points(tmp_path):
    (tmp_path / 'p.xyz').write_text('2\n\nX 0 0 0\nX 1 0 0\n')
    with pytest.raises(ValueError, match=r'p\.xyz holds no springs: give an edge list'):
        read_net(tmp_path / 'p.xyz')
    (tmp_path / 'p.edges.txt').write_text('0 1\n')
    (tmp_path / 'fixed.txt').write_text('0\n2\n')
    with pytest.raises(ValueError, match=r'fixed\.txt line 2: index 2 out of range'):
        read_net(tmp_path / 'p.xyz', fixed=tmp_path / 'fixed.txt')
    with pytest.raises(ValueError, match='fixed point 5 out of range'):
        read_net(tmp_path / 'p.xyz', fixed=[5])
    (tmp_path / 'points.obj').write_text('v 0 0 0\nv 1 0 0\n')   # no f, no l
    with pytest.raises(ValueError, match=r'points\.obj holds no springs'):
        read_net(tmp_path / 'points.obj')
    (tmp_path / 'q.xyz').write_text('2\n\nX 0 0 0\nX 1 0 zz\n')
    with pytest.raises(ValueError, match=r'q\.xyz: ASE cannot read it'):
        read_net(tmp_path / 'q.xyz')


def test_write_refuses_a_mismatched_original(tmp_path):
    path, *_ = write_quad_net(tmp_path, 'obj', n=4)
    atoms = read_net(path)
    with pytest.raises(ValueError, match='different formats'):
        write_net(tmp_path / 'out.json', atoms, like=path)
    short = atoms[:9]
    short.calc = atoms.calc
    with pytest.raises(ValueError, match=r'has 16 points \(16 vertices, coincident ones '
                       r'merged\), the net 9'):
        write_net(tmp_path / 'out.obj', short, like=path)


@pytest.mark.parametrize('kind', FORMATS)
def test_writing_over_the_file_read_keeps_it_whole(tmp_path, kind):
    # like= the output itself: it is read before anything is replaced
    path, *_ = write_quad_net(tmp_path, kind, seed=4)
    atoms = read_net(path)
    atoms.positions += np.random.default_rng(5).normal(size=atoms.positions.shape)
    write_net(path, atoms, like=path if kind != 'xyz' else None)
    again = read_net(path)
    np.testing.assert_array_equal(again.positions, atoms.positions)
    np.testing.assert_array_equal(again.calc.springs, atoms.calc.springs)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith('.')) == []


@pytest.mark.parametrize('kind', FORMATS)
def test_a_failed_write_leaves_the_old_file(tmp_path, kind, monkeypatch):
    path, *_ = write_quad_net(tmp_path, kind, seed=6)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    atoms = read_net(path)
    atoms.positions += 1.0

    def full_disk(*args, **kwargs):
        raise OSError(28, 'No space left on device')

    monkeypatch.setattr('ase_maud.files.atomic_replace.os.replace', full_disk)
    with pytest.raises(OSError, match='No space left'):
        write_net(path, atoms, like=path if kind != 'xyz' else None)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


@pytest.mark.parametrize('mode', [0o644, 0o600, 0o664])
@pytest.mark.parametrize('kind', FORMATS)
def test_writing_over_a_file_keeps_its_permissions(tmp_path, kind, mode):
    path, *_ = write_quad_net(tmp_path, kind, seed=mode % 7)
    os.chmod(path, mode)
    atoms = read_net(path)
    write_net(path, atoms, like=path if kind != 'xyz' else None)
    assert stat.S_IMODE(path.stat().st_mode) == mode
    fresh = tmp_path / f'new{path.suffix}'
    write_net(fresh, atoms, like=path if kind != 'xyz' else None)
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(fresh.stat().st_mode) == 0o666 & ~umask


@pytest.mark.parametrize('seed, fmax', [(0, 1e-2), (1, 3e-4), (2, 1e-5)])
def test_relaxed_fmax_is_the_one_the_run_was_given(tmp_path, seed, fmax):
    from ase.optimize import BFGS

    from ase_maud.io.nets import relaxed_fmax
    from ase_maud.scenes.catalogue import build
    for name, optimizer in (('maud', Maud), ('bfgs', BFGS)):
        atoms = build('ring', 8, seed=seed)
        with optimizer(atoms, trajectory=str(tmp_path / f'{name}.traj'), logfile=None) as opt:
            opt.run(fmax=fmax, steps=200)
        assert relaxed_fmax(tmp_path / f'{name}.traj') == fmax
    write_net(tmp_path / 'written.traj', atoms)   # no optimizer: nothing stored
    write_net(tmp_path / 'written.obj', atoms)
    assert relaxed_fmax(tmp_path / 'written.traj') is None
    assert relaxed_fmax(tmp_path / 'written.obj') is None


def compas_net(kind, seed):
    """A COMPAS mesh (compas's faces.obj) or a graph of its edges, with a
    random force density ``q`` on half the edges (the rest take the default,
    2.0) and a random load on a third of the vertices."""
    compas = pytest.importorskip('compas')
    from compas.datastructures import Graph, Mesh
    rng = np.random.default_rng(seed)
    mesh = Mesh.from_obj(compas.get('faces.obj'))
    net = mesh if kind == 'mesh' else Graph.from_nodes_and_edges(
        {v: mesh.vertex_coordinates(v) for v in mesh.vertices()}, list(mesh.edges()))
    net.update_default_edge_attributes(q=2.0)
    edges = list(net.edges())
    for k in rng.choice(len(edges), len(edges) // 2, replace=False):
        net.edge_attribute(edges[k], 'q', float(rng.uniform(0.2, 3.0)))
    points = list(net.vertices() if kind == 'mesh' else net.nodes())
    attributes = net.vertex_attributes if kind == 'mesh' else net.node_attributes
    for k in rng.choice(len(points), len(points) // 3, replace=False):
        attributes(points[k], ['px', 'py', 'pz'], rng.normal(size=3).tolist())
    return net, points


def compas_forces(net, points, springs):
    """``q`` of ``springs`` and the loads of ``points``, as compas reads them."""
    attribute = getattr(net, 'vertex_attribute', None) or net.node_attribute
    q = [net.edge_attribute((points[i], points[j]), 'q') if net.has_edge((points[i], points[j]))
         else net.edge_attribute((points[j], points[i]), 'q') for i, j in springs]
    loads = [[attribute(p, name) or 0.0 for name in ('px', 'py', 'pz')] for p in points]
    return np.array(q), np.array(loads)


def by_pair(springs, q):
    return {tuple(sorted(map(int, pair))): float(value) for pair, value in zip(springs, q,
                                                                               strict=True)}


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('kind', ['mesh', 'graph'])
def test_compas_force_densities_and_loads_round_trip(tmp_path, kind, seed):
    """Edge ``q`` and vertex ``px, py, pz`` written by compas are the
    calculator's ``q`` and ``loads``; changed, they are written back where
    compas reads them (like the file, and in a fresh graph), and a
    trajectory keeps them."""
    compas = pytest.importorskip('compas')
    net, points = compas_net(kind, seed)
    path = tmp_path / f'{kind}.json'
    net.to_json(str(path))
    atoms = read_net(path)
    q, loads = compas_forces(net, points, atoms.calc.springs)
    np.testing.assert_array_equal(atoms.calc.parameters['q'], q)
    np.testing.assert_array_equal(atoms.calc.parameters['loads'], loads)
    rng = np.random.default_rng(100 + seed)
    changed = rng.choice(len(q), 5, replace=False)
    q[changed] = rng.uniform(0.2, 3.0, 5)
    loads[rng.choice(len(loads), 4, replace=False)] = rng.normal(size=(4, 3))
    atoms.calc.set(q=q, loads=loads)
    for out, like in ((tmp_path / 'like.json', path), (tmp_path / 'fresh.json', None)):
        write_net(out, atoms, like=like)
        again = compas.json_load(str(out))   # a mesh like the file, or a graph
        keys = list(again.vertices() if hasattr(again, 'vertices') else again.nodes())
        np.testing.assert_array_equal(compas_forces(again, keys, atoms.calc.springs)[0], q)
        np.testing.assert_array_equal(compas_forces(again, keys, atoms.calc.springs)[1], loads)
        back = read_net(out)   # a fresh graph lists its edges in its own order
        assert by_pair(back.calc.springs, back.calc.parameters['q']) == by_pair(
            atoms.calc.springs, q)
        np.testing.assert_array_equal(back.calc.parameters['loads'], loads)
    write_net(tmp_path / 'net.traj', atoms)
    back = read_net(tmp_path / 'net.traj')
    np.testing.assert_array_equal(back.calc.parameters['q'], q)
    np.testing.assert_array_equal(back.calc.parameters['loads'], loads)
    np.testing.assert_array_equal(back.get_forces(), atoms.get_forces())


def test_a_compas_file_without_forces_leaves_the_defaults(tmp_path):
    path, *_ = write_quad_net(tmp_path, 'mesh2.json')
    atoms = read_net(path)
    assert atoms.calc.parameters['q'] is None and atoms.calc.parameters['loads'] is None
    write_net(tmp_path / 'out.json', atoms, like=path)
    data = json.loads((tmp_path / 'out.json').read_text())['data']
    assert data['edgedata'] == {} and not any('px' in v for v in data['vertex'].values())


@pytest.mark.parametrize('where, value, message', [
    ('edge', 0.0, "edge 0-1, attribute q: q must be a finite nonzero number"),
    ('edge', 'x', "edge 0-1, attribute q: q must be"),
    ('vertex', None, "vertex 3, attribute pz: loads must be a finite number"),
])
def test_bad_force_densities_and_loads_name_the_file_and_item(tmp_path, where, value, message):
    path, *_ = write_quad_net(tmp_path, 'network1.json')
    document = json.loads(path.read_text())
    if where == 'edge':
        document['edge']['0']['1'] = {'q': value}
    else:
        document['node']['3']['pz'] = value
    path.write_text(json.dumps(document))
    with pytest.raises(ValueError, match=f'{path.name}: {message}'):
        read_net(path)


def test_a_load_on_every_free_point(tmp_path):
    """``load=``: the same load on every point not fixed, none on the fixed
    ones; a flat net under a load out of its plane is 3D, under one in its
    plane still 2D."""
    path, _, _, fixed = write_quad_net(tmp_path, 'obj', flat=True)
    atoms = read_net(path, fixed=fixed, load=[0, 0, -0.5])
    loads = atoms.calc.parameters['loads']
    free = np.setdiff1d(np.arange(len(atoms)), fixed)
    assert atoms.calc.dim == 3
    assert (loads[free] == [0, 0, -0.5]).all() and not loads[fixed].any()
    assert read_net(path, fixed=fixed, load=[0.1, 0, 0]).calc.dim == 2
    with pytest.raises(ValueError, match='needs 3 numbers'):
        read_net(path, load=[0, 1])
    with pytest.raises(ValueError, match='loads of component 1 must be a finite number'):
        read_net(path, load=[0, np.nan, 1])


def rhino_lines(points, springs, jitter, seed):
    """A Rhino-style OBJ of a line network: every spring a curve of degree 1
    with its own copies of its two end vertices, each copy moved by up to
    ``jitter`` per coordinate."""
    rng = np.random.default_rng(seed)
    lines, count = ['# Rhino', ''], 0
    for i, j in springs:
        for k in (i, j):
            x, y, z = (points[k] + rng.uniform(-jitter, jitter, 3)).tolist()
            lines.append(f'v {x!r} {y!r} {z!r}')
        count += 2
        lines += ['cstype bspline', 'deg 1', f'curv 0 1 {count - 1} {count}',
                  'parm u 0 0 1 1', 'end']
    return '\r\n'.join(lines) + '\r\n'


def random_network(seed, n=30):
    """n points at a random scale (1e-3 to 1e3) and a random connected graph
    on them: a random tree plus a few chords."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-1, 1, (n, 3)) * 10.0 ** rng.uniform(-3, 3)
    springs = {(int(rng.integers(k)), k) for k in range(1, n)}
    while len(springs) < n + 5:
        i, j = sorted(rng.choice(n, 2, replace=False).tolist())
        springs.add((i, j))
    return points, list(springs)


@pytest.mark.parametrize('seed', range(4))
def test_rhino_curves_merge_into_one_graph(tmp_path, seed):
    """Copies closer than the tolerance (relative to the net's size) are one
    point, at the place of the first copy, in the order of first copies;
    copies ten times farther apart than the tolerance stay apart."""
    points, springs = random_network(seed)
    diagonal = np.linalg.norm(np.ptp(points, axis=0))
    near = tmp_path / 'near.obj'
    near.write_text(rhino_lines(points, springs, 0.2 * MERGE_TOLERANCE * diagonal, seed),
                    newline='')
    atoms = read_net(near)
    order = list(dict.fromkeys(k for pair in springs for k in pair))   # first appearance
    assert len(atoms) == len(order)
    np.testing.assert_allclose(atoms.positions, points[order], rtol=0,
                               atol=0.2 * MERGE_TOLERANCE * diagonal)
    rank = {k: n for n, k in enumerate(order)}
    assert pairs(atoms.calc.springs) == sorted(tuple(sorted((rank[i], rank[j])))
                                               for i, j in springs)
    vertices = np.array([line.split()[1:] for line in near.read_text().splitlines()
                         if line.startswith('v ')], dtype=float)
    first = {}   # the file's first copy of each point: vertex 2 s + end of spring s
    for s, pair in enumerate(springs):
        for end, k in enumerate(pair):
            first.setdefault(k, 2 * s + end)
    np.testing.assert_array_equal(atoms.positions, vertices[[first[k] for k in order]])
    far = tmp_path / 'far.obj'
    far.write_text(rhino_lines(points, springs, 10 * MERGE_TOLERANCE * diagonal, seed))
    assert len(read_net(far, a=1.0)) == 2 * len(springs)


@pytest.mark.parametrize('seed', range(3))
def test_merge_coincident_against_all_pairs(seed):
    """Clusters of copies within the tolerance, chains included, against
    the connected components of the all-pairs distance graph."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, 1, (20, 3))
    diagonal = np.linalg.norm(np.ptp(centres, axis=0))
    copies = centres[rng.integers(20, size=60)] + rng.uniform(
        -0.3, 0.3, (60, 3)) * MERGE_TOLERANCE * diagonal
    points = np.vstack([centres, copies])
    point_of, merged = merge_coincident(points)
    distance = np.linalg.norm(points[:, None] - points[None], axis=-1)
    tolerance = MERGE_TOLERANCE * np.linalg.norm(np.ptp(points, axis=0))
    same = distance <= tolerance
    assert (same == (point_of[:, None] == point_of[None])).all()
    assert len(merged) == 20
    np.testing.assert_array_equal(merged[point_of[:20]], centres)


CURVES = [
    ('v 0 0 0\nv 1 0 0\nv 2 1 0\ncstype rat bspline\ndeg 1\ncurv 0 2 1 2 \\\n 3\n'
     'parm u 0 0 1 2 2\nend\np 1\n', [[0, 1], [1, 2]]),
    ('v 0 0 0\nv 1 0 0\nv 1 0 0\nv 2 0 0\ncstype bezier\ndeg 1\ncurv 0 1 1 2\n'
     'curv 0 1 -2 -1\nl 1 4\n', [[0, 1], [1, 2], [0, 2]]),
]


@pytest.mark.parametrize('text, springs', CURVES)
def test_curves_of_degree_one_are_polylines(tmp_path, text, springs):
    """Rational and Bezier curves of degree 1, a statement continued on the
    next line, negative indices, and a vertex written twice, merged."""
    (tmp_path / 'c.obj').write_text(text)
    assert read_obj(tmp_path / 'c.obj').springs.tolist() == springs


BROKEN_CURVES = [
    ('v 0 0 0\nv 1 0 0\ncurv 0 1 1 2\n', r'line 3: a .curv. needs .cstype. and .deg.'),
    ('v 0 0 0\nv 1 0 0\ncstype bspline\ndeg 3\ncurv 0 1 1 2\n',
     r"line 5: a curve of type 'bspline' and degree 3; only polylines"),
    ('v 0 0 0\nv 1 0 0\ncstype cardinal\ndeg 1\ncurv 0 1 1 2\n',
     r"line 5: a curve of type 'cardinal'"),
    ('v 0 0 0\nv 1 0 0\ncstype bspline\ndeg x\n', r'line 4: expected a degree'),
    ('v 0 0 0\nv 1 0 0\ncstype bspline\ndeg 1\ncurv 0 u 1 2\n',
     r'line 5: expected .curv u0 u1 v1 v2 ....'),
    ('v 0 0 0\nv 1 0 0\ncstype bspline\ndeg 1\ncurv 0 1 1\n', r'line 5: a .curv. needs its'),
    ('v 0 0 0\nv 1 0 0\ncstype bspline\ndeg 1\ncurv 0 1 1 3\n',
     r'line 5: curve index 3 out of range \(2 vertices\)'),
    ('v 0 0 0\nv 1 0 0\nv 0 0 1e-12\nl 2 1 3\n',
     r'line 4: vertex 1 and vertex 3 next to it are one point \(closer than 1e-09'),
]


@pytest.mark.parametrize('text, message', BROKEN_CURVES)
def test_malformed_curves_name_the_line(tmp_path, text, message):
    (tmp_path / 'c.obj').write_text(text)
    with pytest.raises(ValueError, match=r'c\.obj ' + message):
        read_net(tmp_path / 'c.obj')


def crlf_obj(tmp_path, seed):
    """The quad net as a CRLF OBJ with coordinates of 3 decimals (some with
    trailing zeros), comments (one not ASCII, some on vertex lines), tabs,
    groups and normals."""
    positions, quads, *_ = quad_net(5, seed)
    lines = ['# exported, Größe in m', 'g net', 'vn 0 0 1']
    for n, p in enumerate(np.round(positions, 3)):
        text = ' '.join(f'{c:.3f}' for c in p)
        lines.append(f'v\t{text}  # point {n}' if n % 7 == 0 else
                     f'v {text}#' if n % 5 == 0 else f'v {text}')
    lines += ['f ' + ' '.join(f'{i + 1}//1' for i in q) for q in quads]
    path = tmp_path / 'crlf.obj'
    path.write_bytes(('\r\n'.join(lines) + '\r\n').encode())
    return path


@pytest.mark.parametrize('seed', range(3))
def test_obj_write_back_keeps_the_file(tmp_path, seed):
    """CRLF stays CRLF; every line but the coordinates of moved points is
    byte for byte the original; a moved coordinate is the shortest text that
    reads back as the float, an unmoved one keeps its text ('1.500')."""
    path = crlf_obj(tmp_path, seed)
    atoms = read_net(path)
    rng = np.random.default_rng(seed)
    moved = rng.random(len(atoms)) < 0.5
    atoms.positions[moved] += rng.normal(size=(moved.sum(), 3))
    write_net(tmp_path / 'out.obj', atoms, like=path)
    old = path.read_bytes().split(b'\r\n')
    new = (tmp_path / 'out.obj').read_bytes().split(b'\r\n')
    assert len(new) == len(old) and b'\n' not in b''.join(new)
    rows = [n for n, line in enumerate(old) if line.startswith(b'v') and not
            line.startswith(b'vn')]
    assert [n for n, (a, b) in enumerate(zip(old, new, strict=True)) if a != b] == \
        [rows[k] for k in np.flatnonzero(moved)]
    for k, n in enumerate(rows):
        before, after = (line.decode().split('#')[0].split() for line in (old[n], new[n]))
        tokens = after[1:4]
        np.testing.assert_array_equal(np.array(tokens, dtype=float), atoms.positions[k])
        for token, value in zip(tokens, atoms.positions[k], strict=True):
            assert token == repr(float(value)) or token in before
        assert new[n].endswith(old[n][len(old[n].split(b'#')[0].rstrip()):]) or moved[k]
    np.testing.assert_array_equal(read_net(tmp_path / 'out.obj').positions, atoms.positions)


@pytest.mark.parametrize('seed', range(3))
def test_json_write_back_keeps_the_layout(tmp_path, seed):
    """An indented CRLF COMPAS mesh with integer coordinates and a byte-order
    mark: only the moved numbers change, each to its float's repr."""
    path, positions, *_ = write_quad_net(tmp_path, 'mesh2.json', seed=seed)
    document = json.loads(path.read_text())
    for attributes in document['data']['vertex'].values():
        attributes['x'] = round(attributes['x'])   # integers, as some files hold
    text = json.dumps(document, indent=4).replace('\n', '\r\n')
    path.write_bytes(b'\xef\xbb\xbf' + text.encode())
    atoms = read_net(path)
    rng = np.random.default_rng(seed)
    moved = rng.random(len(atoms)) < 0.5
    atoms.positions[moved] += rng.normal(size=(moved.sum(), 3))
    write_net(tmp_path / 'out.json', atoms, like=path)
    out = (tmp_path / 'out.json').read_bytes()
    assert out.startswith(b'\xef\xbb\xbf') and out.count(b'\r\n') == text.count('\r\n')
    expected = json.loads(text)
    for attributes, x, m in zip(expected['data']['vertex'].values(), atoms.positions, moved,
                                strict=True):
        if m:
            attributes.update(zip('xyz', map(float, x), strict=True))
    assert out.decode('utf-8-sig') == json.dumps(expected, indent=4).replace('\n', '\r\n')
    np.testing.assert_array_equal(read_net(tmp_path / 'out.json').positions, atoms.positions)


def test_json_write_back_of_a_default_coordinate(tmp_path):
    """A vertex whose z comes from the default attributes and moves in z: the
    document is written anew, with the new z."""
    path = tmp_path / 'm.json'
    path.write_text('{"dva": {"z": 0.0}, "vertex": {"0": {"x": 0, "y": 0}, "1": {"x": 1, '
                    '"y": 0}, "2": {"x": 0, "y": 1}}, "face": {"0": [0, 1, 2]}}')
    atoms = read_net(path)
    atoms.positions[2, 2] = 0.25
    write_net(tmp_path / 'out.json', atoms, like=path)
    np.testing.assert_array_equal(read_net(tmp_path / 'out.json').positions, atoms.positions)


@pytest.mark.parametrize('kind', ['obj', 'mesh2.json'])
@pytest.mark.parametrize('seed', range(5))
def test_moved_coordinates_are_shortest_exact_text(tmp_path, kind, seed):
    """Coordinates of nets of any size (1e-9 to 1e9) come back exactly, each
    written as repr: no longer than 17 significant digits and as short as
    any text that reads back as the float."""
    path, *_ = write_quad_net(tmp_path, kind, seed=seed)
    atoms = read_net(path)
    rng = np.random.default_rng(seed)
    atoms.positions = rng.normal(size=atoms.positions.shape) * 10.0 ** rng.uniform(-9, 9)
    out = tmp_path / f'out.{kind}'
    write_net(out, atoms, like=path)
    np.testing.assert_array_equal(read_net(out).positions, atoms.positions)
    text = out.read_text()
    for x in atoms.positions.ravel():
        token = repr(float(x))
        assert token in text and len(token) <= len(f'{x:.17g}') + 2   # '.0' or 'e-05'
        shorter = [f'{x:.{digits}g}' for digits in range(1, 17)]
        assert not [t for t in shorter if float(t) == x and len(t) < len(token)]
