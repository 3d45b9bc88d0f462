"""Inputs read exactly or refused with the file, line and reason (issue 52,
item 2): face indices out of range (negative included), faces listed twice,
meshio's failures (its SystemExit included), OFF of any face size; and every
writer's file read back to the scene that wrote it, under the options that
wrote it (q and Q, loads, a)."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

from ase_maud.bench.hard_inputs import round_trip_scene
from ase_maud.form.force_density import solve_force_density
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_net
from ase_maud.scenes.catalogue import build

PLY = ('ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n'
       'property float z\nelement face {faces}\nproperty list uchar int vertex_indices\n'
       'end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n{rows}')


def ply(tmp_path, *faces):
    path = tmp_path / 'net.ply'
    path.write_text(PLY.format(faces=len(faces), rows=''.join(
        f'{len(f)} {" ".join(map(str, f))}\n' for f in faces)))
    return path


@pytest.mark.parametrize('bad', [-1, -4, 4, 99])
def test_a_ply_face_index_out_of_range_is_refused(tmp_path, bad):
    with pytest.raises(ValueError, match=r'net\.ply: triangle 1 .* 4 points'):
        read_net(ply(tmp_path, (0, 1, 2), (0, 2, bad)))


def test_off_of_any_face_size_colours_and_normals(tmp_path):
    cases = {'quad.off': 'OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n',
             'colour.off': 'OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 255 0 0\n',
             'normals.off': ('NOFF\n# a comment\n4 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n'
                             '1 1 0 0 0 1\n0 1 0 0 0 1\n4 0 1 2 3\n'),
             'counts.off': 'OFF 4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n'}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        atoms = read_net(tmp_path / name, fixed='boundary')
        assert sorted(map(tuple, atoms.calc.springs.tolist())) == [(0, 1), (0, 3), (1, 2),
                                                                   (2, 3)], name


@pytest.mark.parametrize('text, said', [
    ('OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 5\n', 'line 6: face index 5'),
    ('OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 -1\n', 'line 6: face index -1'),
    ('OFF\n3 1 0\n0 0 0\n1 x 0\n1 1 0\n3 0 1 2\n', 'line 4: expected a vertex'),
    ('OFF\n3 2 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 2\n', '3 vertices and 2 faces declared'),
    ('4OFF\n1 0 0\n0 0 0 1\n', 'line 1'),
    ('OFF BINARY\n', 'line 1')])
def test_a_malformed_off_names_its_line(tmp_path, text, said):
    (tmp_path / 'bad.off').write_text(text)
    with pytest.raises(ValueError, match=said):
        read_net(tmp_path / 'bad.off')


def test_meshio_failures_are_named_never_an_exit(tmp_path):
    """A VTK polyline (meshio exits), an empty STL (meshio's IndexError):
    ValueErrors naming the file, the interpreter alive."""
    (tmp_path / 'line.vtk').write_text(
        '# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n'
        '0 0 0 1 0 0 1 1 0 0 1 0\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n4\n')
    (tmp_path / 'empty.stl').write_text('solid x\nendsolid x\n')
    (tmp_path / 'nothing.stl').write_bytes(b'')
    for name in ('line.vtk', 'empty.stl', 'nothing.stl'):
        with pytest.raises(ValueError, match=name.replace('.', r'\.')):
            read_net(tmp_path / name)
    run = subprocess.run([sys.executable, '-m', 'ase_maud', 'relax', 'line.vtk'],
                         cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert run.returncode == 2 and run.stderr.count('\n') == 1 and 'line.vtk' in run.stderr


def test_a_face_listed_twice_is_read_once_with_a_note(tmp_path):
    path = ply(tmp_path, (0, 1, 2), (0, 2, 3), (2, 1, 0))
    with pytest.warns(UserWarning, match='face 2, 0-based, repeats face 0'):
        atoms = read_net(path, fixed='boundary')
    assert sorted(atoms.constraints[0].index.tolist()) == [0, 1, 2, 3]
    (tmp_path / 'twice.obj').write_text('v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n'
                                        'f 1 2 3\nf 1 3 4\nf 1 2 3\n')
    with pytest.warns(UserWarning, match='listed again'):
        atoms = read_net(tmp_path / 'twice.obj', fixed='boundary')
    assert sorted(atoms.constraints[0].index.tolist()) == [0, 1, 2, 3]


def forces_of(atoms):
    return atoms.get_potential_energy(), atoms.get_forces()


@pytest.mark.parametrize('seed', range(3))
def test_compas_json_comes_back_as_written(tmp_path, seed):
    """q and Q, loads, a: the default read and the read with the options
    that wrote it give the scene written (a = 0 too)."""
    atoms = round_trip_scene(seed)
    for a in (atoms.calc.parameters['a'], 0.0):
        atoms.calc.set(a=a)
        write_net(tmp_path / 'net.json', atoms)
        energy, forces = forces_of(atoms)
        options = {'a': a, 'Q': atoms.calc.parameters['Q']}
        for given in ({}, options):
            back = read_net(tmp_path / 'net.json', **given)
            assert back.calc.parameters['Q'] == options['Q']
            assert back.calc.parameters['a'] == a
            np.testing.assert_allclose(forces_of(back)[1], forces, rtol=1e-12, atol=1e-12)
            assert forces_of(back)[0] == pytest.approx(energy, rel=1e-12)


@pytest.mark.parametrize('kind', ['traj', 'json'])
def test_every_stored_parameter_comes_back(tmp_path, kind):
    atoms = round_trip_scene(7)
    write_net(tmp_path / f'net.{kind}', atoms)
    back = read_net(tmp_path / f'net.{kind}')
    np.testing.assert_allclose(forces_of(back)[1], forces_of(atoms)[1], rtol=1e-12,
                               atol=1e-12)


@pytest.mark.parametrize('kind', ['obj', 'xyz'])
def test_formats_without_parameters_come_back_under_the_options(tmp_path, kind):
    """OBJ and XYZ hold points, springs (and XYZ the supports): read with
    the options that wrote them, the scene is the one written."""
    atoms = build('hanging_net', 5, seed=3)
    atoms.calc.set(a=0.4, Q=2.0)
    write_net(tmp_path / f'net.{kind}', atoms)
    fixed = atoms.constraints[0].index.tolist()
    back = read_net(tmp_path / f'net.{kind}', a=0.4, Q=2.0, fixed=fixed, dim=3)
    np.testing.assert_allclose(back.positions, atoms.positions, rtol=0, atol=0)
    np.testing.assert_allclose(forces_of(back)[1], forces_of(atoms)[1], rtol=1e-12,
                               atol=1e-12)


def test_cli_relax_with_q_out_json_is_an_equilibrium_when_read_back(tmp_path):
    """relax --Q 2 --out r.json: r.json read with --Q 2 (and without) is at
    the equilibrium relax reached."""
    from ase_maud.cli.command import main
    write_net(tmp_path / 'net.obj', build('hanging_net', 5, seed=2))
    fixed = tmp_path / 'fixed.txt'
    fixed.write_text('\n'.join(map(str, build('hanging_net', 5, seed=2).constraints[0]
                                   .index.tolist())) + '\n')
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        status = main(['relax', str(tmp_path / 'net.obj'), '--fix', str(fixed), '--Q', '2',
                       '--a', '0.5', '--load', '0', '0', '-1e-1', '--quiet', '--fmax', '1e-6',
                       '--traj', str(tmp_path / 'r.traj'), '--out', str(tmp_path / 'r.json')])
    assert status == 0
    for given in ({}, {'Q': 2.0, 'a': 0.5}):
        back = read_net(tmp_path / 'r.json', **given)
        assert np.linalg.norm(back.get_forces(), axis=1).max() < 1e-6


def test_an_overflowing_force_density_solve_is_refused():
    atoms = build('hanging_net', 5, seed=1)
    atoms.calc.set(a=0.0, loads=np.tile([0.0, 0.0, -1e306], (len(atoms), 1)),
                   q=np.full(len(atoms.calc.springs), 1e-10))
    start = atoms.positions.copy()
    with pytest.raises(ValueError, match='overflows'):
        solve_force_density(atoms)
    assert np.array_equal(atoms.positions, start)
