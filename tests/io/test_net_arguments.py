"""Every argument of the net readers and writers (ase_maud.io.nets) checked where
it enters: frames, COMPAS edges listed twice, write_net's calculator, sizes a
file declares, continued OBJ vertices, huge numbers, repeated fixed points.
Each case was silently wrong, a hang or a raw error before."""

import json
import re

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.emt import EMT

import ase_maud.io.nets
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_net

from helpers import one_line_error, write_quad_net


@pytest.mark.parametrize('index', [-999, 4, -5, 10**6])
def test_a_frame_past_the_end_is_refused(four_frames, index):
    for path in four_frames:
        with pytest.raises(ValueError, match=re.escape(
                f'{path}: no frame {index}: the file holds 4 frames (0 to 3, or -1 to -4)')):
            read_net(path, index=index)


def test_every_frame_in_range_is_read(four_frames):
    for path in four_frames:
        xs = [read_net(path, index=i).positions[0, 0] for i in range(-4, 4)]
        assert np.allclose(xs[:4], xs[4:]) and len(set(np.round(xs[:4], 9))) == 4
    with pytest.raises(ValueError, match='index must be a whole number'):
        read_net(four_frames[0], index=1.0)


def test_frame_of_a_one_frame_format(capsys, tmp_path):
    net, *_ = write_quad_net(tmp_path, 'obj', n=4, seed=2)
    for index in (0, -1):
        assert len(read_net(net, index=index)) == 16
    for index in (1, -2, 5):
        with pytest.raises(ValueError, match=r'holds one frame \(index 0 or -1\)'):
            read_net(net, index=index)
    assert 'no frame 5' in one_line_error(capsys, ['classify', net, '--frame', '5'])


def compas_graph(path, q_one_way, q_other_way, seed):
    """A 3-node COMPAS graph listing edge 0-1 both ways, with random points."""
    rng = np.random.default_rng(seed)
    node = {str(n): dict(zip('xyz', map(float, rng.normal(size=3)), strict=True))
            for n in range(3)}
    node['0']['is_anchor'] = node['2']['is_anchor'] = True
    edge = {'0': {'1': {'q': q_one_way}}, '1': {'0': {'q': q_other_way}, '2': {}}}
    path.write_text(json.dumps({'dtype': 'compas.datastructures/Graph',
                                'data': {'node': node, 'edge': edge}}))
    return path


@pytest.mark.parametrize('seed', [3, 4])
def test_an_edge_listed_both_ways_with_two_q_is_refused(tmp_path, seed):
    path = compas_graph(tmp_path / 'g.json', 2, 5, seed)
    with pytest.raises(ValueError, match=r'g.json: edge 0-1 is listed both ways with '
                                         r'different q \(2.0 and 5.0\)'):
        read_net(path)
    compas_graph(path, 2, 2, seed)
    atoms = read_net(path)
    assert atoms.calc.springs.tolist() == [[0, 1], [1, 2]]
    assert atoms.calc.parameters['q'].tolist() == [2, 1]
    atoms.calc.set(q=[3.0, 1.0])
    write_net(tmp_path / 'h.json', atoms, like=path)   # both listings get the new q
    assert read_net(tmp_path / 'h.json').calc.parameters['q'].tolist() == [3, 1]


def test_write_net_needs_a_maud_calculator(tmp_path):
    atoms = Atoms('H3', positions=np.random.default_rng(5).normal(size=(3, 3)))
    with pytest.raises(ValueError, match='needs its MaudCalculator .* no calculator'):
        write_net(tmp_path / 'n.obj', atoms)
    atoms.calc = EMT()
    with pytest.raises(ValueError, match='needs its MaudCalculator .* a EMT'):
        write_net(tmp_path / 'n.traj', atoms)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize('text, line', [
    ('100000000\n\nH 0 0 0\nH 1 0 0\n', 1),
    ('2\n\nH 0 0 0\nH 1 0 0\n100000000\n\nH 0 0 0\n', 5),
    ('5\n\nH 0 0 0\n', 1)])
def test_an_xyz_count_beyond_the_file_is_refused_before_ase_reads(tmp_path, monkeypatch,
                                                                  text, line):
    path = tmp_path / 'big.xyz'
    path.write_text(text)

    def never(*args, **kwargs):
        raise AssertionError('ase.io.read reached')

    monkeypatch.setattr(ase_maud.io.nets.ase.io, 'read', never)
    with pytest.raises(ValueError, match=rf'big.xyz line {line}: declares \d+ atoms, '
                                         r'but the \d+ bytes after it hold at most \d+'):
        read_net(path)


def test_a_continued_obj_vertex_is_refused_with_its_line(tmp_path):
    rng = np.random.default_rng(6)
    x = rng.normal(size=(3, 3)).round(6).tolist()
    path = tmp_path / 'c.obj'
    path.write_text(f'v {x[0][0]} {x[0][1]} {x[0][2]}\nv {x[1][0]} {x[1][1]} \\\n'
                    f' {x[1][2]}\nv {x[2][0]} {x[2][1]} {x[2][2]}\nl 1 2 3\n')
    with pytest.raises(ValueError, match=r"c.obj line 2: a 'v' statement goes on"):
        read_net(path)
    path.write_text(f'v {x[0][0]} {x[0][1]} {x[0][2]}\nv {x[1][0]} {x[1][1]} {x[1][2]}\n'
                    f'v {x[2][0]} {x[2][1]} {x[2][2]}\nl 1 \\\n 2 3\n')
    atoms = read_net(path, fixed=[0, 2])   # other statements go on as before
    assert atoms.calc.springs.tolist() == [[0, 1], [1, 2]]
    atoms.positions[1] += 0.5
    write_net(tmp_path / 'd.obj', atoms, like=path)
    assert np.allclose(read_net(tmp_path / 'd.obj').positions, atoms.positions)


def test_a_400_digit_coordinate_is_a_clear_error(tmp_path):
    path = compas_graph(tmp_path / 'g.json', 1, 1, 7)
    data = json.loads(path.read_text())
    data['data']['node']['1']['x'] = 10**400
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r'g.json: vertex 1 has x = 1000.* \(401 digits\), '
                                         'beyond the float64 range'):
        read_net(path)


def test_a_fixed_point_given_twice(capsys, tmp_path):
    net, *_ = write_quad_net(tmp_path, 'obj', n=4, seed=8)
    fixed = tmp_path / 'twice.txt'
    fixed.write_text('0 3\n# again\n5 3\n')
    error = one_line_error(capsys, ['classify', net, '--fix', fixed])
    assert f'{fixed} line 3: point 3 repeats line 1' in error
    with pytest.raises(ValueError, match='fixed point 3 is given twice'):
        read_net(net, fixed=[3, 0, 3])
