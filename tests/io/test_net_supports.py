"""Supports by rule when a net is read (ase_maud.io.nets: a mesh's boundary, a
network's leaves, compas anchors), the a of a net read from a file, and relax's
warnings and --fix from the command line."""

import numpy as np
import pytest

from ase_maud import Maud
from ase_maud.cli.command import main
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import mean_spring_length, read_net
from ase_maud.physics.topology import A_PER_MEAN_SPRING, support_excursion

from helpers import quad_net, write_quad_net


@pytest.mark.parametrize('kind', ['obj', 'mesh2.json', 'mesh1.json'])
@pytest.mark.parametrize('seed', range(2))
def test_read_net_fixes_the_boundary_of_a_mesh(tmp_path, kind, seed):
    path, _, _, boundary = write_quad_net(tmp_path, kind, n=int(3 + seed * 3), seed=seed)
    atoms = read_net(path, fixed='boundary')
    assert atoms.constraints[0].index.tolist() == boundary.tolist()


def test_read_net_fixes_the_leaves_of_a_network(tmp_path):
    path = tmp_path / 'star.obj'
    path.write_text('v 0 0 0\nv 1 0 0\nv 0 1 0\nv -1 0 1\nv -2 0 1\nl 2 1 3\nl 1 4 5\n')
    atoms = read_net(path, fixed='leaves')
    assert atoms.constraints[0].index.tolist() == [1, 2, 4]
    with pytest.raises(ValueError, match=r"star\.obj: fixed='boundary' needs a mesh's faces"):
        read_net(path, fixed='boundary')
    closed = tmp_path / 'tetra.obj'
    closed.write_text('v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 4 2\nf 2 4 3\n'
                      'f 1 3 4\n')
    with pytest.raises(ValueError, match=r"fixed='boundary' finds no point \(every edge"):
        read_net(closed, fixed='boundary')
    with pytest.raises(ValueError, match=r"fixed='leaves' finds no point"):
        read_net(closed, fixed='leaves')
    with pytest.raises(ValueError, match=r"fixed='bondary' is neither a rule \(boundary, "
                       r'outer, leaves\) nor a file'):
        read_net(path, fixed='bondary')
    (tmp_path / 'leaves').write_text('0 3\n')   # a file of that name, given as a Path
    assert read_net(path, fixed=tmp_path / 'leaves').constraints[0].index.tolist() == [0, 3]


@pytest.mark.parametrize('seed', range(3))
def test_a_of_a_file_is_a_fraction_of_its_mean_spring(tmp_path, seed):
    """Files without a stored a get the rule's (0, the force-density
    equilibrium, where supports hold every spring component); a trajectory
    keeps its own, the calculator's default 1 included; a given a wins."""
    path, positions, springs, _ = write_quad_net(tmp_path, 'obj', seed=seed)
    mean = np.mean([np.linalg.norm(positions[i] - positions[j]) for i, j in springs])
    assert read_net(path).calc.parameters['a'] == pytest.approx(A_PER_MEAN_SPRING * mean,
                                                                rel=1e-14)
    assert read_net(path, fixed='boundary').calc.parameters['a'] == 0.0
    assert read_net(path, fixed=[0]).calc.parameters['a'] == 0.0   # one component
    (tmp_path / 'two.txt').write_text('0 1\n2 3\n')
    assert read_net(path, edges=tmp_path / 'two.txt', fixed=[0]).calc.parameters['a'] \
        == pytest.approx(A_PER_MEAN_SPRING * np.linalg.norm(positions[0] - positions[1])
                         / 2 + A_PER_MEAN_SPRING * np.linalg.norm(positions[2] - positions[3])
                         / 2, rel=1e-14)
    assert read_net(path, a=2.5).calc.parameters['a'] == 2.5
    atoms = read_net(path, a=1.0)
    write_net(tmp_path / 'one.traj', atoms)
    assert read_net(tmp_path / 'one.traj').calc.parameters['a'] == 1.0


def test_relax_warns_when_a_balloons_the_net(tmp_path, capsys):
    """A quad net relaxed with a far above its spring length leaves its
    supports' box and is warned about, naming --a; with the default a (0, the
    force-density equilibrium) it is not, nor with the rule's a."""
    path, *_ = write_quad_net(tmp_path, 'obj', n=6, seed=0)
    traj = str(tmp_path / 'r.traj')
    assert main(['relax', str(path), '--fix', 'boundary', '--quiet', '--traj', traj]) == 0
    out, err = capsys.readouterr()
    assert 'a 0 (the force-density equilibrium: no repulsion)' in out
    assert 'warning' not in err
    a = A_PER_MEAN_SPRING * mean_spring_length(read_net(path).positions,
                                               read_net(path).calc.springs)
    assert main(['relax', str(path), '--fix', 'boundary', '--quiet', '--traj', traj,
                 '--a', repr(a)]) == 0
    out, err = capsys.readouterr()
    assert f'({A_PER_MEAN_SPRING:g} x the mean spring length at the start)' in out
    assert 'warning' not in err
    main(['relax', str(path), '--fix', 'boundary', '--a', '4', '--quiet', '--traj', traj])
    out, err = capsys.readouterr()
    relaxed = read_net(traj)
    beyond, diagonal = support_excursion(relaxed)
    assert beyond > diagonal / 10
    assert 'ase-maud: warning: the repulsion of a = 4 carries' in err and '--a' in err


def test_relax_fixes_by_rule_like_python(tmp_path, capsys):
    """--fix boundary from the command line gives the net relaxed in Python
    with the boundary's indices fixed."""
    path, positions, springs, boundary = write_quad_net(tmp_path, 'obj', seed=2)
    traj = str(tmp_path / 'r.traj')
    assert main(['relax', str(path), '--fix', 'boundary', '--fmax', '1e-8', '--quiet',
                 '--traj', traj]) == 0
    atoms = read_net(path, fixed=boundary.tolist())
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-8, steps=500)
    np.testing.assert_allclose(read_net(traj).positions, atoms.positions, atol=1e-7)
    assert quad_net(5, 2)[3].tolist() == read_net(traj).constraints[0].index.tolist()


@pytest.mark.parametrize('seed', range(3))
def test_compas_anchors_hold_unless_a_rule_is_given(tmp_path, seed):
    """is_anchor or is_fixed true (on the vertex or by default) fixes a point;
    a rule replaces them."""
    import json
    path, _, _, boundary = write_quad_net(tmp_path, 'mesh2.json', seed=seed)
    document = json.loads(path.read_text())
    rng = np.random.default_rng(seed)
    flags = rng.choice(['is_anchor', 'is_fixed', None], size=25)
    document['data']['default_vertex_attributes']['is_fixed'] = False
    for vertex, flag in zip(document['data']['vertex'].values(), flags, strict=True):
        if flag is not None:
            vertex[flag] = bool(rng.random() < 0.5)
    path.write_text(json.dumps(document))
    held = [n for n, (vertex, flag) in enumerate(zip(document['data']['vertex'].values(),
                                                    flags, strict=True))
            if flag is not None and vertex[flag]]
    atoms = read_net(path)
    assert (atoms.constraints[0].index.tolist() if held else atoms.constraints) == (
        held if held else [])
    assert read_net(path, fixed='boundary').constraints[0].index.tolist() == boundary.tolist()
